"""Operators: every pipeline stage as ``bpy.ops.mirrorcap.*``.

All inputs are operator properties; an empty one falls back to the scene's settings
(``scene.mirrorcap``), so a script needs no UI state. Long stages are
:class:`.jobs.MirrorCapJobOperator` s: modal with a progress bar and Esc to cancel from the
UI, synchronous from a script, and the scene changes only once the work has succeeded.

Capture (Movie Clip Editor): ``open_clip``, ``calibrate_camera``, ``detect_markers``,
``solve_mirrors``, ``track``, ``track_clip_tracks``.
Animation (3D View): ``import_take``, ``add_generic_head``, ``fit_head``, ``bind``, ``bake``.
"""

from __future__ import annotations

import json
from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

from ..core.errors import InputError
from .jobs import MirrorCapJobOperator, MirrorCapOperator
from .properties import BAKE_MODES



def _settings(context):
    return context.scene.mirrorcap


def _path(value: str, fallback: str = "", what: str = "file", must_exist: bool = True) -> Path | None:
    """An absolute path from an operator property or its scene fallback (``//`` = the .blend's folder)."""
    text = value or fallback
    if not text:
        return None
    path = Path(bpy.path.abspath(text))
    if must_exist and not path.exists():
        raise InputError(f"the {what} {path} does not exist")
    return path


def _need(path, what: str):
    if path is None:
        raise InputError(f"choose the {what} first")
    return path


def _report_path(take: Path) -> Path:
    return take.with_name(take.stem + "_report.json")


def _head_object(context, name: str):
    if name:
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise InputError(f"there is no object named {name!r}")
    else:
        obj = _settings(context).head_object or context.active_object
    if obj is None or obj.type != "MESH":
        raise InputError("choose a head mesh (Head in the MirrorCap panel, or the active object)")
    return obj


# -- capture ---------------------------------------------------------------------------------
class MIRRORCAP_OT_open_clip(MirrorCapOperator):
    """Open the rig video as a movie clip and make it the scene's rig video"""

    bl_idname = "mirrorcap.open_clip"
    bl_label = "Open Rig Video"

    filepath: StringProperty(name="Video", subtype="FILE_PATH")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        path = _need(_path(self.filepath, what="video"), "rig video")
        try:
            clip = bpy.data.movieclips.load(str(path), check_existing=True)
        except RuntimeError as exc:
            raise InputError(f"Blender cannot open {path} as a clip ({exc})") from None
        _settings(context).video = str(path)
        scene = context.scene
        scene.frame_start, scene.frame_end = 1, max(1, clip.frame_duration)
        scene.render.fps = max(1, int(round(clip.fps)))
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
        from ..core.calibrate import Board
        from ..core.video import open_source

        board = Board.parse(self.board)
        source = open_source(_need(_path(self.board_video, what="board video"), "board video"))
        out = _need(_path(self.output, must_exist=False), "camera file")

        def work(progress):
            from ..core.atomic import write_files_atomically
            from ..core.calibrate import calibrate_camera

            result = calibrate_camera(source, board, progress=progress.stage(0.0, 0.95, "finding the board"))
            write_files_atomically({out: json.dumps(result.to_dict(), indent=2) + "\n"})
            return out, result

        return work

    def finish(self, context, result):
        out, res = result
        _settings(context).camera = str(out)
        return f"camera from {res.views_used} views, RMS {res.rms_px:.3f} px -> {out.name}"


