"""``mirrorcap batch`` speed: 4 copies of a take baked with 1 and with 2 workers.

The take and the head come from the demo's first steps on the sample clip (track, fit), run
here with no preview render; each batch run bakes the 4 copies (frames mode) into its own
folder. Two take lengths: the sample take itself (120 frames, 4 s) and the same take looped to
1,800 frames (a 60 s take). The figure is the wall-clock ratio, 1 worker over 2: of the
fastest runs, of the medians, and the median of each repeat's ratio (1-worker and 2-worker runs
alternate, so that the machine's drift hits both alike).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np


def _loop_take(src: Path, dst: Path, frames: int) -> None:
    from mirrorcap.core.take.c3d import read_c3d, write_c3d

    d = read_c3d(src)
    reps = -(-frames // d["points"].shape[0])
    pts = np.concatenate([d["points"]] * reps)[:frames]
    write_c3d(dst, d["labels"], pts, d["rate"])


def run_batch_benchmark(copies: int = 4, repeats: int = 5, long_frames: int = 1800) -> dict:
    """Both take lengths; see the module text."""
    return {"sample_take": _run_batch(copies, repeats, None), f"looped_{long_frames}": _run_batch(copies, repeats,
                                                                                                 long_frames)}


def _run_batch(copies: int, repeats: int, frames_override) -> dict:
    import subprocess
    import sys

    root = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory(prefix="mirrorcap-batch-") as tmp:
        tmp = Path(tmp)
        demo = tmp / "demo"
        res = subprocess.run([sys.executable, "-c", "from mirrorcap.demo.rig import run_demo; "
                              f"run_demo({str(demo)!r}, quiet=True, preview=False)"],
                             capture_output=True, text=True, cwd=root)
        if res.returncode != 0:
            raise RuntimeError(res.stderr[-2000:])
        takes = []
        for i in range(copies):
            takes.append(tmp / f"take_{i}.c3d")
            if frames_override:
                _loop_take(demo / "take.c3d", takes[-1], frames_override)
            else:
                shutil.copy(demo / "take.c3d", takes[-1])
        walls = {1: [], 2: []}
        for r in range(repeats):
            for workers in (1, 2):      # alternated, so that the machine's drift hits both alike
                times = walls[workers]
                out = tmp / f"out_{workers}_{r}"
                t0 = time.perf_counter()
                res = subprocess.run([sys.executable, "-m", "mirrorcap", "batch", *map(str, takes), "--head",
                                      str(demo / "fitted_head.blend"), "--out", str(out), "--workers", str(workers),
                                      "--drop-unseen", "-q"], capture_output=True, text=True, cwd=root)
                times.append(time.perf_counter() - t0)
                if res.returncode != 0:
                    raise RuntimeError(res.stdout[-1000:] + res.stderr[-2000:])
        frames = frames_override or int(__import__("json").loads((demo / "demo.json").read_text())["clip"]["frames"])
    best1, best2 = min(walls[1]), min(walls[2])
    return {"takes": copies, "frames_per_take": frames, "seconds_1_worker": walls[1], "seconds_2_workers": walls[2],
            "speedup_best": best1 / best2,
            "speedup_median": sorted(walls[1])[len(walls[1]) // 2] / sorted(walls[2])[len(walls[2]) // 2],
            # each 1-worker run over the 2-worker run right after it: the machine's drift cancels
            "speedup_paired_median": float(np.median(np.divide(walls[1], walls[2])))}


def batch_summary(res) -> list:
    lines = ["## `mirrorcap batch` (4 copies of a take, frames mode, the whole command incl. Blender start)", "",
             "| take | 1 worker, s (each run) | 2 workers, s (each run) | speed-up fastest / median "
             "/ median of the runs' ratios |",
             "| --- | --- | --- | --- |"]
    for name, b in res.items():
        lines.append(f"| {name.replace('_', ' ')} ({b['frames_per_take']} frames) | "
                     f"{', '.join(f'{s:.1f}' for s in b['seconds_1_worker'])} | "
                     f"{', '.join(f'{s:.1f}' for s in b['seconds_2_workers'])} | "
                     f"**{b['speedup_best']:.2f}x** / {b['speedup_median']:.2f}x / "
                     f"{b.get('speedup_paired_median', float('nan')):.2f}x |")
    return lines + [""]
