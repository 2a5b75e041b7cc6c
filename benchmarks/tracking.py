"""Tracking from detections: accuracy under the stress faults, and speed.

Synthetic 300-marker performances (core.simulate.rig_performance: 10 deg head turn,
5 mm expressions, 600 mm) turned into detections without rendering
(core.simulate.synthetic_detections), tracked with the true mirror planes.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from mirrorcap.synthetic.simulate import face_rig, rig_performance, synthetic_detections
from mirrorcap.core.track.tracker import track

SCENARIOS = {
    "clean": dict(noise_px=0.05),
    "10 % missing, 20 % false blobs": dict(noise_px=0.1, missing=0.1, false_blobs=0.2),
    "stress: + 50 % false blobs, 12 group occlusions x 10 frames": dict(noise_px=0.1, missing=0.1,
                                                                        false_blobs=0.5, occlusions=12),
}


def score(frames, perf, result) -> dict:
    """Accuracy of a tracking result against the synthetic truth. Each tracked marker's
    true identity (``ids``) is the majority of the true markers it was assigned; an
    identity switch is a measurement of any other (or of a false blob)."""
    F, N = result.points.shape[:2]
    votes = [[] for _ in range(N)]
    for t in range(F):
        for n, b in enumerate(result.assigned_blob[t].tolist()):
            if b >= 0:
                votes[n].append(int(frames[t].direct_id[b]))
    ids = np.array([max(set(v), key=v.count) if v else -1 for v in votes])
    switches = measured = 0
    for t in range(F):
        ab = result.assigned_blob[t]
        ok = ab >= 0
        if not ok.any():
            continue
        switches += int(np.count_nonzero(ok & (frames[t].direct_id[np.maximum(ab, 0)] != ids)))
        measured += int(ok.sum())
    err = np.linalg.norm(result.points - perf[0][:, np.maximum(ids, 0)], axis=2)
    reported = np.all(np.isfinite(result.points), axis=2)
    meas = reported & ~result.conjectured
    # reported-of-visible counts true markers: two tracked markers of one true marker
    # (a duplicate) report it once
    n_true = perf[0].shape[1]
    rep_true = np.zeros((F, n_true), bool)
    np.logical_or.at(rep_true, (slice(None), np.maximum(ids, 0)), reported & (ids >= 0)[None])
    vis_total = rep_vis = 0
    for t in range(F):
        seen = (set(frames[t].direct_id.tolist())
                & (set(frames[t].mirror_id[0].tolist()) | set(frames[t].mirror_id[1].tolist()))) - {-1}
        vis_total += len(seen)
        rep_vis += int(np.sum(rep_true[t, list(seen)]))
    tracked, times_tracked = np.unique(ids[ids >= 0], return_counts=True)
    ce = err[result.conjectured]
    return {"ids": ids, "markers": N, "duplicates": int(np.sum(times_tracked > 1)),
            "measured": measured, "identity_switches": switches,
            "rms_mm": float(np.sqrt(np.mean(err[meas] ** 2))), "reported_of_visible": rep_vis / vis_total,
            "conjectured_rms_mm": float(np.sqrt(np.mean(ce ** 2))) if ce.size else 0.0,
            "conjectured_p99_mm": float(np.percentile(ce, 99)) if ce.size else 0.0,
            "conjectured_max_mm": float(ce.max()) if ce.size else 0.0,
            "conjectured": int(result.conjectured.sum()),
            "withheld": int(np.sum(result.stats.get("withheld", 0))),
            "candidates_per_measured": float(result.stats["candidates"][1:].sum() /
                                             max(result.stats["measured"][1:].sum(), 1))}


def run_tracking_benchmark(n_frames: int = 150, progress=print, repeats: int = 3, long_frames: int = 600) -> dict:
    """Each scenario tracked ``repeats`` times (this VM's speed varies 10-50 % from run to
    run: the fastest and the median are reported), plus the stress scenario on a
    ``long_frames`` take, where the per-take set-up (pairing, candidates, late markers)
    weighs less."""
    rig = face_rig(n_markers=300, seed=3, layout="even")
    out = {}
    runs = [(name, n_frames, kw) for name, kw in SCENARIOS.items()]
    stress = list(SCENARIOS)[-1]
    runs.append((f"{stress.split(':')[0]}, {long_frames} frames", long_frames, SCENARIOS[stress]))
    for name, frames_n, kw in runs:
        perf = rig_performance(rig, frames_n, head_motion_deg=10, expression_mm=5)
        _, frames = synthetic_detections(rig, frames_n, seed=4, performance=perf, **kw)
        times, stages = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            result = track(frames, rig.camera, rig.planes)
            times.append(time.perf_counter() - t0)
            stages.append(result.timings)
        r = score(frames, perf, result)
        del r["ids"]
        r["frames"] = frames_n
        r["frames_per_s"] = frames_n / min(times)
        r["frames_per_s_median"] = frames_n / float(np.median(times))
        fastest = stages[int(np.argmin(times))]
        r["stages_ms"] = {k: 1e3 * v for k, v in fastest.items()}
        out[name] = r
        progress(f"  {name:60s} rms {r['rms_mm']:.3f} mm  switches {r['identity_switches']}/{r['measured']}  "
                 f"reported {r['reported_of_visible'] * 100:.1f} %  conjectured p99 {r['conjectured_p99_mm']:.2f} "
                 f"max {r['conjectured_max_mm']:.2f} mm  {r['frames_per_s']:.0f} frames/s "
                 f"(median {r['frames_per_s_median']:.0f})")
    return out


def render_performance_mp4(path, n_frames: int, fps: float = 60.0, seed: int = 1):
    """A 1280x720 MP4 of the benchmark performance (300 markers, 10 deg, 5 mm), rendered
    by :func:`core.render.render_rig_frame` (2 grey levels of noise, mp4v). Returns
    ``(rig, truth points (F, N, 3))``."""
    import cv2

    from mirrorcap.core.capture.markers import DEFAULT_CLASSES
    from mirrorcap.synthetic.render import RenderSettings, render_rig_frame
    from mirrorcap.synthetic.simulate import visibility

    rig = face_rig(n_markers=300, seed=3, layout="even")
    pts, nrm, *_ = rig_performance(rig, n_frames, head_motion_deg=10, expression_mm=5)
    class_rgb = np.array([s[0] for s in DEFAULT_CLASSES.values()])
    rng = np.random.default_rng(seed)
    color = np.arange(len(rig.points)) % len(class_rgb)
    rng.shuffle(color)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, rig.camera.image_size)
    try:
        for f in range(n_frames):
            vis = visibility(rig.camera, rig.planes, pts[f], nrm[f])
            img, _ = render_rig_frame(rig.camera, rig.planes, pts[f], color, class_rgb,
                                      RenderSettings(noise_sigma=2.0), rng, visible=vis)
            writer.write(img)
    finally:
        writer.release()
    return rig, pts


def _speed(n_frames: int, times, reports) -> dict:
    """Frames per second (fastest and median of the runs) and the fastest run's stages."""
    fastest = reports[int(np.argmin(times))]["timings_s"]
    return {"frames_per_s": n_frames / min(times), "frames_per_s_median": n_frames / float(np.median(times)),
            "seconds": min(times), "stages_s": {"detect": fastest["detect"], "track": fastest["track"],
                                                "other": min(times) - fastest["detect"] - fastest["track"]},
            "track_stages_s": fastest["track_stages"]}


