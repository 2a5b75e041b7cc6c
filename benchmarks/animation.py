"""Animation-half benchmarks (issue: head, fit, rig, bake).

* ``bake_1000``: ``mirrorcap bake`` of a 1,000-frame synthetic take (150 markers) onto the
  generic head, headless, in a fresh process each run (bpy import included in ``wall_s``).
* ``bake_long``: ``mirrorcap bake`` of 60 frames/s takes of 3,600 frames (both modes) and 12,000 frames (pca),
  one run each, with the process's peak resident memory (``os.wait4``): a long take is deformed a block of frames
  at a time and never held whole.
* ``fit``: the generic head fitted to scans of ~73k and ~291k vertices (the head, warped, scaled
  and turned, then subdivided), with the residual.
* ``rig``: the face rig driven by 150 markers of a faceunit performance against that
  performance's own vertex motion (face regions, 300 frames).
* ``pca``: reconstruction error against the number of modes, as in Rurainsky & Eisert's
  Table 2, for a 25-channel faceunit performance and for the rig's output of a take.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
HEAD = ROOT / "sample_scenes" / "generic_head"


def _face_mask(head):
    from mirrorcap.core.face.head import REGIONS

    face = np.zeros(len(head.vertices), bool)
    for r in REGIONS:
        face[head.members(f"region_{r}")] = True
    return face


#: runs ``mirrorcap`` and, as it exits, writes its own peak resident memory (Linux's VmHWM, kB) to stderr: a child's
#: ``ru_maxrss`` would count the high-water mark of the process it was forked from (the kernel keeps it across exec)
_PEAK_WRAPPER = (
    "import atexit, sys\n"
    "def _peak():\n"
    "    status = open('/proc/self/status').read()\n"
    "    print('PEAK_KB', status.split('VmHWM:')[1].split()[0], file=sys.stderr)\n"
    "atexit.register(_peak)\n"
    "from mirrorcap.cli import entry\n"
    "sys.argv[0] = 'mirrorcap'\n"
    "sys.exit(entry())\n"
)


def _peak_rss_run(args) -> tuple[float, float]:
    """Run ``mirrorcap ARGS`` in a fresh process: its wall seconds and its own peak resident memory in MB (Linux)."""
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", _PEAK_WRAPPER, *map(str, args)], cwd=ROOT, capture_output=True,
                         text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(res.stderr)
    peak_kb = [ln.split()[1] for ln in res.stderr.splitlines() if ln.startswith("PEAK_KB ")]
    return wall, float(peak_kb[-1]) / 1024.0


def _long_bakes(head, keys, tmp) -> list:
    from mirrorcap.core.take.c3d import write_c3d
    from mirrorcap.synthetic.headsim import synthetic_take

    rows = []
    for n_frames, modes in ((3600, ("frames", "pca")), (12000, ("pca",))):
        # the take alone is kept: its truth (F, V, 3) would be 1.3 GB at 12,000 frames, and a child forked from
        # this process counts the pages it shares in its own peak
        labels, pts = synthetic_take(head, keys, n_markers=150, n_frames=n_frames, seed=3)[:2]
        write_c3d(tmp / "long.c3d", labels, pts, 60.0)
        del labels, pts
        for mode in modes:
            wall, peak = _peak_rss_run(["bake", tmp / "long.c3d", "--head", HEAD / "head.blend", "-o",
                                        tmp / "long.blend", "--mode", mode, "--report", tmp / "long.json", "-q"])
            rep = json.loads((tmp / "long.json").read_text())
            rows.append({"frames": n_frames, "mode": mode, "wall_s": wall, "peak_rss_mb": peak,
                         "file_mb": (tmp / "long.blend").stat().st_size / 1e6,
                         **{k: rep[k] for k in ("pca_max_error_mm", "pca_mean_error_mm") if k in rep}})
    return rows


def run_animation_benchmark(repeats: int = 3) -> dict:
    from mirrorcap.core.face.bind import bind_take
    from mirrorcap.core.take.c3d import write_c3d
    from mirrorcap.core.face.facerig import FaceRig, RigSettings
    from mirrorcap.core.face.headfit import fit_head, subdivide
    from mirrorcap.core.face.headio import load_head_npz
    from mirrorcap.synthetic.headsim import SINGLE_UNITS, performance, synthetic_take
    from mirrorcap.core.geometry.rigid import rotation_zyx
    from mirrorcap.core.face.rbf import RBFScattering
    from mirrorcap.core.face.shapes import pca_error_table

    head, keys = load_head_npz(HEAD / "head.npz", with_shape_keys=True)
    out = {"head": {"vertices": int(len(head.vertices)), "shape_keys": len(keys)}}

    # -- bake 1,000 frames ------------------------------------------------------------
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        labels, pts, verts, disp, pose = synthetic_take(head, keys, n_markers=150, n_frames=1000, seed=11)
        write_c3d(tmp / "take.c3d", labels, pts, 30.0)
        (tmp / "report.json").write_text(json.dumps({"head_pose": pose.tolist()}))
        runs = {}
        for mode, extra in (("frames", []), ("pca", ["--modes", "8"])):
            walls, reports = [], []
            for _ in range(repeats):
                t0 = time.perf_counter()
                res = subprocess.run([sys.executable, "-m", "mirrorcap", "bake", tmp / "take.c3d", "--head",
                                      HEAD / "head.blend", "-o", tmp / f"{mode}.blend", "--mode", mode, *extra,
                                      "--head-pose", tmp / "report.json", "--report", tmp / "bake.json", "-q"],
                                     capture_output=True, text=True, cwd=ROOT)
                walls.append(time.perf_counter() - t0)
                if res.returncode != 0:
                    raise RuntimeError(res.stderr)
                reports.append(json.loads((tmp / "bake.json").read_text()))
            best = int(np.argmin(walls))
            runs[mode] = {"wall_s_fastest": min(walls), "wall_s_median": float(np.median(walls)),
                          "timings_s": reports[best]["timings_s"],
                          "file_mb": (tmp / f"{mode}.blend").stat().st_size / 1e6}
            if mode == "pca":
                runs[mode]["pca_max_error_mm"] = reports[best]["pca_max_error_mm"]
                runs[mode]["pca_mean_error_mm"] = reports[best]["pca_mean_error_mm"]
        out["bake_1000"] = runs
        out["bake_long"] = _long_bakes(head, keys, tmp)

    # -- fit to scans ---------------------------------------------------------------------
    rng = np.random.default_rng(0)
    c = head.vertices[rng.choice(len(head.vertices), 12, replace=False)]
    warped = head.vertices + RBFScattering(c, k=60.0)(head.vertices, rng.normal(0, 4.0, (12, 3)))
    truth = 1.06 * warped @ rotation_zyx(np.deg2rad([5, -8, 3])).T + [10, -20, 600]
    lms = {n: truth[i] for n, i in head.landmarks().items()}
    fits = []
    for levels in (2, 3):
        S, T = subdivide(truth, head.triangles(), levels)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            r = fit_head(head, S, T, lms)
            times.append(time.perf_counter() - t0)
        r0 = fit_head(head, S, T, lms, rounds=0)
        fits.append({"scan_vertices": int(len(S)), "seconds_fastest": min(times), "seconds_median": float(np.median(times)),
                     "residual_rms_mm": r.residual_rms_mm, "residual_p95_mm": r.residual_p95_mm,
                     "residual_max_mm": r.residual_max_mm, "landmark_only_residual_rms_mm": r0.residual_rms_mm,
                     "landmark_rms_mm": r.landmark_rms_mm, "rounds": r.rounds})
    out["fit"] = fits

    # -- rig against a faceunit performance ----------------------------------------------------
    labels, pts, verts, disp, pose = synthetic_take(head, keys, n_markers=150, n_frames=300, seed=12)
    b = bind_take(head, labels, pts, head_pose=pose)
    t0 = time.perf_counter()
    rig = FaceRig(head, b.vertices, RigSettings(blinks=False))
    t1 = time.perf_counter()
    D = rig.deform(b.displacements)
    t2 = time.perf_counter()
    face = _face_mask(head)
    for g in ("inner_lip_lower",):
        face[head.members(g)] = False
    err = np.linalg.norm(D - disp, axis=2)[:, face]
    mag = np.linalg.norm(disp, axis=2)[:, face]
    out["rig"] = {"markers": 150, "frames": 300, "setup_s": t1 - t0, "deform_s": t2 - t1,
                  "frames_per_s": 300 / (t2 - t1), "face_vertices": int(face.sum()),
                  "error_rms_mm": float(np.sqrt(np.mean(err ** 2))), "error_p95_mm": float(np.percentile(err, 95)),
                  "error_max_mm": float(err.max()), "motion_rms_mm": float(np.sqrt(np.mean(mag ** 2))),
                  "motion_max_mm": float(mag.max()), "markers_exact_mm": float(np.abs(D[:, b.vertices] - b.displacements).max())}

    # -- PCA error vs modes --------------------------------------------------------------------
    rich, _ = performance(head, keys, 300, seed=13, singles=SINGLE_UNITS)
    rig_b = FaceRig(head, b.vertices, RigSettings(blinks=True, blink_seed=1))
    take_def = rig_b.deform(b.displacements)
    ks = (1, 2, 3, 8, 23, 65)
    out["pca"] = {"faceunit_performance_25_channels": pca_error_table(rich, ks),
                  "rig_output_of_a_take_with_blinks": pca_error_table(take_def, ks)}
    return out


def animation_summary(a) -> list:
    b = a["bake_1000"]
    lines = ["", "## Head, fit, rig and bake (issue #5)", "",
             f"Generic head: {a['head']['vertices']} vertices, {a['head']['shape_keys']} faceunit shape keys.", "",
             "| bake of 1,000 frames (150 markers) | wall, fastest / median | read | bind + rig set-up | rig + shape keys | save | file |",
             "|---|---|---|---|---|---|---|"]
    for mode, r in b.items():
        t = r["timings_s"]
        lines.append(f"| `--mode {mode}` | {r['wall_s_fastest']:.2f} / {r['wall_s_median']:.2f} s | {t['read_s']:.2f} s | "
                     f"{t['bind_s']:.2f} s | {t['rig_and_keys_s']:.2f} s | {t['save_s']:.2f} s | {r['file_mb']:.1f} MB |")
    if "bake_long" in a:
        lines += ["", "| long bake, 60 frames/s, 150 markers | wall | peak resident memory | .blend | PCA error max / mean |",
                  "|---|---|---|---|---|"]
        for r in a["bake_long"]:
            pca = (f"{r['pca_max_error_mm']:.3f} / {r['pca_mean_error_mm']:.4f} mm" if "pca_max_error_mm" in r
                   else "--")
            lines.append(f"| {r['frames']:,} frames, `--mode {r['mode']}` | {r['wall_s']:.1f} s | "
                         f"{r['peak_rss_mb'] / 1024:.2f} GB | {r['file_mb']:.0f} MB | {pca} |")
    lines += ["", "| fit to a scan | time, fastest / median | residual RMS / p95 / max | landmarks only |", "|---|---|---|---|"]
    for f in a["fit"]:
        lines.append(f"| {f['scan_vertices']:,} vertices | {f['seconds_fastest']:.2f} / {f['seconds_median']:.2f} s | "
                     f"{f['residual_rms_mm']:.2f} / {f['residual_p95_mm']:.2f} / {f['residual_max_mm']:.2f} mm | "
                     f"{f['landmark_only_residual_rms_mm']:.2f} mm RMS |")
    r = a["rig"]
    lines += ["", f"Rig from {r['markers']} markers against a faceunit performance ({r['frames']} frames, "
                  f"{r['face_vertices']} face vertices, motion RMS {r['motion_rms_mm']:.2f} / max {r['motion_max_mm']:.1f} mm): "
                  f"error RMS {r['error_rms_mm']:.2f}, p95 {r['error_p95_mm']:.2f}, max {r['error_max_mm']:.1f} mm; "
                  f"markers exact to {r['markers_exact_mm']:.1e} mm; {r['frames_per_s']:.0f} frames/s after a "
                  f"{r['setup_s'] * 1000:.0f} ms setup.", "",
              "| PCA modes K | " + " | ".join(str(row["modes"]) for row in a["pca"]["faceunit_performance_25_channels"]) + " |",
              "|---|" + "---|" * len(a["pca"]["faceunit_performance_25_channels"])]
    for name, rows in a["pca"].items():
        lines.append(f"| {name.replace('_', ' ')}: max / mean mm | "
                     + " | ".join(f"{row['max_mm']:.2f} / {row['mean_mm']:.3f}" for row in rows) + " |")
    return lines
