"""Rig video -> DETECTIONS.csv (``mirrorcap detect``), and learning colour classes.

DETECTIONS.csv -- one row per marker found in a frame::

    frame,view,x,y,color,area,intensity
    0,mirror0,212.4183,340.0127,pink,21,187.3

``frame`` is the source's frame number; ``view`` is ``direct``, ``mirror0`` (the mirror
imaged on the left) or ``mirror1``; ``x, y`` the sub-pixel centre in pixels of the
original image; ``color`` the colour-class name; ``area`` in pixels; ``intensity``
the mean brightest-channel value (0..255).

DETECTIONS.json beside it records the source, the frame selection, the view layout
used, the colour classes, the settings, counts and timings.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from ..common.errors import InputError
from ..common.files import check_output_paths, default_file_mode, write_files_atomically
from ..common.log import FrameProgress
from ..common.threads import detection_threads, with_limited_threads
from ..geometry.camera import Camera
from .detections import MAX_DOT_PX, disc_diameter_px, typical_dot_diameter_px
from .markers import ColorClasses, ExtractionSettings, marker_extractor
from .rig import VIEW_NAMES, ViewLayout, XHistogram, check_view_boundaries, split_views_by_gaps
from .video import VideoSource, check_frame_step

DETECTION_COLUMNS = ("frame", "view", "x", "y", "color", "area", "intensity")
LAYOUT_FRAMES = 30  # frames pooled to find the gaps between views
#: ... that show the face -- at least FACE_DETECTIONS detections each -- up to DECISION_MAX_FRAMES frames: a take
#: that opens on frames with no face (a slate, the performer stepping in) decides its layout and whether it keeps
#: its washed-out dots (keeps_between) on the first frames that show it
FACE_DETECTIONS = 10
DECISION_MAX_FRAMES = 300


def format_detection_rows(frame: int, view, x, y, color, area, intensity, view_names=VIEW_NAMES,
                          color_names=()) -> str:
    """CSV rows for one frame's detections, formatted in one C-level operation."""
    n = len(x)
    if n == 0:
        return ""
    vn = np.asarray(view_names, dtype=object)[np.asarray(view)]
    cn = np.asarray(color_names, dtype=object)[np.asarray(color)]
    cols = [np.full(n, frame).tolist(), vn.tolist(), np.asarray(x).tolist(), np.asarray(y).tolist(), cn.tolist(),
            np.asarray(area).tolist(), np.asarray(intensity).tolist()]
    flat = [v for row in zip(*cols) for v in row]
    return ("%d,%s,%.4f,%.4f,%s,%d,%.1f\n" * n) % tuple(flat)


def read_detections(path) -> dict:
    """DETECTIONS.csv -> dict of arrays: frame, view (index into VIEW_NAMES), x, y,
    color (name), area, intensity."""
    import csv

    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None or tuple(h.strip() for h in header) != DETECTION_COLUMNS:
            raise InputError(f"{path} is not a DETECTIONS.csv (header {','.join(DETECTION_COLUMNS)})")
        rows = list(reader)
    cols = list(zip(*rows)) if rows else [()] * 7
    index = {v: k for k, v in enumerate(VIEW_NAMES)}
    try:
        return {
            "frame": np.array(cols[0], dtype=int), "view": np.array([index[v] for v in cols[1]], dtype=int),
            "x": np.array(cols[2], dtype=float), "y": np.array(cols[3], dtype=float),
            "color": np.array(cols[4], dtype=object), "area": np.array(cols[5], dtype=int),
            "intensity": np.array(cols[6], dtype=float),
        }
    except (KeyError, ValueError) as exc:
        raise InputError(f"{path}: malformed row ({exc})") from None


def _layout_from(pending, settings: ExtractionSettings, source: VideoSource) -> ViewLayout:
    xs = np.concatenate([d.x for _, d in pending])
    if xs.size == 0:
        raise InputError(f"no markers found in the first {len(pending)} frames of {source.path} "
                         f"{_nothing_found_hint(settings)}")
    return split_views_by_gaps(xs, min_gap_px=2.0 * dot_diameter_px(settings, [d for _, d in pending]))


