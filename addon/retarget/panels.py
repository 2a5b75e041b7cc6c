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
        col.prop(s, "retarget_method")
        if s.retarget_method == "transfer":
            from .landmarks import LANDMARK_ORDER, next_landmark, placed_landmarks

            placed = placed_landmarks(s.retarget_target)
            nxt = next_landmark(placed)
            col.label(text=f"Landmarks {len([n for n in LANDMARK_ORDER if n in placed])}/{len(LANDMARK_ORDER)}"
                           + (f", next: lm_{nxt}" if nxt else ""), icon="PIVOT_CURSOR")
            row = col.row(align=True)
            row.operator("mirrorcap.place_landmarks", icon="RESTRICT_SELECT_OFF")
            row.operator("mirrorcap.guess_landmarks", icon="SHADERFX")
            row = col.row(align=True)
            row.prop(s, "bake_mode", text="Keys")
            if s.bake_mode == "pca":
                row.prop(s, "modes")
        else:
            col.prop(s, "livelink_csv")
        row = col.row(align=True)
        row.prop(s, "bake_take_start")
        row.prop(s, "bake_take_end")
        op = col.operator("mirrorcap.retarget", icon="ARMATURE_DATA")
        op.take_start, op.take_end = s.bake_take_start, s.bake_take_end
        col.label(text=f"keys from the scene's start frame, {context.scene.frame_start}")
        col.label(text="Esc cancels", icon="INFO")
        col.separator()
        col.label(text="MPEG-4 facial animation parameters")
        col.prop(s, "fap_file")
        row = col.row(align=True)
        row.operator("mirrorcap.export_faps", icon="EXPORT")
        row.operator("mirrorcap.bake", text="Play FAP File", icon="PLAY").fap = s.fap_file


PANELS = (MIRRORCAP_PT_retarget,)