class MIRRORCAP_OT_detect_markers(MirrorCapOperator):
    """Find the markers in one frame of the rig video and show them as clip tracks (one per marker)"""

    bl_idname = "mirrorcap.detect_markers"
    bl_label = "Detect Markers"

    frame: IntProperty(name="Frame", default=-1, min=-1, description="video frame (0-based); -1: the scene's current")

    def run(self, context):
        from ..core.markers import ColorClasses, ExtractionSettings, MarkerExtractor, load_rig_views, split_views_by_gaps
        from ..core.video import open_source
        from .clip import detections_to_clip_tracks, find_clip

        s = _settings(context)
        video = _need(_path(s.video, what="rig video"), "rig video")
        source = open_source(video)
        n = context.scene.frame_current - 1 if self.frame < 0 else self.frame
        n = min(max(n, 0), source.frame_count - 1)
        image = next(iter(source.frames(n, n + 1, 1)))[1]
        colors = ColorClasses.load(_path(s.colors, what="colour file")) if s.colors else ColorClasses.default()
        settings = ExtractionSettings()
        det = MarkerExtractor(colors, settings)(image)
        if len(det) == 0:
            raise InputError(f"no markers found in frame {n}: is the clip dark with bright dots?")
        layout = ((load_rig_views(_path(s.rig, what="rig file")) if s.rig else None)
                  or split_views_by_gaps(det.x, 2.0 * settings.marker_diameter_px))
        view = layout.assign(det.x, det.y)
        clip = find_clip(video)
        count = detections_to_clip_tracks(clip, n, det.x, det.y, det.color, view, source.size)
        per_view = np.bincount(view[view >= 0], minlength=3)
        return (f"frame {n}: {count} markers ({per_view[0]} direct, {per_view[1]} mirror 0, {per_view[2]} mirror 1) "
                "shown as tracks of the clip's 'MirrorCap' object")


class _UnseenMarkers:
    """The bind and bake operators' options for markers not seen in the neutral frame."""

    drop_unseen: BoolProperty(name="Drop Unseen Markers", default=True,
                              description="leave out markers not seen in the neutral frame (else refuse the take)")
    conjecture_unseen: BoolProperty(name="Conjecture Unseen Markers", default=True,
                                    description="place markers not seen in the neutral frame from their neighbours' "
                                                "learned relations; those expected off by more than 2 mm are left "
                                                "out (off: Drop Unseen Markers decides)")

    def unseen(self) -> str:
        """bind_take's ``unseen`` from the two options."""
        return "conjecture" if self.conjecture_unseen else "drop" if self.drop_unseen else "error"


def _rigid(s, classes):
    """The rigid markers for the tracker: the settings' region/colours if set, else RIG.json's
    ``"rigid"``, else None (automatic). Returns ``(spec for core.track, source name)``."""
    from ..core.markers import RigidMarkers, load_rig_rigid, rectangle
    from ..core.take import rigid_selection

    region = tuple(int(v) for v in s.rigid_region)
    names = tuple(n.strip() for n in s.rigid_colors.split(",") if n.strip())
    if any(region) or names:
        box = rectangle(region, f"the rigid region {region}") if any(region) else None
        rigid, source = RigidMarkers(region=box, colors=names or None), "settings"
    else:
        rigid = load_rig_rigid(_path(s.rig, what="rig file")) if s.rig else None
        source = "rig file"
    spec = rigid_selection(rigid, classes)
    return spec, (source if spec is not None else "automatic")


class MIRRORCAP_OT_rigid_from_tracks(MirrorCapOperator):
    """Set the rigid region (the markers that carry the head pose) to the box around the clip's selected tracks"""

    bl_idname = "mirrorcap.rigid_from_tracks"
    bl_label = "Rigid From Selected Tracks"

    frame: IntProperty(name="Frame", default=-1, min=-1, description="video frame (0-based); -1: the scene's current")
    margin_px: IntProperty(name="Margin", default=6, min=0, description="pixels added around the tracks")

    def run(self, context):
        from .clip import find_clip, selected_track_pixels

        s = _settings(context)
        clip = find_clip(_need(_path(s.video, what="rig video"), "rig video"))
        n = context.scene.frame_current - 1 if self.frame < 0 else self.frame
        xy = selected_track_pixels(clip, n)
        if len(xy) < 4:
            raise InputError(f"select at least 4 direct-view tracks at frame {n} (forehead, nose bridge); "
                             f"{len(xy)} selected")
        lo = np.maximum(np.floor(xy.min(axis=0)) - self.margin_px, 0)
        hi = np.minimum(np.ceil(xy.max(axis=0)) + self.margin_px + 1, clip.size)
        s.rigid_region = (int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1]))
        return f"rigid region {tuple(s.rigid_region)} around {len(xy)} tracks"


