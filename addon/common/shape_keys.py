"""Displacements onto a mesh as shape keys: the one writer behind ``bake``, the Bake operator,
``retarget --method transfer`` and the demo.

``frames``: key ``frame_00001`` .. one per take frame, its value keyed 0-1-0 with
constant interpolation so exactly that frame's key is 1 at its frame.
``pca``: keys ``mode_01`` .. ``mode_K`` (eigen-deformations, see :mod:`core.face.shapes`) with
linear-interpolated value keys on every frame; slider range -1..1.
Head motion (optional): the object's location and quaternion rotation keyed per frame, about its own
location and after its own rotation (a head imported turned and scaled keeps both; one parented to a rig is keyed in
its parent's frame).
Coordinates go into the object's own frame (:func:`.frames.object_axes`), as :func:`.headio.read_head` reads them.
Shape-key coordinates go through ``foreach_set``; keyframes through ``keyframe_points.foreach_set``.
"""

from __future__ import annotations

import bpy
import numpy as np

from ...core.common.errors import InputError
from ...core.face.shapes import displacement_source, pca_shapes
from .frames import core_rotation_to_blender, core_to_blender, object_axes
from .keys import key_fcurves, keyed_frames

MODES = ("frames", "pca")


def _clear_mirrorcap_keys(obj):
    key = obj.data.shape_keys
    if key is None:
        return
    for kb in [kb for kb in key.key_blocks if kb.name.startswith(("frame_", "mode_"))]:
        obj.shape_key_remove(kb)


def check_keying(mode: str, n_modes: int, n_frames: int | None = None, modes_option: str = "--modes") -> None:
    """A bake's ``mode`` (:data:`MODES`) and, in pca mode, its ``n_modes`` against the ``n_frames`` to key, checked
    before any work (``modes_option``: how the user names the number of modes)."""
    if mode not in MODES:
        raise InputError(f"--mode must be one of {', '.join(MODES)}")
    if n_frames is not None and mode == "pca" and not 1 <= n_modes <= n_frames:
        raise InputError(f"{modes_option} must be between 1 and the {n_frames} frames keyed")


def bake_displacements(obj, neutral_mm, displacements, mode: str = "frames", n_modes: int = 8,
                       frame_start: int = 1, head_motion=None, progress=None) -> dict:
    """Write ``displacements (F, V, 3)`` (core mm, head frame: an array, or an :class:`core.face.animate.Animation`
    whose frames are deformed a block at a time as they are written, so that a long take never has them all in
    memory) onto ``obj`` as shape keys, keyed from the scene frame ``frame_start`` on (the scene's frame range is
    set to the keyed frames)."""
    src = displacement_source(displacements)
    F, V = src.n_frames, len(neutral_mm)
    check_keying(mode, n_modes, F)
    if V != len(obj.data.vertices):
        raise InputError(f"{V} displacements for a head of {len(obj.data.vertices)} vertices")
    axes = object_axes(obj)
    frames = keyed_frames(bpy.context.scene, frame_start, F)
    _clear_mirrorcap_keys(obj)
    if obj.data.shape_keys is None:
        obj.shape_key_add(name="Basis", from_mix=False)
    key = obj.data.shape_keys
    key.use_relative = True
    if key.animation_data is None:
        key.animation_data_create()
    action = bpy.data.actions.new(f"{obj.name}_mirrorcap")
    key.animation_data.action = action
    out = {"mode": mode, "frames": int(F), "vertices": int(V)}
    if mode == "frames":
        names = [f"frame_{i + 1:05d}" for i in range(F)]
        for f0, block in src.blocks():
            for i, disp in enumerate(block, f0):
                kb = obj.shape_key_add(name=names[i], from_mix=False)
                kb.value = 0.0  # its F-curve sets it to 1 on its own frame only
                kb.points.foreach_set("co", core_to_blender(neutral_mm + disp, axes).astype(np.float32).ravel())
            if progress:
                progress((f0 + len(block)) / F)
        # each key: 0 the frame before, 1 on its frame, 0 the frame after (constant steps)
        kf = np.stack([frames - 1, frames, frames + 1], 1)
        key_fcurves(key, action, names, kf, np.tile([0.0, 1.0, 0.0], (F, 1)), "CONSTANT")
    else:
        pca = pca_shapes(src, n_modes)
        names = [f"mode_{k + 1:02d}" for k in range(n_modes)]
        for k, name in enumerate(names):
            kb = obj.shape_key_add(name=name, from_mix=False)
            kb.slider_min, kb.slider_max, kb.value = -1.0, 1.0, 0.0
            kb.points.foreach_set("co", core_to_blender(neutral_mm + pca.modes[k], axes).astype(np.float32).ravel())
        key_fcurves(key, action, names, frames, pca.weights.T, "LINEAR")
        out.update({"modes": int(n_modes), "pca_max_error_mm": pca.max_error_mm, "pca_mean_error_mm": pca.mean_error_mm,
                    "energy": [float(e) for e in pca.energy]})
    if head_motion is not None:
        loc, quat = _head_motion_keys(obj, *head_motion)
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
    out["frame_start"] = int(frames[0])
    return out


def _head_motion_keys(obj, R, t):
    """The location ``(F, 3)`` and rotation quaternions ``(F, 4)`` to key on ``obj`` so that it moves by the head
    motion ``R (F, 3, 3)``, ``t (F, 3)`` (core; about the object's origin, in world axes, as :func:`.headio.read_head`
    reads the head) from where it stands: at frame f its world matrix is ``[R_f A | o + t_f]`` (``A`` its linear
    part, ``o`` its origin), expressed in the frame its own transform lives in -- its parent's, for a head parented
    to a rig. Its scale stays as it is."""
    world = np.array(obj.matrix_world, float)
    parent = world @ np.linalg.inv(np.array(obj.matrix_basis, float))      # identity when not parented
    moved = np.tile(np.eye(4), (len(R), 1, 1))
    moved[:, :3, :3] = core_rotation_to_blender(R) @ world[:3, :3]
    moved[:, :3, 3] = world[:3, 3] + core_to_blender(t)
    basis = np.linalg.inv(parent) @ moved
    return basis[:, :3, 3], _quaternions(_rotation_of(basis[:, :3, :3]))


def _rotation_of(linear):
    """The rotations of rotation-and-scale matrices ``(..., 3, 3)`` (their polar factors)."""
    u, _, vt = np.linalg.svd(linear)
    u[..., :, -1] *= np.sign(np.linalg.det(u @ vt))[..., None]
    return u @ vt


def _quaternions(R):
    """(w, x, y, z) unit quaternions of rotation matrices ``(F, 3, 3)``, sign-continuous."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    flip = np.r_[1.0, np.sign(np.einsum("fi,fi->f", q[1:], q[:-1]))]
    return q * np.cumprod(np.where(flip == 0, 1.0, flip))[:, None]
