"""Bind and bake (3D View): register a take to the head and bake the face rig as shape keys.

Operators (``bpy.ops.mirrorcap.*``); all inputs are operator properties, an empty one falls back
to the scene's settings. Long ones are modal jobs (:class:`..common.jobs.MirrorCapJobOperator`)."""

from __future__ import annotations

import json

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

from ...core.common.errors import InputError
from ..common.inputs import head_object_from, input_path, required, scene_settings
from ..common.jobs import MirrorCapJobOperator, MirrorCapOperator
from ..common.properties import BAKE_MODES


class _UnseenMarkers:
    """The bind and bake operators' options for markers not seen in the neutral frame."""

    drop_unseen: BoolProperty(name="Drop Unseen Markers", default=True,
                              description="leave out markers not seen in the neutral frame (else refuse the take)")
    conjecture_unseen: BoolProperty(name="Conjecture Unseen Markers", default=True,
                                    description="place markers not seen in the neutral frame from their neighbours' "
                                                "learned relations; those expected off by more than 2 mm are left "
                                                "out (off: Drop Unseen Markers decides)")

    def unseen(self) -> str:
        """bind_take's ``unseen`` from the two options."""
        from ...core.face.animate import unseen_policy

        return unseen_policy(self.drop_unseen, self.conjecture_unseen)


class MIRRORCAP_OT_bind(_UnseenMarkers, MirrorCapOperator):
    """Register the take to the head and show which vertex each marker drives (vertex group mirrorcap_bound)"""

    bl_idname = "mirrorcap.bind"
    bl_label = "Bind Markers"

    take: StringProperty(name="Take", subtype="FILE_PATH")
    head_object: StringProperty(name="Head")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)

    def run(self, context):
        from ...core.face.bind import bind_take
        from ...core.take.c3d import read_c3d
        from ..common.headio import read_head

        obj = head_object_from(context, self.head_object)
        data = read_c3d(required(input_path(self.take, scene_settings(context).take, what="take"), "take (TAKE.c3d)"))
        head = read_head(obj)
        b = bind_take(head, data["labels"], data["points"], neutral_frame=self.neutral_frame,
                      unseen=self.unseen())
        group = obj.vertex_groups.get("mirrorcap_bound") or obj.vertex_groups.new(name="mirrorcap_bound")
        group.remove(list(range(len(obj.data.vertices))))
        group.add([int(v) for v in b.vertices], 1.0, "REPLACE")
        obj["mirrorcap_binding"] = json.dumps({"labels": b.labels, "vertices": b.vertices.tolist(),
                                               "registration": b.registration, "rms_mm": b.landmark_rms_mm,
                                               "scale": b.scale})
        how = "landmarks " + ", ".join(b.landmarks_used) if b.registration == "landmarks" else "the skin surface"
        return (f"bound {len(b.labels)} markers by {how} ({b.landmark_rms_mm:.2f} mm RMS); "
                f"marker-to-vertex distance max {b.distance_mm.max():.2f} mm")


class MIRRORCAP_OT_bake(_UnseenMarkers, MirrorCapJobOperator):
    """Bake a C3D take onto the head as shape keys (face rig: regions, jaw, inner lip, blinks)"""

    bl_idname = "mirrorcap.bake"
    bl_label = "Bake Take"

    take: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d to bake (default: the scene's)")
    head_object: StringProperty(name="Head", description="head mesh object (default: the scene's head or the active one)")
    mode: EnumProperty(name="Mode", items=BAKE_MODES, default="frames")
    modes: IntProperty(name="Modes", default=8, min=1, max=512, description="number of PCA modes")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)
    head_motion: BoolProperty(name="Head Motion", default=False, description="key the head motion on the object")
    blinks: BoolProperty(name="Blinks", default=True)
    blink_seed: IntProperty(name="Blink Seed", default=0)

    def prepare(self, context):
        from ...core.take.c3d import read_c3d
        from ..common.headio import read_head

        obj = head_object_from(context, self.head_object)
        data = read_c3d(required(input_path(self.take, scene_settings(context).take, what="take"), "take (TAKE.c3d)"))
        if self.mode == "pca" and self.modes > data["points"].shape[0]:
            raise InputError(f"Modes must be at most the take's {data['points'].shape[0]} frames")
        head = read_head(obj)
        head.validate()
        self._obj_name = obj.name

        def work(progress):
            from ...core.face.animate import animate_take
            from ...core.face.facerig import RigSettings

            anim = animate_take(head, data["labels"], data["points"], data["rate"], neutral_frame=self.neutral_frame,
                                unseen=self.unseen(), settings=RigSettings(blinks=self.blinks, blink_seed=self.blink_seed),
                                progress=progress)
            return head, anim.binding, anim.displacements, anim.rate

        return work

    def finish(self, context, result):
        from .bake import bake_displacements

        head, binding, D, rate = result
        obj = bpy.data.objects[self._obj_name]
        out = bake_displacements(obj, head.vertices, D, self.mode, self.modes,
                                 head_motion=binding.head_motion if self.head_motion else None)
        context.scene.render.fps = max(1, int(round(rate)))
        context.scene.frame_start, context.scene.frame_end = 1, out["frames"]
        extra = f", PCA max error {out['pca_max_error_mm']:.3f} mm" if self.mode == "pca" else ""
        return f"baked {out['frames']} frames onto {obj.name}{extra}"


OPERATORS = (MIRRORCAP_OT_bind, MIRRORCAP_OT_bake)
