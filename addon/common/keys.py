"""Keying shape-key values: one F-curve per key, filled with one ``keyframe_points.foreach_set``
(the bake's frame and PCA keys, the retarget's ARKit weights); the scene frames they are keyed at; and the
scene's frame rate."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import IntProperty

from ...core.common.errors import InputError


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


def set_scene_rate(scene, rate: float) -> None:
    """Play ``scene`` at ``rate`` frames/s exactly: Blender's rate is ``fps / fps_base``, so a camera's 29.97 or
    59.94 (NTSC: 30000/1001, 60000/1001) is 30 or 60 over 1.001 -- rounded to 30 or 60 the animation would run
    0.1 % fast and drift from the take's sound by 60 ms a minute."""
    rate = float(rate)
    if not rate > 0:
        return
    fps = max(1, int(np.ceil(rate - 1e-6)))
    scene.render.fps = fps
    scene.render.fps_base = fps / rate


def keyed_frames(scene, frame_start: int, n_frames: int) -> np.ndarray:
    """The scene frames ``frame_start`` .. ``frame_start + n_frames - 1`` that ``n_frames`` take frames are keyed at
    (``--frame-start``: a pipeline's shots may start at 1001), checked against the frames a Blender scene can hold;
    the scene's frame range is set to them."""
    props = bpy.types.Scene.bl_rna.properties
    lowest, highest = props["frame_start"].hard_min, props["frame_end"].hard_max
    frame_start = int(frame_start)
    if not lowest <= frame_start <= highest - n_frames + 1:
        raise InputError(f"--frame-start {frame_start}: {n_frames} frames keyed from there must lie within Blender's "
                         f"frames {lowest}..{highest}")
    scene.frame_start, scene.frame_end = frame_start, frame_start + n_frames - 1
    return frame_start + np.arange(n_frames)


class TakeStretch:
    """The Bake and Retarget operators' stretch of the take to key (the panels pass the scene's From and To)."""

    take_start: IntProperty(name="From Take Frame", default=0, min=0,
                            description="first take frame to key (0-based; the whole take is bound)")
    take_end: IntProperty(name="To Take Frame", default=0, min=0,
                          description="take frame to stop before (0: the take's end)")

    def stretch(self, n_frames: int) -> tuple:
        """The take frames ``(START, END)`` to key of a take of ``n_frames`` frames, checked
        (:func:`core.face.animate.take_frame_range`)."""
        from ...core.face.animate import take_frame_range

        return take_frame_range((self.take_start, self.take_end or None), n_frames)
