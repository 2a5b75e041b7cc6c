"""The layout promises of docs/architecture.md: the import-linter contracts of pyproject.toml
hold (stages layered, the core bpy-free, no synthetic tools in the product, no cycles), the
core's top level holds only stage subpackages, no module grows past ~600 lines, and there is
one import name for every module."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from conftest import ROOT

PACKAGES = ("core", "addon", "cli", "synthetic", "demo")


def test_import_linter_contracts_hold():
    lint = Path(sys.executable).parent / "lint-imports"
    res = subprocess.run([str(lint)], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "Contracts: 6 kept, 0 broken." in res.stdout


def test_core_top_level_holds_only_stage_packages():
    modules = sorted(p.name for p in (ROOT / "core").glob("*.py"))
    assert modules == ["__init__.py"]
    stages = sorted(p.name for p in (ROOT / "core").iterdir() if (p / "__init__.py").is_file())
    assert stages == ["capture", "common", "face", "geometry", "retarget", "take", "track"]


def test_no_module_over_600_lines():
    long = {str(p.relative_to(ROOT)): n for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")
            if (n := len(p.read_text().splitlines())) > 620}
    assert not long, long


def test_one_import_name_for_the_core():
    """``core`` is ``mirrorcap.core`` only: importing it as a top-level package fails, so no
    file can load as two modules."""
    res = subprocess.run([sys.executable, "-c", "import core"], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode != 0 and "mirrorcap.core" in res.stderr
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            text = path.read_text()
            assert "from mirrorcap" not in text and "import mirrorcap" not in text, path


def test_the_test_suite_runs_in_a_folder_that_is_no_python_name(tmp_path):
    """A clone in "mirrorcap-main" (a GitHub zip) or "my clone": pytest collects the repository's root as a package
    it cannot name and imports its ``__init__.py`` alone, as "__init__", before every test (397 errors in a clone
    in "clone dir", stop 52). The file then defines nothing and raises nothing; imported as the package it is, it
    gives the version."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("__init__", ROOT / "__init__.py")
    alone = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(alone)                      # no parent package: its relative import would raise
    assert not hasattr(alone, "__version__") and callable(alone.register)
    import mirrorcap

    assert mirrorcap.__version__ == mirrorcap.core.__version__
