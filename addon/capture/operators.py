"""Capture (Movie Clip Editor): open the rig video, calibrate the camera, detect markers, solve the mirrors from a board.

Operators (``bpy.ops.mirrorcap.*``); all inputs are operator properties, an empty one falls back
to the scene's settings. Long ones are modal jobs (:class:`..common.jobs.MirrorCapJobOperator`)."""

from __future__ import annotations

import json

import bpy
import numpy as np
from bpy.props import IntProperty, StringProperty

from ...core.common.errors import InputError
from ..common.inputs import extraction_settings, input_path, required, rig_and_colours, scene_settings
from ..common.jobs import MirrorCapJobOperator, MirrorCapOperator
from ..common.keys import set_scene_rate


class MIRRORCAP_OT_open_clip(MirrorCapOperator):
    """Open the rig video as a movie clip and make it the scene's rig video"""

    bl_idname = "mirrorcap.open_clip"
    bl_label = "Open Rig Video"

    filepath: StringProperty(name="Video", subtype="FILE_PATH")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        path = required(input_path(self.filepath, what="video"), "rig video")
        try:
            clip = bpy.data.movieclips.load(str(path), check_existing=True)
        except RuntimeError as exc:
            raise InputError(f"Blender cannot open {path} as a clip ({exc})") from None
        scene_settings(context).video = str(path)
        scene = context.scene
        scene.frame_start, scene.frame_end = 1, max(1, clip.frame_duration)
        set_scene_rate(scene, clip.fps)
        space = getattr(context, "space_data", None)
        if space is not None and space.type == "CLIP_EDITOR":
            space.clip = clip
        return f"opened {path.name}: {clip.size[0]}x{clip.size[1]}, {clip.frame_duration} frames"


class MIRRORCAP_OT_calibrate_camera(MirrorCapJobOperator):
    """Calibrate the camera's intrinsics from a video of a chessboard or ChArUco board"""

    bl_idname = "mirrorcap.calibrate_camera"
    bl_label = "Calibrate Camera"

    board_video: StringProperty(name="Board Video", subtype="FILE_PATH")
    board: StringProperty(name="Board", default="charuco:7x5:30:22",
                          description="chessboard:COLSxROWS:SQUARE_MM or charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT]")
    output: StringProperty(name="Camera File", subtype="FILE_PATH", default="//camera.json")

    def prepare(self, context):
        from ...core.capture.calibrate import Board
        from ...core.capture.video import open_source

        board = Board.parse(self.board)
        source = open_source(required(input_path(self.board_video, what="board video"), "board video"))
        out = required(input_path(self.output, must_exist=False), "camera file")

        def work(progress):
            from ...core.capture.calibrate import calibrate_camera
            from ...core.common.files import write_files_atomically

            result = calibrate_camera(source, board, progress=progress.stage(0.0, 0.95, "finding the board"))
            write_files_atomically({out: json.dumps(result.to_dict(), indent=2) + "\n"})
            return out, result

        return work

    def finish(self, context, result):
        out, res = result
        scene_settings(context).camera = str(out)
        return (f"camera from {res.views_used} views, RMS {res.rms_px:.3f} px, focal length "
                f"+-{res.focal_sd_percent:.2f} % (the board turned {res.board_turn_deg:.0f} deg) -> {out.name}")


