"""The bake panel of the "MirrorCap" sidebar tab; they lay out ``scene.mirrorcap`` and call operators."""

from __future__ import annotations

import bpy

from ..common.panel import SidebarPanel


class MIRRORCAP_PT_bake(SidebarPanel, bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_label = "Bind and Bake"

    def draw(self, context):
        s = context.scene.mirrorcap
        col = self.layout.column()
        col.operator("mirrorcap.bind", icon="CONSTRAINT_BONE")
        col.prop(s, "bake_mode")
        if s.bake_mode == "pca":
            col.prop(s, "modes")
        col.prop(s, "head_motion")
        col.prop(s, "blinks")
        row = col.row(align=True)
        row.prop(s, "bake_take_start")
        row.prop(s, "bake_take_end")
        op = col.operator("mirrorcap.bake", icon="SHAPEKEY_DATA")
        op.mode, op.modes, op.head_motion, op.blinks = s.bake_mode, s.modes, s.head_motion, s.blinks
        op.take_start, op.take_end = s.bake_take_start, s.bake_take_end
        col.label(text=f"keys from the scene's start frame, {context.scene.frame_start}")
        box = col.box()
        box.label(text="Marker map (sparse takes: pick a marker empty, then)")
        box.prop(s, "marker_map")
        row = box.row(align=True)
        row.operator("mirrorcap.map_marker", text="Selected Vertex").role = "VERTEX"
        row.operator_menu_enum("mirrorcap.map_marker", "landmark", text="Landmark")
        row = box.row(align=True)
        row.operator("mirrorcap.map_marker", text="Rigid").role = "RIGID"
        row.operator("mirrorcap.map_marker", text="Ignore").role = "IGNORE"
        row.operator("mirrorcap.map_marker", text="Remove").role = "REMOVE"


PANELS = (MIRRORCAP_PT_bake,)
