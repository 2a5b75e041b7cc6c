"""Drive the take operators headless (import any system's C3D, Stabilize, the marker-map
editor, Bake with a map) and print what happened as JSON (tests/test_addon.py asserts on it).

    python tests/blender/take_ops.py WORK_DIR
"""

import json
import sys
from pathlib import Path

import bpy
import numpy as np

import mirrorcap

work = Path(sys.argv[1])
out = {}
bpy.ops.wm.read_factory_settings(use_empty=True)
mirrorcap.register()
scene = bpy.context.scene
s = scene.mirrorcap


def call(op, **kw):
    try:
        return sorted(op(**kw))
    except RuntimeError as exc:               # an operator's ERROR report
        return ["ERROR", str(exc).strip().splitlines()[-1]]


def fcurves(action):
    return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags for fc in bag.fcurves]


# 1. another system's C3D (lab axes, metres, analog channels, gaps): empties keyed where seen
out["import_vendor"] = call(bpy.ops.mirrorcap.import_take, filepath=str(work / "vendor.c3d"))
parent = [o for o in bpy.data.objects if o.get("mirrorcap_take", "").endswith("vendor.c3d")][0]
out["vendor_frame"] = parent["mirrorcap_frame"]
out["vendor_keys"] = {o["mirrorcap_label"]: len(fcurves(o.animation_data.action)[0].keyframe_points)
                      for o in parent.children}
empty = [o for o in parent.children if o["mirrorcap_label"] == "M05"][0]
scene.frame_set(2)                            # take frame 1, the last before the gap
out["vendor_M05_frame2_m"] = list(empty.matrix_world.translation)

# 2. Stabilize the sparse take: the stabilised take and its pivot in the scene, files on disk
s.take = str(work / "sparse.c3d")
s.stable_take = str(work / "stable.c3d")
s.rigid_labels = "LFHD RFHD TFHD"
out["stabilize"] = call(bpy.ops.mirrorcap.stabilize_take)
out["stable_files"] = sorted(p.name for p in work.iterdir() if p.name.startswith("stable"))
out["pivot_objects"] = [o.name for o in bpy.data.objects if "mirrorcap_pivot_mm" in o]
report = json.loads((work / "stable.json").read_text())
out["stable_pivot_mm"] = report["pivot_mm"]
before = sorted(o.name for o in bpy.data.objects)
out["stabilize_bad"] = call(bpy.ops.mirrorcap.stabilize_take, rigid="LFHD NOSE")
out["stabilize_bad_unchanged"] = sorted(o.name for o in bpy.data.objects) == before

# 3. the marker-map editor: pick an empty, then a vertex (Edit Mode), a landmark, rigid, ignore
bpy.ops.mirrorcap.import_take(filepath=str(work / "sparse.c3d"))
sparse = [o for o in bpy.data.objects if o.get("mirrorcap_take", "").endswith("sparse.c3d")][0]
markers = {o["mirrorcap_label"]: o for o in sparse.children}
bpy.ops.mirrorcap.add_generic_head()
head = bpy.context.active_object
s.head_object = head
s.marker_map = str(work / "map.json")
mapping = json.loads((work / "truth_map.json").read_text())


def select_marker(label):
    for o in bpy.data.objects:
        o.select_set(False)
    markers[label].select_set(True)


results = []
for label, role in mapping.items():
    select_marker(label)
    if isinstance(role, int):              # a vertex: select it on the head, as a user does in Edit Mode
        sel = np.zeros(len(head.data.vertices), bool)
        sel[role] = True
        head.data.vertices.foreach_set("select", sel)
        bpy.context.view_layer.objects.active = head
        head.select_set(True)
        results.append(call(bpy.ops.mirrorcap.map_marker, role="VERTEX"))
    elif role.startswith("lm_"):
        results.append(call(bpy.ops.mirrorcap.map_marker, role="LANDMARK", landmark=role))
    else:
        results.append(call(bpy.ops.mirrorcap.map_marker, role=role.upper()))
