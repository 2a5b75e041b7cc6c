"""Baking a take onto a head as shape keys (``mirrorcap bake`` and ``MIRRORCAP_OT_bake``).

Data flow: TAKE.c3d -> :func:`core.face.bind.bind_take` -> :class:`core.face.facerig.FaceRig`
-> displacements ``(F, V, 3)`` -> shape keys (:func:`..common.shape_keys.bake_displacements`:
frame keys or PCA keys, and the head motion).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import bpy

from ...core.common.errors import InputError
from ...core.face.animate import animate_take, head_pose_from_report, take_frame_range
from ...core.face.bind import load_marker_map
from ...core.face.facerig import RigSettings
from ...core.retarget.mpeg4 import read_fap, replay_take
from ...core.take.c3d import read_c3d
from ..common.keys import set_scene_rate
from ..common.shape_keys import bake_displacements, check_keying
from ..common.headio import find_head_object, head_feature_points, open_blend, read_head, save_blend_atomically

#: a frames-mode bake of more frames than this is warned about (one shape key a frame)
FRAMES_MODE_WARNING = 5000
#: .blend megabytes a frame key takes (measured: 153 MB for 3,600 frames of the 4,608-vertex generic head),
#: per 1,000 vertices
FRAME_KEY_MB_PER_KVERT = 0.0092


def fap_as_take(track, obj, head):
    """A .fap track (:func:`core.retarget.mpeg4.read_fap`) as the take ``bake`` animates on the
    head ``obj`` (its model ``head``): ``(take data, marker map, head pose)``
    (:func:`core.retarget.mpeg4.replay_take`, at the head's own feature points)."""
    labels, points, mapping, pose = replay_take(track, head, head_feature_points(obj, head))
    return {"labels": labels, "points": points, "rate": track.fps}, mapping, pose


def run_bake(take, head_blend, output, object_name=None, mode: str = "frames", n_modes: int = 8,
             neutral_frame: int = 0, head_pose_report=None, head_motion: bool = False,
             settings: RigSettings | None = None, report=None, progress=None, unseen: str = "conjecture",
             marker_map=None, fap=None, frames=None, frame_start: int = 1) -> dict:
    """The whole ``mirrorcap bake``: read, bind, rig, bake, save atomically. Returns the report.
    Markers not seen in the neutral frame (``unseen``): placed from their neighbours (``"conjecture"``, a
    tracker's markers first seen later), left out (``"drop"``) or refused (``"error"``;
    :func:`core.face.bind.bind_take`). ``marker_map``:
    a MAP.json path (:func:`core.face.bind.load_marker_map`). ``fap``: a .fap file to play on the
    head instead of a take (:func:`core.retarget.mpeg4.replay_take`; ``take`` is then None).
    ``frames``: the take frames ``(START, END)`` to bake (END exclusive, None: to the end; the whole
    take is bound), keyed from the scene frame ``frame_start`` on."""
    check_keying(mode, n_modes)
    if (take is None) == (fap is None):
        raise InputError("give either a take (TAKE.c3d) or --fap TAKE.fap")
    timings = {}
    t0 = time.perf_counter()
    if fap is not None:
        if marker_map or head_pose_report:
            raise InputError("--marker-map and --head-pose belong to C3D takes, not to a .fap file")
        track = read_fap(fap)
        F, pose = track.frames, None
    else:
        data = read_c3d(take)
        mapping = load_marker_map(marker_map) if marker_map else None
        F = data["points"].shape[0]
        pose = None if head_pose_report is None else head_pose_from_report(head_pose_report, F)
    start, end = take_frame_range(frames, F)
    check_keying(mode, n_modes, end - start)
    open_blend(head_blend)
    obj = find_head_object(object_name)
    head = read_head(obj)
    head.validate()
    if fap is not None:
        data, mapping, pose = fap_as_take(track, obj, head)
    timings["read_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    anim = animate_take(head, data["labels"], data["points"], data["rate"], neutral_frame=neutral_frame,
                        head_pose=pose, unseen=unseen, settings=settings,
                        marker_map=mapping, frames=(start, end))
    timings["bind_s"] = time.perf_counter() - t1          # binding and the face rig's set-up
    t2 = time.perf_counter()
    out = bake_displacements(obj, head.vertices, anim, mode, n_modes, frame_start=frame_start,
                             head_motion=anim.head_motion if head_motion else None, progress=progress)
    set_scene_rate(bpy.context.scene, data["rate"])
    warnings = []
    if mode == "frames" and anim.n_frames > FRAMES_MODE_WARNING:
        warnings.append(f"{anim.n_frames} frames as one shape key each: about "
                        f"{anim.n_frames * FRAME_KEY_MB_PER_KVERT * len(head.vertices) / 1000:.0f} MB "
                        "of .blend and as much memory in Blender; --mode pca keys a few shapes instead, or bake the "
                        "take in stretches (--frames START:END)")
    timings["rig_and_keys_s"] = time.perf_counter() - t2  # the rig's deformation, a block of frames at a time, keyed
    t3 = time.perf_counter()
    save_blend_atomically(output)
    timings["save_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    result = {
        "take": str(take if fap is None else fap), "head": str(head_blend), "object": obj.name, "output": str(output), **out,
        "rate": data["rate"], "markers": len(data["labels"]), **anim.summary(),
        "warnings": warnings, "timings_s": timings,
    }
    if report is not None:
        from ...core.common.files import write_files_atomically

        write_files_atomically({Path(report): json.dumps(result, indent=1) + "\n"})
    return result