def run_track_command_benchmark(n_frames: int = 600, repeats: int = 3, progress=print) -> dict:
    """The whole ``mirrorcap track`` (decode, extraction, mirror self-calibration,
    tracking, C3D and report written) on a rendered 1280x720 MP4 of ``n_frames`` frames,
    ``repeats`` times; speed (fastest and median) and accuracy against the truth."""
    import tempfile
    from pathlib import Path

    from mirrorcap.core.take.c3d import read_c3d
    from mirrorcap.synthetic.evaluate import score_take
    from mirrorcap.core.track.pipeline import run_track
    from mirrorcap.core.capture.video import open_source

    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "performance.mp4"
        rig, truth = render_performance_mp4(video, n_frames)
        source = open_source(video)
        times, reports = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            reports.append(run_track(source, rig.camera, Path(tmp) / "take.c3d", report=Path(tmp) / "take.json"))
            times.append(time.perf_counter() - t0)
        take = read_c3d(Path(tmp) / "take.c3d")
        s = score_take(take["points"], truth, rig.camera, conjectured=take["conjectured"])
    out = {"frames": n_frames, "size": list(rig.camera.image_size), "markers": s["markers_tracked"],
           **_speed(n_frames, times, reports), "withheld": int(sum(reports[-1]["per_frame"]["withheld"])),
           **{k: s[k] for k in ("markers_matched", "identity_switches", "measured_marker_frames", "rms_mm", "p95_mm",
                                "max_mm", "conjectured", "conjectured_rms_mm", "conjectured_max_mm")}}
    progress(f"  whole track, {n_frames} frames 1280x720: {out['frames_per_s']:.0f} frames/s "
             f"(median {out['frames_per_s_median']:.0f}); detect {out['stages_s']['detect']:.2f} s, track "
             f"{out['stages_s']['track']:.2f} s, other {out['stages_s']['other']:.2f} s; RMS {s['rms_mm']:.3f} mm, "
             f"{s['identity_switches']} switches")
    return out


