"""Track (Movie Clip Editor) and the take (3D View): the rigid markers, tracking a rig video or the clip's own tracks to a C3D take, importing a take as empties.

Operators (``bpy.ops.mirrorcap.*``); all inputs are operator properties, an empty one falls back
to the scene's settings. Long ones are modal jobs (:class:`..common.jobs.MirrorCapJobOperator`)."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ...core.common.errors import InputError
from ..common.inputs import (extraction_settings, input_path, required, rig_and_colours, rigid_from_settings,
                             scene_settings, selected_marker_labels, take_report_path)
from ..common.jobs import MirrorCapJobOperator, MirrorCapOperator


class MIRRORCAP_OT_rigid_from_tracks(MirrorCapOperator):
    """Set the rigid region (the markers that carry the head pose) to the box around the clip's selected tracks"""

    bl_idname = "mirrorcap.rigid_from_tracks"
    bl_label = "Rigid From Selected Tracks"

    frame: IntProperty(name="Frame", default=-1, min=-1, description="video frame (0-based); -1: the scene's current")
    margin_px: IntProperty(name="Margin", default=6, min=0, description="pixels added around the tracks")

    def run(self, context):
        from ..common.clip import find_clip, selected_track_pixels

        s = scene_settings(context)
        clip = find_clip(required(input_path(s.video, what="rig video"), "rig video"))
        n = context.scene.frame_current - 1 if self.frame < 0 else self.frame
        xy = selected_track_pixels(clip, n)
        if len(xy) < 4:
            raise InputError(f"select at least 4 direct-view tracks at frame {n} (forehead, nose bridge); "
                             f"{len(xy)} selected")
        lo = np.maximum(np.floor(xy.min(axis=0)) - self.margin_px, 0)
        hi = np.minimum(np.ceil(xy.max(axis=0)) + self.margin_px + 1, clip.size)
        s.rigid_region = (int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1]))
        return f"rigid region {tuple(s.rigid_region)} around {len(xy)} tracks"


