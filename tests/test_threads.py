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
                         lambda: pipeline.track_detections([0, 1], [None, None], None, 30.0, "t.c3d")):
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