STRESS_CLIPS = Path(__file__).resolve().parents[1] / "sample_scenes" / "stress"
NORMAL_CLIPS = Path(__file__).resolve().parents[1] / "sample_scenes" / "normal"   # issue #21
OCCLUDED_CLIPS = Path(__file__).resolve().parents[1] / "sample_scenes" / "occluded"   # stop 46


def _rendered_clip(clip: Path) -> tuple:
    """A clip folder of ``make_rig_clip.py``: ``(camera, view layout, light)``; the normal-light clips' clip.json
    says ``"light": "normal"``."""
    import json

    from mirrorcap.core.capture.rig import load_rig_views
    from mirrorcap.core.geometry.camera import Camera

    camera = Camera.from_dict(json.loads((clip / "camera.json").read_text()))
    made = json.loads((clip / "clip.json").read_text()) if (clip / "clip.json").is_file() else {}
    return camera, load_rig_views(clip / "rig.json"), made.get("light", "uv")


def _scored(truth, camera, path) -> tuple:
    """The take at ``path`` against a rendered clip's ``truth`` (truth.npz): its frames, its scores
    (:func:`synthetic.evaluate.score_take`, with the marker-frames seen in the direct view and a mirror) and its
    points over 2 mm."""
    from mirrorcap.core.take.c3d import read_c3d
    from mirrorcap.synthetic.evaluate import score_take

    take = read_c3d(path)
    F = take["points"].shape[0]
    seen = None
    if "visible" in truth.files:
        vis = truth["visible"][:F]
        seen = vis[:, 0] & (vis[:, 1] | vis[:, 2])
    s = score_take(take["points"], truth["points"][:F], camera, conjectured=take["conjectured"], seen=seen)
    err = s["error_mm"][:, s["ids"] >= 0]
    return F, s, int(np.count_nonzero(err[np.isfinite(err)] > 2.0))


