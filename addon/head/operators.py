"""Head (3D View): add the generic head, fit it to the performer's scan.

Operators (``bpy.ops.mirrorcap.*``); all inputs are operator properties, an empty one falls back
to the scene's settings. Long ones are modal jobs (:class:`..common.jobs.MirrorCapJobOperator`)."""

from __future__ import annotations

import json

import bpy
from bpy.props import StringProperty

from ...core.common.errors import InputError
from ..common.inputs import head_object_from, input_path, required, scene_settings
from ..common.jobs import MirrorCapJobOperator, MirrorCapOperator


class MIRRORCAP_OT_add_generic_head(MirrorCapOperator):
    """Add MirrorCap's generic head (regions, landmarks, eyelids, teeth, 52 faceunit shape keys)"""

    bl_idname = "mirrorcap.add_generic_head"
    bl_label = "Add Generic Head"

    def run(self, context):
        from ...core.face.headio import load_head_npz
        from ..common.headio import GENERIC_HEAD, new_head_object

        if not GENERIC_HEAD.is_file():
            raise InputError(f"the generic head is missing from the add-on ({GENERIC_HEAD})")
        head, keys = load_head_npz(GENERIC_HEAD, with_shape_keys=True)
        obj = new_head_object(head, keys, name="generic_head")
        scene_settings(context).head_object = obj
        for o in context.view_layer.objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        return f"added {obj.name}: {len(head.vertices)} vertices, {len(keys)} shape keys"


class MIRRORCAP_OT_fit_head(MirrorCapJobOperator):
    """Fit the head to a scan of the subject (landmarks, then RBF scattering onto the surface); adds a fitted copy"""

    bl_idname = "mirrorcap.fit_head"
    bl_label = "Fit Head To Scan"

    head_object: StringProperty(name="Head", description="head object (default: the scene's head, or the active object)")
    scan_file: StringProperty(name="Scan", subtype="FILE_PATH", description="PLY or OBJ in mm (default: the scene's)")
    landmarks: StringProperty(name="Landmarks", subtype="FILE_PATH", description="JSON landmarks of the scan")

    def prepare(self, context):
        from ...core.face.scanio import read_landmarks, read_scan
        from ..common.headio import read_head

        s = scene_settings(context)
        obj = head_object_from(context, self.head_object)
        head = read_head(obj)
        head.validate()
        V, T = read_scan(required(input_path(self.scan_file, s.scan_file, what="scan"), "scan (PLY or OBJ)"))
        lms = read_landmarks(required(input_path(self.landmarks, s.scan_landmarks, what="landmarks file"), "scan landmarks"))
        self._obj_name = obj.name

        def work(progress):
            from ...core.face.headfit import fit_head

            progress(0.05, "fitting")
            fit = fit_head(head, V, T, lms)
            progress(1.0, "fitted")
            return head, fit

        return work

    def finish(self, context, result):
        from ..common.headio import replace_head_vertices

        head, fit = result
        src = bpy.data.objects[self._obj_name]
        obj = src.copy()
        obj.data = src.data.copy()
        obj.name = obj.data.name = f"{src.name}_fitted"
        for coll in src.users_collection:
            coll.objects.link(obj)
        replace_head_vertices(obj, head.vertices, fit.vertices)
        obj["mirrorcap_fit"] = json.dumps({"residual_rms_mm": fit.residual_rms_mm, "scale": fit.scale,
                                           "landmark_rms_mm": fit.landmark_rms_mm})
        scene_settings(context).head_object = obj
        return (f"{obj.name}: residual to the scan {fit.residual_rms_mm:.2f} mm RMS "
                f"(95 % under {fit.residual_p95_mm:.2f} mm), landmarks {fit.landmark_rms_mm:.2f} mm")


OPERATORS = (MIRRORCAP_OT_add_generic_head, MIRRORCAP_OT_fit_head)
