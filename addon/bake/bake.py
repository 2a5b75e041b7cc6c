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
from ...core.face.animate import animate_take, head_pose_from_report, unseen_policy
from ...core.face.bind import load_marker_map
from ...core.face.facerig import RigSettings
from ...core.retarget.mpeg4 import read_fap, replay_take
from ...core.take.c3d import read_c3d
from ..common.keys import set_scene_rate
from ..common.shape_keys import MODES, bake_displacements
from ..common.headio import find_head_object, head_feature_points, open_blend, read_head, save_blend_atomically

def fap_as_take(track, obj, head):
    """A .fap track (:func:`core.retarget.mpeg4.read_fap`) as the take ``bake`` animates on the
    head ``obj`` (its model ``head``): ``(take data, marker map, head pose)``
    (:func:`core.retarget.mpeg4.replay_take`, at the head's own feature points)."""
    labels, points, mapping, pose = replay_take(track, head, head_feature_points(obj, head))
    return {"labels": labels, "points": points, "rate": track.fps}, mapping, pose


def run_bake(take, head_blend, output, object_name=None, mode: str = "frames", n_modes: int = 8,
             neutral_frame: int = 0, head_pose_report=None, head_motion: bool = False,
             settings: RigSettings | None = None, report=None, progress=None, drop_unseen: bool = False,
             conjecture_unseen: bool = False, marker_map=None, fap=None) -> dict:
    """The whole ``mirrorcap bake``: read, bind, rig, bake, save atomically. Returns the report.
    Markers not seen in the neutral frame: refused, left out (``drop_unseen``) or placed from
    their neighbours (``conjecture_unseen``, :func:`core.face.bind.bind_take`). ``marker_map``:
    a MAP.json path (:func:`core.face.bind.load_marker_map`). ``fap``: a .fap file to play on the
    head instead of a take (:func:`core.retarget.mpeg4.replay_take`; ``take`` is then None)."""
    if mode not in MODES:
        raise InputError(f"--mode must be one of {', '.join(MODES)}")
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
    if mode == "pca" and not 1 <= n_modes <= F:
        raise InputError(f"--modes must be between 1 and the take's {F} frames")
    open_blend(head_blend)
    obj = find_head_object(object_name)
    head = read_head(obj)
    head.validate()
    if fap is not None:
        data, mapping, pose = fap_as_take(track, obj, head)
    timings["read_s"] = time.perf_counter() - t0
    t1 = time.perf_counter()
    anim = animate_take(head, data["labels"], data["points"], data["rate"], neutral_frame=neutral_frame,
                        head_pose=pose, unseen=unseen_policy(drop_unseen, conjecture_unseen), settings=settings,
                        marker_map=mapping)
    binding, D = anim.binding, anim.displacements
    timings["rig_s"] = time.perf_counter() - t1
    t2 = time.perf_counter()
    out = bake_displacements(obj, head.vertices, D, mode, n_modes, head_motion=binding.head_motion if head_motion else None,
                             progress=progress)
    set_scene_rate(bpy.context.scene, data["rate"])
    timings["bake_s"] = time.perf_counter() - t2
    t3 = time.perf_counter()
    save_blend_atomically(output)
    timings["save_s"] = time.perf_counter() - t3
    timings["total_s"] = time.perf_counter() - t0
    result = {
        "take": str(take if fap is None else fap), "head": str(head_blend), "object": obj.name, "output": str(output), **out,
        "rate": data["rate"], "markers": len(data["labels"]), **anim.summary(),
        "timings_s": timings,
    }
    if report is not None:
        from ...core.common.files import write_files_atomically

        write_files_atomically({Path(report): json.dumps(result, indent=1) + "\n"})
    return result