class MIRRORCAP_OT_solve_mirrors(MirrorCapJobOperator):
    """Mirror planes in millimetres from a clip of a ChArUco board seen directly and in both mirrors"""

    bl_idname = "mirrorcap.solve_mirrors"
    bl_label = "Solve Mirrors"

    board_video: StringProperty(name="Board Video", subtype="FILE_PATH")
    board: StringProperty(name="Board", default="charuco:7x5:30:22")
    output: StringProperty(name="Mirrors File", subtype="FILE_PATH", default="//mirrors.json")

    def prepare(self, context):
        from ..core.calibrate import Board
        from ..core.camera import Camera
        from ..core.detect import _check_camera
        from ..core.markers import load_rig_views
        from ..core.video import open_source

        s = _settings(context)
        board = Board.parse(self.board)
        camera = Camera.load(_need(_path(s.camera, what="camera file"), "camera file (CAMERA.json)"))
        source = open_source(_need(_path(self.board_video, what="board video"), "board video"))
        _check_camera(camera, source)
        layout = load_rig_views(_path(s.rig, what="rig file")) if s.rig else None
        out = _need(_path(self.output, must_exist=False), "mirrors file")

        def work(progress):
            from ..core.atomic import write_files_atomically
            from ..core.boardcal import calibrate_mirrors_from_board, write_mirrors_json

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
        _settings(context).mirrors = str(out)
        return f"mirror planes from {res.frames_used} frames -> {out.name}"


