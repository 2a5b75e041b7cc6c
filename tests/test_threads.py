"""The core's long jobs run their array code on one BLAS thread (core/common/threads.py): OpenBLAS
threads stalled every tiny solve of the tracker whenever another job kept the cores busy."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import mirrorcap.core.track.gapfill as gapfill
from mirrorcap.core.common.errors import InputError
from mirrorcap.core.common.threads import BLAS_THREADS_ENV, blas_threads
from mirrorcap.core.track.tracker import track
from mirrorcap.synthetic.simulate import face_rig, rig_performance, synthetic_detections


def _blas_threads() -> list:
    """The thread counts of the loaded BLAS libraries that can thread (OpenCV bundles one built without)."""
    return sorted({i["num_threads"] for i in threadpool_info()
                   if i["user_api"] == "blas" and i.get("threading_layer") != "disabled"})


@pytest.fixture(scope="module")
def small_take():
    rig = face_rig(n_markers=120, seed=3, layout="even")
    perf = rig_performance(rig, 24, head_motion_deg=5, expression_mm=3)
    _, frames = synthetic_detections(rig, 24, seed=1, performance=perf, noise_px=0.05)
    return rig, frames


def _threads_inside_the_gap_fill(monkeypatch, small_take) -> tuple[list, list]:
    """BLAS thread counts seen inside the tracker's learned relations, and after it returned,
    the caller having asked for two threads."""
    seen = []
    inner = gapfill.learned_conjectures

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        return inner(*args, **kwargs)

    monkeypatch.setattr(gapfill, "learned_conjectures", spy)
    rig, frames = small_take
    with threadpool_limits(limits=2, user_api="blas"):
        if _blas_threads() != [2]:
            pytest.skip("this machine's BLAS offers one thread: nothing to limit")
        result = track(frames, rig.camera, rig.planes)
        after = _blas_threads()
    assert len(result.labels) > 80 and np.isfinite(result.points).any()
    assert seen                                   # the spy sat where the tracker spends its BLAS calls
    return seen, after


def test_the_tracker_runs_on_one_blas_thread_and_gives_the_callers_count_back(monkeypatch, small_take):
    monkeypatch.delenv(BLAS_THREADS_ENV, raising=False)
    seen, after = _threads_inside_the_gap_fill(monkeypatch, small_take)
    assert all(s == [1] for s in seen)
    assert after == [2]


def test_the_blas_thread_count_is_the_users_to_set(monkeypatch, small_take):
    monkeypatch.setenv(BLAS_THREADS_ENV, "0")           # BLAS's own count: the caller's two
    seen, _ = _threads_inside_the_gap_fill(monkeypatch, small_take)
    assert all(s == [2] for s in seen)
    monkeypatch.setenv(BLAS_THREADS_ENV, "3")
    assert blas_threads() == 3
    for bad in ("two", "-1", "1.5"):
        monkeypatch.setenv(BLAS_THREADS_ENV, bad)
        with pytest.raises(InputError, match=BLAS_THREADS_ENV):
            blas_threads()


def test_detection_and_the_whole_track_command_run_on_one_blas_and_one_opencv_thread(monkeypatch):
    """``run_detection``, ``run_track`` and ``track_detections`` (the add-on's and the CLI's entry points)
    enter their work with one BLAS thread and one OpenCV thread: each is stopped at its first step and the
    counts read there; the caller's counts come back."""
    import cv2

    import mirrorcap.core.capture.detect as detect
    import mirrorcap.core.track.pipeline as pipeline

    monkeypatch.delenv(BLAS_THREADS_ENV, raising=False)
    seen = []

    class Stop(Exception):
        pass

    def first_step(*args, **kwargs):
        seen.append((_blas_threads(), cv2.getNumThreads()))
        raise Stop

    monkeypatch.setattr(detect, "_check_camera", first_step)          # run_detection's and run_track's first step
    monkeypatch.setattr(pipeline, "ClipDetections", type("C", (), {"of": staticmethod(first_step)}))
    opencv_before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    try:
        with threadpool_limits(limits=2, user_api="blas"):
            if _blas_threads() != [2]:
                pytest.skip("this machine's BLAS offers one thread: nothing to limit")
            for call in (lambda: detect.run_detection(None, "out.csv"), lambda: pipeline.run_track(None, None, "t.c3d"),
                         lambda: pipeline.track_detections(list(range(10)), [None] * 10, None, 30.0, "t.c3d")):
                with pytest.raises(Stop):
                    call()
            assert _blas_threads() == [2]
            assert cv2.getNumThreads() == 2
    finally:
        cv2.setNumThreads(opencv_before)
    assert seen == [([1], 1), ([1], 1), ([1], 1)]


