"""Any-C3D figures for ``make bench``: ``mirrorcap stabilize`` on synthetic 23-marker takes
(:mod:`mirrorcap.synthetic.sparse_take`, the take of issue #20) over twenty noise draws and two
rigid layouts, and the speed of reading and stabilising a long take."""

from __future__ import annotations

import tempfile
import json
import time
from pathlib import Path

import numpy as np


def _rms(a, b) -> float:
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


def run_stabilize_benchmark(draws: int = 20) -> dict:
    from mirrorcap.core.geometry.rigid import rigid_fit
    from mirrorcap.core.take.c3d import read_c3d, write_c3d
    from mirrorcap.core.take.stabilize import stabilize
    from mirrorcap.synthetic.sparse_take import FOREHEAD_TRIANGLE, HEADBAND, sparse_take

    out = {"draws": draws, "take": "23 markers, +-20 deg yaw, +-10 pitch, +-5 roll, 0.5 mm sway, 0.15 mm noise, "
                                   "60 frames/s, 600 frames", "layouts": {}}
    for name, band in (("headband (temples + forehead, 136 mm)", HEADBAND),
                       ("forehead triangle (70 mm)", FOREHEAD_TRIANGLE)):
        rows = {k: [] for k in ("invariants", "arun", "pivot_mm", "agree", "aligned", "no_pivot", "raw")}
        for seed in range(draws):
            take = sparse_take(seed, band=band)
            pts = {}
            for method in ("invariants", "arun"):
                st = stabilize(take.points, take.labels, rigid=take.labels[:3], method=method, rate=take.rate)
                rows[method].append(_rms(st.points[:, 3:], take.head_frame0[:, 3:]))
                pts[method] = st.points
            rows["pivot_mm"].append(float(np.linalg.norm(st.pivot_mm - take.pivot)))
            rows["agree"].append(_rms(pts["invariants"], pts["arun"]))
            a, b = pts["arun"][:, 3:].reshape(-1, 3), take.head_frame0[:, 3:].reshape(-1, 3)
            R, t = rigid_fit(a, b)
            rows["aligned"].append(_rms(a @ R.T + t, b))
            for key, kw in (("no_pivot", {"pivot": None}), ("raw", {"pivot": None, "smooth_s": 0.0})):
                st = stabilize(take.points, take.labels, rigid=take.labels[:3], rate=take.rate, **kw)
                rows[key].append(_rms(st.points[:, 3:], take.head_frame0[:, 3:]))
        out["layouts"][name] = {k: {"median": float(np.median(v)), "min": float(np.min(v)), "max": float(np.max(v)),
                                    "over_0_45": int(np.sum(np.asarray(v) > 0.45))} for k, v in rows.items()}
    # held out: other draws (seeds 100-119) with the neck swaying faster and further than the take
    out["sways"] = {}
    for sway_mm, sway_hz in ((0.5, 0.05), (0.5, 0.5), (1.0, 0.3), (2.0, 0.3), (1.0, 1.0)):
        rows = {"invariants": [], "arun": [], "window_s": []}
        for seed in range(100, 100 + draws):
            take = sparse_take(seed, sway_mm=sway_mm, sway_hz=sway_hz)
            for method in ("invariants", "arun"):
                st = stabilize(take.points, take.labels, rigid=take.labels[:3], method=method, rate=take.rate)
                rows[method].append(_rms(st.points[:, 3:], take.head_frame0[:, 3:]))
            rows["window_s"].append(st.sway_window_s)
        out["sways"][f"{sway_mm:g} mm at {sway_hz:g} Hz"] = {
            **{k: {"median": float(np.median(rows[k])), "max": float(np.max(rows[k])),
                   "over_0_45": int(np.sum(np.asarray(rows[k]) > 0.45))} for k in ("invariants", "arun")},
            "window_s": {f"{w:.1f}": int(n) for w, n in zip(*np.unique(np.round(rows["window_s"], 1),
                                                                        return_counts=True))}}
    # speed: a 10-minute take at 60 frames/s (36,000 frames, 23 markers)
    take = sparse_take(0, frames=36000)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.c3d"
        t0 = time.perf_counter()
        write_c3d(path, take.labels, take.points, take.rate)
        t1 = time.perf_counter()
        data = read_c3d(path)
        t2 = time.perf_counter()
        stabilize(data["points"], data["labels"], rigid=take.labels[:3], rate=data["rate"])
        t3 = time.perf_counter()
    out["speed"] = {"frames": 36000, "markers": 23, "write_s": t1 - t0, "read_s": t2 - t1, "stabilize_s": t3 - t2}
    return out


