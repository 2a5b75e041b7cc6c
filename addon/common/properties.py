"""Settings: one property group on the scene (``scene.mirrorcap``) and the add-on preferences.

The panels show these; every operator also takes its inputs as its own properties, and an
empty operator property falls back to the scene's setting, so ``bpy.ops.mirrorcap.*`` from a
script needs no UI state at all.
"""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    IntVectorProperty,
    PointerProperty,
    StringProperty,
)

#: the add-on's own module: this package's parent (``bl_ext.<repo>.mirrorcap`` inside Blender)
ADDON_ID = __package__.rsplit(".", 2)[0]  # the extension package: <...>.mirrorcap of <...>.mirrorcap.addon.common

LIGHTS = (("auto", "Auto", "what the colour file says, else what the video's first frame shows: a dark frame with "
                            "bright dots is UV, a lit face ordinary light"),
          ("uv", "UV", "fluorescent markers under black-light lamps"),
          ("normal", "Normal", "coloured dots under ordinary lamps"))
RETARGET_METHODS = (("arkit", "ARKit-52", "solve ARKit weights and key the character's shape keys of the same names"),
                    ("transfer", "Transfer", "carry the motion itself onto a character with lm_* landmarks"))
WASHED_OUT = (("auto", "Auto", "keep them when the first 30 frames hold more than 2 % as many as other dots"),
              ("keep", "Keep", "keep them, each classed by its colour less the skin's"),
              ("drop", "Drop", "drop them"))
BAKE_MODES = (("frames", "Frames", "one shape key per take frame, keyed on its frame"),
              ("pca", "PCA", "K eigen-deformation shape keys with keyed weights (compact)"))


def _is_mesh(_self, obj):
    return obj.type == "MESH"


class MirrorCapSettings(bpy.types.PropertyGroup):
    # capture (Movie Clip Editor)
    video: StringProperty(name="Rig Video", subtype="FILE_PATH", description="The rig video (or an image folder)")
    camera: StringProperty(name="Camera", subtype="FILE_PATH", description="CAMERA.json: intrinsics (mirrorcap calibrate)")
    rig: StringProperty(name="Rig", subtype="FILE_PATH", description="RIG.json: view rectangles (optional)")
    mirrors: StringProperty(name="Mirrors", subtype="FILE_PATH",
                            description="MIRRORS.json in mm (optional; default: self-calibration from the markers)")
    colors: StringProperty(name="Colours", subtype="FILE_PATH", description="COLORS.json colour classes (optional)")
    seeds: StringProperty(name="Seeds", subtype="FILE_PATH", default="",
                          description="SEEDS.csv (id,view,x,y): markers designated in the first tracked frame; "
                                      "their ids become their labels (optional)")
    light: EnumProperty(name="Light", items=LIGHTS, default="auto",
                        description="how the markers were lit: fluorescent under black light, or coloured dots")
    washed_out: EnumProperty(name="Washed-out Dots", items=WASHED_OUT, default="auto",
                             description="normal light: dots whose colour video compression washed out between the "
                                         "colour classes")
    take: StringProperty(name="Take", subtype="FILE_PATH", default="//take.c3d", description="TAKE.c3d to write or read")
    frame_start: IntProperty(name="First Frame", default=0, min=0, description="first video frame to track (0-based)")
    frame_end: IntProperty(name="End Frame", default=0, min=0, description="video frame to stop before (0: the end)")
    conjecture_limit_mm: FloatProperty(name="Conjecture Limit (mm)", default=2.0, min=0.0, soft_max=10.0,
                                       description="a hidden marker's conjectured position is kept only where its "
                                                   "expected error (3 sigma) is within this; the rest stay gaps")
    rigid_region: IntVectorProperty(name="Rigid Region", size=4, default=(0, 0, 0, 0), min=0,
                                    description="x0, y0, x1, y1 (pixels, first frame, direct view): the markers in "
                                                "this box (forehead, nose bridge) carry the head pose; all 0: RIG.json's "
                                                "\"rigid\", else found automatically")
    rigid_colors: StringProperty(name="Rigid Colours", default="",
                                 description="comma-separated colour classes of the rigid markers (e.g. a head "
                                             "band's); empty: any colour")
    # head (3D View)
    head_object: PointerProperty(name="Head", type=bpy.types.Object, poll=_is_mesh,
                                 description="The head mesh (region_* and lm_* vertex groups)")
    scan_file: StringProperty(name="Scan", subtype="FILE_PATH", description="the subject's scan: PLY or OBJ, mm")
    scan_landmarks: StringProperty(name="Scan Landmarks", subtype="FILE_PATH",
                                   description="JSON {landmark: [x, y, z]} in the scan's frame (mm)")
    bake_mode: EnumProperty(name="Mode", items=BAKE_MODES, default="frames")
    modes: IntProperty(name="Modes", default=8, min=1, max=512, description="number of PCA modes")
    head_motion: BoolProperty(name="Head Motion", default=False, description="key the head motion on the object")
    blinks: BoolProperty(name="Blinks", default=True, description="synthetic eyelid blinks (no eyelid markers)")
    bake_take_start: IntProperty(name="From", default=0, min=0,
                                 description="first take frame to key, by Bake and Retarget (0-based; the whole take "
                                             "is bound)")
    bake_take_end: IntProperty(name="To", default=0, min=0, description="take frame to stop before (0: the take's end)")
    stable_take: StringProperty(name="Stabilised Take", subtype="FILE_PATH", default="//take_stable.c3d",
                                description="OUT.c3d that Stabilize writes (the take in the head frame of its first frame)")
    rigid_labels: StringProperty(name="Rigid Labels", default="",
                                 description="labels of >= 3 rigid (headband) markers, space-separated; empty: the "
                                             "selected marker empties, or the markers that deform least")
    retarget_target: PointerProperty(name="Character", type=bpy.types.Object, poll=_is_mesh,
                                     description="the mesh Retarget animates: with ARKit-named shape keys (ARKit-52) "
                                                 "or lm_* landmarks (Transfer)")
    retarget_method: EnumProperty(name="Method", items=RETARGET_METHODS, default="arkit")
    livelink_csv: StringProperty(name="Live Link CSV", subtype="FILE_PATH", default="",
                                 description="LIVELINK.csv that Retarget writes (optional)")
    fap_file: StringProperty(name="FAP File", subtype="FILE_PATH", default="//take.fap",
                             description="TAKE.fap: MPEG-4 FAPs that Export FAPs writes and Play FAP File reads")
    marker_map: StringProperty(name="Marker Map", subtype="FILE_PATH", default="",
                               description="MAP.json binding markers by name (LABEL: lm_<name> | vertex | rigid | "
                                           "ignore); the map buttons below write it")


class MirrorCapPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    empty_size_mm: IntProperty(name="Marker Size (mm)", default=2, min=1, max=20,
                               description="display size of imported take markers")

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "empty_size_mm")


def preferences(context=None):
    """The add-on's preferences, or ``None`` when it runs outside the add-on system (tests)."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None


CLASSES = (MirrorCapSettings, MirrorCapPreferences)


def register_properties():
    bpy.types.Scene.mirrorcap = PointerProperty(type=MirrorCapSettings)


def unregister_properties():
    del bpy.types.Scene.mirrorcap