def dot_diameter_px(settings: ExtractionSettings, detections) -> float:
    """A dot's diameter in pixels: ``settings.marker_diameter_px`` when given, else the typical dot
    (:func:`.detections.typical_dot_diameter_px`) of the blobs of ``detections`` (a list of
    :class:`.detections.Detections`), at most ``MAX_DOT_PX`` -- as the extractor merges fragments
    (:func:`.markers.merge_marker_fragments`)."""
    if settings.marker_diameter_px is not None:
        return float(settings.marker_diameter_px)
    areas = np.concatenate([np.asarray(d.area, float) for d in detections]) if detections else np.zeros(0)
    dot = typical_dot_diameter_px(areas)
    return min(dot, MAX_DOT_PX) if dot > 0 else MAX_DOT_PX


def _nothing_found_hint(settings: ExtractionSettings) -> str:
    if settings.light == "normal":
        return ("under normal light: are there coloured dots on the face, and do the colour classes match them "
                "(`mirrorcap colors learn --light normal`)? Is the capture lit with UV (--light uv)?")
    return (f"(threshold {settings.threshold:g}): is this a rig video, or does --threshold need lowering? "
            "Coloured dots under ordinary light need --light normal")


class DetectionStream:
    """Detections of a source frame by frame, each assigned to its view: iterate to get
    ``(frame_number, Detections, view (n,))``. The detections of the first ``LAYOUT_FRAMES`` frames that show
    the face (``FACE_DETECTIONS`` or more; at most ``DECISION_MAX_FRAMES`` frames in all) are
    buffered -- detections, never images -- until three things are known from them: the view layout
    (a rig file's, or their gaps'), ``dot_px`` (a dot's diameter, :func:`dot_diameter_px`) and, under
    normal light, whether the dots whose colour fell between the classes are kept (``keep_between``;
    ``ExtractionSettings.washed_out``: ``"auto"`` keeps them when they number more than
    :data:`BETWEEN_CLASSES_MAX_SHARE` of the other dots there, :func:`keeps_between`). Frames are extracted
    ``threads`` at once (:func:`extracted`; by default :func:`..common.threads.detection_threads`: under normal light
    one per core, under UV light one), with the same detections as one after the other. ``extract_s`` accumulates
    the extraction time (summed over the threads) and ``processed`` the frames read, ``blobs`` the detections
    (between-class blobs not counted) and ``between_classes`` the between-class blobs, kept or not; ``first_face``
    is the number of the first frame that shows the face (None while none has)."""

    def __init__(self, source: VideoSource, colors: ColorClasses, settings: ExtractionSettings,
                 layout: ViewLayout | None = None, start: int = 0, end: int | None = None, step: int = 1,
                 progress=None, threads: int | None = None):
        self.source, self.colors, self.settings, self.layout = source, colors, settings, layout
        check_frame_step(step)
        self.start, self.end, self.step = start, end, step
        self.threads = detection_threads(extraction_bound=settings.light == "normal") if threads is None \
            else max(int(threads), 1)
        end_eff = source.frame_count if end is None else min(end, source.frame_count)
        self.total = len(range(start, end_eff, step))
        self.progress = progress
        self.extract_s = 0.0
        self.processed = 0
        self.blobs = 0               # detections of a colour class, and ...
        self.between_classes = 0     # ... blobs of a hue between the colour classes (normal light)
        self.keep_between = None     # are the latter kept? (decided after the first frames)
        self.first_face = None       # the number of the first frame that shows the face (FACE_DETECTIONS or more)
        self.dot_px = settings.marker_diameter_px

    def __iter__(self):
        pending, with_face = [], 0
        frames = self.source.frames(self.start, self.end, self.step, prefetch=4)
        for n, det, seconds in extracted(frames, lambda: marker_extractor(self.colors, self.settings), self.threads):
            self.extract_s += seconds
            self.processed += 1
            between = det.between_count()
            self.blobs += len(det) - between
            self.between_classes += between
            if self.progress:
                self.progress(self.processed)
            shows_face = len(det) >= FACE_DETECTIONS
            if shows_face and self.first_face is None:
                self.first_face = n
            if self.keep_between is None:
                pending.append((n, det))
                with_face += shows_face
                if with_face >= min(LAYOUT_FRAMES, self.total) or len(pending) >= DECISION_MAX_FRAMES:
                    yield from self._first_frames(pending)
                    pending = []
            else:
                det = between_chosen(det, self.keep_between)
                yield n, det, self.layout.assign(det.x, det.y)
        if self.keep_between is None:
            if self.processed == 0:
                raise InputError(f"no frame could be read from {self.source.path}")
            yield from self._first_frames(pending)

    def _first_frames(self, pending):
        """Decide from the buffered first frames ``pending`` (``(frame number, Detections)``) whether the
        between-class blobs are kept, a dot's diameter and the view layout; yield those frames."""
        self.keep_between = keeps_between(self.settings.washed_out, self.between_classes, self.blobs)
        chosen = [(n, between_chosen(det, self.keep_between)) for n, det in pending]
        if self.dot_px is None:
            self.dot_px = dot_diameter_px(self.settings, [det for _, det in chosen])
        if self.layout is None:
            self.layout = _layout_from(chosen, self.settings, self.source)
        for n, det in chosen:
            yield n, det, self.layout.assign(det.x, det.y)


