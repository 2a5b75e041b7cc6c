"""Rig video -> TAKE.c3d + REPORT.json (``mirrorcap track``).

The stages in order: marker detection (``core.capture.detect``), mirror planes (from
MIRRORS.json, else self-calibrated from the first frames' markers, ``core.track.selfcal``),
tracking (``core.track``), an optional known-length scale, and the outputs, written
together atomically.

Without MIRRORS.json the take's units are "relative": self-calibration has no scale, so the
face is put ``face_distance_mm`` (600) from the camera, which makes the units close to mm;
``--known-length`` makes them exact.

REPORT.json: ``units``; ``mirrors`` (normal, d per mirror; ``source``: file or
self-calibration); ``mirror_scale_link`` (self-calibration only: how mirror 1's distance was put in
mirror 0's units, :func:`.mirrorscale.link_mirror_scales` -- ratio, relative_spread, standard_error,
samples, markers -- or, with fewer than 3 markers in both mirrors or their ratios spread over 0.5 %,
:func:`.mirrorscale.link_mirror_scales_by_motion`, which adds markers_per_mirror, rigid_markers_per_mirror
and relative_spread_all_markers and, in the second case,
``shared_markers_link``: the doubted link it stands in for (the choice:
:func:`.mirrorscale.link_self_calibrated_scales`); ``source`` says which; null with MIRRORS.json;
a warning, :func:`.mirrorscale.scale_link_warning`, when the shared markers' link had to stay though doubted);
``mirror_agreement`` (:func:`.mirrorscale.mirror_agreement`:
markers seen in both mirrors, the median / median-absolute / p95 difference of their depth through
the two mirrors in take units, the expected sd, the observed sd (1.4826 MAD), noise_px,
relative_difference, ``scattered``, ``consistent``: false -- with a warning -- when the median difference
exceeds twice the expected sd or the observed sd ten times it (``scattered``); null when too few markers are
seen in both); ``view_layout``
(:func:`..capture.rig.check_view_boundaries`: per boundary between views its ``x``, the views
``between`` it, ``dots_per_frame`` within a dot of it, ``crowding`` -- the detection density there
over a view's --, the ``emptiest_x`` line nearby and its ``emptiest_crowding``, and ``crowded``, with a
warning; ``note`` when the automatic split had to take the emptiest lines, the views touching; null for
detections given without a layout); ``frames`` (first, last, step, count, fps); ``markers`` (count,
labels, the rigid markers that carried the head pose and ``rigid_source``: "rig file",
"settings" (the add-on's) or "automatic"; ``undecided``: direct-view markers of the first frames that could not be
paired with a mirror image and were not found later, each with the frame and pixel position
where it was first seen, its colour class index, the frames it was seen in and the
``reason``: "no mirror partner" or "ambiguous in mirror K" -- rival partners); ``head_pose`` (per frame
``[rx, ry, rz, tx, ty, tz]``, radians and output units, eq. 5.4, relative to the first
frame); ``per_frame`` counts (``candidates``, ``measured``, ``false_tracking``,
``conflicts``, ``conjectured``, ``withheld``: conjectures left as gaps, expected off by more than
the limit; ``doubted`` and ``repaired``: single-mirror measurements made gaps or re-paired,
:func:`.gapfill.doubt_outlying_measurements`;
the tracker's other stages add theirs); ``video`` (:meth:`..capture.video.VideoSource.compression`: mbit_per_s,
bits_per_pixel; null for image sequences and detections given); ``between_classes``
(:func:`..capture.detect.between_classes`: blobs, between_classes, share, kept -- a warning under normal light above
2 %, :func:`..capture.detect.between_classes_warning`; null for detections given); ``timings_s`` (``detect``, ``track``,
``track_stages``: seconds per
tracker stage, ``tracking_frames_per_s``).
"""

from __future__ import annotations

import json
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..capture.markers import ColorClasses, ExtractionSettings
from ..capture.rig import ViewLayout, check_view_boundaries, view_boundary_warnings
from ..capture.views import ClipDetections, FrameDets
from ..capture.video import VideoSource
from ..common.log import MessageLog
from ..common.errors import DegenerateError, InputError
from ..common.files import check_output_paths, write_files_atomically
from ..common.threads import with_limited_threads
from ..geometry.camera import Camera
from ..geometry.mirror import MirrorPlane
from ..take.c3d import c3d_bytes
from .tracker import TrackSettings, track

SELFCAL_FRAMES = 10
FACE_DISTANCE_MM = 600.0   # nominal camera-to-face distance that fixes a self-calibrated take's scale


