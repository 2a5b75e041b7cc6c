"""Operator inputs shared by every feature: the scene's settings, paths from operator
properties (``//`` = the .blend's folder) with the scene's value as fallback, the head object."""

from __future__ import annotations

from pathlib import Path

import bpy

from ...core.common.errors import InputError


def scene_settings(context):
    return context.scene.mirrorcap


def input_path(value: str, fallback: str = "", what: str = "file", must_exist: bool = True) -> Path | None:
    """An absolute path from an operator property or its scene fallback (``//`` = the .blend's folder)."""
    text = value or fallback
    if not text:
        return None
    path = Path(bpy.path.abspath(text))
    if must_exist and not path.exists():
        raise InputError(f"the {what} {path} does not exist")
    return path


def selected_marker_labels(context) -> list:
    """The labels (``mirrorcap_label``) of the selected marker empties of imported takes."""
    return [str(o["mirrorcap_label"]) for o in context.selected_objects if "mirrorcap_label" in o]


def required(path, what: str):
    if path is None:
        raise InputError(f"choose the {what} first")
    return path


def take_report_path(take: Path) -> Path:
    return take.with_name(take.stem + "_report.json")


def head_object_from(context, name: str):
    if name:
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise InputError(f"there is no object named {name!r}")
    else:
        obj = scene_settings(context).head_object or context.active_object
    if obj is None or obj.type != "MESH":
        raise InputError("choose a head mesh (Head in the MirrorCap panel, or the active object)")
    return obj


def rig_and_colours(s, source=None, start: int = 0):
    """The scene's rig file (RIG.json: views and rigid markers), colour classes (COLORS.json, else the four
    colours of the light), light (the scene's Light; Auto: what COLORS.json says, else what frame ``start`` of
    the rig video ``source`` shows, else UV: :func:`...core.capture.markers.capture_light`) and whether the frame
    said it, each read once."""
    from ...core.capture.markers import ColorClasses, capture_light, frame_says_light
    from ...core.capture.rig import load_rig

    rig = load_rig(input_path(s.rig, what="rig file") if s.rig else None)
    colours = ColorClasses.load(input_path(s.colors, what="colour file")) if s.colors else None
    said = None if s.light == "auto" else s.light
    light = capture_light(said, colours, source, start)
    return rig, colours or ColorClasses.default(light), light, source is not None and frame_says_light(said, colours)


def extraction_settings(s, light: str):
    """The marker extraction settings of the capture's ``light`` (:func:`rig_and_colours`; under normal light, of
    the scene's washed-out dots)."""
    from ...core.capture.markers import ExtractionSettings

    return ExtractionSettings(light=light, washed_out=s.washed_out)


def rigid_from_settings(s, rig, colours):
    """The tracker's rigid markers from the scene's settings (region, colours), else the rig
    file's, else automatic: ``(spec, source)`` (:func:`...core.capture.rig.rigid_markers`)."""
    from ...core.capture.rig import rigid_markers

    return rigid_markers(s.rigid_region, s.rigid_colors.split(","), rig, colours)


def scene_marker_map(context):
    """The scene's marker map (MAP.json, :func:`...core.face.bind.load_marker_map`), or None when
    none is set."""
    from ...core.face.bind import load_marker_map

    path = input_path(scene_settings(context).marker_map, what="marker map")
    return load_marker_map(path) if path is not None else None

