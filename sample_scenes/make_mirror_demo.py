"""Make the embedded mirror-demo sample: ``sample_scenes/mirror_demo/``.

A synthetic two-mirror face rig (core.simulate.face_rig): 150 markers on a
face-sized surface 600 mm from a 1280x720 camera with mild lens distortion, two
mirrors beside the cheeks. Every marker seen directly and in a mirror becomes a
correspondence, observed with 0.15 px Gaussian noise (sub-pixel marker
extraction); 5 % of the correspondences are then deliberately wrong (swapped
with another marker's mirror image) to exercise the robust estimate.

Files written (deterministic, seed 7):

* ``pairs.csv``   -- PAIRS.csv (see core/pairs.py)
* ``camera.json`` -- CAMERA.json
* ``truth.csv``   -- id,x,y,z of every marker in millimetres (camera frame)
* ``truth.json``  -- the true mirror planes, the wrong pairs, and the known length
  the demo uses (the two markers furthest apart among those seen in both mirrors)

Run from the repository root:  python sample_scenes/make_mirror_demo.py
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mirrorcap.core.common.files import write_files_atomically  # noqa: E402
from mirrorcap.core.take.pairs import format_pairs, format_points  # noqa: E402
from mirrorcap.synthetic.simulate import face_rig, observe  # noqa: E402

SEED = 7
NOISE_PX = 0.15
WRONG_FRACTION = 0.05


def main(out_dir: Path = ROOT / "sample_scenes" / "mirror_demo") -> None:
    rig = face_rig(n_markers=150, seed=SEED, dist=[-0.08, 0.03, 0.0005, -0.0003, 0.0])
    rng = np.random.default_rng(SEED)
    direct, mirrored = observe(rig.points, rig.planes, rig.camera, noise_px=NOISE_PX, rng=rng)
    visible = rig.visible_mirror & rig.visible_direct[None]
    ids = [f"m{i:03d}" for i in range(len(rig.points))]
    # Wrong correspondences: swap mirror images between markers of the same mirror.
    wrong = []
    for k in range(visible.shape[0]):
        idx = np.flatnonzero(visible[k])
        n_bad = int(round(WRONG_FRACTION * idx.size))
        bad = rng.choice(idx, size=n_bad, replace=False)
        mirrored[k, bad] = mirrored[k, np.roll(bad, 1)]
        wrong += [{"id": ids[i], "mirror": k} for i in bad]
    both = np.flatnonzero(visible.all(axis=0))
    d = np.linalg.norm(rig.points[both, None] - rig.points[None, both], axis=-1)
    a, b = np.unravel_index(np.argmax(d), d.shape)
    seen = visible.any(axis=0)
    truth = {
        "description": "synthetic two-mirror face rig; see sample_scenes/make_mirror_demo.py",
        "seed": SEED,
        "noise_px": NOISE_PX,
        "mirrors": [{"normal": n.tolist(), "d": float(dd)} for n, dd in rig.planes],
        "wrong_pairs": wrong,
        "known_length": [ids[both[a]], ids[both[b]], float(d[a, b])],
        "markers_with_pairs": int(seen.sum()),
        "markers_in_both_mirrors": int(both.size),
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    write_files_atomically({
        out_dir / "pairs.csv": format_pairs(ids, direct, mirrored, visible),
        out_dir / "camera.json": json.dumps(rig.camera.to_dict(), indent=2) + "\n",
        out_dir / "truth.csv": format_points([ids[i] for i in np.flatnonzero(seen)], rig.points[seen],
                                             ["+".join(str(k) for k in range(2) if visible[k, i])
                                              for i in np.flatnonzero(seen)]),
        out_dir / "truth.json": json.dumps(truth, indent=2) + "\n",
    })
    print(f"wrote {out_dir}: {int(visible.sum())} pairs for {int(seen.sum())} markers "
          f"({both.size} in both mirrors, {len(wrong)} wrong pairs)")


if __name__ == "__main__":
    main()
