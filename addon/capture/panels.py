"""The capture panel of the "MirrorCap" sidebar tab; they lay out ``scene.mirrorcap`` and call operators."""

from __future__ import annotations

import bpy

from ..common.panel import SidebarPanel


class MIRRORCAP_PT_capture(SidebarPanel, bpy.types.Panel):
    bl_space_type = "CLIP_EDITOR"
    bl_label = "Capture"

    def draw(self, context):
        s = context.scene.mirrorcap
        col = self.layout.column()
        col.operator("mirrorcap.open_clip", icon="FILE_MOVIE")
        col.prop(s, "video")
        col.separator()
        col.label(text="Camera and rig")
        col.prop(s, "camera")
        col.operator("mirrorcap.calibrate_camera", icon="CAMERA_DATA")
        col.prop(s, "rig")
        col.prop(s, "colors")
        col.prop(s, "light", expand=True)
        if s.light != "uv":
            col.prop(s, "washed_out")
        col.separator()
        col.operator("mirrorcap.detect_markers", icon="TRACKER")
        col.prop(s, "mirrors")
        col.operator("mirrorcap.solve_mirrors", icon="MOD_MIRROR")


PANELS = (MIRRORCAP_PT_capture,)
