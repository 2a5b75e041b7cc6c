"""Bind and bake (3D View): register a take to the head and bake the face rig as shape keys.

Operators (``bpy.ops.mirrorcap.*``); all inputs are operator properties, an empty one falls back
to the scene's settings. Long ones are modal jobs (:class:`..common.jobs.MirrorCapJobOperator`)."""

from __future__ import annotations

import json

import bpy
from bpy.props import BoolProperty, EnumProperty, IntProperty, StringProperty

from ...core.common.errors import InputError
from ..common.inputs import (head_object_from, input_path, required, scene_marker_map, scene_settings,
                             selected_marker_labels)
from ..common.jobs import MirrorCapJobOperator, MirrorCapOperator
from ..common.keys import TakeStretch, set_scene_rate
from ..common.properties import BAKE_MODES


MAP_ROLES = [("AUTO", "Auto", "the landmark if one is chosen, else the head's selected vertex"),
             ("VERTEX", "Selected Vertex", "the one vertex selected on the head (Edit Mode)"),
             ("LANDMARK", "Landmark", "a landmark vertex group (lm_<name>) of the head"),
             ("RIGID", "Rigid", "a marker on a rigid part (headband): it carries the head motion, not bound"),
             ("IGNORE", "Ignore", "left out of the bind"),
             ("REMOVE", "Remove", "take the marker out of the map")]


def _landmark_items(self, context):
    obj = context.scene.mirrorcap.head_object if context and context.scene else None
    names = sorted(g.name for g in obj.vertex_groups if g.name.startswith("lm_")) if obj is not None else []
    return [("NONE", "(none)", "")] + [(n, n, "") for n in names]


class MIRRORCAP_OT_map_marker(MirrorCapOperator):
    """Put the selected marker empty in the marker map: on the head's selected vertex, on a landmark, rigid or ignored"""

    bl_idname = "mirrorcap.map_marker"
    bl_label = "Map Marker"

    label: StringProperty(name="Label", description="the marker's label (default: the selected marker empty's)")
    role: EnumProperty(name="Role", items=MAP_ROLES, default="AUTO")
    landmark: EnumProperty(name="Landmark", items=_landmark_items)
    vertex: IntProperty(name="Vertex", default=-1, min=-1, description="-1: the head's one selected vertex")
    head_object: StringProperty(name="Head", description="head mesh object (default: the scene's head or the active one)")

    def run(self, context):
        from pathlib import Path

        from ...core.common.files import read_json, write_files_atomically

        s = scene_settings(context)
        path = required(input_path(s.marker_map, must_exist=False), "marker map file (MAP.json)")
        if not Path(path).parent.is_dir():
            raise InputError(f"the marker map's folder {path.parent} does not exist (save the .blend first for // paths)")
        labels = [self.label] if self.label else selected_marker_labels(context)
        if len(labels) != 1:
            raise InputError(f"select one marker empty (an imported take's) or give its label; {len(labels)} selected")
        label = labels[0]
        role = self.role
        if role == "AUTO":
            role = "LANDMARK" if self.landmark not in ("", "NONE") else "VERTEX"
        mapping = read_json(path, "marker map") if Path(path).exists() else {}
        if not isinstance(mapping, dict):
            raise InputError(f"{path} is not a marker map (a JSON object)")
        if role == "REMOVE":
            mapping.pop(label, None)
            value = "removed"
        elif role in ("RIGID", "IGNORE"):
            value = mapping[label] = role.lower()
        elif role == "LANDMARK":
            if self.landmark in ("", "NONE"):
                raise InputError("choose a landmark (the head's lm_<name> vertex groups)")
            value = mapping[label] = self.landmark
        else:
            value = mapping[label] = self._selected_vertex(context)
        taken = [k for k, v in mapping.items() if k != label and v == value and v not in ("rigid", "ignore")]
        if taken:
            raise InputError(f"{value} is already {taken[0]}'s: one marker per vertex")
        write_files_atomically({path: json.dumps(mapping, indent=1, sort_keys=True) + "\n"})
        return f"{label}: {value} ({len(mapping)} markers in {path.name})"

    def _selected_vertex(self, context) -> int:
        import numpy as np

        obj = head_object_from(context, self.head_object)
        if self.vertex >= 0:
            if self.vertex >= len(obj.data.vertices):
                raise InputError(f"{obj.name} has {len(obj.data.vertices)} vertices; vertex {self.vertex} is not one")
            return int(self.vertex)
        if obj.mode == "EDIT":
            obj.update_from_editmode()
        sel = np.zeros(len(obj.data.vertices), bool)
        obj.data.vertices.foreach_get("select", sel)
        if sel.sum() != 1:
            raise InputError(f"select exactly one vertex of {obj.name} (Edit Mode); {int(sel.sum())} selected")
        return int(np.flatnonzero(sel)[0])


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
        from ...core.face.animate import unseen_policy

        return unseen_policy(self.drop_unseen, self.conjecture_unseen)


