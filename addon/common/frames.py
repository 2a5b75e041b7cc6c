"""The one place where the core's frame meets Blender's.

The core works in millimetres in the OpenCV camera frame (x right, y down,
z forward, away from the camera). A head in Blender stands Z-up and looks down
-Y, with a camera in front looking along +Y; Blender's unit is the metre. So

    core = 1000 * (bx, -bz, by)          blender = 0.001 * (cx, cz, -cy)

a proper rotation (no mirroring) and a scale.
"""

from __future__ import annotations

import numpy as np

MM_PER_BLENDER_UNIT = 1000.0


def blender_to_core(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    return MM_PER_BLENDER_UNIT * np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


def core_to_blender(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], -1) / MM_PER_BLENDER_UNIT


def core_rotation_to_blender(R) -> np.ndarray:
    """A rotation acting on core coordinates, expressed on Blender coordinates."""
    C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # blender = C @ core (up to scale)
    return C @ np.asarray(R, float) @ C.T
