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
            n = len(track.markers)
            if n == 0:
                continue
            fr = np.empty(n, np.int32)
            co = np.empty(2 * n, np.float32)
            mute = np.empty(n, bool)
            track.markers.foreach_get("frame", fr)
            track.markers.foreach_get("co", co)
            track.markers.foreach_get("mute", mute)
            keep = ~mute
            co = co.reshape(-1, 2)[keep]
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