def extracted(frames, make_extractor, threads: int = 1):
    """``(frame number, Detections, seconds)`` for each ``(frame number, BGR image)`` of ``frames``, in their
    order: the frame's markers and its extraction time. ``threads`` > 1 extracts that many frames at once, each
    thread with an extractor of its own (``make_extractor()``; an extractor keeps per-frame buffers), at most
    twice as many frames in flight (memory stays bounded). Each frame's detections are those of one extractor
    alone; an extraction's error is raised here, in the frame's turn; stopping early cancels the frames not yet
    begun and waits for those begun."""
    if threads <= 1:
        extractor = make_extractor()
        for n, frame in frames:
            t0 = time.perf_counter()
            det = extractor(frame)
            yield n, det, time.perf_counter() - t0
        return
    import threading
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor

    own = threading.local()

    def extract(frame):
        extractor = getattr(own, "extractor", None)
        if extractor is None:
            extractor = own.extractor = make_extractor()
        t0 = time.perf_counter()
        det = extractor(frame)
        return det, time.perf_counter() - t0

    pool = ThreadPoolExecutor(threads, thread_name_prefix="mirrorcap-extract")
    in_flight = deque()
    try:
        for n, frame in frames:
            in_flight.append((n, pool.submit(extract, frame)))
            if len(in_flight) >= 2 * threads:
                oldest, job = in_flight.popleft()
                yield oldest, *job.result()
        while in_flight:
            oldest, job = in_flight.popleft()
            yield oldest, *job.result()
    finally:
        for _, job in in_flight:
            job.cancel()
        pool.shutdown(wait=True)


def between_chosen(det, keep: bool):
    """:class:`.detections.Detections` ``det`` with its blobs of a hue between the colour classes if ``keep``, else
    without them."""
    return det if keep or not det.between_count() else det.subset(~det.between)


def keeps_between(washed_out: str, between: int, blobs: int) -> bool:
    """Are the blobs whose hue fell between the colour classes kept (``ExtractionSettings.washed_out``)?
    ``"auto"``: when the first frames hold ``between`` of them against ``blobs`` dots of a class, more than
    :data:`BETWEEN_CLASSES_MAX_SHARE` of those -- a video whose compression washed the dots' colours out (the
    figures at :data:`BETWEEN_CLASSES_MAX_SHARE`). Where the colours are sound, such blobs are mostly a dot's
    rim or a grazing image, and kept they cost more than they give (stops 41-42: tan720 4 -> 42 points over
    2 mm, med720 at CRF 20 13 -> 32 identity switches)."""
    if washed_out == "keep":
        return True
    return washed_out == "auto" and between > BETWEEN_CLASSES_MAX_SHARE * max(blobs, 1)


def _check_camera(camera: Camera | None, source: VideoSource):
    if camera is not None and camera.image_size != source.size:
        raise InputError(f"the camera file is for {camera.image_size[0]}x{camera.image_size[1]} images but "
                         f"{source.path} is {source.size[0]}x{source.size[1]}")


