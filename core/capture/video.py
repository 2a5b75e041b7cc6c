"""Rig video ingest: video files and image sequences, streamed frame by frame.

Sources:

* a video file OpenCV can decode (mp4, mov, avi, mkv, ...);
* a folder of images (png, jpg, jpeg, exr, tif, tiff, bmp), in natural order;
* a glob pattern such as ``shots/take3_*.png``.

Frames come out as 8-bit BGR arrays ``(height, width, 3)``; 16-bit and float
images (EXR) are scaled to 8 bits (float: 0..1 -> 0..255, clipped). A 16-bit sequence is scaled by the
bits its samples use (:func:`sample_bits`, from its first, middle and last images): a machine-vision
camera's 10-, 12- or 14-bit samples stored low in 16-bit files keep their range. Frames are
read one at a time -- a clip is never held in memory.

A frame selection is ``start:end`` (end exclusive, either side optional) plus a
``step``, in frame numbers of the source.
"""

from __future__ import annotations

import glob
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..common.errors import InputError

os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")  # before cv2 is imported

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".exr", ".tif", ".tiff", ".bmp")
DEFAULT_IMAGE_FPS = 30.0


def _natural_key(path: str):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path)]


def parse_frame_range(text: str | None) -> tuple[int, int | None]:
    """``"START:END"`` -> ``(start, end)``; either side may be empty; END exclusive."""
    if text is None or text == "":
        return 0, None
    m = re.fullmatch(r"\s*(\d*)\s*:\s*(\d*)\s*", text)
    if not m:
        raise InputError(f"frame range must look like START:END (e.g. 0:300), got {text!r}")
    start = int(m.group(1)) if m.group(1) else 0
    end = int(m.group(2)) if m.group(2) else None
    if end is not None and end <= start:
        raise InputError(f"frame range {text!r} is empty")
    return start, end


#: the sample depths a 16-bit image may carry (:func:`sample_bits`)
SAMPLE_BITS = (8, 10, 12, 14, 16)


def sample_bits(images) -> int:
    """The bits the samples of 16-bit ``images`` use: the least of :data:`SAMPLE_BITS` that holds their largest
    value (a 12-bit camera's data stored low in 16-bit files: 12; scaled to the full range: 16)."""
    top = max((int(im.max()) for im in images if im is not None and im.size), default=0)
    need = max(top, 1).bit_length()
    return next((b for b in SAMPLE_BITS if b >= need), 16)


