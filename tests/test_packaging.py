"""Repository promises: core is bpy-free, the extension manifest is valid for
Blender's own tool, the add-on registers in a real bpy session, versions agree."""

from __future__ import annotations

import pkgutil
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from conftest import ROOT

from mirrorcap import core


def _core_modules():
    return sorted(m.name for m in pkgutil.walk_packages(core.__path__, "mirrorcap.core."))


def test_importing_all_of_core_never_imports_bpy():
    mods = _core_modules()
    assert {"mirrorcap.core.geometry.mirror", "mirrorcap.core.geometry.camera", "mirrorcap.core.geometry.reconstruct",
            "mirrorcap.core.track.tracker"} <= set(mods)
    code = (
        "import importlib, sys\n"
        f"for m in {mods!r}: importlib.import_module(m)\n"
        "import mirrorcap.cli.parser; mirrorcap.cli.parser.build_parser()\n"
        "bad = [m for m in ('bpy', 'mathutils', 'bmesh') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == ""


def test_core_source_has_no_blender_imports_and_uses_relative_imports():
    paths = list((ROOT / "core").rglob("*.py"))
    assert len(paths) > 30
    for path in paths:
        text = path.read_text()
        assert not re.search(r"^\s*(import|from)\s+(bpy|mathutils|bmesh)\b", text, re.M), path
        # inside Blender the package is bl_ext.<repo>.mirrorcap: absolute `core.` imports would break
        assert not re.search(r"^\s*(from|import)\s+core\b", text, re.M), path


def _blender_ext_tool():
    import importlib.util

    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        pytest.fail("bpy is not installed in this environment (see requirements.txt)")
    tool = Path(spec.origin).parent / "5.0" / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    assert tool.is_file(), tool
    return tool


def test_manifest_validates_with_blenders_tool():
    res = subprocess.run([sys.executable, str(_blender_ext_tool()), "validate", str(ROOT)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "success" in (res.stdout + res.stderr).lower()


def test_versions_agree():
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert manifest["version"] == project["project"]["version"] == core.__version__
    assert manifest["blender_version_min"] == "4.2.0"
    excluded = manifest["build"]["paths_exclude_pattern"]
    for folder in ("/tests/", "/sample_scenes/*", "/benchmarks/", "/tools/"):
        assert folder in excluded
    # of the samples only the generic head ships (Add Generic Head); test_addon checks the zip
    assert "!/sample_scenes/generic_head/" in excluded


def test_addon_registers_in_bpy():
    """The extension package imports and registers inside a headless bpy session."""
    code = (
        "import mirrorcap as pkg\n"
        f"assert pkg.__file__.startswith({str(ROOT)!r}), pkg.__file__\n"
        "import bpy\n"
        "pkg.register()\n"
        "assert bpy.app.driver_namespace['mirrorcap_version'] == pkg.__version__\n"
        "pkg.unregister()\n"
        "assert 'mirrorcap_version' not in bpy.app.driver_namespace\n"
        "print('ok', bpy.app.version_string)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "ok 5.0" in res.stdout


def test_requirements_are_pinned():
    for name in ("requirements.txt", "requirements-dev.txt"):
        for line in (ROOT / name).read_text().splitlines():
            line = line.split("#")[0].strip()
            if line and not line.startswith("-r"):
                assert re.fullmatch(r"[A-Za-z0-9_.\-]+==[0-9][A-Za-z0-9_.]*", line), f"{name}: {line}"