class _TrackInputs:
    """Properties shared by the two track operators."""

    take: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d to write (default: the scene's)")
    import_result: BoolProperty(name="Import Take", default=True, description="add the take to the scene as empties")

    def _common(self, context):
        from ..core.boardcal import load_mirrors
        from ..core.camera import Camera

        s = _settings(context)
        camera = Camera.load(_need(_path(s.camera, what="camera file"), "camera file (CAMERA.json)"))
        mirrors = load_mirrors(_path(s.mirrors, what="mirrors file")) if s.mirrors else None
        take = _need(_path(self.take, s.take, must_exist=False), "take file")
        if not take.parent.is_dir():
            raise InputError(f"the take's folder {take.parent} does not exist (save the .blend first for // paths)")
        return s, camera, mirrors, take

    def _finish_track(self, context, result):
        take, report = result
        _settings(context).take = str(take)
        if self.import_result:
            from .take_io import import_take

            import_take(context, take)
        pf = report["per_frame"]
        undecided = len(report["markers"].get("undecided", ()))
        return (f"{report['markers']['count']} markers over {report['frames']['count']} frames -> {take.name}; "
                f"{np.mean(pf['measured']):.1f} measured, {np.mean(pf['conjectured']):.1f} conjectured per frame"
                + (f"; {undecided} markers not paired with a mirror image (no 3D; listed in the report)" if undecided else ""))


class MIRRORCAP_OT_track(_TrackInputs, MirrorCapJobOperator):
    """Track the rig video: markers, mirror planes, 3D trajectories with head motion, written as a C3D take"""

    bl_idname = "mirrorcap.track"
    bl_label = "Track"

    video: StringProperty(name="Video", subtype="FILE_PATH", description="rig video (default: the scene's)")

    def prepare(self, context):
        from ..core.markers import ColorClasses, load_rig_views
        from ..core.video import open_source

        s, camera, mirrors, take = self._common(context)
        source = open_source(_need(_path(self.video, s.video, what="rig video"), "rig video"))
        colors = ColorClasses.load(_path(s.colors, what="colour file")) if s.colors else None
        layout = load_rig_views(_path(s.rig, what="rig file")) if s.rig else None
        rigid, rigid_source = _rigid(s, colors or ColorClasses.default())
        end = s.frame_end or None
        n = len(range(s.frame_start, min(end or source.frame_count, source.frame_count)))

        def work(progress):
            from ..core.take import run_track
            from ..core.track import TrackSettings

            report = run_track(source, camera, take, report=_report_path(take), colors=colors, layout=layout,
                               mirrors=mirrors, start=s.frame_start, end=end,
                               settings=TrackSettings.with_conjecture_limit(s.conjecture_limit_mm),
                               rigid=rigid, rigid_source=rigid_source,
                               progress=lambda k: progress(0.8 * k / max(n, 1), "finding markers"),
                               track_progress=progress.stage(0.8, 1.0, "tracking"))
            return take, report

        return work

    def finish(self, context, result):
        return self._finish_track(context, result)


class MIRRORCAP_OT_track_clip_tracks(_TrackInputs, MirrorCapJobOperator):
    """Track in 3D from 2D tracks made with Blender's own tracker (the clip's tracks are the detections)"""

    bl_idname = "mirrorcap.track_clip_tracks"
    bl_label = "Track From Clip Tracks"

    clip: StringProperty(name="Clip", description="movie clip name (default: the one of the scene's rig video)")
    tracking_object: StringProperty(name="Tracking Object", default="",
                                    description="the clip's tracking object holding the tracks (default: all)")

    def prepare(self, context):
        from ..core.markers import ColorClasses, load_rig_views
        from .clip import clip_tracks_to_detections, find_clip

        s, camera, mirrors, take = self._common(context)
        clip = bpy.data.movieclips.get(self.clip) if self.clip else find_clip(_path(s.video, what="rig video"))
        if clip is None:
            raise InputError("open the rig video as a clip first")
        if tuple(clip.size) != tuple(camera.image_size):
            raise InputError(f"the camera file is for {camera.image_size[0]}x{camera.image_size[1]} images but the "
                             f"clip is {clip.size[0]}x{clip.size[1]}")
        layout = load_rig_views(_path(s.rig, what="rig file")) if s.rig else None
        rigid, rigid_source = _rigid(s, ColorClasses.load(_path(s.colors, what="colour file")) if s.colors
                                     else ColorClasses.default())
        numbers, frames = clip_tracks_to_detections(clip, layout, self.tracking_object or None)
        fps = float(clip.fps) or 30.0

        def work(progress):
            from ..core.take import track_detections
            from ..core.track import TrackSettings

            report = track_detections(numbers, frames, camera, fps, take, report=_report_path(take),
                                      mirrors=mirrors, progress=progress.stage(0.0, 1.0, "tracking"),
                                      settings=TrackSettings.with_conjecture_limit(s.conjecture_limit_mm),
                                      timings={"detect": 0.0}, rigid=rigid, rigid_source=rigid_source)
            return take, report

        return work

    def finish(self, context, result):
        return self._finish_track(context, result)


# -- animation -------------------------------------------------------------------------------
class MIRRORCAP_OT_import_take(MirrorCapOperator):
    """Add a C3D take to the scene as animated empties (one per marker) under one parent"""

    bl_idname = "mirrorcap.import_take"
    bl_label = "Import Take"

    filepath: StringProperty(name="Take", subtype="FILE_PATH")

    def run(self, context):
        from .take_io import import_take

        path = _need(_path(self.filepath, _settings(context).take, what="take"), "take (TAKE.c3d)")
        parent = import_take(context, path)
        return f"imported {len(parent.children)} markers from {path.name}"


class MIRRORCAP_OT_add_generic_head(MirrorCapOperator):
    """Add MirrorCap's generic head (regions, landmarks, eyelids, teeth, 52 faceunit shape keys)"""

    bl_idname = "mirrorcap.add_generic_head"
    bl_label = "Add Generic Head"

    def run(self, context):
        from ..core.headio import load_head_npz
        from .headio import GENERIC_HEAD, new_head_object

        if not GENERIC_HEAD.is_file():
            raise InputError(f"the generic head is missing from the add-on ({GENERIC_HEAD})")
        head, keys = load_head_npz(GENERIC_HEAD, with_shape_keys=True)
        obj = new_head_object(head, keys, name="generic_head")
        _settings(context).head_object = obj
        for o in context.view_layer.objects:
            o.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        return f"added {obj.name}: {len(head.vertices)} vertices, {len(keys)} shape keys"


class MIRRORCAP_OT_fit_head(MirrorCapJobOperator):
    """Fit the head to a scan of the subject (landmarks, then RBF scattering onto the surface); adds a fitted copy"""

    bl_idname = "mirrorcap.fit_head"
    bl_label = "Fit Head To Scan"

    head_object: StringProperty(name="Head", description="head object (default: the scene's head, or the active object)")
    scan_file: StringProperty(name="Scan", subtype="FILE_PATH", description="PLY or OBJ in mm (default: the scene's)")
    landmarks: StringProperty(name="Landmarks", subtype="FILE_PATH", description="JSON landmarks of the scan")

    def prepare(self, context):
        from ..core.scanio import read_landmarks, read_scan
        from .headio import read_head

        s = _settings(context)
        obj = _head_object(context, self.head_object)
        head = read_head(obj)
        head.validate()
        V, T = read_scan(_need(_path(self.scan_file, s.scan_file, what="scan"), "scan (PLY or OBJ)"))
        lms = read_landmarks(_need(_path(self.landmarks, s.scan_landmarks, what="landmarks file"), "scan landmarks"))
        self._obj_name = obj.name

        def work(progress):
            from ..core.headfit import fit_head

            progress(0.05, "fitting")
            fit = fit_head(head, V, T, lms)
            progress(1.0, "fitted")
            return head, fit

        return work

    def finish(self, context, result):
        from .headio import replace_head_vertices

        head, fit = result
        src = bpy.data.objects[self._obj_name]
        obj = src.copy()
        obj.data = src.data.copy()
        obj.name = obj.data.name = f"{src.name}_fitted"
        for coll in src.users_collection:
            coll.objects.link(obj)
        replace_head_vertices(obj, head.vertices, fit.vertices)
        obj["mirrorcap_fit"] = json.dumps({"residual_rms_mm": fit.residual_rms_mm, "scale": fit.scale,
                                           "landmark_rms_mm": fit.landmark_rms_mm})
        _settings(context).head_object = obj
        return (f"{obj.name}: residual to the scan {fit.residual_rms_mm:.2f} mm RMS "
                f"(95 % under {fit.residual_p95_mm:.2f} mm), landmarks {fit.landmark_rms_mm:.2f} mm")


class MIRRORCAP_OT_bind(_UnseenMarkers, MirrorCapOperator):
    """Register the take to the head and show which vertex each marker drives (vertex group mirrorcap_bound)"""

    bl_idname = "mirrorcap.bind"
    bl_label = "Bind Markers"

    take: StringProperty(name="Take", subtype="FILE_PATH")
    head_object: StringProperty(name="Head")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)

    def run(self, context):
        from ..core.bind import bind_take
        from ..core.c3d import read_c3d
        from .headio import read_head

        obj = _head_object(context, self.head_object)
        data = read_c3d(_need(_path(self.take, _settings(context).take, what="take"), "take (TAKE.c3d)"))
        head = read_head(obj)
        b = bind_take(head, data["labels"], data["points"], neutral_frame=self.neutral_frame,
                      unseen=self.unseen())
        group = obj.vertex_groups.get("mirrorcap_bound") or obj.vertex_groups.new(name="mirrorcap_bound")
        group.remove(list(range(len(obj.data.vertices))))
        group.add([int(v) for v in b.vertices], 1.0, "REPLACE")
        obj["mirrorcap_binding"] = json.dumps({"labels": b.labels, "vertices": b.vertices.tolist(),
                                               "registration": b.registration, "rms_mm": b.landmark_rms_mm,
                                               "scale": b.scale})
        how = "landmarks " + ", ".join(b.landmarks_used) if b.registration == "landmarks" else "the skin surface"
        return (f"bound {len(b.labels)} markers by {how} ({b.landmark_rms_mm:.2f} mm RMS); "
                f"marker-to-vertex distance max {b.distance_mm.max():.2f} mm")


