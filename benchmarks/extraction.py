"""Marker extraction: accuracy under faults, speed on one core, decode speed, and
memory over a 10,000-frame stream.

Frames come from :mod:`core.render` (the 300-marker face rig at 1280 x 720, 2.5 mm
dots 600 mm from the camera, evenly spaced). OpenCV runs single-threaded here so
the figures are per core.
"""

from __future__ import annotations

import os
import tempfile
import threading
import time
from pathlib import Path
from unittest import mock

import numpy as np

from mirrorcap.core.capture.markers import ColorClasses, ExtractionSettings, MarkerExtractor, marker_extractor
from mirrorcap.core.capture.rig import split_views_by_gaps
from mirrorcap.synthetic.render import RenderSettings, match_detections, render_rig_frame, rig_clip_frames
from mirrorcap.synthetic.simulate import face_rig

CONDITIONS = {
    "clean (noise 1)": RenderSettings(noise_sigma=1.0),
    "noise 3": RenderSettings(noise_sigma=3.0),
    "noise 6": RenderSettings(noise_sigma=6.0),
    "small dots 3.3 px, noise 3": RenderSettings(marker_radius_mm=0.75, noise_sigma=3.0),
    "colour shift 10 %, noise 3": RenderSettings(color_jitter=0.10, noise_sigma=3.0),
    "interlace comb 4 px, noise 3": RenderSettings(comb_px=4, noise_sigma=3.0),
    "interlace comb 6 px, noise 3": RenderSettings(comb_px=6, noise_sigma=3.0),
    "occlusion 10 %, noise 3": RenderSettings(occlusion=0.10, noise_sigma=3.0),
}


def rig_300():
    return face_rig(n_markers=300, seed=3, layout="even")


def evaluate_extraction(rig, settings: RenderSettings, seeds=(1, 2, 3), extraction=None, class_rgb=None) -> dict:
    """Render frames of ``rig`` with ``settings``, extract, split views and match
    against the truth (2 px). Returns centre RMS error (px), mean error, colour-class
    accuracy, missed rate (of visible dots) and false rate (of detections)."""
    from mirrorcap.core.capture.markers import DEFAULT_CLASSES

    class_rgb = np.array([s[0] for s in DEFAULT_CLASSES.values()]) if class_rgb is None else class_rgb
    ex = MarkerExtractor(ColorClasses.default(), extraction)
    errs, color_ok, missed, visible, false, dets = [], [], 0, 0, 0, 0
    for seed in seeds:
        rng = np.random.default_rng(seed)
        color = rng.integers(0, len(class_rgb), len(rig.points))
        vis = np.vstack([rig.visible_direct, rig.visible_mirror])
        img, truth = render_rig_frame(rig.camera, rig.planes, rig.points, color, class_rgb, settings, rng,
                                      visible=vis)
        det = ex(img)
        view = split_views_by_gaps(det.x, 12.0).assign(det.x, det.y)
        pairs, miss, fal = match_detections(det.x, det.y, view, truth, max_px=2.0)
        n = truth.visible.shape[1]
        errs.append(np.c_[det.x, det.y][pairs[:, 0]] - truth.centres.reshape(-1, 2)[pairs[:, 1]])
        color_ok.append(det.color[pairs[:, 0]] == truth.color[pairs[:, 1] % n])
        missed += miss.sum()
        visible += truth.visible.sum()
        false += fal.sum()
        dets += len(det)
    e = np.concatenate(errs)
    return {"rms_px": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))), "mean_err": e.mean(axis=0),
            "color": float(np.concatenate(color_ok).mean()), "missed": missed / visible,
            "false": false / max(dets, 1), "dots_per_frame": visible / len(seeds)}


