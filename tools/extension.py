"""Build the MirrorCap Blender extension with its wheels bundled.

    python tools/extension.py fetch            # download the pinned wheels into wheels/
    python tools/extension.py build [--out D]  # fetch, validate, build one zip per platform
    python tools/extension.py validate         # Blender's own manifest check

The wheels Blender installs with the extension are listed in `blender_manifest.toml`
(`wheels = [...]`); this file pins each one's SHA-256. numpy is never bundled: Blender ships
it, and bpy 5.0.1 fixes it below 2. Every wheel is checked against its hash after download,
and the download lands under a temporary name first, so an interrupted fetch leaves nothing
that looks complete. Blender's tool (`blender_ext.py`, shipped inside the bpy wheel) does the
validation and the build; `--split-platforms` gives one zip per platform, each carrying only
its own wheels.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import os
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"

# filename -> (requirement, pip --platform tags, sha256). Keep in step with requirements.txt.
WHEELS: dict[str, tuple[str, tuple[str, ...], str]] = {
    "scipy-1.15.3-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl": (
        "scipy==1.15.3", ("manylinux_2_17_x86_64", "manylinux2014_x86_64"),
        "39cb9c62e471b1bb3750066ecc3a3f3052b37751c7c3dfd0fd7e48900ed52982"),
    "scipy-1.15.3-cp311-cp311-win_amd64.whl": (
        "scipy==1.15.3", ("win_amd64",),
        "ae48a786a28412d744c62fd7816a4118ef97e5be0bee968ce8f0a2fba7acf3bb"),
    "scipy-1.15.3-cp311-cp311-macosx_14_0_arm64.whl": (
        "scipy==1.15.3", ("macosx_14_0_arm64",),
        "3b0334816afb8b91dab859281b1b9786934392aa3d527cd847e41bb6f45bee65"),
    "scipy-1.15.3-cp311-cp311-macosx_10_13_x86_64.whl": (
        "scipy==1.15.3", ("macosx_10_13_x86_64",),
        "993439ce220d25e3696d1b23b233dd010169b62f6456488567e830654ee37a6b"),
    "opencv_contrib_python_headless-4.11.0.86-cp37-abi3-manylinux_2_17_x86_64.manylinux2014_x86_64.whl": (
        "opencv-contrib-python-headless==4.11.0.86", ("manylinux_2_17_x86_64", "manylinux2014_x86_64"),
        "3e7a86bf02e8157a2d9fce26d44eaafd31113fc21fc8b4f44ff56c28ab32fdba"),
    "opencv_contrib_python_headless-4.11.0.86-cp37-abi3-win_amd64.whl": (
        "opencv-contrib-python-headless==4.11.0.86", ("win_amd64",),
        "2671a828e5c8ec9d237dd8506a9e0268487d37e07625725f1a6de5fa973ea7fa"),
    "opencv_contrib_python_headless-4.11.0.86-cp37-abi3-macosx_13_0_arm64.whl": (
        "opencv-contrib-python-headless==4.11.0.86", ("macosx_13_0_arm64",),
        "b34485c0164057726eee8cb80d5cd5dedaab5edde716451fb4107dcc60cf40f0"),
    "opencv_contrib_python_headless-4.11.0.86-cp37-abi3-macosx_13_0_x86_64.whl": (
        "opencv-contrib-python-headless==4.11.0.86", ("macosx_13_0_x86_64",),
        "ec88044ecb426549b05a8a6187e68051299848c4556ef8cef310621ca8f4316b"),
    "ezc3d-1.7.2-cp311-cp311-manylinux_2_24_x86_64.manylinux_2_28_x86_64.whl": (
        "ezc3d==1.7.2", ("manylinux_2_28_x86_64",),
        "ea7f255a397253ceb1c0367906084d4a53e6f4505770956105e748424bfec3e9"),
    "ezc3d-1.7.2-cp311-cp311-win_amd64.whl": (
        "ezc3d==1.7.2", ("win_amd64",),
        "cbd019a0deb42d0250cb8b984388734e616b69b38975b94318a4b7445de74085"),
    "ezc3d-1.7.2-cp311-cp311-macosx_11_0_arm64.whl": (
        "ezc3d==1.7.2", ("macosx_11_0_arm64",),
        "9c40b2e0a1886e9137dc50ecbf392f70130cbd53b7a24e371360b3f351c10965"),
    "ezc3d-1.7.2-cp311-cp311-macosx_10_9_x86_64.whl": (
        "ezc3d==1.7.2", ("macosx_10_9_x86_64",),
        "0254ac8fac4c2d5855db455eeb7cb8fe9dd5088e7bd1c287fbf65c0f2383dd7e"),
    "threadpoolctl-3.6.0-py3-none-any.whl": (
        "threadpoolctl==3.6.0", ("any",),
        "43a0b8fd5a2928500110039e43a5eed8480b918967083ea48dc3ab9f13c4a7fb"),
}


class BuildError(RuntimeError):
    pass


def manifest_wheels() -> list[str]:
    """The wheel paths the manifest lists (relative, './wheels/<file>')."""
    manifest = tomllib.loads(MANIFEST.read_text())
    return list(manifest.get("wheels", []))


def blender_ext_tool() -> Path:
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise BuildError("bpy is not installed: run `make venv` (requirements.txt pins bpy==5.0.1)")
    tool = Path(spec.origin).parent / "5.0" / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    if not tool.is_file():
        raise BuildError(f"Blender's extension tool is missing from the bpy wheel: {tool}")
    return tool


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def fetch(dest: Path = ROOT / "wheels", log=print) -> list[Path]:
    """Download every wheel the manifest lists (skipping ones already present with the right
    hash) and return their paths."""
    dest.mkdir(parents=True, exist_ok=True)
    listed = [Path(w).name for w in manifest_wheels()]
    unknown = sorted(set(listed) - set(WHEELS))
    if unknown:
        raise BuildError(f"the manifest lists wheels without a pinned hash in {__file__}: {unknown}")
    paths = []
    for name in listed:
        requirement, platforms, digest = WHEELS[name]
        target = dest / name
        if target.is_file() and sha256(target) == digest:
            paths.append(target)
            continue
        with tempfile.TemporaryDirectory(dir=dest, prefix=".fetch-") as tmp:
            cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
                   "--only-binary=:all:", "--python-version", "3.11", "--dest", tmp, requirement]
            for p in platforms:
                cmd += ["--platform", p]
            log(f"fetching {name}")
            res = subprocess.run(cmd, capture_output=True, text=True)
            got = Path(tmp) / name
            if res.returncode != 0 or not got.is_file():
                raise BuildError(f"could not download {name}: {res.stderr.strip()[-400:]}")
            if sha256(got) != digest:
                raise BuildError(f"{name}: SHA-256 does not match the pinned hash; refusing it")
            os.replace(got, target)
        paths.append(target)
    return paths


def run_tool(*args: str) -> str:
    res = subprocess.run([sys.executable, str(blender_ext_tool()), *args], capture_output=True, text=True)
    out = res.stdout + res.stderr
    if res.returncode != 0:
        raise BuildError(f"blender_ext {args[0]} failed:\n{out}")
    return out


def validate() -> str:
    return run_tool("validate", str(ROOT))


def build(out_dir: Path = ROOT / "dist", log=print) -> list[Path]:
    """Fetch the wheels, validate the manifest and build one zip per platform into out_dir."""
    fetch(log=log)
    validate()
    out_dir.mkdir(parents=True, exist_ok=True)
    before = set(out_dir.glob("*.zip"))
    log(run_tool("build", "--source-dir", str(ROOT), "--output-dir", str(out_dir), "--split-platforms").strip())
    zips = sorted(p for p in out_dir.glob("mirrorcap-*.zip") if p not in before or p.stat().st_size)
    if not zips:
        raise BuildError(f"Blender's tool reported success but wrote no zip into {out_dir}")
    return zips


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("fetch", help="download the pinned wheels into wheels/")
    sub.add_parser("validate", help="check blender_manifest.toml with Blender's tool")
    b = sub.add_parser("build", help="fetch, validate and build one zip per platform")
    b.add_argument("--out", type=Path, default=ROOT / "dist")
    args = parser.parse_args(argv)
    try:
        if args.command == "fetch":
            for p in fetch():
                print(p)
        elif args.command == "validate":
            print(validate().strip())
        else:
            for z in build(args.out):
                print(f"{z}  {z.stat().st_size / 1e6:.1f} MB")
    except BuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
