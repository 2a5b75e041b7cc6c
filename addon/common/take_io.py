"""A C3D take in the scene: one empty per marker under a parent empty, animated.

The parent carries the unit conversion (a take in mm, or in the relative units of a
self-calibrated take, is shown at 1 unit = 1 mm) and, for a MirrorCap take in the camera
frame, the camera-to-Blender frame change of :mod:`.frames` (another system's take keeps its
own axes: most are Z-up, as Blender is); each marker's location is keyed on the frames it was reported (gaps stay
gaps), three F-curves per marker, each written with one ``keyframe_points.foreach_set``.
Scene frame ``1 + f`` is take frame ``f``.
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np

from ...core.take.c3d import read_c3d
from .frames import core_to_blender
from .keys import keyed_frames, set_scene_rate
from .properties import preferences


def import_take(context, path, name: str | None = None, data: dict | None = None):
    """Add the take at ``path`` (or ``data`` as :func:`read_c3d` returns it), keyed from the scene's start frame on
    as a bake is (:func:`.keys.keyed_frames`); returns the parent empty."""
    data = read_c3d(path) if data is None else data
    P = data["points"]                          # (F, M, 3) core frame
    F, M, _ = P.shape
    name = name or Path(path).stem
    coll = bpy.data.collections.new(f"MirrorCap take {name}")
    context.scene.collection.children.link(coll)
    parent = bpy.data.objects.new(f"MirrorCap take {name}", None)
    parent.empty_display_type = "ARROWS"
    parent.empty_display_size = 0.02
    parent["mirrorcap_take"] = str(path)
    parent["mirrorcap_units"] = data["units"]
    coll.objects.link(parent)
    prefs = preferences(context)
    size = 0.001 * (prefs.empty_size_mm if prefs is not None else 2)
    if data["frame"] == "camera":
        B = core_to_blender(np.nan_to_num(P)).reshape(F, M, 3)  # metres at 1 unit = 1 mm
    else:
        B = 0.001 * np.nan_to_num(P)                            # the lab's own axes, metres
    parent["mirrorcap_frame"] = data["frame"]
    seen = np.all(np.isfinite(P), axis=2)
    frames = keyed_frames(context.scene, context.scene.frame_start, F).astype(np.float32)
    for m, label in enumerate(data["labels"]):
        ob = bpy.data.objects.new(f"{name}_{label}", None)
        ob.empty_display_type = "SPHERE"
        ob.empty_display_size = size
        ob.parent = parent
        ob["mirrorcap_label"] = label
        coll.objects.link(ob)
        ok = seen[:, m]
        if not ok.any():
            continue
        ob.location = B[np.argmax(ok), m]
        action = bpy.data.actions.new(f"{name}_{label}")
        ob.animation_data_create().action = action
        for axis in range(3):
            fc = action.fcurve_ensure_for_datablock(ob, "location", index=axis)
            n = int(ok.sum())
            fc.keyframe_points.add(n)
            fc.keyframe_points.foreach_set("co", np.column_stack([frames[ok], B[ok, m, axis]]).astype(np.float32).ravel())
            fc.update()
    set_scene_rate(context.scene, data["rate"])
    return parent