def stabilize_summary(res: dict) -> list:
    lines = [f"### `mirrorcap stabilize` ({res['draws']} noise draws: {res['take']})", "",
             "| rigid layout | face RMS, invariants (median / max, > 0.45) | Arun | after one rigid alignment | "
             "pivot error (median / max) | invariants vs Arun | no pivot | no pivot, no smoothing |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in res["layouts"].items():
        def mm(k):
            return f"{r[k]['median']:.2f} / {r[k]['max']:.2f} mm"
        lines.append(f"| {name} | {mm('invariants')} ({r['invariants']['over_0_45']}) | {mm('arun')} "
                     f"({r['arun']['over_0_45']}) | {mm('aligned')} | {mm('pivot_mm')} | {mm('agree')} | "
                     f"{r['no_pivot']['median']:.2f} mm | {r['raw']['median']:.2f} mm |")
    if "sways" in res:
        lines += ["", "Held out (headband, other draws, the neck swaying faster and further):", "",
                  "| sway | invariants (median / worst, > 0.45) | Arun | sway window chosen (s: draws) |",
                  "| --- | --- | --- | --- |"]
        for name, r in res["sways"].items():
            lines.append(f"| {name} | {r['invariants']['median']:.2f} / {r['invariants']['max']:.2f} mm "
                         f"({r['invariants']['over_0_45']}) | {r['arun']['median']:.2f} / {r['arun']['max']:.2f} mm "
                         f"({r['arun']['over_0_45']}) | " + ", ".join(f"{w}: {n}" for w, n in r["window_s"].items()) + " |")
    s = res["speed"]
    lines += ["", f"A {s['frames']}-frame take of {s['markers']} markers: written in {s['write_s']:.2f} s, read in "
                  f"{s['read_s']:.2f} s, stabilised in {s['stabilize_s']:.2f} s."]
    return lines


def run_arkit_benchmark() -> dict:
    """ARKit-52 weights from a 1,000-frame, 150-marker take of the generic head (27 channels with
    known weights, head motion, 0.1 mm noise): accuracy and the solve's time."""
    from mirrorcap.core.face.bind import bind_take
    from mirrorcap.core.face.headio import load_head_npz
    from mirrorcap.core.retarget.arkit import arkit_basis, solve_weights
    from mirrorcap.synthetic.headsim import ARKIT_CHANNELS as channels
    from mirrorcap.synthetic.headsim import arkit_take

    root = Path(__file__).resolve().parent.parent
    head, keys = load_head_npz(root / "sample_scenes" / "generic_head" / "head.npz", with_shape_keys=True)
    F = 1000
    labels, pts, W = arkit_take(head, keys, frames=F, seed=21)
    t0 = time.perf_counter()
    b = bind_take(head, labels, pts)
    t1 = time.perf_counter()
    names, B = arkit_basis(keys, b.vertices)
    sol = solve_weights(B, b.displacements, names)
    t2 = time.perf_counter()
    truth = np.zeros_like(sol.weights)
    for k, n in enumerate(channels):
        truth[:, names.index(n)] = W[:, k]
    err = sol.weights - truth
    return {"frames": F, "markers": 150, "channels": len(channels), "bind_s": t1 - t0, "solve_s": t2 - t1,
            "iterations": sol.iterations, "weight_rms": float(np.sqrt(np.mean(err ** 2))),
            "weight_max": float(np.abs(err).max()), "residual_mm_rms": float(np.sqrt(np.mean(sol.residual_mm ** 2)))}


def arkit_summary(res: dict) -> list:
    return [f"### ARKit-52 solve ({res['frames']} frames, {res['markers']} markers, {res['channels']} channels, "
            "0.1 mm noise)", "",
            f"Weights RMS error {res['weight_rms']:.4f}, max {res['weight_max']:.3f}; fit residual "
            f"{res['residual_mm_rms']:.3f} mm RMS; bind {res['bind_s']:.2f} s, solve {res['solve_s']:.2f} s "
            f"({res['iterations']} ADMM iterations)."]


def run_transfer_benchmark() -> dict:
    """``mirrorcap retarget --method transfer`` of a 1,000-frame, 150-marker take onto an 18,289-vertex
    character (the generic head subdivided, 12 % wider and shorter, landmarks only), run as a user runs
    it (a fresh process, the .blend written), in frame keys and in 8 PCA keys."""
    import subprocess
    import sys
    import tempfile

    from mirrorcap.core.face.head import HeadModel
    from mirrorcap.core.face.headfit import subdivide
    from mirrorcap.core.face.headio import load_head_npz, save_head_npz
    from mirrorcap.core.take.c3d import write_c3d
    from mirrorcap.synthetic.headsim import arkit_take

    root = Path(__file__).resolve().parent.parent
    head, keys = load_head_npz(root / "sample_scenes" / "generic_head" / "head.npz", with_shape_keys=True)
    F = 1000
    out = {"take_frames": F, "markers": 150}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        labels, pts, _ = arkit_take(head, keys, frames=F, seed=21)
        write_c3d(tmp / "take.c3d", labels, pts, 30.0)
        V2, T2 = subdivide(head.vertices, head.triangles(), 1)
        pad = len(V2) - len(head.vertices)
        char = HeadModel(vertices=V2 * [1.12, 0.88, 1.0], polygons=T2.ravel(), polygon_sizes=np.full(len(T2), 3),
                         groups={g: np.r_[w, np.zeros(pad)] for g, w in head.groups.items() if g.startswith("lm_")},
                         name="Character")
        save_head_npz(tmp / "character.npz", char)
        subprocess.run([sys.executable, "-c", "from mirrorcap.core.face.headio import load_head_npz\n"
                        "from mirrorcap.addon.common.headio import write_head_blend\n"
                        f"write_head_blend(load_head_npz({str(tmp / 'character.npz')!r}), {str(tmp / 'target.blend')!r})"],
                       check=True, capture_output=True)
        out["vertices"] = int(len(char.vertices))
        for mode in ("frames", "pca"):
            t0 = time.perf_counter()
            res = subprocess.run([sys.executable, "-m", "mirrorcap", "retarget", str(tmp / "take.c3d"), "--head",
                                  str(root / "sample_scenes" / "generic_head" / "head.blend"), "--target",
                                  str(tmp / "target.blend"), "-o", str(tmp / f"out_{mode}.blend"), "--method", "transfer",
                                  "--mode", mode, "--report", str(tmp / f"r_{mode}.json"), "-q"],
                                 capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if res.returncode != 0:
                raise RuntimeError(res.stdout + res.stderr)
            rep = json.loads((tmp / f"r_{mode}.json").read_text())
            out[mode] = {"wall_s": wall, **rep["timings_s"],
                         "blend_mb": (tmp / f"out_{mode}.blend").stat().st_size / 1e6}
    return out


def transfer_summary(res: dict) -> list:
    def row(mode):
        r = res[mode]
        return (f"| `--mode {mode}` | {r['wall_s']:.1f} s | {r['transfer_s']:.1f} s | {r['keys_s']:.1f} s | "
                f"{r['blend_mb']:.0f} MB |")
    return [f"### `mirrorcap retarget --method transfer` ({res['take_frames']} frames, {res['markers']} markers, "
            f"{res['vertices']}-vertex character, a fresh process as a user runs it)", "",
            "| keys | wall | transfer | keys | OUT.blend |", "| --- | --- | --- | --- | --- |", row("frames"), row("pca")]
