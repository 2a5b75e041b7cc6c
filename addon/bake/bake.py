"""Baking a take onto a head as shape keys (``mirrorcap bake`` and ``MIRRORCAP_OT_bake``).

Data flow: TAKE.c3d -> :func:`core.face.bind.bind_take` -> :class:`core.face.facerig.FaceRig`
-> displacements ``(F, V, 3)`` -> shape keys here. Shape-key coordinates go through
``foreach_set``; keyframes through ``keyframe_points.foreach_set``. Blender has no
call that creates many shape keys or F-curves at once, so there is one
``shape_key_add`` and one F-curve per key -- each filled in a single array call.

``frames``: key ``frame_00001`` .. one per take frame, its value keyed 0-1-0 with
constant interpolation so exactly that frame's key is 1 at its frame.
``pca``: keys ``mode_01`` .. ``mode_K`` (eigen-deformations, see :mod:`core.face.shapes`) with
linear-interpolated value keys on every frame; slider range -1..1.
Head motion (optional): the object's location and quaternion rotation keyed per frame.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import bpy
import numpy as np

from ...core.common.errors import InputError
from ...core.face.animate import animate_take, head_pose_from_report, unseen_policy
from ...core.face.bind import load_marker_map
from ...core.face.facerig import RigSettings
from ...core.face.shapes import pca_shapes
from ...core.retarget.mpeg4 import read_fap, replay_take
from ...core.take.c3d import read_c3d
from ..common.frames import core_rotation_to_blender, core_to_blender
from ..common.keys import key_fcurves
from ..common.headio import find_head_object, head_feature_points, open_blend, read_head, save_blend_atomically

MODES = ("frames", "pca")


def _clear_mirrorcap_keys(obj):
    key = obj.data.shape_keys
    if key is None:
        return
    for kb in [kb for kb in key.key_blocks if kb.name.startswith(("frame_", "mode_"))]:
        obj.shape_key_remove(kb)


def bake_displacements(obj, neutral_mm, displacements, mode: str = "frames", n_modes: int = 8,
                       frame_start: int = 1, head_motion=None, progress=None) -> dict:
    """Write ``displacements (F, V, 3)`` (core mm, head frame) onto ``obj`` as shape keys."""
    if mode not in MODES:
        raise InputError(f"--mode must be one of {', '.join(MODES)}")
    D = np.asarray(displacements, float)
    F, V = D.shape[:2]
    if V != len(obj.data.vertices):
        raise InputError(f"{V} displacements for a head of {len(obj.data.vertices)} vertices")
    _clear_mirrorcap_keys(obj)
    if obj.data.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    key = obj.data.shape_keys
    key.use_relative = True
    if key.animation_data is None:
        key.animation_data_create()
    action = bpy.data.actions.new(f"{obj.name}_mirrorcap")
    key.animation_data.action = action
    frames = frame_start + np.arange(F)
    out = {"mode": mode, "frames": int(F), "vertices": int(V)}
    if mode == "frames":
        names = [f"frame_{i + 1:05d}" for i in range(F)]
        for i, name in enumerate(names):
            kb = obj.shape_key_add(name=name, from_mix=False)
            kb.value = 0.0  # its F-curve sets it to 1 on its own frame only
            kb.points.foreach_set("co", core_to_blender(neutral_mm + D[i]).astype(np.float32).ravel())
            if progress and i % 100 == 0:
                progress(i / F)
        # each key: 0 the frame before, 1 on its frame, 0 the frame after (constant steps)
        kf = np.stack([frames - 1, frames, frames + 1], 1)
        key_fcurves(key, action, names, kf, np.tile([0.0, 1.0, 0.0], (F, 1)), "CONSTANT")
    else:
        pca = pca_shapes(D, n_modes)
        names = [f"mode_{k + 1:02d}" for k in range(n_modes)]
        for k, name in enumerate(names):
            kb = obj.shape_key_add(name=name, from_mix=False)
            kb.slider_min, kb.slider_max, kb.value = -1.0, 1.0, 0.0
            kb.points.foreach_set("co", core_to_blender(neutral_mm + pca.modes[k]).astype(np.float32).ravel())
        key_fcurves(key, action, names, frames, pca.weights.T, "LINEAR")
        out.update({"modes": int(n_modes), "pca_max_error_mm": pca.max_error_mm, "pca_mean_error_mm": pca.mean_error_mm,
                    "energy": [float(e) for e in pca.energy]})
    if head_motion is not None:
        R, t = head_motion
        Rb = np.array([core_rotation_to_blender(r) for r in R])
        quat = _quaternions(Rb)
        loc = np.asarray(obj.location)[None] + core_to_blender(t)
        obj.rotation_mode = "QUATERNION"
        obj.animation_data_create()
        oact = bpy.data.actions.new(f"{obj.name}_head_motion")
        obj.animation_data.action = oact
        for path, vals in (("location", loc), ("rotation_quaternion", quat)):
            for axis in range(vals.shape[1]):
                fc = oact.fcurve_ensure_for_datablock(obj, path, index=axis)
                fc.keyframe_points.add(F)
                fc.keyframe_points.foreach_set("co", np.column_stack([frames, vals[:, axis]]).astype(np.float32).ravel())
                fc.update()
        out["head_motion"] = True
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = int(frame_start), int(frame_start + F - 1)
    return out


def _quaternions(R):
    """(w, x, y, z) unit quaternions of rotation matrices ``(F, 3, 3)``, sign-continuous."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    flip = np.r_[1.0, np.sign(np.einsum("fi,fi->f", q[1:], q[:-1]))]
    return q * np.cumprod(np.where(flip == 0, 1.0, flip))[:, None]


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
    bpy.context.scene.render.fps = max(1, int(round(data["rate"])))
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
