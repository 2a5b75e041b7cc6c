"""Panels: a "MirrorCap" tab in the Movie Clip Editor's sidebar (capture) and in the 3D View's
sidebar (take, head, bake). They only lay out ``scene.mirrorcap`` and call operators."""

from __future__ import annotations

import bpy


class _Panel:
    bl_region_type = "UI"
    bl_category = "MirrorCap"


class MIRRORCAP_PT_capture(_Panel, bpy.types.Panel):
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
        col.separator()
        col.operator("mirrorcap.detect_markers", icon="TRACKER")
        col.prop(s, "mirrors")
        col.operator("mirrorcap.solve_mirrors", icon="MOD_MIRROR")


class MIRRORCAP_PT_track(_Panel, bpy.types.Panel):
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
        box = col.box()
        box.label(text="Rigid markers (head pose): all 0 = RIG.json / automatic")
        box.prop(s, "rigid_region", text="")
        box.prop(s, "rigid_colors")
        box.operator("mirrorcap.rigid_from_tracks", icon="RESTRICT_SELECT_OFF")
        col.operator("mirrorcap.track", icon="TRACKING")
        col.operator("mirrorcap.track_clip_tracks", icon="TRACKING_FORWARDS")
        col.label(text="Esc cancels a running job", icon="INFO")


class MIRRORCAP_PT_take(_Panel, bpy.types.Panel):
    bl_space_type = "VIEW_3D"
    bl_label = "Take"

    def draw(self, context):
        s = context.scene.mirrorcap
        col = self.layout.column()
        col.prop(s, "take")
        col.operator("mirrorcap.import_take", icon="EMPTY_DATA")


class MIRRORCAP_PT_head(_Panel, bpy.types.Panel):
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


class MIRRORCAP_PT_bake(_Panel, bpy.types.Panel):
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
        op = col.operator("mirrorcap.bake", icon="SHAPEKEY_DATA")
        op.mode, op.modes, op.head_motion, op.blinks = s.bake_mode, s.modes, s.head_motion, s.blinks
        col.label(text="Retargeting: coming next", icon="INFO")


CLASSES = (MIRRORCAP_PT_capture, MIRRORCAP_PT_track, MIRRORCAP_PT_take, MIRRORCAP_PT_head, MIRRORCAP_PT_bake)