def test_every_command_of_the_command_line_runs_on_one_blas_thread(monkeypatch, tmp_path):
    """The command line enters each command with one BLAS thread, and a bad ``MIRRORCAP_BLAS_THREADS`` is
    one error line, nothing run."""
    import mirrorcap.cli.commands as commands
    from mirrorcap.cli import main

    seen = []

    def info(args):
        seen.append(_blas_threads())
        return 0

    monkeypatch.setattr(commands, "info", info)
    monkeypatch.delenv(BLAS_THREADS_ENV, raising=False)
    with threadpool_limits(limits=2, user_api="blas"):
        if _blas_threads() != [2]:
            pytest.skip("this machine's BLAS offers one thread: nothing to limit")
        assert main(["info", str(tmp_path / "take.c3d")]) == 0
        assert _blas_threads() == [2]
        monkeypatch.setenv(BLAS_THREADS_ENV, "many")
        assert main(["info", str(tmp_path / "take.c3d")]) == 2
    assert seen == [[1]]


def test_the_detection_thread_count_is_the_users_to_set(monkeypatch):
    """Under normal light detection extracts one frame per core (at most four), under UV light one frame at a time
    (measured: no faster); ``MIRRORCAP_DETECT_THREADS`` sets another count under either; anything but a whole
    number of at least 1 is refused with the variable's name."""
    import os

    from mirrorcap.core.common.threads import DETECT_THREADS_ENV, MAX_DETECTION_THREADS, detection_threads

    monkeypatch.delenv(DETECT_THREADS_ENV, raising=False)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    assert detection_threads() == max(1, min(cores, MAX_DETECTION_THREADS))
    assert detection_threads(extraction_bound=False) == 1
    monkeypatch.setenv(DETECT_THREADS_ENV, "3")
    assert detection_threads() == 3 and detection_threads(extraction_bound=False) == 3
    for bad in ("0", "-2", "two", "1.5"):
        monkeypatch.setenv(DETECT_THREADS_ENV, bad)
        with pytest.raises(InputError, match=DETECT_THREADS_ENV):
            detection_threads()


def test_frames_extracted_on_threads_give_the_same_detections_in_order(monkeypatch):
    """Stop 43: under normal light frames are extracted on several threads at once. Each thread keeps its own
    extractor (they hold per-frame buffers), so 40 frames of the light clip give, frame by frame, the detections of
    one extractor alone, in the frames' order, on 1, 2 and 3 threads; the stream's counts agree too."""
    from pathlib import Path

    from mirrorcap.core.capture.detect import DetectionStream
    from mirrorcap.core.capture.markers import ColorClasses, ExtractionSettings
    from mirrorcap.core.capture.rig import load_rig_views
    from mirrorcap.core.capture.video import open_source

    clip = Path(__file__).resolve().parents[1] / "sample_scenes" / "normal" / "light"
    colours, settings = ColorClasses.default("normal"), ExtractionSettings(light="normal")
    runs = {}
    for threads in (1, 2, 3):
        stream = DetectionStream(open_source(clip / "clip.mp4"), colours, settings, load_rig_views(clip / "rig.json"),
                                 0, 40, threads=threads)
        assert stream.threads == threads
        runs[threads] = ([(n, det, view) for n, det, view in stream], stream.processed, stream.blobs)
    serial, processed, blobs = runs[1]
    assert processed == 40 and blobs > 40 * 100 and [n for n, _, _ in serial] == list(range(40))
    for threads in (2, 3):
        got, got_processed, got_blobs = runs[threads]
        assert (got_processed, got_blobs) == (processed, blobs)
        assert [n for n, _, _ in got] == list(range(40))
        for (_, a, view_a), (_, b, view_b) in zip(serial, got):
            assert np.array_equal(view_a, view_b)
            for field in ("x", "y", "color", "area", "intensity", "rgb", "elongation", "between"):
                assert np.array_equal(getattr(a, field), getattr(b, field)), field


def test_threaded_extraction_raises_in_the_frames_turn_and_stops_cleanly():
    """A frame the extractor refuses raises its error where that frame's turn comes, after the frames before it;
    a consumer that stops early leaves no extraction thread behind."""
    import threading

    from mirrorcap.core.capture.detect import extracted

    calls = []

    def make_extractor():
        def extract(frame):
            calls.append(frame)
            if frame < 0:
                raise InputError(f"frame {frame} refused")
            return frame * 10
        return extract

    frames = [(n, n if n != 5 else -5) for n in range(12)]
    got = []
    with pytest.raises(InputError, match="frame -5 refused"):
        for n, det, seconds in extracted(iter(frames), make_extractor, threads=2):
            got.append((n, det))
            assert seconds >= 0.0
    assert got == [(n, 10 * n) for n in range(5)]
    stream = extracted(iter([(n, n) for n in range(1000)]), make_extractor, threads=3)
    assert [next(stream)[:2] for _ in range(3)] == [(0, 0), (1, 10), (2, 20)]
    stream.close()
    assert len(calls) < 100                                  # at most twice the threads' frames ran ahead
    assert not [t for t in threading.enumerate() if t.name.startswith("mirrorcap-extract")]