class MIRRORCAP_OT_detect_markers(MirrorCapOperator):
    """Find the markers in one frame of the rig video and show them as clip tracks (one per marker)"""

    bl_idname = "mirrorcap.detect_markers"
    bl_label = "Detect Markers"

    frame: IntProperty(name="Frame", default=-1, min=-1, description="video frame (0-based); -1: the scene's current")

    def run(self, context):
        from ...core.capture.markers import marker_extractor
        from ...core.capture.detect import (between_chosen, dot_diameter_px, dot_px_by_view, dot_px_text, keeps_between,
                                            small_dot_warning)
        from ...core.capture.rig import split_views_by_gaps
        from ...core.capture.video import open_source
        from ..common.clip import detections_to_clip_tracks, find_clip

        s = scene_settings(context)
        video = required(input_path(s.video, what="rig video"), "rig video")
        source = open_source(video)
        n = context.scene.frame_current - 1 if self.frame < 0 else self.frame
        n = min(max(n, 0), source.frame_count - 1)
        image = next(iter(source.frames(n, n + 1, 1)))[1]
        rig, colors, light, from_frame = rig_and_colours(s, source, n)
        settings = extraction_settings(s, light)
        det = marker_extractor(colors, settings)(image)
        between = det.between_count()       # washed-out dots: as a take would decide, from this one frame
        det = between_chosen(det, keeps_between(settings.washed_out, between, len(det) - between))
        if len(det) == 0:
            raise InputError(f"no markers found in frame {n}: " + ("are there coloured dots of the colour classes on "
                             "the face?" if light == "normal" else "is the clip dark with bright dots? (coloured dots "
                             "under ordinary light: set Light to Normal)"))
        layout = rig.views or split_views_by_gaps(det.x, 2.0 * dot_diameter_px(settings, [det]))
        view = layout.assign(det.x, det.y)
        clip = find_clip(video)
        count = detections_to_clip_tracks(clip, n, det.x, det.y, det.color, view, source.size)
        per_view = np.bincount(view[view >= 0], minlength=3)
        dot_px = dot_px_by_view(det.area, view)
        small = small_dot_warning(light, dot_px)
        if small:
            self.messages.warning(small)
        return (f"frame {n}: {count} markers ({per_view[0]} direct, {per_view[1]} mirror 0, {per_view[2]} mirror 1; "
                f"dots {dot_px_text(dot_px)} px across) shown as tracks of the clip's 'MirrorCap' object"
                + (f"; light: {'ordinary' if light == 'normal' else 'UV'}, as the frame shows it" if from_frame
                   else ""))


class MIRRORCAP_OT_solve_mirrors(MirrorCapJobOperator):
    """Mirror planes in millimetres from a clip of a ChArUco board seen directly and in both mirrors"""

    bl_idname = "mirrorcap.solve_mirrors"
    bl_label = "Solve Mirrors"

    board_video: StringProperty(name="Board Video", subtype="FILE_PATH")
    board: StringProperty(name="Board", default="charuco:7x5:30:22")
    output: StringProperty(name="Mirrors File", subtype="FILE_PATH", default="//mirrors.json")

    def prepare(self, context):
        from ...core.capture.calibrate import Board
        from ...core.capture.detect import _check_camera
        from ...core.capture.video import open_source
        from ...core.geometry.camera import Camera

        s = scene_settings(context)
        board = Board.parse(self.board)
        camera = Camera.load(required(input_path(s.camera, what="camera file"), "camera file (CAMERA.json)"))
        source = open_source(required(input_path(self.board_video, what="board video"), "board video"))
        _check_camera(camera, source)
        layout = rig_and_colours(s)[0].views
        out = required(input_path(self.output, must_exist=False), "mirrors file")

        def work(progress):
            from ...core.capture.boardcal import calibrate_mirrors_from_board, write_mirrors_json
            from ...core.common.files import write_files_atomically

            total = max(source.frame_count, 1)

            def frames():
                for i, (_, img) in enumerate(source.frames(0, None, 1)):
                    progress(0.9 * i / total, "finding the board in all three views")
                    yield img

            result = calibrate_mirrors_from_board(frames(), camera, board, layout=layout)
            write_files_atomically({out: write_mirrors_json(result, board)})
            return out, result

        return work

    def finish(self, context, result):
        out, res = result
        scene_settings(context).mirrors = str(out)
        return f"mirror planes from {res.frames_used} frames -> {out.name}"


OPERATORS = (MIRRORCAP_OT_open_clip, MIRRORCAP_OT_calibrate_camera, MIRRORCAP_OT_detect_markers, MIRRORCAP_OT_solve_mirrors)