def to_bgr8(image: np.ndarray, bits: int = 16) -> np.ndarray:
    """Any OpenCV-read image -> 8-bit, 3-channel BGR; a 16-bit one's samples use ``bits`` (:func:`sample_bits`),
    and any above that range saturate."""
    import cv2

    img = image
    if img.dtype == np.uint16:
        img = np.minimum(img >> max(int(bits) - 8, 0), 255).astype(np.uint8)
    elif img.dtype in (np.float32, np.float64):
        img = np.clip(img * 255.0 + 0.5, 0, 255).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise InputError(f"unsupported image type {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    return img


@dataclass
class VideoSource:
    """An opened rig video or image sequence."""

    path: str
    kind: str  # "video" or "images"
    fps: float
    frame_count: int
    size: tuple[int, int]  # (width, height)
    files: list | None = None
    bits: int = 16  # a 16-bit image sequence's sample depth (sample_bits)

    def compression(self) -> dict | None:
        """How hard a video file is compressed: ``{"mbit_per_s", "bits_per_pixel"}`` -- the file's bits per
        second, and per pixel of one frame (the file over its frames' pixels: a container's other streams
        and headers count too). None for an image sequence, or a video of unknown length or rate."""
        if self.kind != "video" or self.frame_count <= 0 or not self.fps > 0:
            return None
        bits = 8.0 * os.path.getsize(self.path)
        return {"mbit_per_s": bits * self.fps / self.frame_count / 1e6,
                "bits_per_pixel": bits / (self.frame_count * self.size[0] * self.size[1])}

    def frames(self, start: int = 0, end: int | None = None, step: int = 1, prefetch: int = 0):
        """Yield ``(frame_number, bgr_image)`` for ``start <= n < end`` every ``step``.

        ``prefetch > 0`` decodes in a background thread, at most ``prefetch`` frames
        ahead (OpenCV releases the GIL while decoding, so decoding overlaps the
        caller's work on another core; memory stays bounded)."""
        check_frame_step(step)
        end = self.frame_count if end is None else min(end, self.frame_count)
        if start >= end:
            raise InputError(f"frame range {start}:{end} selects no frame of {self.path} "
                             f"({self.frame_count} frames)")
        if prefetch <= 0:
            yield from self._read(start, end, step)
            return
        yield from _prefetched(self._read(start, end, step), prefetch)

    def _read(self, start: int, end: int, step: int):
        import cv2

        if self.kind == "images":
            for n in range(start, end, step):
                img = cv2.imread(self.files[n], cv2.IMREAD_UNCHANGED)
                if img is None:
                    raise InputError(f"cannot read image {self.files[n]}")
                img = to_bgr8(img, self.bits)
                if (img.shape[1], img.shape[0]) != self.size:
                    raise InputError(f"image {self.files[n]} is {img.shape[1]}x{img.shape[0]}, "
                                     f"the sequence is {self.size[0]}x{self.size[1]}")
                yield n, img
            return
        cap = cv2.VideoCapture(self.path)
        try:
            if start:
                cap.set(cv2.CAP_PROP_POS_FRAMES, start)
            n = start
            while n < end:
                if (n - start) % step == 0:
                    ok, img = cap.read()
                    if not ok:
                        break
                    yield n, to_bgr8(img)
                elif not cap.grab():  # skipped frames are not decoded
                    break
                n += 1
        finally:
            cap.release()


def _prefetched(iterator, depth: int):
    """Run ``iterator`` in a daemon thread, ``depth`` items ahead; re-raise its errors;
    stop it when the consumer stops early."""
    import queue
    import threading

    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def work():
        try:
            for item in iterator:
                while not stop.is_set():
                    try:
                        q.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            q.put(done)
        except BaseException as exc:  # handed to the consumer
            q.put(exc)

    thread = threading.Thread(target=work, name="mirrorcap-decode", daemon=True)
    thread.start()
    try:
        while True:
            item = q.get()
            if item is done:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        thread.join(timeout=5)


def check_frame_step(step) -> None:
    """Every ``step``-th frame: a whole number, at least 1 (one message wherever a step is taken)."""
    if not (isinstance(step, (int, np.integer)) and step >= 1):
        raise InputError(f"frame step must be a whole number, at least 1 (not {step!r})")


def open_source(path, fps: float | None = None) -> VideoSource:
    """Open a video file, an image folder or a glob; clear errors for anything else."""
    import cv2

    if fps is not None and not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
        raise InputError(f"the frame rate must be a positive number of frames per second (not {fps!r})")
    text = str(path)
    p = Path(text)
    files = None
    if p.is_dir():
        files = sorted((str(f) for f in p.iterdir() if f.suffix.lower() in IMAGE_EXTENSIONS), key=_natural_key)
        if not files:
            raise InputError(f"folder {p} holds no images ({', '.join(IMAGE_EXTENSIONS)})")
    elif any(ch in text for ch in "*?[") and not p.exists():
        files = sorted((f for f in glob.glob(text) if Path(f).suffix.lower() in IMAGE_EXTENSIONS), key=_natural_key)
        if not files:
            raise InputError(f"no images match {text}")
    if files is not None:
        first = cv2.imread(files[0], cv2.IMREAD_UNCHANGED)
        if first is None:
            raise InputError(f"cannot read image {files[0]}")
        bits = 16
        if first.dtype == np.uint16:   # the sequence's sample depth, from its first, middle and last images
            bits = sample_bits([first] + [cv2.imread(files[k], cv2.IMREAD_UNCHANGED)
                                          for k in sorted({len(files) // 2, len(files) - 1} - {0})])
        first = to_bgr8(first, bits)
        return VideoSource(path=text, kind="images", fps=float(fps or DEFAULT_IMAGE_FPS), frame_count=len(files),
                           size=(first.shape[1], first.shape[0]), files=files, bits=bits)
    if not p.is_file():
        raise InputError(f"no such video, folder or image pattern: {text}")
    if p.stat().st_size == 0:
        raise InputError(f"video {text} is empty")
    cap = cv2.VideoCapture(text)
    try:
        if not cap.isOpened():
            raise InputError(f"cannot decode video {text} (not a video OpenCV can read)")
        ok, img = cap.read()
        if not ok or img is None:
            raise InputError(f"video {text} has no readable frame")
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        rate = cap.get(cv2.CAP_PROP_FPS)
    finally:
        cap.release()
    if count <= 0:  # some containers do not store it: count by decoding (streamed)
        cap = cv2.VideoCapture(text)
        count = 0
        while cap.grab():
            count += 1
        cap.release()
    return VideoSource(path=text, kind="video", fps=float(fps or rate or DEFAULT_IMAGE_FPS), frame_count=count,
                       size=(img.shape[1], img.shape[0]))
