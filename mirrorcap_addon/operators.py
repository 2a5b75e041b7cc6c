"""Operators. Every one derives from :class:`MirrorCapOperator` (after MPFB2): ``run()``
does the work; a :class:`core.errors.MirrorCapError` becomes a ``self.report`` error and
``{'CANCELLED'}`` -- never a bare traceback -- unless ``MIRRORCAP_RAISE=1`` (tests), when
it propagates. All inputs are properties, so ``bpy.ops.mirrorcap.*`` drives batch jobs.
"""

from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

from ..core.errors import MirrorCapError


class MirrorCapOperator(bpy.types.Operator):
    bl_options = {"REGISTER", "UNDO"}

    def run(self, context):  # pragma: no cover - overridden
        raise NotImplementedError

    def execute(self, context):
        try:
            message = self.run(context)
        except MirrorCapError as exc:
            if os.environ.get("MIRRORCAP_RAISE") == "1":
                raise
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        if message:
            self.report({"INFO"}, message)
        return {"FINISHED"}


class MIRRORCAP_OT_bake(MirrorCapOperator):
    """Bake a C3D take onto the active head as shape keys (face rig: regions, jaw, inner lip, blinks)"""

    bl_idname = "mirrorcap.bake"
    bl_label = "Bake Take"

    take: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d to bake")
    head_object: StringProperty(name="Head", description="head mesh object (default: the active object)")
    mode: EnumProperty(name="Mode", items=(("frames", "Frames", "one shape key per frame"),
                                           ("pca", "PCA", "eigen-deformation shape keys with keyed weights")),
                       default="frames")
    modes: IntProperty(name="Modes", default=8, min=1, max=512, description="number of PCA modes")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)
    head_motion: BoolProperty(name="Head Motion", default=False, description="key the head motion on the object")
    blinks: BoolProperty(name="Blinks", default=True)
    blink_seed: IntProperty(name="Blink Seed", default=0)

    def run(self, context):
        from ..core.bind import bind_take
        from ..core.c3d import read_c3d
        from ..core.errors import InputError
        from ..core.facerig import FaceRig, RigSettings
        from .bake import bake_displacements
        from .headio import read_head

        obj = bpy.data.objects.get(self.head_object) if self.head_object else context.active_object
        if obj is None:
            raise InputError("choose a head object (none is active)")
        if not self.take:
            raise InputError("choose a take (TAKE.c3d)")
        data = read_c3d(bpy.path.abspath(self.take))
        head = read_head(obj)
        binding = bind_take(head, data["labels"], data["points"], neutral_frame=self.neutral_frame)
        rig = FaceRig(head, binding.vertices, RigSettings(blinks=self.blinks, blink_seed=self.blink_seed))
        D = rig.deform(binding.displacements, fps=data["rate"])
        if self.mode == "pca" and self.modes > D.shape[0]:
            raise InputError(f"Modes must be at most the take's {D.shape[0]} frames")
        out = bake_displacements(obj, head.vertices, D, self.mode, self.modes,
                                 head_motion=binding.head_motion if self.head_motion else None)
        context.scene.render.fps = max(1, int(round(data["rate"])))
        extra = f", PCA max error {out['pca_max_error_mm']:.3f} mm" if self.mode == "pca" else ""
        return f"baked {out['frames']} frames onto {obj.name}{extra}"


CLASSES = (MIRRORCAP_OT_bake,)
