"""Retarget (3D View): the scene's take onto a character.

The actor is the scene's head (the generic head or the fitted one, carrying the ARKit shape
keys). ``arkit``: the character is any mesh with ARKit-named shape keys, keyed with the solved
weights. ``transfer``: the character is any mesh with ``lm_<name>`` landmarks (Place Landmarks,
Guess the Rest); the motion itself is carried onto it as frame or PCA keys. The work runs as a
modal job (pure core, no ``bpy``); the character changes only once it succeeded."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty, FloatProperty, IntProperty, StringProperty

from ...core.common.errors import InputError
from ..common.inputs import head_object_from, input_path, required, scene_marker_map, scene_settings
from ..common.jobs import MirrorCapJobOperator
from ..common.keys import TakeStretch, set_scene_rate
from ..common.properties import BAKE_MODES, RETARGET_METHODS


class MIRRORCAP_OT_retarget(TakeStretch, MirrorCapJobOperator):
    """Retarget the take onto the character: ARKit-52 weights on its shape keys, or the motion itself
(transfer) onto a character with landmarks"""

    bl_idname = "mirrorcap.retarget"
    bl_label = "Retarget Take"

    method: EnumProperty(name="Method", items=(("SCENE", "Scene", "the Retarget panel's method"),) + RETARGET_METHODS,
                         default="SCENE")
    mode: EnumProperty(name="Keys", items=(("SCENE", "Scene", "the Bake panel's mode"),) + BAKE_MODES,
                       default="SCENE", description="transfer: frame keys or PCA keys")

    take: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d (default: the scene's)")
    head_object: StringProperty(name="Actor", description="the actor's head with ARKit shape keys (default: the scene's head)")
    target_object: StringProperty(name="Character", description="the character's mesh (default: the scene's)")
    csv: StringProperty(name="Live Link CSV", subtype="FILE_PATH", description="LIVELINK.csv to write (optional)")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)
    smoothness: FloatProperty(name="Smoothness", default=8.0, min=0.0, description="temporal smoothness lambda, mm^2")

    def prepare(self, context):
        from ...core.take.c3d import read_c3d
        from ..common.headio import read_head, read_shape_keys

        s = scene_settings(context)
        actor = head_object_from(context, self.head_object)
        target = bpy.data.objects.get(self.target_object) if self.target_object else s.retarget_target
        if target is None or target.type != "MESH":
            raise InputError("choose the character (a mesh with ARKit shape keys, or with landmarks) first")
        if target == actor:
            raise InputError("the character is the actor's head itself: choose another mesh")
        self._method = s.retarget_method if self.method == "SCENE" else self.method
        if self._method == "transfer":
            return self._prepare_transfer(context, s, actor, target)
        if target.data.shape_keys is None:
            raise InputError(f"{target.name} has no shape keys")
        csv = input_path(self.csv or s.livelink_csv, must_exist=False)
        if csv is not None and not csv.parent.is_dir():
            raise InputError(f"the CSV's folder {csv.parent} does not exist (save the .blend first for // paths)")
        data = read_c3d(required(input_path(self.take, s.take, what="take"), "take (TAKE.c3d)"))
        frames = self.stretch(data["points"].shape[0])
        head = read_head(actor)
        head.validate()
        keys = read_shape_keys(actor)
        mapping = scene_marker_map(context)
        self._target, self._csv, self._rate = target.name, csv, data["rate"]

        def work(progress):
            from ...core.retarget.arkit import retarget_take

            progress(0.1, "binding and solving the ARKit weights")
            # markers first seen after the neutral frame: placed from their neighbours, as Bake does
            _, solve, angles = retarget_take(head, keys, data["labels"], data["points"],
                                             neutral_frame=self.neutral_frame, marker_map=mapping,
                                             unseen="conjecture", smoothness=self.smoothness)
            progress(0.95, "keying")
            return solve.frames(*frames), angles[frames[0]:frames[1]]   # the stretch keyed

        return work

    def _prepare_transfer(self, context, s, actor, target):
        from ...core.retarget.transfer import check_landmarks
        from ...core.take.c3d import read_c3d
        from ..common.headio import read_head, read_shape_keys
        from ..common.shape_keys import check_keying

        data = read_c3d(required(input_path(self.take, s.take, what="take"), "take (TAKE.c3d)"))
        frames = self.stretch(data["points"].shape[0])
        head = read_head(actor)
        head.validate()
        keys = read_shape_keys(actor)
        character = read_head(target)
        check_landmarks(character, "character")
        mapping = scene_marker_map(context)
        self._target, self._rate = target.name, data["rate"]
        self._mode, self._modes = (s.bake_mode if self.mode == "SCENE" else self.mode), s.modes
        check_keying(self._mode, self._modes, frames[1] - frames[0], modes_option="Modes")

        def work(progress):
            from ...core.retarget.transfer import transfer_take

            tr = transfer_take(head, keys, character, data["labels"], data["points"], data["rate"],
                               neutral_frame=self.neutral_frame, marker_map=mapping, unseen="conjecture",
                               progress=lambda f, text: progress(0.9 * f, text), frames=frames)
            progress(0.95, "keying")
            return character, tr

        return work

    def _finish_transfer(self, context, result):
        from ..common.shape_keys import bake_displacements

        character, tr = result
        target = bpy.data.objects[self._target]
        out = bake_displacements(target, character.vertices, tr.displacements, self._mode, self._modes,
                                 frame_start=context.scene.frame_start)
        set_scene_rate(context.scene, self._rate)
        sc = tr.scales
        return (f"transferred {out['frames']} frames onto {target.name} ({self._mode} keys); scales upper "
                f"{'/'.join(f'{v:.2f}' for v in sc['upper'])}, lower {'/'.join(f'{v:.2f}' for v in sc['lower'])}")

    def finish(self, context, result):
        from ...core.common.files import write_files_atomically
        from ...core.retarget.livelink import livelink_csv
        from .retarget import key_weights

        if self._method == "transfer":
            return self._finish_transfer(context, result)
        solve, angles = result
        target = bpy.data.objects[self._target]
        text = livelink_csv(solve.weights, solve.names, self._rate, head=angles) if self._csv else None
        keyed = key_weights(target, solve.names, solve.weights, context.scene.frame_start)
        F = solve.weights.shape[0]
        set_scene_rate(context.scene, self._rate)
        if text is not None:
            write_files_atomically({self._csv: text})
        if keyed["missing"]:
            self.report({"WARNING"}, f"{target.name} lacks {len(keyed['missing'])} ARKit shapes (skipped): "
                                     + ", ".join(keyed["missing"]))
        return (f"retargeted {F} frames onto {target.name}: {len(keyed['keyed'])} shapes keyed, "
                f"fit residual {float((solve.residual_mm ** 2).mean() ** 0.5):.3f} mm RMS")


class MIRRORCAP_OT_export_faps(MirrorCapJobOperator):
    """Measure the take's MPEG-4 facial animation parameters on the head and write them as a .fap file"""

    bl_idname = "mirrorcap.export_faps"
    bl_label = "Export FAPs"

    take: StringProperty(name="Take", subtype="FILE_PATH", description="TAKE.c3d (default: the scene's)")
    head_object: StringProperty(name="Head", description="the head mesh (default: the scene's head)")
    fap: StringProperty(name="FAP File", subtype="FILE_PATH", description="TAKE.fap to write (default: the scene's)")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)

    def prepare(self, context):
        from ...core.take.c3d import read_c3d
        from ..common.headio import head_feature_points, read_head

        s = scene_settings(context)
        obj = head_object_from(context, self.head_object)
        out = required(input_path(self.fap or s.fap_file, must_exist=False), "FAP file to write (TAKE.fap)")
        if not out.parent.is_dir():
            raise InputError(f"the FAP file's folder {out.parent} does not exist (save the .blend first for // paths)")
        take = required(input_path(self.take, s.take, what="take"), "take (TAKE.c3d)")
        data = read_c3d(take)
        head = read_head(obj)
        head.validate()
        points = head_feature_points(obj, head)
        mapping = scene_marker_map(context)
        self._out = out

        def work(progress):
            from ...core.retarget.mpeg4 import fap_text, take_faps

            # markers first seen after the neutral frame: placed from their neighbours, as Bake does
            _, track = take_faps(head, data["labels"], data["points"], data["rate"], feature=points,
                                 neutral_frame=self.neutral_frame, unseen="conjecture", marker_map=mapping,
                                 name=take.stem, progress=progress)
            return track, fap_text(track)

        return work

    def finish(self, context, result):
        from ...core.common.files import write_files_atomically

        track, text = result
        write_files_atomically({self._out: text})
        return f"{int(track.mask.sum())} FAPs over {track.frames} frames -> {self._out.name}"


from .landmarks import OPERATORS as LANDMARK_OPERATORS  # noqa: E402

OPERATORS = (MIRRORCAP_OT_retarget, MIRRORCAP_OT_export_faps) + LANDMARK_OPERATORS