class MIRRORCAP_OT_bind(_UnseenMarkers, MirrorCapOperator):
    """Register the take to the head and show which vertex each marker drives (vertex group mirrorcap_bound)"""

    bl_idname = "mirrorcap.bind"
    bl_label = "Bind Markers"

    take: StringProperty(name="Take", subtype="FILE_PATH")
    head_object: StringProperty(name="Head")
    neutral_frame: IntProperty(name="Neutral Frame", default=0, min=0)

    def run(self, context):
        from ...core.face.bind import bind_take
        from ...core.take.c3d import read_c3d
        from ..common.headio import read_head

        obj = head_object_from(context, self.head_object)
        data = read_c3d(required(input_path(self.take, scene_settings(context).take, what="take"), "take (TAKE.c3d)"))
        head = read_head(obj)
        b = bind_take(head, data["labels"], data["points"], neutral_frame=self.neutral_frame,
                      unseen=self.unseen(), marker_map=scene_marker_map(context))
        group = obj.vertex_groups.get("mirrorcap_bound") or obj.vertex_groups.new(name="mirrorcap_bound")
        group.remove(list(range(len(obj.data.vertices))))
        group.add([int(v) for v in b.vertices], 1.0, "REPLACE")
        obj["mirrorcap_binding"] = json.dumps({"labels": b.labels, "vertices": b.vertices.tolist(),
                                               "registration": b.registration, "rms_mm": b.landmark_rms_mm,
                                               "scale": b.scale})
        how = "landmarks " + ", ".join(b.landmarks_used) if b.registration == "landmarks" else "the skin surface"
        return (f"bound {len(b.labels)} markers by {how} ({b.landmark_rms_mm:.2f} mm RMS); "
                f"marker-to-vertex distance max {b.distance_mm.max():.2f} mm")


class MIRRORCAP_OT_bake(_UnseenMarkers, TakeStretch, MirrorCapJobOperator):
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
    fap: StringProperty(name="FAP File", subtype="FILE_PATH",
                        description="an MPEG-4 .fap file to play on the head instead of the take")

    def prepare(self, context):
        from ...core.take.c3d import read_c3d
        from ..common.headio import read_head

        obj = head_object_from(context, self.head_object)
        head = read_head(obj)
        head.validate()
        pose = None
        if self.fap:
            from ...core.retarget.mpeg4 import read_fap
            from .bake import fap_as_take

            track = read_fap(required(input_path(self.fap, what="FAP file"), "FAP file"))
            data, mapping, pose = fap_as_take(track, obj, head)
        else:
            data = read_c3d(required(input_path(self.take, scene_settings(context).take, what="take"),
                                     "take (TAKE.c3d)"))
            mapping = scene_marker_map(context)
        from ..common.shape_keys import check_keying

        frames = self.stretch(data["points"].shape[0])
        check_keying(self.mode, self.modes, frames[1] - frames[0], modes_option="Modes")
        self._obj_name = obj.name

        def work(progress):
            from ...core.face.animate import animate_take
            from ...core.face.facerig import RigSettings

            anim = animate_take(head, data["labels"], data["points"], data["rate"], neutral_frame=self.neutral_frame,
                                head_pose=pose, unseen=self.unseen(),
                                settings=RigSettings(blinks=self.blinks, blink_seed=self.blink_seed, blink_interval_s=None),
                                progress=lambda f, text: progress(0.3 * f, text), marker_map=mapping, frames=frames)
            # the face rig's work, here where it can be cancelled
            anim.deform_all(lambda f: progress(0.3 + 0.65 * f, "face rig"))
            return head, anim

        return work

    def finish(self, context, result):
        from ..common.shape_keys import bake_displacements

        head, anim = result
        obj = bpy.data.objects[self._obj_name]
        out = bake_displacements(obj, head.vertices, anim.displacements, self.mode, self.modes,
                                 frame_start=context.scene.frame_start,
                                 head_motion=anim.head_motion if self.head_motion else None)
        set_scene_rate(context.scene, anim.rate)
        extra = f", PCA max error {out['pca_max_error_mm']:.3f} mm" if self.mode == "pca" else ""
        return f"baked {out['frames']} frames onto {obj.name}{extra}"


OPERATORS = (MIRRORCAP_OT_bind, MIRRORCAP_OT_bake, MIRRORCAP_OT_map_marker)