def collect_detections(stream) -> tuple[list, list]:
    """Frame numbers and :class:`FrameDets` from a :class:`core.capture.detect.DetectionStream`."""
    numbers, frames = [], []
    for n, det, view in stream:
        pick = [view == v for v in range(3)]
        xy = np.c_[det.x, det.y]
        frames.append(FrameDets(direct=xy[pick[0]], direct_color=det.color[pick[0]],
                                mirror=[xy[pick[1]], xy[pick[2]]], mirror_color=[det.color[pick[1]], det.color[pick[2]]],
                                direct_area=det.area[pick[0]], mirror_area=[det.area[pick[1]], det.area[pick[2]]]))
        numbers.append(n)
    return numbers, frames


@with_limited_threads
def run_track(source: VideoSource, camera: Camera, output, *, report=None, colors: ColorClasses | None = None,
              extraction: ExtractionSettings | None = None, layout: ViewLayout | None = None, mirrors=None,
              known_length=None, start: int = 0, end: int | None = None, step: int = 1,
              settings: TrackSettings | None = None, progress=None, track_progress=None,
              face_distance_mm: float = FACE_DISTANCE_MM, rigid=None, rigid_source: str = "rig file",
              log: MessageLog | None = None, seeds=None) -> dict:
    """Track ``source`` and write the take (C3D) and its report (JSON). ``seeds``: the user's
    designations in the first tracked frame (:func:`.seeds.read_seeds`). ``progress(frames_read)``
    is called per decoded frame, ``track_progress(frame, frames)`` per tracked frame;
    ``rigid`` names the markers that carry the head pose, as :func:`..capture.rig.rigid_selection` gives
    them (``rigid_source`` says where they came from, for the report). Frames at the start that show no face
    (fewer than :data:`..capture.detect.FACE_DETECTIONS` detections: a slate, an empty chair) are left out, with
    a warning: the take starts at the first frame that shows it, its neutral frame."""
    from ..capture.detect import (FACE_DETECTIONS, DetectionStream, _check_camera, between_classes,
                                  between_classes_warning)

    _check_camera(camera, source)
    check_output_paths(output, report)
    check_known_length(known_length)
    extraction = extraction or ExtractionSettings()
    t0 = time.perf_counter()
    stream = DetectionStream(source, colors or ColorClasses.default(extraction.light), extraction, layout,
                             start, end, step, progress)
    numbers, frames = collect_detections(stream)
    t_detect = time.perf_counter() - t0
    washed = between_classes(stream)
    log = log if log is not None else MessageLog()
    lead = numbers.index(stream.first_face) if stream.first_face is not None else 0
    if lead:          # a slate, an empty chair: the take starts where the face does (its neutral frame)
        log.warning(f"the first {lead} frames ({numbers[0]} to {numbers[lead - 1]}) show no face (fewer than "
                    f"{FACE_DETECTIONS} markers each): the take starts at frame {numbers[lead]}")
        numbers, frames = numbers[lead:], frames[lead:]
    washed_out = between_classes_warning(extraction.light, washed)
    if washed_out:
        log.warning(washed_out)
    xs = np.concatenate([np.r_[f.direct[:, 0], f.mirror[0][:, 0], f.mirror[1][:, 0]] for f in frames]) if frames \
        else np.zeros(0)
    views = check_view_boundaries(xs, stream.layout, len(frames), stream.dot_px or 0.0) \
        if stream.layout is not None else None
    # the clip's detections as flat arrays, once; the per-frame objects go (a long take's memory while it tracks)
    frames = ClipDetections.from_frames(frames, camera)
    return track_detections(numbers, frames, camera, source.fps / step, output, report=report, mirrors=mirrors,
                            known_length=known_length, step=step, settings=settings, progress=track_progress,
                            timings={"detect": t_detect}, face_distance_mm=face_distance_mm, rigid=rigid,
                            rigid_source=rigid_source, log=log, seeds=seeds, view_check=views,
                            video=source.compression(), between=washed, light=extraction.light)


def check_known_length(known_length) -> None:
    """``(label, label, mm)``: a positive length, refused before any work when not (the labels are known only once
    the take is tracked)."""
    if known_length is not None and not known_length[2] > 0:
        raise InputError(f"--known-length must be a positive length in millimetres (not {known_length[2]:g})")


def _listed(items) -> str:
    """Items (frame numbers, names) for a warning: the first six."""
    return ", ".join(map(str, items[:6])) + (", ..." if len(items) > 6 else "")


def _median_depth(det: ClipDetections, camera: Camera, cals, ds) -> float:
    """Median depth of the 3D candidates of ``det`` under self-calibrated planes."""
    from .candidates import clip_candidates

    normals = np.stack([c.plane.normal for c in cals])
    z = clip_candidates(det, normals, ds, camera.focal_px).points[:, 2]
    z = z[np.isfinite(z) & (z > 0)]
    if z.size == 0:
        raise DegenerateError("no marker pairs between the direct view and the mirrors: cannot place the face")
    return float(np.median(z))