out["map_calls"] = sorted(set(map(tuple, results)))
out["map_written"] = json.loads((work / "map.json").read_text())
for o in bpy.data.objects:
    o.select_set(False)
markers["F03"].select_set(True)
markers["F04"].select_set(True)
out["map_two_selected"] = call(bpy.ops.mirrorcap.map_marker, role="RIGID")
out["map_unchanged"] = json.loads((work / "map.json").read_text()) == out["map_written"]

# 4. Bake the sparse take with the map
s.take = str(work / "sparse.c3d")
out["bake"] = call(bpy.ops.mirrorcap.bake)
out["bake_keys"] = len(head.data.shape_keys.key_blocks)

# 5. Retarget the sparse take onto a second character (another generic head, its ARKit keys)
bpy.ops.mirrorcap.add_generic_head()
character = bpy.context.active_object
character.name = "Character"
s.head_object = head
s.retarget_target = character
s.livelink_csv = str(work / "live.csv")
out["retarget_self"] = call(bpy.ops.mirrorcap.retarget, target_object=head.name)
out["retarget"] = call(bpy.ops.mirrorcap.retarget)
action = character.data.shape_keys.animation_data.action
curves = fcurves(action)
out["retarget_keyed"] = len(curves)
jaw = [fc for fc in curves if "jawOpen" in fc.data_path][0]
out["retarget_jaw_max"] = max(k.co[1] for k in jaw.keyframe_points)
out["csv_rows"] = len((work / "live.csv").read_text().splitlines())
# ... a stretch of it (take frames 5-11) in a scene starting at 1001: the whole take's weights at those frames
whole_jaw = {int(k.co[0]) - scene.frame_start: k.co[1] for k in jaw.keyframe_points}     # take frame: weight
first_frame = scene.frame_start
scene.frame_start = 1001
out["retarget_stretch"] = call(bpy.ops.mirrorcap.retarget, take_start=5, take_end=12)
jaw = [fc for fc in fcurves(character.data.shape_keys.animation_data.action) if "jawOpen" in fc.data_path][0]
out["stretch_jaw_frames"] = [int(k.co[0]) for k in jaw.keyframe_points]
out["stretch_jaw_off"] = max(abs(k.co[1] - whole_jaw[int(k.co[0]) - 1001 + 5]) for k in jaw.keyframe_points)
out["stretch_csv_rows"] = len((work / "live.csv").read_text().splitlines())
out["retarget_bad_stretch"] = call(bpy.ops.mirrorcap.retarget, take_start=15, take_end=40)
scene.frame_start = first_frame

# 6. MPEG-4 FAPs: Export FAPs writes the take's FAPs; Play FAP File bakes them back onto the head
s.take = str(work / "sparse.c3d")
s.fap_file = str(work / "take.fap")
out["export_faps"] = call(bpy.ops.mirrorcap.export_faps)
out["fap_lines"] = len((work / "take.fap").read_text().splitlines())
out["play_fap"] = call(bpy.ops.mirrorcap.bake, fap=str(work / "take.fap"))
out["play_fap_keys"] = len(head.data.shape_keys.key_blocks)
(work / "bad.fap").write_text("2.1 x 30 1\n1 0 1\n0 0\n")
before = [kb.name for kb in head.data.shape_keys.key_blocks]
out["play_bad"] = call(bpy.ops.mirrorcap.bake, fap=str(work / "bad.fap"))
out["play_bad_unchanged"] = [kb.name for kb in head.data.shape_keys.key_blocks] == before

# 7. Transfer onto a character with no shape keys and no groups: its landmarks clicked (a ray onto the
#    mesh, as the modal operator casts from the mouse), four by vertex, the rest guessed
from mathutils import Vector  # noqa: E402

