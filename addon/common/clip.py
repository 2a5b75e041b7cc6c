"""Movie clips and their 2D tracks: MirrorCap's detections shown as tracks, and tracks made
with Blender's own tracker used as detections.

Coordinates: a clip marker's ``co`` is normalised with its origin at the frame's bottom-left
corner; the core's pixels have their origin at the centre of the top-left pixel. So

    x_px = co.x * width - 0.5          y_px = (1 - co.y) * height - 0.5

Clip frame ``n + 1`` is video frame ``n`` (clips start at frame 1). MirrorCap's tracks live
in the clip's tracking object ``MirrorCap``, named ``<view>_<colour class>_<index>``; a track
named otherwise (a user's) has colour class 0.
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np

from ...core.capture.rig import VIEW_NAMES, split_views_by_gaps
from ...core.common.errors import InputError

TRACKING_OBJECT = "MirrorCap"
#: display colours of the default colour classes' tracks (pink, blue-green, dark blue, purple)
CLASS_COLORS = ((1.0, 0.43, 0.78), (0.27, 0.9, 0.78), (0.24, 0.31, 1.0), (0.69, 0.27, 1.0))


def find_clip(video: Path | None):
    """The clip of ``video`` in the file, loading it if needed; ``None`` without a video."""
    if video is None:
        return None
    target = Path(video).resolve()
    for clip in bpy.data.movieclips:
        if Path(bpy.path.abspath(clip.filepath)).resolve() == target:
            return clip
    try:
        return bpy.data.movieclips.load(str(target))
    except RuntimeError as exc:
        raise InputError(f"Blender cannot open {target} as a clip ({exc})") from None


def detections_to_clip_tracks(clip, frame: int, x, y, color, view, size) -> int:
    """Replace the ``MirrorCap`` tracking object's tracks by one track per detection at ``frame``."""
    objects = clip.tracking.objects
    old = objects.get(TRACKING_OBJECT)
    if old is not None:
        objects.remove(old)
    obj = objects.new(TRACKING_OBJECT)
    w, h = size
    co = np.c_[(np.asarray(x) + 0.5) / w, 1.0 - (np.asarray(y) + 0.5) / h]
    count = 0
    for i in np.flatnonzero(np.asarray(view) >= 0):
        track = obj.tracks.new(name=f"{VIEW_NAMES[view[i]]}_{int(color[i])}_{i:03d}", frame=frame + 1)
        marker = track.markers.find_frame(frame + 1)
        marker.co = co[i]
        track.color = CLASS_COLORS[int(color[i]) % len(CLASS_COLORS)]
        track.use_custom_color = True
        count += 1
    return count


def _class_of(name: str) -> int:
    parts = name.split("_")
    if len(parts) >= 3 and parts[0] in VIEW_NAMES and parts[1].isdigit():
        return int(parts[1])
    return 0


def track_markers(track):
    """A clip track's markers as arrays: clip frames ``(n,)``, normalised positions ``(n, 2)``, muted ``(n,)``."""
    n = len(track.markers)
    fr = np.empty(n, np.int32)
    co = np.empty(2 * n, np.float32)
    mute = np.empty(n, bool)
    track.markers.foreach_get("frame", fr)
    track.markers.foreach_get("co", co)
    track.markers.foreach_get("mute", mute)
    return fr, co.reshape(-1, 2), mute


def clip_tracks_to_detections(clip, layout=None, object_name: str | None = None):
    """Per-frame detections (:class:`core.capture.views.FrameDets`) from the clip's tracks: frame numbers
    (0-based video frames) and frames. Muted markers are left out; views come from ``layout``
    (a :class:`core.capture.markers.ViewLayout`) or from the gaps between the tracks."""
    from ...core.capture.views import FrameDets

    objects = [o for o in clip.tracking.objects if object_name in (None, o.name)]
    if object_name is not None and not objects:
        raise InputError(f"the clip has no tracking object {object_name!r}")
    w, h = clip.size
    rows = []
    for obj in objects:
        for track in obj.tracks:
            if len(track.markers) == 0:
                continue
            fr, co, mute = track_markers(track)
            keep = ~mute
            co = co[keep]
            k = np.full(keep.sum(), _class_of(track.name))
            rows.append(np.c_[fr[keep] - 1, co[:, 0] * w - 0.5, (1.0 - co[:, 1]) * h - 0.5, k])
    if not rows:
        raise InputError("the clip has no 2D tracks: track markers with Blender's tracker, or use Detect Markers")
    data = np.concatenate(rows)
    if layout is None:
        layout = split_views_by_gaps(data[:, 1], 12.0)
    view = layout.assign(data[:, 1], data[:, 2])
    numbers = np.unique(data[:, 0]).astype(int)
    frames = []
    for n in numbers:
        sel = data[:, 0] == n
        xy, k, v = data[sel, 1:3], data[sel, 3].astype(int), view[sel]
        frames.append(FrameDets(direct=xy[v == 0], direct_color=k[v == 0], mirror=[xy[v == 1], xy[v == 2]],
                                mirror_color=[k[v == 1], k[v == 2]]))
    return numbers.tolist(), frames


