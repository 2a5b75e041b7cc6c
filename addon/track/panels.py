"""The track panels of the "MirrorCap" sidebar tab; they lay out ``scene.mirrorcap`` and call operators."""

from __future__ import annotations

import bpy

from ..common.panel import SidebarPanel


class MIRRORCAP_PT_track(SidebarPanel, bpy.types.Panel):
    bl_space_type = "CLIP_EDITOR"
    bl_label = "Track"

    def draw(self, context):
        s = context.scene.mirrorcap
        col = self.layout.column()
        col.prop(s, "take")
        row = col.row(align=True)
        row.prop(s, "frame_start")
        row.prop(s, "frame_end")
        col.prop(s, "conjecture_limit_mm")
        col.prop(s, "light", expand=True)
        if s.light != "uv":
            col.prop(s, "washed_out")
        col.prop(s, "seeds")
        box = col.box()
        box.label(text="Rigid markers (head pose): all 0 = RIG.json / automatic")
        box.prop(s, "rigid_region", text="")
        box.prop(s, "rigid_colors")
        box.operator("mirrorcap.rigid_from_tracks", icon="RESTRICT_SELECT_OFF")
        col.operator("mirrorcap.track", icon="TRACKING")
        col.operator("mirrorcap.track_clip_tracks", icon="TRACKING_FORWARDS")
        box = col.box()
        box.label(text="Fix-ups: the take as clip tracks, then Re-solve")
        row = box.row(align=True)
        row.operator("mirrorcap.take_to_clip", icon="TRACKER")
        row.operator("mirrorcap.resolve", icon="FILE_REFRESH")
        col.label(text="Esc cancels a running job", icon="INFO")


class MIRRORCAP_PT_take(SidebarPanel, bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_label = "Take"

    def draw(self, context):
        s = context.scene.mirrorcap
        col = self.layout.column()
        col.prop(s, "take")
        col.operator("mirrorcap.import_take", icon="EMPTY_DATA")
        box = col.box()
        box.label(text="Stabilize (any system's C3D)")
        box.prop(s, "stable_take")
        box.prop(s, "rigid_labels")
        box.operator("mirrorcap.stabilize_take", icon="ORIENTATION_GIMBAL")


PANELS = (MIRRORCAP_PT_track, MIRRORCAP_PT_take)