class _TrackInputs:
    """Properties shared by the two track operators."""

    take: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d to write (default: the scene's)")
    import_result: BoolProperty(name="Import Take", default=True, description="add the take to the scene as empties")

    def _common(self, context):
        from ...core.capture.boardcal import load_mirrors
        from ...core.geometry.camera import Camera

        s = scene_settings(context)
        camera = Camera.load(required(input_path(s.camera, what="camera file"), "camera file (CAMERA.json)"))
        mirrors = load_mirrors(input_path(s.mirrors, what="mirrors file")) if s.mirrors else None
        take = required(input_path(self.take, s.take, must_exist=False), "take file")
        if not take.parent.is_dir():
            raise InputError(f"the take's folder {take.parent} does not exist (save the .blend first for // paths)")
        return s, camera, mirrors, take

    def _finish_track(self, context, result):
        take, report = result
        scene_settings(context).take = str(take)
        if self.import_result:
            from ..common.take_io import import_take

            import_take(context, take)
        pf = report["per_frame"]  # the run's warnings (undecided markers, ...) follow from the message log
        repaired, doubted, merged = (int(np.sum(pf.get(key, 0))) for key in ("repaired", "doubted", "merged_images"))
        return (f"{report['markers']['count']} markers over {report['frames']['count']} frames -> {take.name}; "
                f"{np.mean(pf['measured']):.1f} measured, {np.mean(pf['conjectured']):.1f} conjectured per frame"
                + (f"; {repaired} one-mirror measurements re-paired, {doubted} left to the gap fill"
                   if repaired or doubted else "")
                + (f" ({merged} through one blob of two dots' images)" if merged else ""))


class MIRRORCAP_OT_track(_TrackInputs, MirrorCapJobOperator):
    """Track the rig video: markers, mirror planes, 3D trajectories with head motion, written as a C3D take"""

    bl_idname = "mirrorcap.track"
    bl_label = "Track"

    video: StringProperty(name="Video", subtype="FILE_PATH", description="rig video (default: the scene's)")

    def prepare(self, context):
        from ...core.capture.video import open_source

        s, camera, mirrors, take = self._common(context)
        source = open_source(required(input_path(self.video, s.video, what="rig video"), "rig video"))
        rig, colors, light, _ = rig_and_colours(s, source, s.frame_start)
        layout = rig.views
        rigid, rigid_source = rigid_from_settings(s, rig, colors)
        seeds = None
        if s.seeds:
            from ...core.track.seeds import read_seeds

            seeds = read_seeds(input_path(s.seeds, what="seeds file"), camera.image_size)
        log = self.messages
        end = s.frame_end or None
        n = len(range(s.frame_start, min(end or source.frame_count, source.frame_count)))

        def work(progress):
            from ...core.track.pipeline import run_track
            from ...core.track.tracker import TrackSettings

            report = run_track(source, camera, take, report=take_report_path(take), colors=colors,
                               extraction=extraction_settings(s, light), layout=layout,
                               mirrors=mirrors, start=s.frame_start, end=end,
                               settings=TrackSettings.with_conjecture_limit(s.conjecture_limit_mm),
                               rigid=rigid, rigid_source=rigid_source, log=log, seeds=seeds,
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
        from ...core.capture.video import open_source
        from ..common.clip import clip_tracks_to_detections, find_clip

        s, camera, mirrors, take = self._common(context)
        clip = bpy.data.movieclips.get(self.clip) if self.clip else find_clip(input_path(s.video, what="rig video"))
        if clip is None:
            raise InputError("open the rig video as a clip first")
        if tuple(clip.size) != tuple(camera.image_size):
            raise InputError(f"the camera file is for {camera.image_size[0]}x{camera.image_size[1]} images but the "
                             f"clip is {clip.size[0]}x{clip.size[1]}")
        video = input_path(s.video, what="rig video")          # Light at Auto: its first frame says
        rig, colors, _, _ = rig_and_colours(s, open_source(video) if video else None)
        layout = rig.views
        rigid, rigid_source = rigid_from_settings(s, rig, colors)
        numbers, frames = clip_tracks_to_detections(clip, layout, self.tracking_object or None)
        log = self.messages
        fps = float(clip.fps) or 30.0

        def work(progress):
            from ...core.track.pipeline import track_detections
            from ...core.track.tracker import TrackSettings

            report = track_detections(numbers, frames, camera, fps, take, report=take_report_path(take),
                                      mirrors=mirrors, progress=progress.stage(0.0, 1.0, "tracking"),
                                      settings=TrackSettings.with_conjecture_limit(s.conjecture_limit_mm),
                                      timings={"detect": 0.0}, rigid=rigid, rigid_source=rigid_source,
                                      log=log)
            return take, report

        return work

    def finish(self, context, result):
        return self._finish_track(context, result)


class MIRRORCAP_OT_import_take(MirrorCapOperator):
    """Add a C3D take to the scene as animated empties (one per marker) under one parent"""

    bl_idname = "mirrorcap.import_take"
    bl_label = "Import Take"

    filepath: StringProperty(name="Take", subtype="FILE_PATH")

    def run(self, context):
        from ..common.take_io import import_take

        path = required(input_path(self.filepath, scene_settings(context).take, what="take"), "take (TAKE.c3d)")
        parent = import_take(context, path)
        return f"imported {len(parent.children)} markers from {path.name}"


STABILIZE_METHODS = [("invariants", "Invariants", "eq. 1-3 of Huang, Lin & Ouhyoung 2000 from three rigid markers"),
                     ("arun", "Arun", "SVD fit of every rigid marker")]
PIVOT_MODES = [("auto", "Auto", "estimate the rotation pivot (eq. 4-8)"), ("none", "None", "no pivot")]


class MIRRORCAP_OT_stabilize_take(MirrorCapOperator):
    """Remove the head motion from a C3D take (any system's): rigid markers, rotation pivot, every marker in the head frame of the first frame"""

    bl_idname = "mirrorcap.stabilize_take"
    bl_label = "Stabilize Take"

    filepath: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d (default: the scene's)")
    output: StringProperty(name="Output", subtype="FILE_PATH", description="OUT.c3d (default: the scene's)")
    rigid: StringProperty(name="Rigid Labels", description="space-separated; default: the scene's, the selected "
                                                           "marker empties, or automatic")
    method: EnumProperty(name="Method", items=STABILIZE_METHODS, default="invariants")
    pivot: EnumProperty(name="Pivot", items=PIVOT_MODES, default="auto")
    smooth_s: FloatProperty(name="Smoothing (s)", default=0.2, min=0.0, soft_max=1.0,
                            description="head pose smoothed by a local quadratic over this window (0: none)")
    import_result: BoolProperty(name="Import", default=True, description="add the stabilised take and its pivot")

    def run(self, context):
        from ...core.take.stabilize import stabilize_file
        from ..common.take_io import import_take

        s = scene_settings(context)
        src = required(input_path(self.filepath, s.take, what="take"), "take (TAKE.c3d)")
        out = required(input_path(self.output, s.stable_take, must_exist=False), "output take (OUT.c3d)")
        if not out.parent.is_dir():
            raise InputError(f"the output's folder {out.parent} does not exist (save the .blend first for // paths)")
        labels = (self.rigid or s.rigid_labels).replace(",", " ").split() or selected_marker_labels(context) or None
        take, st, _ = stabilize_file(src, out, out.with_suffix(".json"), rigid=labels, method=self.method,
                                     pivot="auto" if self.pivot == "auto" else None, smooth_s=self.smooth_s)
        if self.import_result:
            stable = dict(take, points=st.points, gaps=~np.all(np.isfinite(st.points), axis=2))
            parent = import_take(context, out, data=stable)
            if st.pivot_mm is not None:
                from ..common.frames import core_to_blender

                pivot = bpy.data.objects.new(f"{parent.name} pivot", None)
                pivot.empty_display_type = "PLAIN_AXES"
                pivot.empty_display_size = 0.03
                pivot.parent = parent
                pivot.location = (core_to_blender(st.pivot_mm) if take["frame"] == "camera" else 0.001 * st.pivot_mm)
                pivot["mirrorcap_pivot_mm"] = [float(v) for v in st.pivot_mm]
                parent.users_collection[0].objects.link(pivot)
        where = "no pivot" if st.pivot_mm is None else f"pivot {st.pivot_status}"
        for text in st.warnings:
            self.report({"WARNING"}, text)
        return (f"stabilised {len(st.labels)} markers by {st.method} from {', '.join(st.rigid)} ({where}) "
                f"-> {out.name}")


def _take_clip(s, camera):
    from ..common.clip import find_clip

    clip = find_clip(input_path(s.video, what="rig video"))
    if clip is None:
        raise InputError("choose the rig video (the Capture panel's Video) first")
    if tuple(clip.size) != tuple(camera.image_size):
        raise InputError(f"the camera file is for {camera.image_size[0]}x{camera.image_size[1]} images but the clip "
                         f"is {clip.size[0]}x{clip.size[1]}")
    return clip


def _camera(s):
    from ...core.geometry.camera import Camera

    return Camera.load(required(input_path(s.camera, what="camera file"), "camera file (CAMERA.json)"))


class MIRRORCAP_OT_take_to_clip(MirrorCapOperator):
    """Write the take's markers as 2D tracks of the clip (<label>.<view>), to fix with Blender's own tracking tools before Re-solve"""

    bl_idname = "mirrorcap.take_to_clip"
    bl_label = "Take To Clip"

    def run(self, context):
        from ...core.common.files import read_json
        from ...core.take.c3d import read_c3d
        from ..common.clip import take_to_clip_tracks

        s = scene_settings(context)
        camera = _camera(s)
        take = required(input_path(s.take, what="take"), "take (TAKE.c3d)")
        report = read_json(required(input_path(str(take_report_path(take)), what="take report"), "take report"),
                           "take report")
        data = read_c3d(take)
        clip = _take_clip(s, camera)
        measured = ~np.asarray(data["conjectured"], bool)
        n = take_to_clip_tracks(clip, data["labels"], data["points"], report["mirrors"], camera,
                                first_frame=int(report["frames"]["first"]), measured=measured,
                                step=int(report["frames"].get("step", 1)))
        return (f"{n} tracks in the clip's 'MirrorCap Take' object: fix them with Blender's tracking tools "
                "(rename a track <label>.<view> to give it a name), then Re-solve")


class MIRRORCAP_OT_resolve(MirrorCapJobOperator):
    """Re-estimate the mirrors from the clip's take tracks (your fixes included) and recompute every marker's 3D trajectory into the take"""

    bl_idname = "mirrorcap.resolve"
    bl_label = "Re-solve"

    threshold_px: FloatProperty(name="Threshold (px)", default=2.0, min=0.1,
                                description="epipolar distance within which a correspondence counts as one dot")
    import_result: BoolProperty(name="Import Take", default=True, description="add the re-solved take as empties")

    def prepare(self, context):
        from ...core.common.files import read_json
        from ...core.take.c3d import read_c3d
        from ..common.clip import clip_tracks_to_take_tracks

        s = scene_settings(context)
        camera = _camera(s)
        take = required(input_path(s.take, what="take"), "take (TAKE.c3d)")
        report_path = take_report_path(take)
        report = read_json(required(input_path(str(report_path), what="take report"), "take report"), "take report")
        rate = float(read_c3d(take)["rate"])
        clip = _take_clip(s, camera)
        first, count = int(report["frames"]["first"]), int(report["frames"]["count"])
        labels, tracks = clip_tracks_to_take_tracks(clip, count, first, int(report["frames"].get("step", 1)))
        units = "mm" if report.get("units") == "mm" else "rel"
        self._take = take

        def work(progress):
            import json

            from ...core.common.files import write_files_atomically
            from ...core.take.c3d import c3d_bytes
            from ...core.track.resolve import resolve_tracks

            progress(0.1, "re-estimating the mirrors")
            res = resolve_tracks(labels, tracks, camera, report.get("mirrors"), self.threshold_px)
            progress(0.9, "writing the take")
            kept = np.flatnonzero(np.isfinite(res.points[..., 0]).any(axis=0))    # a deleted track: no marker
            if kept.size == 0:
                raise InputError("no marker could be reconstructed from the clip's take tracks")
            names = [labels[i] for i in kept]
            res.report["markers_without_a_frame"] = [labels[i] for i in np.setdiff1d(np.arange(len(labels)), kept)]
            new = {**{k: v for k, v in report.items() if k not in ("head_pose", "per_frame", "mirror_agreement")},
                   "mirrors": res.report["mirrors"], "markers": {"count": len(names), "labels": names},
                   "resolve": res.report}
            write_files_atomically({take: c3d_bytes(names, res.points[:, kept], rate, units=units),
                                    report_path: json.dumps(new, indent=1) + "\n"})
            return res

        return work

    def finish(self, context, res):
        if self.import_result:
            from ..common.take_io import import_take

            import_take(context, self._take)
        r = res.report
        change = ", ".join(f"{c:.3f}" for c in r.get("mirror_change_deg", []))
        return (f"re-solved {r['reconstructed']} of {r['correspondences']} marker-frames "
                f"({r['rejected_correspondences']} correspondences not one dot, left out); mirrors moved "
                f"{change or '-'} deg -> {self._take.name}")


OPERATORS = (MIRRORCAP_OT_rigid_from_tracks, MIRRORCAP_OT_track, MIRRORCAP_OT_track_clip_tracks, MIRRORCAP_OT_import_take,
             MIRRORCAP_OT_stabilize_take, MIRRORCAP_OT_take_to_clip, MIRRORCAP_OT_resolve)
