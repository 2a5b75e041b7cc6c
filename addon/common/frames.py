"""The one place where the core's frame meets Blender's.

The core works in millimetres in the OpenCV camera frame (x right, y down,
z forward, away from the camera). A head in Blender stands Z-up and looks down
-Y, with a camera in front looking along +Y; Blender's unit is the metre. So

    core = 1000 * (bx, -bz, by)          blender = 0.001 * (cx, cz, -cy)

a proper rotation (no mirroring) and a scale.

A head object's own frame need not be Blender's: a head imported from a Y-up package in centimetres
(FBX: data in cm, the object scaled 0.01 and turned 90° about X) keeps its vertices in that frame.
``axes`` -- :func:`object_axes`, the linear part of the object's world matrix -- takes an object's
coordinates to Blender's axes and metres first (and back), so the core always sees millimetres in
the head's world orientation; the object's location is left out (the head frame's origin is the
object's).
"""

from __future__ import annotations

import numpy as np

from ...core.common.errors import InputError

MM_PER_BLENDER_UNIT = 1000.0


def blender_to_core(points, axes=None) -> np.ndarray:
    """Core mm of Blender ``points`` ``(..., 3)``; with ``axes`` (:func:`object_axes`), of points -- or
    offsets -- in that object's own frame."""
    p = np.asarray(points, dtype=float)
    if axes is not None:
        p = p @ np.asarray(axes, float).T
    return MM_PER_BLENDER_UNIT * np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


def core_to_blender(points, axes=None) -> np.ndarray:
    """Blender coordinates of core mm ``points`` ``(..., 3)``; with ``axes`` (:func:`object_axes`), in that
    object's own frame (points or offsets)."""
    p = np.asarray(points, dtype=float)
    b = np.stack([p[..., 0], p[..., 2], -p[..., 1]], -1) / MM_PER_BLENDER_UNIT
    return b if axes is None else b @ np.linalg.inv(np.asarray(axes, float)).T


def object_axes(obj) -> np.ndarray:
    """The linear part ``(3, 3)`` of ``obj``'s world matrix (rotation and scale, its location left out):
    ``world - location = axes @ own``. A head whose scale is zero in some axis is refused."""
    axes = np.array(obj.matrix_world, float)[:3, :3]
    if not abs(np.linalg.det(axes)) > 1e-12:
        raise InputError(f"{obj.name!r} is scaled to nothing along some axis (its scale {tuple(obj.scale)}): "
                         "apply or fix its scale first")
    return axes


def core_rotation_to_blender(R) -> np.ndarray:
    """A rotation acting on core coordinates, expressed on Blender coordinates."""
    C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # blender = C @ core (up to scale)
    return C @ np.asarray(R, float) @ C.T