@with_limited_threads
def run_detection(source: VideoSource, output, *, colors: ColorClasses | None = None,
                  settings: ExtractionSettings | None = None, layout: ViewLayout | None = None,
                  camera: Camera | None = None, start: int = 0, end: int | None = None, step: int = 1,
                  progress=None) -> dict:
    """Stream ``source`` through the extractor and write DETECTIONS.csv (+ .json)
    atomically. Returns the report written to the JSON. ``progress(text, final)``, if given,
    receives a progress line at most once a second (:class:`..common.log.FrameProgress`)."""
    settings = settings or ExtractionSettings()
    colors = colors or ColorClasses.default(settings.light)
    _check_camera(camera, source)
    output = Path(output)
    if output.suffix.lower() == ".json":
        raise InputError(f"{output}: the detections are a CSV file, and their report is written beside it as "
                         f"{output.stem}.json -- name the detections {output.stem}.csv")
    check_output_paths(output, output.with_suffix(".json"))
    stream = DetectionStream(source, colors, settings, layout, start, end, step)
    stream.progress = FrameProgress(stream.total, "detect", progress or None)
    counts = np.zeros(len(VIEW_NAMES) + 1, dtype=np.int64)  # last: outside every view
    t_write = 0.0
    xs = XHistogram()                                       # the detections' x, for the layout check
    areas = AreaHistogram()                                 # the blobs' areas by view, for each view's typical dot
    fd, tmp = tempfile.mkstemp(prefix=f".{output.name}.", suffix=".tmp", dir=output.parent)
    t_start = time.perf_counter()
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(",".join(DETECTION_COLUMNS) + "\n")
            for n, det, view in stream:
                counts[:-1] += np.bincount(view[view >= 0], minlength=len(VIEW_NAMES))
                counts[-1] += np.count_nonzero(view < 0)
                xs.add(det.x)
                ok = view >= 0
                areas.add(det.area, view)
                t0 = time.perf_counter()
                fh.write(format_detection_rows(n, view[ok], det.x[ok], det.y[ok], det.color[ok], det.area[ok],
                                               det.intensity[ok], color_names=colors.names))
                t_write += time.perf_counter() - t0
            fh.flush()
            os.fsync(fh.fileno())
        stream.progress(stream.processed, final=True)
        done = stream.processed
        if done == 0:
            raise InputError(f"no frame could be read from {source.path}")
        if counts[:-1].sum() == 0:
            raise InputError(f"no markers found in {source.path} {_nothing_found_hint(settings)}")
        elapsed = time.perf_counter() - t_start
        t_extract = stream.extract_s
        end_eff = source.frame_count if end is None else min(end, source.frame_count)
        layout = stream.layout
        report = {
            "source": {"path": source.path, "kind": source.kind, "fps": source.fps,
                       "frame_count": source.frame_count, "size": list(source.size)},
            "frames": {"start": start, "end": end_eff, "step": step, "processed": done},
            "layout": layout.to_dict(),
            "view_layout": check_view_boundaries(xs, layout, done, stream.dot_px or 0.0),
            "colors": colors.to_dict(),
            "settings": asdict(settings),
            "counts": {**{v: int(c) for v, c in zip(VIEW_NAMES, counts)}, "outside_views": int(counts[-1])},
            "dot_px": areas.dot_px(),
            "video": source.compression(),
            "between_classes": between_classes(stream),
            "timings_s": {"total": elapsed, "extract": t_extract, "write": t_write},
            "extract_threads": stream.threads,
            "frames_per_second": done / elapsed if elapsed > 0 else None,
        }
        write_files_atomically({output.with_suffix(".json"): json.dumps(report, indent=2) + "\n"})
        os.chmod(tmp, default_file_mode())
        os.replace(tmp, output)
        tmp = None
        return report
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)


#: under normal light, a mirror whose median dot measures less than this (pixels across) is warned about
#: (:func:`small_dot_warning`): mirror images of 2.5-3.0 px lost most of their dots (small540, pale600: the video's
#: halved colour resolution blends them into the skin), 3.6 px and more kept them (ruddy540 and the other six
#: normal-light clips)
NORMAL_LIGHT_MIN_DOT_PX = 3.3


#: what the warnings on a take's mirrors advise (README, "The rig: what it needs": video quality)
VIDEO_QUALITY_HINT = ("under normal light, keep the video near-lossless (H.264 CRF 17 or better): compression washes "
                      "out small dots")