def run_stress_clip_benchmark(clips=None, repeats: int = 2, progress=print) -> dict:
    """The whole ``mirrorcap track`` (mirrors self-calibrated, RIG.json's views) on each rendered
    stress clip (``make stress-clips``, ``normal-clips``, ``compressed-clips``, ``occluded-clips``),
    ``repeats`` times: speed, and accuracy and completeness
    against the clip's truth -- RMS / p95 / max after one similarity, identity switches, markers
    split over two labels, and the share of the marker-frames seen in the direct view and a
    mirror (truth.npz ``visible``) that the take reports. A clip the product refuses is recorded with
    its message (``refused``). ``without_rig_file``: once more as a new user tracks it, with no rig file
    (the views split automatically): its completeness, switches, points over 2 mm and RMS, or ``refused``."""
    import tempfile

    from mirrorcap.core.capture.markers import ExtractionSettings
    from mirrorcap.core.capture.video import open_source
    from mirrorcap.core.common.errors import MirrorCapError
    from mirrorcap.core.track.pipeline import run_track

    default = [clip for folder in (STRESS_CLIPS, NORMAL_CLIPS, OCCLUDED_CLIPS) if folder.is_dir()
               for clip in sorted(folder.iterdir())]
    folders = [p for p in (default if clips is None else map(Path, clips))
               if (p / "clip.mp4").is_file() and (p / "truth.npz").is_file()]
    out = {}
    for clip in folders:
        camera, layout, light = _rendered_clip(clip)
        truth = np.load(clip / "truth.npz")
        source = open_source(clip / "clip.mp4")
        times, reports = [], []
        name = clip.name if light == "uv" else f"normal-light {clip.name}"

        with tempfile.TemporaryDirectory() as tmp:
            try:
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    reports.append(run_track(source, camera, Path(tmp) / "take.c3d", report=Path(tmp) / "take.json",
                                             layout=layout, extraction=ExtractionSettings(light=light)))
                    times.append(time.perf_counter() - t0)
            except MirrorCapError as exc:   # a clip the product refuses, with its one message
                out[name] = {"frames": int(truth["points"].shape[0]), "size": list(camera.image_size),
                             "refused": str(exc), "light": light}
                progress(f"  {clip.name}: refused -- {exc}")
                continue
            F, s, over_2mm = _scored(truth, camera, Path(tmp) / "take.c3d")
            # as a new user tracks it: no rig file, the views split automatically (the rig files' lines come from
            # the clip's truth, where the fewest dots land in the wrong view)
            without = None
            if layout is not None:
                try:
                    run_track(source, camera, Path(tmp) / "auto.c3d", extraction=ExtractionSettings(light=light))
                    _, s_auto, over_auto = _scored(truth, camera, Path(tmp) / "auto.c3d")
                    without = {"seen_reported_fraction": s_auto.get("seen_reported_fraction"),
                               "identity_switches": s_auto["identity_switches"], "points_over_2mm": over_auto,
                               "rms_mm": s_auto["rms_mm"]}
                except MirrorCapError as exc:
                    without = {"refused": str(exc)}
        report = reports[-1]
        ds = [m["d"] for m in report["mirrors"]]
        r = {"frames": F, "size": list(camera.image_size), "markers_true": s["markers_true"],
             "markers": s["markers_tracked"], **_speed(F, times, reports),
             "mirror_ratio_error": (ds[1] / ds[0]) / (truth["mirror_d"][1] / truth["mirror_d"][0]) - 1.0,
             "mirrors_consistent": report["mirror_agreement"]["consistent"],
             "points_over_2mm": over_2mm,
             **{k: s[k] for k in ("markers_matched", "identity_switches", "measured_marker_frames", "rms_mm",
                                  "p95_mm", "max_mm", "conjectured", "conjectured_rms_mm", "conjectured_max_mm",
                                  "split_markers")}}
        if "seen_reported_fraction" in s:
            r.update({"seen_marker_frames": s["seen_marker_frames"],
                      "seen_reported_fraction": s["seen_reported_fraction"],
                      "never_tracked": len(s["never_tracked"])})
        r["without_rig_file"] = without
        r["light"] = light
        out[name] = r
        progress(f"  {clip.name}: {r['frames_per_s']:.0f} frames/s, {r['markers']} markers, RMS {r['rms_mm']:.3f} "
                 f"mm (max {r['max_mm']:.2f}), {r['identity_switches']} switches, "
                 f"{100 * r.get('seen_reported_fraction', float('nan')):.1f} % of seen marker-frames reported")
    return out


def _keep_a_core_busy(stop) -> None:
    """A competing job: spins one core until ``stop`` (a multiprocessing Event) is set."""
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


@contextmanager
def _cores_kept_busy(busy: int):
    """``busy`` other processes spinning (:func:`_keep_a_core_busy`) while the block runs."""
    from multiprocessing import get_context

    ctx = get_context("spawn")
    stop = ctx.Event()
    hogs = [ctx.Process(target=_keep_a_core_busy, args=(stop,), daemon=True) for _ in range(busy)]
    for h in hogs:
        h.start()
    try:
        time.sleep(0.5)                                  # spun up before the timing starts
        yield
    finally:
        stop.set()
        for h in hogs:
            h.join()


LOADED_CLIPS = (STRESS_CLIPS / "tilt630", STRESS_CLIPS / "dense", NORMAL_CLIPS / "light")