def selected_track_pixels(clip, frame: int):
    """Pixel positions ``(n, 2)`` at video ``frame`` of the clip's selected tracks, over all
    tracking objects; MirrorCap's own mirror-view tracks are left out (the rigid region is a
    box in the direct view)."""
    w, h = clip.size
    pts = []
    for obj in clip.tracking.objects:
        for track in obj.tracks:
            if not track.select or track.name.startswith(tuple(f"{v}_" for v in VIEW_NAMES[1:])):
                continue
            marker = track.markers.find_frame(frame + 1)
            if marker is None or marker.mute:
                continue
            pts.append((marker.co[0] * w - 0.5, (1.0 - marker.co[1]) * h - 0.5))
    return np.array(pts, float).reshape(-1, 2)


TAKE_TRACKS = "MirrorCap Take"   # the tracking object holding a take's 2D tracks (``<label>.<view>``)


def take_to_clip_tracks(clip, labels, points, mirrors, camera, first_frame: int = 0, measured=None,
                        step: int = 1) -> int:
    """Write a take as 2D clip tracks the user can fix with Blender's tracking tools: per marker and
    view, a track ``<label>.<view>`` (views :data:`VIEW_NAMES`) with a marker on every frame where the
    take measured it (``measured (F, M)``, default every finite point), at its projection through the
    view (``mirrors``: the take report's planes, in the take's units); take frame ``f`` is video frame
    ``first_frame + f * step`` (clip frame one more). Replaces the clip's :data:`TAKE_TRACKS` object.
    Returns the number of tracks."""
    from ...core.geometry.mirror import reflect_points

    P = np.asarray(points, float)
    F, M, _ = P.shape
    ok = np.all(np.isfinite(P), axis=2) if measured is None else np.asarray(measured, bool) & np.all(np.isfinite(P), 2)
    views = [camera.project(P.reshape(-1, 3)).reshape(F, M, 2)]
    for m in mirrors:
        views.append(camera.project(reflect_points(P.reshape(-1, 3), np.asarray(m["normal"], float),
                                                   float(m["d"]))).reshape(F, M, 2))
    objects = clip.tracking.objects
    old = objects.get(TAKE_TRACKS)
    if old is not None:
        objects.remove(old)
    obj = objects.new(TAKE_TRACKS)
    w, h = clip.size
    count = 0
    for v, px in enumerate(views):
        inside = ok & (px[..., 0] >= 0) & (px[..., 0] < w) & (px[..., 1] >= 0) & (px[..., 1] < h)
        for m in np.flatnonzero(inside.any(axis=0)):
            frames = np.flatnonzero(inside[:, m])
            clip_frames = first_frame + frames * step + 1
            track = obj.tracks.new(name=f"{labels[m]}.{VIEW_NAMES[v]}", frame=int(clip_frames[0]))
            co = np.c_[(px[frames, m, 0] + 0.5) / w, 1.0 - (px[frames, m, 1] + 0.5) / h]
            for f, c in zip(clip_frames[1:], co[1:]):           # no bulk insert for clip markers
                track.markers.insert_frame(int(f), co=(float(c[0]), float(c[1])))
            track.markers.find_frame(int(clip_frames[0])).co = (float(co[0, 0]), float(co[0, 1]))
            track.color = CLASS_COLORS[v % len(CLASS_COLORS)]
            track.use_custom_color = True
            count += 1
    return count


def clip_tracks_to_take_tracks(clip, n_frames: int, first_frame: int = 0, step: int = 1):
    """The :data:`TAKE_TRACKS` tracks back as ``labels, tracks (F, M, 3, 2)`` pixels (NaN where a track
    has no marker or a muted one), the user's fixes included; tracks not named ``<label>.<view>`` are
    refused by name."""
    obj = clip.tracking.objects.get(TAKE_TRACKS)
    if obj is None or not len(obj.tracks):
        raise InputError(f"the clip has no {TAKE_TRACKS!r} tracks: write the take to the clip first (Take To Clip)")
    w, h = clip.size
    per = {}
    for track in obj.tracks:
        label, _, view = track.name.rpartition(".")
        if not label or view not in VIEW_NAMES:
            raise InputError(f"track {track.name!r}: take tracks are named <label>.<view> with view one of "
                             f"{', '.join(VIEW_NAMES)}")
        if len(track.markers) == 0:
            continue
        fr, co, mute = track_markers(track)
        off = fr - 1 - first_frame
        f = off // step
        keep = ~mute & (off % step == 0) & (f >= 0) & (f < n_frames)
        co = co[keep]
        per.setdefault(label, {})[VIEW_NAMES.index(view)] = (f[keep], np.c_[co[:, 0] * w - 0.5, (1.0 - co[:, 1]) * h - 0.5])
    labels = sorted(per)
    tracks = np.full((n_frames, len(labels), 3, 2), np.nan)
    for m, label in enumerate(labels):
        for v, (f, xy) in per[label].items():
            tracks[f, m, v] = xy
    return labels, tracks
