"""One BLAS thread and one OpenCV thread for MirrorCap's jobs (every command of the command line,
every add-on job, and the core's detection and tracking entry points for callers of their own).

The core's array code makes tens of thousands of BLAS and LAPACK calls on tiny matrices (batched
3x3 solves and inverses, (frames x 3) @ (3 x 3) products, per-frame least squares). OpenBLAS, which
numpy and scipy bundle, runs each of them on all its threads, and a thread that is not scheduled at
once stalls the call: with another job keeping the cores busy (Blender rendering, a second take
tracked, a batch) a 90-frame clip's tracking took 24 s against 1.3 s, the ARKit solve of 1,000
frames 46 s against 2.8 s. On an idle machine one thread is as fast or faster (the 600-frame bench
clip tracks as fast with about a fifth less CPU; the ARKit solve 1.4 s against 1.8 s), except for
the PCA bake's one large SVD (0.9 s against 0.5 s).

OpenCV's own thread pool does the same to marker detection: its calls on one 1280x720 frame are too
short to share, and on 2 cores the 600-frame bench clip's extraction took 1.73-1.83 s and 2.08-2.22
core-seconds with OpenCV's threads against 1.67-1.74 s and as many core-seconds on one (stop 41, frames held
in memory, three runs each).

``MIRRORCAP_BLAS_THREADS`` sets the count for both (a whole number; 0 leaves BLAS and OpenCV their own
defaults). The limit is process-wide while a job runs (threadpoolctl; ``cv2.setNumThreads``) and is lifted
when it returns. It reaches the BLAS libraries loaded when the job starts, so numpy's and scipy's are
loaded first.

Detection shares the cores its own way: frames are independent, so :class:`..capture.detect.DetectionStream`
extracts several at once under normal light, each on a thread of its own (:func:`detection_threads`: one per core
this process may run on, at most :data:`MAX_DETECTION_THREADS`; ``MIRRORCAP_DETECT_THREADS`` sets another count,
under either light). A frame's extraction releases the GIL in most of its time (OpenCV's calls, numpy's loops over
its pixels), and the video's decoder runs on threads of its own beside them. Under UV light one thread is as fast:
a 1280x720 frame's extraction (about 3.5 ms) is little more than its decoding, which already keeps the second core
busy. Self-calibration (``core.track.pipeline.track_detections``) searches the two mirrors' planes at once, a thread
each: their batched array work releases the GIL (the 600-frame bench clip's two searches, measured alone on the idle
machine: 1.13-1.22 s one after the other, 0.65-0.72 s at once). The clip's 2D tracks do not: their three views'
linking, measured while a render kept a core busy, took 1.2-1.3 s on three threads against 0.8 s in one.
"""

from __future__ import annotations

import functools
import os
from contextlib import contextmanager

from .errors import InputError

BLAS_THREADS_ENV = "MIRRORCAP_BLAS_THREADS"
DEFAULT_BLAS_THREADS = 1
DETECT_THREADS_ENV = "MIRRORCAP_DETECT_THREADS"
MAX_DETECTION_THREADS = 4   # a cap (measured on 2 cores only: with more, the video's decoder may be the bound)


def detection_threads(extraction_bound: bool = True) -> int:
    """Threads that extract markers from frames at once: ``MIRRORCAP_DETECT_THREADS`` (a whole number, at least
    1; 1 extracts frame after frame), else one per core this process may run on, at most
    :data:`MAX_DETECTION_THREADS`, where the extraction is what bounds detection (``extraction_bound``), and 1
    where it is not."""
    raw = os.environ.get(DETECT_THREADS_ENV, "").strip()
    if not raw:
        if not extraction_bound:
            return 1
        try:
            cores = len(os.sched_getaffinity(0))
        except (AttributeError, OSError):          # not on Linux
            cores = os.cpu_count() or 1
        return max(1, min(cores, MAX_DETECTION_THREADS))
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise InputError(f"{DETECT_THREADS_ENV}={raw!r}: give a whole number of threads, at least 1")
    return n


def blas_threads() -> int:
    """The BLAS thread count the core's jobs run with: ``MIRRORCAP_BLAS_THREADS`` or
    :data:`DEFAULT_BLAS_THREADS`; 0 means BLAS's own default (no limit)."""
    raw = os.environ.get(BLAS_THREADS_ENV, "").strip()
    if not raw:
        return DEFAULT_BLAS_THREADS
    try:
        n = int(raw)
    except ValueError:
        n = -1
    if n < 0:
        raise InputError(f"{BLAS_THREADS_ENV}={raw!r}: give a whole number of threads (0: BLAS's own default)")
    return n


@contextmanager
def limited_threads():
    """Run the enclosed work with :func:`blas_threads` BLAS threads and as many OpenCV threads,
    restoring the previous counts after."""
    n = blas_threads()
    if n == 0:
        yield
        return
    import importlib

    import cv2
    from threadpoolctl import threadpool_limits

    for name in ("numpy", "scipy.linalg"):           # both BLAS libraries loaded, so that the limit reaches them
        importlib.import_module(name)

    opencv_before = cv2.getNumThreads()
    cv2.setNumThreads(n)
    try:
        with threadpool_limits(limits=n, user_api="blas"):
            yield
    finally:
        cv2.setNumThreads(opencv_before)


def with_limited_threads(job):
    """Decorator: the job runs inside :func:`limited_threads`."""

    @functools.wraps(job)
    def run(*args, **kwargs):
        with limited_threads():
            return job(*args, **kwargs)

    return run