def _rss_mb() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def run_extraction_benchmark(stream_frames: int = 10000, progress=print) -> dict:
    import cv2

    from mirrorcap.core.capture.detect import run_detection
    from mirrorcap.core.capture.video import open_source

    cv2.setNumThreads(1)
    rig = rig_300()
    out = {"conditions": {}}
    for name, settings in CONDITIONS.items():
        r = evaluate_extraction(rig, settings)
        out["conditions"][name] = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()}
        progress(f"  {name:32s} rms {r['rms_px']:.3f} px  colour {r['color'] * 100:.2f} %  "
                 f"missed {r['missed'] * 100:.2f} %  false {r['false'] * 100:.2f} %")
    # speed of extraction alone, on 40 distinct frames held in memory
    frames = [img for _, img, _ in rig_clip_frames(rig, 40, RenderSettings(noise_sigma=2.0), seed=5)]
    ex = MarkerExtractor(ColorClasses.default(), ExtractionSettings())
    for img in frames[:5]:
        ex(img)
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        for img in frames:
            ex(img)
        times.append((time.perf_counter() - t0) / len(frames))
    out["extract_ms_per_frame"] = float(np.median(times) * 1e3)
    out["extract_frames_per_s"] = float(1.0 / np.median(times))
    out["detections_per_frame"] = float(np.mean([len(ex(img)) for img in frames[:5]]))
    progress(f"  extraction alone: {out['extract_ms_per_frame']:.2f} ms/frame = {out['extract_frames_per_s']:.0f} "
             f"frames/s on one core ({out['detections_per_frame']:.0f} dots per frame)")
    # a long MP4 stream: decode speed, whole-detect speed, memory
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "stream.mp4")
        writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"mp4v"), 30, (1280, 720))
        for k in range(stream_frames):
            writer.write(frames[k % len(frames)])
        writer.release()
        source = open_source(path)
        t0 = time.perf_counter()
        for _ in source.frames(0, min(2000, stream_frames)):
            pass
        decode = (time.perf_counter() - t0) / min(2000, stream_frames)
        out["decode_ms_per_frame"] = decode * 1e3
        samples = []
        stop = threading.Event()

        def sample():
            while not stop.is_set():
                samples.append((time.perf_counter(), _rss_mb()))
                time.sleep(0.25)

        thread = threading.Thread(target=sample, daemon=True)
        thread.start()
        t0 = time.perf_counter()
        report = run_detection(source, os.path.join(tmp, "det.csv"), progress=None)
        elapsed = time.perf_counter() - t0
        stop.set()
        thread.join()
        rss = np.array([r for _, r in samples])
        n = len(rss)
        out["stream"] = {
            "frames": stream_frames, "seconds": elapsed, "frames_per_s": stream_frames / elapsed,
            "rss_mb_at_10_50_100_percent": [float(rss[max(0, n // 10)]), float(rss[n // 2]), float(rss[-1])],
            "rss_growth_mb_after_first_10_percent": float(rss[n // 10:].max() - rss[max(0, n // 10)]),
            "csv_mb": os.path.getsize(os.path.join(tmp, "det.csv")) / 1e6,
            "timings_s": report["timings_s"],
        }
    s = out["stream"]
    progress(f"  decode alone: {out['decode_ms_per_frame']:.2f} ms/frame; whole detect on a {stream_frames}-frame "
             f"MP4: {s['frames_per_s']:.0f} frames/s; RSS {s['rss_mb_at_10_50_100_percent']} MB "
             f"(growth after warm-up {s['rss_growth_mb_after_first_10_percent']:.1f} MB)")
    out["normal_light"] = run_normal_light_detection_benchmark(progress=progress)
    return out


NORMAL_LIGHT_CLIP = Path(__file__).resolve().parents[1] / "sample_scenes" / "normal" / "light"


def run_normal_light_detection_benchmark(repeats: int = 3, progress=print) -> dict:
    """Normal-light detection on the light clip (1280x720 H.264, 120 frames, `make normal-clips`): extraction alone
    on one core (its first 40 frames held in memory, median of ``repeats`` passes), and the whole ``detect`` (decode,
    extraction, CSV) frame after frame and on ``detection_threads()`` threads (fastest of ``repeats``)."""
    import cv2

    from mirrorcap.core.capture.detect import run_detection
    from mirrorcap.core.capture.video import open_source
    from mirrorcap.core.common.threads import DETECT_THREADS_ENV, detection_threads

    source = open_source(NORMAL_LIGHT_CLIP / "clip.mp4")
    settings = ExtractionSettings(light="normal")
    colours = ColorClasses.default("normal")
    cv2.setNumThreads(1)
    frames = [img for _, img in source.frames(0, 40)]
    ex = marker_extractor(colours, settings)
    for img in frames[:3]:
        ex(img)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for img in frames:
            ex(img)
        times.append((time.perf_counter() - t0) / len(frames))
    out = {"clip": "sample_scenes/normal/light", "frames": source.frame_count,
           "extract_ms_per_frame": float(np.median(times) * 1e3), "threads": detection_threads()}
    with tempfile.TemporaryDirectory() as tmp:
        for key, threads in (("detect_frames_per_s_one_thread", 1), ("detect_frames_per_s", out["threads"])):
            with mock.patch.dict(os.environ, {DETECT_THREADS_ENV: str(threads)}):   # restored after
                best = min(run_detection(source, os.path.join(tmp, "det.csv"), colors=colours,
                                         settings=settings)["timings_s"]["total"] for _ in range(repeats))
            out[key] = source.frame_count / best
    progress(f"  normal light (light clip): extraction alone {out['extract_ms_per_frame']:.1f} ms/frame on one core; "
             f"whole detect {out['detect_frames_per_s_one_thread']:.0f} frames/s frame after frame, "
             f"{out['detect_frames_per_s']:.0f} frames/s on {out['threads']} threads")
    return out