#: under normal light, more blobs of a hue between the colour classes than this share of the other detections is
#: warned about (:func:`between_classes_warning`), and from the first frames' share such blobs are kept
#: (:func:`keeps_between`): the rendered normal-light clips hold 0.0-1.1 %; re-encoded at H.264 CRF 20-29, those
#: that lost 7 or more points of their seen marker-frames 2.4-9.0 % (and small540, whose dots are too small,
#: 16.8 %), those that lost 2-5 points 0.7-1.8 % (stop 41); held out, rose720 at CRF 20 lost 11 and held 3.3 %
BETWEEN_CLASSES_MAX_SHARE = 0.02


def between_classes(stream) -> dict:
    """``{"blobs", "between_classes", "share", "kept"}`` of a :class:`DetectionStream` that has run: the detections
    of a colour class, the blobs of a hue between the classes, their share of the former, and whether they were
    kept (:func:`keeps_between`)."""
    return {"blobs": stream.blobs, "between_classes": stream.between_classes,
            "share": stream.between_classes / max(stream.blobs, 1), "kept": bool(stream.keep_between)}


def between_classes_warning(light: str, figures: dict) -> str | None:
    """The warning when, under ``light`` ``"normal"``, the blobs of a hue between the colour classes (``figures``,
    :func:`between_classes`) exceed :data:`BETWEEN_CLASSES_MAX_SHARE` of the detections; None otherwise."""
    if light != "normal" or figures["share"] <= BETWEEN_CLASSES_MAX_SHARE:
        return None
    found = (f"{100 * figures['share']:.1f} % as many blobs as the dots found had a colour between the colour classes "
             f"({figures['between_classes']} of them, {figures['blobs']} dots; up to 1.1 % on the rigs measured): "
             "the dots' colours are washed out")
    if figures.get("kept"):
        return (f"{found}. They were kept, each classed by its colour less the skin's: on the clips measured that "
                "won back a quarter to a half of the marker-frames lost, but such a take still loses some and is "
                f"likelier to mislabel a marker; {VIDEO_QUALITY_HINT}, light the face evenly, or use larger dots")
    return (f"{found}, and they were dropped: on the clips measured the take then lost 7 to 54 points of the "
            f"marker-frames it should report; {VIDEO_QUALITY_HINT}, light the face evenly, or use larger dots")