def run_loaded_track_benchmark(clips=LOADED_CLIPS, busy: int = 2, progress=print) -> dict:
    """The whole ``mirrorcap track`` on rendered clips while ``busy`` other processes keep every
    core of this 2-core machine busy (as a render, a second take or a batch would): with the
    core's one BLAS thread (``core.common.threads``, the default) and with BLAS's own thread count
    (``MIRRORCAP_BLAS_THREADS=0``, what the tracker did before). Seconds and frames/s of each."""
    import os
    import tempfile

    from mirrorcap.core.capture.markers import ExtractionSettings
    from mirrorcap.core.capture.video import open_source
    from mirrorcap.core.common.threads import BLAS_THREADS_ENV
    from mirrorcap.core.track.pipeline import run_track

    out = {}
    before = os.environ.get(BLAS_THREADS_ENV)
    try:
        for clip in map(Path, clips):
            if not (clip / "clip.mp4").is_file():
                continue
            camera, layout, light = _rendered_clip(clip)
            row = {}
            for name, value in (("one_blas_thread", None), ("blas_default", "0")):
                if value is None:
                    os.environ.pop(BLAS_THREADS_ENV, None)
                else:
                    os.environ[BLAS_THREADS_ENV] = value
                with _cores_kept_busy(busy), tempfile.TemporaryDirectory() as tmp:
                    t0 = time.perf_counter()
                    rep = run_track(open_source(clip / "clip.mp4"), camera, Path(tmp) / "take.c3d",
                                    report=Path(tmp) / "take.json", layout=layout,
                                    extraction=ExtractionSettings(light=light))
                    seconds = time.perf_counter() - t0
                frames = rep["frames"]["count"]
                row[name] = {"seconds": seconds, "frames_per_s": frames / seconds,
                             "detect_s": rep["timings_s"]["detect"], "track_s": rep["timings_s"]["track"]}
            out[clip.name] = {"frames": frames, "busy_processes": busy, **row}
            progress(f"  {clip.name} with {busy} busy processes: {row['one_blas_thread']['seconds']:.1f} s "
                     f"(track {row['one_blas_thread']['track_s']:.1f} s) with one BLAS thread, "
                     f"{row['blas_default']['seconds']:.1f} s (track {row['blas_default']['track_s']:.1f} s) "
                     "with BLAS's own")
    finally:
        if before is None:
            os.environ.pop(BLAS_THREADS_ENV, None)
        else:
            os.environ[BLAS_THREADS_ENV] = before
    return out


def run_long_take_benchmark(n_frames: int = 3600, progress=print) -> dict:
    """The whole ``mirrorcap track`` on a long take: the bench performance rendered for ``n_frames``
    frames (3600: a minute at 60 frames/s), once, in a fresh process so that its peak resident
    memory is the take's own. Speed, peak memory and accuracy against the truth."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    with ProcessPoolExecutor(max_workers=1, mp_context=get_context("spawn")) as pool:
        out = pool.submit(_long_take, n_frames).result()
    progress(f"  long take, {n_frames} frames 1280x720: {out['frames_per_s']:.0f} frames/s, peak resident memory "
             f"{out['peak_rss_mb']:.0f} MB (detect {out['detect_s']:.1f} s, track {out['track_s']:.1f} s), "
             f"RMS {out['rms_mm']:.3f} mm, {out['identity_switches']} switches")
    return out


def _long_take(n_frames: int) -> dict:
    import resource
    import tempfile

    from mirrorcap.core.capture.video import open_source
    from mirrorcap.core.take.c3d import read_c3d
    from mirrorcap.core.track.pipeline import run_track
    from mirrorcap.synthetic.evaluate import score_take

    with tempfile.TemporaryDirectory() as tmp:
        video = Path(tmp) / "long.mp4"
        rig, truth = render_performance_mp4(video, n_frames)
        source = open_source(video)
        t0 = time.perf_counter()
        report = run_track(source, rig.camera, Path(tmp) / "take.c3d", report=Path(tmp) / "take.json")
        seconds = time.perf_counter() - t0
        take = read_c3d(Path(tmp) / "take.c3d")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0    # kB on Linux
    s = score_take(take["points"], truth, rig.camera, conjectured=take["conjectured"])
    return {"frames": n_frames, "size": list(rig.camera.image_size), "seconds": seconds,
            "frames_per_s": n_frames / seconds, "peak_rss_mb": peak, "detect_s": report["timings_s"]["detect"],
            "track_s": report["timings_s"]["track"], "track_stages_s": report["timings_s"]["track_stages"],
            **{k: s[k] for k in ("markers_tracked", "identity_switches", "measured_marker_frames", "rms_mm", "max_mm")}}
