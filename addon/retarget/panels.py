"""The retarget panel of the "MirrorCap" sidebar tab (3D View)."""

from __future__ import annotations

import bpy

from ..common.panel import SidebarPanel


class MIRRORCAP_PT_retarget(SidebarPanel, bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_label = "Retarget"

    def draw(self, context):
        s = context.scene.mirrorcap
        col = self.layout.column()
        col.prop(s, "head_object", text="Actor")
        col.prop(s, "retarget_target")
        col.prop(s, "livelink_csv")
        col.operator("mirrorcap.retarget", icon="ARMATURE_DATA")
        col.label(text="ARKit-52 weights; Esc cancels", icon="INFO")


PANELS = (MIRRORCAP_PT_retarget,)
