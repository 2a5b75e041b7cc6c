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
        col.separator()
        col.label(text="MPEG-4 facial animation parameters")
        col.prop(s, "fap_file")
        row = col.row(align=True)
        row.operator("mirrorcap.export_faps", icon="EXPORT")
        row.operator("mirrorcap.bake", text="Play FAP File", icon="PLAY").fap = s.fap_file


PANELS = (MIRRORCAP_PT_retarget,)