class AreaHistogram:
    """Blob areas (whole pixels) pooled by view over a stream, for each view's typical dot: its memory is the largest
    blob's area, not the stream's length (kept as lists, a 10,000-frame UV stream of 557 dots a frame grew the
    process by 164 MB). ``add`` a frame's areas and views (indices into :data:`.rig.VIEW_NAMES`; a blob outside
    every view, -1, is left out)."""

    def __init__(self):
        self.counts = np.zeros((len(VIEW_NAMES), 0), np.int64)

    def add(self, area, view) -> None:
        view = np.asarray(view, np.int64)
        inside = (view >= 0) & (view < len(VIEW_NAMES))
        area, view = np.maximum(np.asarray(area, np.int64)[inside], 0), view[inside]
        if not area.size:
            return
        size = max(self.counts.shape[1], int(area.max()) + 1)
        if size > self.counts.shape[1]:
            self.counts = np.c_[self.counts, np.zeros((len(VIEW_NAMES), size - self.counts.shape[1]), np.int64)]
        self.counts += np.bincount(view * size + area, minlength=len(VIEW_NAMES) * size).reshape(-1, size)

    def dot_px(self) -> dict:
        """Each view's typical dot, as :func:`.detections.typical_dot_diameter_px` gives it from the view's areas
        (the median taken from the counts, as numpy takes it): ``{name: px or None}`` (None: no blob there)."""
        out = {}
        for v, name in enumerate(VIEW_NAMES):
            cum = np.cumsum(self.counts[v]) if self.counts.size else np.zeros(0, np.int64)
            n = int(cum[-1]) if cum.size else 0
            if n == 0:
                out[name] = None
                continue
            ranked = np.searchsorted(cum, [(n - 1) // 2, n // 2], side="right")      # the middle value(s), sorted
            out[name] = disc_diameter_px(ranked.mean()) or None
        return out


def dot_px_by_view(area, view) -> dict:
    """Each view's typical dot (:func:`.detections.typical_dot_diameter_px`) from blob areas ``area`` ``(n,)`` in
    views ``view`` ``(n,)`` (indices into :data:`.rig.VIEW_NAMES`): ``{name: px or None}`` (None: no blob there)."""
    areas = AreaHistogram()
    areas.add(area, view)
    return areas.dot_px()


def dot_px_text(dot_px: dict) -> str:
    """``"3.2, 2.8, 2.5"``: the typical dots of :func:`dot_px_by_view` in the order of :data:`.rig.VIEW_NAMES`
    (``-`` where a view has none), as `detect` and Detect Markers print them."""
    return ", ".join("-" if dot_px.get(v) is None else f"{dot_px[v]:.1f}" for v in VIEW_NAMES)


def small_dot_warning(light: str, dot_px: dict) -> str | None:
    """The warning when, under ``light`` ``"normal"``, a mirror's typical dot (``dot_px``, :func:`dot_px_by_view`)
    measures under :data:`NORMAL_LIGHT_MIN_DOT_PX`; None otherwise."""
    small = {v: p for v, p in dot_px.items() if v != "direct" and p is not None and p < NORMAL_LIGHT_MIN_DOT_PX}
    if light != "normal" or not small:
        return None
    sizes = " and ".join(f"{p:.1f} px in {v}" for v, p in small.items())
    return (f"the mirrors' dots measure {sizes} (the median blob): under normal light, mirror images this small "
            "lose their colour to the video's halved colour resolution, and most are missed (2.5-3.0 px lost most "
            "of their dots on the rigs measured, 3.6 px kept them) -- use larger dots, a closer camera or a higher "
            "resolution, or UV light")


@with_limited_threads
def learn_color_classes(source: VideoSource, n_classes: int, *, names=None, start: int = 0, end: int | None = None,
                        step: int = 1, max_frames: int = 50, threshold: float = 60.0,
                        marker_diameter_px: float | None = None, samples_per_class: int = 8,
                        light: str = "uv") -> ColorClasses:
    """Learn ``n_classes`` colour classes from the markers of sample frames: k-means
    (OpenCV, fixed seed) on each marker's mean normalised colour; each class keeps
    its centre and the members nearest to it as 1-NN samples. Classes are ordered
    by hue; ``names`` (one per class) name them, else ``class0``, ``class1``, ...
    Under ``light="normal"`` the markers are every blob whose colour stands out from the skin
    around it (:mod:`.colordots` without the class test); the classes record their light."""
    import cv2

    if n_classes < 1:
        raise InputError("--classes must be at least 1")
    if names is not None and len(names) != n_classes:
        raise InputError(f"{len(names)} names given for {n_classes} classes")
    one_class = ColorClasses.from_dict({"classes": [{"name": "any", "samples": [[1, 1, 1]]}]})
    extractor = marker_extractor(one_class, ExtractionSettings(light=light, threshold=threshold,
                                                               marker_diameter_px=marker_diameter_px,
                                                               max_hue_deg=180.0))
    pooled = []
    for k, (_, frame) in enumerate(source.frames(start, end, step)):
        if k >= max_frames:
            break
        pooled.append(extractor(frame).rgb)
    rgb = np.concatenate(pooled) if pooled else np.zeros((0, 3))
    if rgb.shape[0] < n_classes * 3:
        raise InputError(f"only {rgb.shape[0]} markers found in the sample frames; cannot learn {n_classes} classes")
    cv2.setRNGSeed(0)
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-6)
    _, labels, centres = cv2.kmeans(rgb.astype(np.float32), n_classes, None, crit, 5, cv2.KMEANS_PP_CENTERS)
    labels = labels.ravel()
    hue = np.arctan2(np.sqrt(3) * (centres[:, 1] - centres[:, 2]), 2 * centres[:, 0] - centres[:, 1] - centres[:, 2])
    order = np.argsort(hue)
    classes = []
    for rank, k in enumerate(order):
        members = rgb[labels == k]
        near = members[np.argsort(np.linalg.norm(members - centres[k], axis=1))[: samples_per_class - 1]]
        samples = np.vstack([centres[k][None], near])
        classes.append({"name": names[rank] if names else f"class{rank}", "samples": samples.tolist()})
    return ColorClasses.from_dict({"classes": classes, "light": light})