@with_limited_threads
def track_detections(numbers, frames, camera: Camera, fps: float, output, *, report=None, mirrors=None,
                     known_length=None, step: int = 1, settings: TrackSettings | None = None, progress=None,
                     timings: dict | None = None, face_distance_mm: float = FACE_DISTANCE_MM, rigid=None,
                     rigid_source: str = "rig file", log: MessageLog | None = None, seeds=None,
                     view_check: dict | None = None, video: dict | None = None,
                     between: dict | None = None, light: str | None = None) -> dict:
    """The tracking half of :func:`run_track`, from per-frame detections (:class:`FrameDets`,
    e.g. from Blender's own 2D tracks): mirror planes, tracking, scale, atomic outputs.
    ``rigid``: the markers that carry the head pose, as :func:`core.track.tracker.track` takes them.
    Without MIRRORS.json the scale is set by putting the face ``face_distance_mm`` away.
    Warnings go to ``log`` (:class:`..common.log.MessageLog`) and REPORT.json's ``warnings``.
    ``view_check``: :func:`..capture.rig.check_view_boundaries` of the detections' view layout
    (REPORT.json ``view_layout``; a warning when a boundary runs through dots); ``video``: the source's
    :meth:`..capture.video.VideoSource.compression` (REPORT.json ``video``); ``between``: the detection's
    :func:`..capture.detect.between_classes` (REPORT.json ``between_classes``); ``light``: the light the markers
    were found under (REPORT.json ``light``; None: the detections came from elsewhere)."""
    from ..capture.detect import VIDEO_QUALITY_HINT
    from .mirrorscale import both_mirror_samples, link_self_calibrated_scales, mirror_agreement, scale_link_warning
    from .coverage import coverage_warning, take_coverage
    from .selfcal import self_calibrate_mirror

    check_output_paths(output, report)
    check_known_length(known_length)
    shortest = (settings or TrackSettings()).min_measured_frames
    if len(frames) < max(shortest, 2):
        raise InputError(f"the take has {len(frames)} frame(s) that show the face, and a marker must be measured in "
                         f"{shortest} frames to be reported: track at least {max(shortest, 2)} frames")
    det = ClipDetections.of(frames, camera)  # the one normalisation of the clip's pixels
    first = det.head(SELFCAL_FRAMES)
    if mirrors is None:
        if any(np.any(first.counts(k + 1) < 6) for k in range(2)):
            raise DegenerateError("a mirror shows fewer than 6 markers in the first frames: are both mirrors "
                                  "visible? (give MIRRORS.json from `mirrorcap mirrors` otherwise)")
        # the two mirrors' searches are independent and their array work releases the GIL: one thread each
        with ThreadPoolExecutor(2, thread_name_prefix="mirrorcap-selfcal") as pool:
            cals = list(pool.map(lambda k: self_calibrate_mirror(first, camera, k), range(2)))
        normals = np.stack([c.plane.normal for c in cals])
        both = both_mirror_samples(det, camera, normals)
        ds, scale_link = link_self_calibrated_scales(both, det, camera, normals, [c.plane.d for c in cals])
        # Self-calibration knows no scale. The tracker's gates, neighbourhoods and noise
        # levels are in mm, so put the face at its nominal distance: the take is then
        # "relative" units that are close to millimetres (a known length makes them exact).
        ds = ds * (face_distance_mm / _median_depth(first, camera, cals, ds))
        planes = [MirrorPlane(normal=c.plane.normal, d=float(d)) for c, d in zip(cals, ds)]
        mirror_source, units = "self-calibration", "relative"
    else:
        planes, mirror_source, units = list(mirrors), "file", "mm"
        both = both_mirror_samples(det, camera, np.stack([p.normal for p in planes]))
        scale_link = None
    t1 = time.perf_counter()
    result = track(det, camera, planes, settings, progress=progress, rigid=rigid, seeds=seeds)
    t_track = time.perf_counter() - t1
    if not result.labels:
        raise DegenerateError(f"no marker was measured in {shortest} frames or more, so the take would be empty: check "
                              "the detections (`mirrorcap detect`, or the clip's 2D tracks) and the mirrors")
    points = result.points
    head = result.head_pose.copy()
    if known_length is not None:
        a, b, mm = known_length
        try:
            ia, ib = result.labels.index(a), result.labels.index(b)
        except ValueError:
            raise InputError(f"--known-length names a marker that is not in the take ({a!r}, {b!r}); labels run "
                             f"{result.labels[0]}..{result.labels[-1]}") from None
        est = float(np.linalg.norm(result.neutral[ia] - result.neutral[ib]))
        if not est > 0:
            raise InputError("--known-length needs two distinct markers")
        scale = mm / est
        points = points * scale
        head[:, 3:] *= scale
        planes = [MirrorPlane(normal=p.normal, d=p.d * scale) for p in planes]
        units = "mm"
    rate = fps
    log = log if log is not None else MessageLog()
    for sentence in view_boundary_warnings(view_check):
        log.warning(sentence)
    agreement = mirror_agreement(both, np.stack([p.normal for p in planes]), np.array([p.d for p in planes]),
                                 camera.focal_px)
    link_doubt = scale_link_warning(scale_link)
    if link_doubt:
        log.warning(link_doubt)
    unit = "mm" if units == "mm" else "units"
    if agreement["consistent"] is False and not agreement["scattered"]:
        log.warning(f"the two mirrors disagree: a marker seen in both lands {agreement['median_difference']:+.2f} "
                    f"{unit} ({100 * agreement['relative_difference']:+.2f} %) further along its ray through mirror 0 "
                    f"than through mirror 1, where {agreement['expected_sd']:.2f} {unit} is expected "
                    f"({agreement['markers']} markers); the take's 3D points are off by up to that much -- "
                    + ("check MIRRORS.json, or track without it to self-calibrate" if mirror_source == "file"
                       else "the mirrors moved, or the clip shows too few markers in both mirrors"))
    elif agreement["consistent"] is False:
        # the scatter's markers are the ones a doubted shared link set aside: the scales came from the head's motion
        set_aside = scale_link is not None and "shared_markers_link" in scale_link
        log.warning(f"the markers seen in both mirrors do not agree: their depths through the two mirrors scatter by "
                    f"{agreement['observed_sd']:.2f} {unit} (sd), where {agreement['expected_sd']:.2f} {unit} is "
                    f"expected ({agreement['markers']} markers) -- their mirror images are poorly found or wrongly "
                    "paired"
                    + (", so the mirrors' scales were linked through the head's motion instead; if the dots in the "
                       "mirrors are poorly found, the take's points through the mirrors are off too" if set_aside
                       else ", and the take's points through the mirrors may be too")
                    + f"; check the dots in the mirrors ({VIDEO_QUALITY_HINT})")
    dropped_seeds = [] if seeds is None else [n for n in seeds.names if n not in result.labels]
    if dropped_seeds:
        log.warning(f"{len(dropped_seeds)} designation(s) of the seeds file did not hold ({_listed(dropped_seeds)}"
                    "): their direct and mirror points are not one dot, or the "
                    "marker was lost; fix them in the clip (Take To Clip, rename the marker's tracks) and Re-solve")
    coverage = take_coverage(det, result.assigned_blob >= 0)
    short = coverage_warning(coverage)
    if short:
        log.warning(short)
    jumps = [numbers[t] for t in np.flatnonzero(result.stats.get("relocated", []))]
    glitches = [numbers[t] for t in np.flatnonzero(result.stats.get("out_of_place", []))]
    if jumps or glitches:
        log.warning("the face jumps in the video" + (f" at frame(s) {_listed(jumps)} (a cut, or a recording paused "
                                                     "and resumed): the head was found again there" if jumps else "")
                    + ("; " if jumps and glitches else "")
                    + (f" -- frame(s) {_listed(glitches)} show(s) it elsewhere than the frames around: left out"
                       if glitches else "")
                    + "; check the take there, or track the stretches apart (--frames START:END)")
    if result.undecided:
        log.warning(f"{len(result.undecided)} direct-view markers of the first frames could not be paired with a "
                    "mirror image (no 3D position): REPORT.json markers.undecided lists where they are")
    report_data = {
        "units": units,
        "mirrors": [{"mirror": k, "normal": [float(v) for v in p.normal], "d": float(p.d), "source": mirror_source}
                    for k, p in enumerate(planes)],
        "mirror_scale_link": scale_link,
        "mirror_agreement": agreement,
        "coverage": coverage,
        "video": video,
        "between_classes": between,
        "light": light,
        "view_layout": view_check,
        "frames": {"first": numbers[0], "last": numbers[-1], "step": step, "count": len(numbers), "fps": rate},
        "markers": {"count": len(result.labels), "labels": result.labels,
                    "rigid": [result.labels[i] for i in result.rigid],
                    "rigid_source": "automatic" if rigid is None else rigid_source,
                    "undecided": result.undecided},
        "head_pose": head.tolist(),
        "per_frame": {k: v.tolist() for k, v in result.stats.items()},
        "timings_s": {**(timings or {}), "track": t_track, "track_stages": result.timings,
                      "tracking_frames_per_s": len(frames) / max(t_track, 1e-9)},
        "warnings": log.warnings,
    }
    files = {output: c3d_bytes(result.labels, points, rate, units=units if units == "mm" else "rel",
                               camera_mask=result.camera_mask, conjectured=result.conjectured)}
    if report is not None:
        files[report] = json.dumps(report_data, indent=1) + "\n"
    write_files_atomically(files)
    return report_data