class MIRRORCAP_OT_bake(_UnseenMarkers, MirrorCapJobOperator):
    """Bake a C3D take onto the head as shape keys (face rig: regions, jaw, inner lip, blinks)"""

    bl_idname = "mirrorcap.bake"
    bl_label = "Bake Take"

    take: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d to bake (default: the scene's)")
    head_object: StringProperty(name="Head", description="head mesh object (default: the scene's head or the active one)")
    mode: EnumProperty(name="Mode", items=BAKE_MODES, default="frames")
    modes: IntProperty(name="Modes", default=8, min=1, max=512, description="number of PCA modes")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)
    head_motion: BoolProperty(name="Head Motion", default=False, description="key the head motion on the object")
    blinks: BoolProperty(name="Blinks", default=True)
    blink_seed: IntProperty(name="Blink Seed", default=0)

    def prepare(self, context):
        from ..core.c3d import read_c3d
        from .headio import read_head

        obj = _head_object(context, self.head_object)
        data = read_c3d(_need(_path(self.take, _settings(context).take, what="take"), "take (TAKE.c3d)"))
        if self.mode == "pca" and self.modes > data["points"].shape[0]:
            raise InputError(f"Modes must be at most the take's {data['points'].shape[0]} frames")
        head = read_head(obj)
        head.validate()
        self._obj_name = obj.name

        def work(progress):
            from ..core.bind import bind_take
            from ..core.facerig import FaceRig, RigSettings

            progress(0.05, "binding")
            binding = bind_take(head, data["labels"], data["points"], neutral_frame=self.neutral_frame,
                                unseen=self.unseen())
            progress(0.2, "face rig")
            rig = FaceRig(head, binding.vertices, RigSettings(blinks=self.blinks, blink_seed=self.blink_seed))
            D = rig.deform(binding.displacements, fps=data["rate"])
            progress(0.9, "face rig")
            return head, binding, D, data["rate"]

        return work

    def finish(self, context, result):
        from .bake import bake_displacements

        head, binding, D, rate = result
        obj = bpy.data.objects[self._obj_name]
        out = bake_displacements(obj, head.vertices, D, self.mode, self.modes,
                                 head_motion=binding.head_motion if self.head_motion else None)
        context.scene.render.fps = max(1, int(round(rate)))
        context.scene.frame_start, context.scene.frame_end = 1, out["frames"]
        extra = f", PCA max error {out['pca_max_error_mm']:.3f} mm" if self.mode == "pca" else ""
        return f"baked {out['frames']} frames onto {obj.name}{extra}"


CAPTURE_OPERATORS = (MIRRORCAP_OT_open_clip, MIRRORCAP_OT_calibrate_camera, MIRRORCAP_OT_detect_markers,
                     MIRRORCAP_OT_solve_mirrors, MIRRORCAP_OT_rigid_from_tracks, MIRRORCAP_OT_track,
                     MIRRORCAP_OT_track_clip_tracks)
ANIMATION_OPERATORS = (MIRRORCAP_OT_import_take, MIRRORCAP_OT_add_generic_head, MIRRORCAP_OT_fit_head,
                       MIRRORCAP_OT_bind, MIRRORCAP_OT_bake)
CLASSES = CAPTURE_OPERATORS + ANIMATION_OPERATORS
