"""Keying shape-key values: one F-curve per key, filled with one ``keyframe_points.foreach_set``
(the bake's frame and PCA keys, the retarget's ARKit weights)."""

from __future__ import annotations

import bpy
import numpy as np


def key_fcurves(key, action, names, frames, values, interpolation: str):
    """One F-curve per shape key ``names[i]`` with keyframes at ``frames`` ((n,) or (K, n)) of ``values (K, n)``."""
    interp = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items[interpolation].value
    values = np.asarray(values, float)
    frames = np.broadcast_to(np.asarray(frames, float), values.shape)
    n = values.shape[1]
    for name, fr, vals in zip(names, frames, values):
        fc = action.fcurve_ensure_for_datablock(key, f'key_blocks["{name}"].value')
        fc.keyframe_points.add(n)
        fc.keyframe_points.foreach_set("co", np.column_stack([fr, vals]).astype(np.float32).ravel())
        fc.keyframe_points.foreach_set("interpolation", np.full(n, interp, np.int32))
        fc.update()
