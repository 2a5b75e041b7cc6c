"""Landmarks on a character (motion transfer's correspondence): placed by clicking, prompted in
order, or guessed from a few by fitting the generic head (:func:`core.retarget.transfer.guess_landmarks`).

A landmark is a vertex group ``lm_<name>`` holding one vertex at weight 1, as on MirrorCap's heads.
"""

from __future__ import annotations

import bpy
from bpy.props import IntProperty, StringProperty

from ...core.common.errors import InputError
from ...core.retarget.transfer import TRANSFER_LANDMARKS
from ..common.inputs import scene_settings
from ..common.jobs import MirrorCapOperator

#: the order Place Landmarks asks for them (the optional lower lip last)
LANDMARK_ORDER = TRANSFER_LANDMARKS + ("lower_lip",)
#: events Place Landmarks leaves to the 3D View (navigation between clicks)
NAVIGATION = {"MIDDLEMOUSE", "WHEELUPMOUSE", "WHEELDOWNMOUSE", "MOUSEMOVE", "INBETWEEN_MOUSEMOVE", "TRACKPADPAN",
              "TRACKPADZOOM", "MOUSEROTATE"}


def placed_landmarks(obj) -> set:
    """The landmark names the object has groups for (``lm_<name>``; Retarget checks each holds a vertex)."""
    if obj is None or obj.type != "MESH":
        return set()
    return {vg.name[3:] for vg in obj.vertex_groups if vg.name.startswith("lm_")}


def next_landmark(placed) -> str | None:
    return next((n for n in LANDMARK_ORDER if n not in placed), None)


def set_landmarks(obj, landmarks: dict) -> None:
    """Write ``{name: vertex}`` as ``lm_<name>`` groups (each replacing any earlier one)."""
    n = len(obj.data.vertices)
    for name, vertex in landmarks.items():
        if not 0 <= int(vertex) < n:
            raise InputError(f"vertex {vertex} is not on {obj.name} ({n} vertices)")
        old = obj.vertex_groups.get(f"lm_{name}")
        if old is not None:
            obj.vertex_groups.remove(old)
        obj.vertex_groups.new(name=f"lm_{name}").add([int(vertex)], 1.0, "REPLACE")


def vertex_under_ray(obj, origin, direction):
    """The vertex of ``obj`` nearest where a world-space ray first hits it, or None."""
    M = obj.matrix_world.inverted()
    o = M @ origin
    d = (M.to_3x3() @ direction).normalized()
    hit, location, _normal, face = obj.ray_cast(o, d)
    if not hit:
        return None
    poly = obj.data.polygons[face]
    return min(poly.vertices, key=lambda i: (obj.data.vertices[i].co - location).length)


def _target(context):
    obj = scene_settings(context).retarget_target
    if obj is None or obj.type != "MESH":
        raise InputError("choose the character (a mesh) in the Retarget panel first")
    return obj


