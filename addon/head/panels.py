"""The head panel of the "MirrorCap" sidebar tab; they lay out ``scene.mirrorcap`` and call operators."""

from __future__ import annotations

import bpy

from ..common.panel import SidebarPanel


class MIRRORCAP_PT_head(SidebarPanel, bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_label = "Head"

    def draw(self, context):
        s = context.scene.mirrorcap
        col = self.layout.column()
        col.operator("mirrorcap.add_generic_head", icon="USER")
        col.prop(s, "head_object")
        col.prop(s, "scan_file")
        col.prop(s, "scan_landmarks")
        col.operator("mirrorcap.fit_head", icon="MOD_SHRINKWRAP")


PANELS = (MIRRORCAP_PT_head,)