from mirrorcap.addon.common.headio import GENERIC_HEAD, new_head_object  # noqa: E402
from mirrorcap.addon.retarget.landmarks import vertex_under_ray  # noqa: E402
from mirrorcap.core.face.head import HeadModel  # noqa: E402
from mirrorcap.core.face.headio import load_head_npz  # noqa: E402

generic = load_head_npz(GENERIC_HEAD)
lm = generic.landmarks()
plain = new_head_object(HeadModel(vertices=generic.vertices * [1.1, 0.95, 1.0], polygons=generic.polygons,
                                  polygon_sizes=generic.polygon_sizes, groups={}, name="Plain"))
plain.location = (0.5, 0.0, 0.0)
bpy.context.view_layer.update()
s.retarget_target = plain
s.retarget_method = "transfer"
out["transfer_no_landmarks"] = call(bpy.ops.mirrorcap.retarget)
nose = plain.matrix_world @ plain.data.vertices[lm["nose_tip"]].co
clicked = vertex_under_ray(plain, nose + Vector((0.0, -0.5, 0.0)), Vector((0.0, 1.0, 0.0)))
out["clicked_nose_mm"] = 1000 * (plain.data.vertices[clicked].co - plain.data.vertices[lm["nose_tip"]].co).length
out["place"] = [call(bpy.ops.mirrorcap.place_landmarks, vertex=clicked)]
for name in ("eye_inner_l", "eye_outer_l", "eye_inner_r"):        # the order Place Landmarks asks
    out["place"].append(call(bpy.ops.mirrorcap.place_landmarks, vertex=lm[name]))
out["transfer_missing"] = call(bpy.ops.mirrorcap.retarget)
out["guess"] = call(bpy.ops.mirrorcap.guess_landmarks)
from mirrorcap.addon.common.headio import read_head  # noqa: E402

placed = read_head(plain).landmarks()
out["guessed_off"] = {n: 1000 * (plain.data.vertices[v].co - plain.data.vertices[lm[n]].co).length
                      for n, v in placed.items()}
out["transfer_cancel"] = call(bpy.ops.mirrorcap.retarget, cancel_after_steps=2)
out["transfer_cancel_unchanged"] = plain.data.shape_keys is None
s.bake_mode = "frames"
out["transfer"] = call(bpy.ops.mirrorcap.retarget)
out["transfer_keys"] = len(plain.data.shape_keys.key_blocks)
depsgraph = bpy.context.evaluated_depsgraph_get()
moved = 0.0
for f in (5, 12):
    scene.frame_set(f)
    ev = plain.evaluated_get(bpy.context.evaluated_depsgraph_get())
    co = np.empty(3 * len(plain.data.vertices), np.float32)
    ev.data.vertices.foreach_get("co", co)
    rest = np.empty_like(co)
    plain.data.shape_keys.reference_key.points.foreach_get("co", rest)
    moved = max(moved, float(np.abs(co - rest).max()) * 1000)
out["transfer_moved_mm"] = moved
# ... a stretch (take frames 5-11) keyed from 1001: the evaluated mesh as the whole take's at those take frames
whole = {}
for f in (5, 9):
    scene.frame_set(first_frame + f)
    ev = plain.evaluated_get(bpy.context.evaluated_depsgraph_get())
    whole[f] = np.empty(3 * len(plain.data.vertices), np.float32)
    ev.data.vertices.foreach_get("co", whole[f])
scene.frame_start = 1001
out["transfer_stretch"] = call(bpy.ops.mirrorcap.retarget, take_start=5, take_end=12)
out["transfer_stretch_keys"] = len(plain.data.shape_keys.key_blocks)
off = 0.0
for f in (5, 9):
    scene.frame_set(1001 + f - 5)
    ev = plain.evaluated_get(bpy.context.evaluated_depsgraph_get())
    co = np.empty(3 * len(plain.data.vertices), np.float32)
    ev.data.vertices.foreach_get("co", co)
    off = max(off, float(np.abs(co - whole[f]).max()) * 1000)
out["transfer_stretch_off_mm"] = off
print("RESULT " + json.dumps(out))