class MIRRORCAP_OT_place_landmarks(MirrorCapOperator):
    """Click the character's landmarks in the order the header asks for them (Backspace: undo, Enter: done,
    Esc: cancel); from a script, give a vertex for the next landmark (or a named one)"""

    bl_idname = "mirrorcap.place_landmarks"
    bl_label = "Place Landmarks"

    vertex: IntProperty(name="Vertex", default=-1, min=-1, options={"SKIP_SAVE"},
                        description="scripts: the vertex for the landmark (default: the next one unplaced)")
    landmark: StringProperty(name="Landmark", default="", options={"SKIP_SAVE"},
                             description="scripts: which landmark (default: the next one unplaced)")

    def run(self, context):
        obj = _target(context)
        if self.vertex < 0:
            raise InputError("give a vertex (scripts), or run Place Landmarks from the 3D View and click")
        placed = placed_landmarks(obj)
        name = self.landmark or next_landmark(placed)
        if name is None:
            raise InputError(f"{obj.name} has every landmark; name one to move it")
        if name not in LANDMARK_ORDER:
            raise InputError(f"unknown landmark {name!r} (one of {', '.join(LANDMARK_ORDER)})")
        set_landmarks(obj, {name: self.vertex})
        nxt = next_landmark(placed | {name})
        return f"lm_{name} on vertex {self.vertex}" + (f"; next: lm_{nxt}" if nxt else "; all placed")

    def invoke(self, context, event):
        if context.window is None or bpy.app.background or context.area is None or context.area.type != "VIEW_3D":
            return self.execute(context)
        ok, obj = self.guarded(_target, context)
        if not ok:
            return {"CANCELLED"}
        self._obj = obj.name
        self._placed = placed_landmarks(obj)
        self._pending = {}
        self._prompt(context)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _prompt(self, context):
        nxt = next_landmark(self._placed | set(self._pending))
        done = len([n for n in LANDMARK_ORDER if n in self._placed | set(self._pending)])
        text = (f"Click lm_{nxt} ({done + 1}/{len(LANDMARK_ORDER)}) on {self._obj} -- Backspace: undo, "
                "Enter: done, Esc: cancel") if nxt else "All landmarks clicked -- Enter: done, Esc: cancel"
        context.area.header_text_set(text)

    def modal(self, context, event):
        from bpy_extras import view3d_utils

        if event.type in NAVIGATION or (event.type.startswith("NUMPAD_") and event.type != "NUMPAD_ENTER"):
            return {"PASS_THROUGH"}                       # orbit, pan and zoom the view between clicks
        if event.value != "PRESS":
            return {"RUNNING_MODAL"}
        if event.type == "ESC":
            context.area.header_text_set(None)
            self.report({"WARNING"}, "Place Landmarks: cancelled; nothing was changed")
            return {"CANCELLED"}
        if event.type in {"RET", "NUMPAD_ENTER"}:
            context.area.header_text_set(None)
            obj = bpy.data.objects[self._obj]
            ok, _ = self.guarded(set_landmarks, obj, self._pending)
            if ok:
                self.report({"INFO"}, f"{len(self._pending)} landmarks placed on {obj.name}")
            return {"FINISHED"} if ok else {"CANCELLED"}
        if event.type == "BACK_SPACE" and self._pending:
            self._pending.pop(list(self._pending)[-1])
        elif event.type == "LEFTMOUSE":
            name = next_landmark(self._placed | set(self._pending))
            region, rv3d = context.region, context.region_data
            coord = (event.mouse_region_x, event.mouse_region_y)
            if name is not None and rv3d is not None:
                origin = view3d_utils.region_2d_to_origin_3d(region, rv3d, coord)
                direction = view3d_utils.region_2d_to_vector_3d(region, rv3d, coord)
                vertex = vertex_under_ray(bpy.data.objects[self._obj], origin, direction)
                if vertex is None:
                    self.report({"WARNING"}, f"click on {self._obj} to place lm_{name}")
                else:
                    self._pending[name] = vertex
        self._prompt(context)
        return {"RUNNING_MODAL"}


class MIRRORCAP_OT_guess_landmarks(MirrorCapOperator):
    """Place the character's missing landmarks by fitting the generic head to it from the ones placed (4 or more)"""

    bl_idname = "mirrorcap.guess_landmarks"
    bl_label = "Guess the Rest"

    def run(self, context):
        from ...core.face.headio import load_head_npz
        from ...core.retarget.transfer import guess_landmarks
        from ..common.headio import GENERIC_HEAD, read_head

        obj = _target(context)
        guessed = guess_landmarks(load_head_npz(GENERIC_HEAD), read_head(obj))
        set_landmarks(obj, guessed)
        if not guessed:
            return f"{obj.name} already has every landmark"
        return f"guessed {len(guessed)} landmarks on {obj.name} ({', '.join(guessed)}): check them before retargeting"


OPERATORS = (MIRRORCAP_OT_place_landmarks, MIRRORCAP_OT_guess_landmarks)
