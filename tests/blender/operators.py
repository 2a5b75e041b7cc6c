"""Drive every MirrorCap operator headless through bpy.ops in a factory-settings session and
print what happened as JSON (tests/test_addon.py asserts on it).

    python tests/blender/operators.py SAMPLE_DIR WORK_DIR
"""

import json
import sys
from pathlib import Path

import bpy

import mirrorcap

sample, work = Path(sys.argv[1]), Path(sys.argv[2])
out = {}

bpy.ops.wm.read_factory_settings(use_empty=True)
mirrorcap.register()
scene = bpy.context.scene
s = scene.mirrorcap
s.video = str(sample / "clip.mp4")
s.camera = str(sample / "camera.json")
s.rig = str(sample / "rig.json")
s.frame_end = 15


def state():
    return {"objects": sorted(o.name for o in bpy.data.objects),
            "collections": sorted(c.name for c in bpy.data.collections),
            "keys": {o.name: len(o.data.shape_keys.key_blocks) for o in bpy.data.objects
                     if o.type == "MESH" and o.data.shape_keys is not None},
            "files": sorted(p.name for p in work.iterdir())}


def call(op, **kw):
    try:
        return sorted(op(**kw))
    except RuntimeError as exc:               # an operator's ERROR report
        return ["ERROR", str(exc).strip().splitlines()[-1]]


# capture
out["open_clip"] = call(bpy.ops.mirrorcap.open_clip, filepath=s.video)
out["clip_frames"] = bpy.data.movieclips[0].frame_duration
out["detect"] = call(bpy.ops.mirrorcap.detect_markers, frame=0)
clip = bpy.data.movieclips[0]
out["detect_tracks"] = len(clip.tracking.objects["MirrorCap"].tracks)

before = state()
out["track_cancelled"] = call(bpy.ops.mirrorcap.track, take=str(work / "cancelled.c3d"), cancel_after_steps=5)
out["track_cancelled_unchanged"] = state() == before
out["track"] = call(bpy.ops.mirrorcap.track, take=str(work / "take.c3d"))
take_parent = [o for o in bpy.data.objects if "mirrorcap_take" in o]
out["take_empties"] = len(take_parent[0].children) if take_parent else 0


def fcurves(action):
    return [fc for layer in action.layers for strip in layer.strips for bag in strip.channelbags for fc in bag.fcurves]


if take_parent:
    child = sorted(take_parent[0].children, key=lambda o: o.name)[0]
    out["take_fcurve_keys"] = [len(fc.keyframe_points) for fc in fcurves(child.animation_data.action)]
out["state_after_track"] = state()

# a camera file for another image size: one clear error, nothing written
bad_cam = work / "camera_640.json"
cam = json.loads((sample / "camera.json").read_text())
cam["image_size"] = [640, 360]
bad_cam.write_text(json.dumps(cam))
s.camera = str(bad_cam)
out["track_bad_camera"] = call(bpy.ops.mirrorcap.track, take=str(work / "bad.c3d"))
s.camera = str(sample / "camera.json")

# rigid markers from the clip: select the direct-view tracks on the top quarter of the face
mc_tracks = clip.tracking.objects["MirrorCap"].tracks
direct = [t for t in mc_tracks if t.name.startswith("direct_")]
ys = sorted(t.markers.find_frame(1).co[1] for t in direct)
top = ys[int(0.75 * len(ys))]                 # clip y points up: the top quarter has the largest y
for t in mc_tracks:
    t.select = t.name.startswith(("direct_", "mirror0_")) and t.markers.find_frame(1).co[1] >= top
out["rigid_selected"] = sum(t.select and t.name.startswith("direct_") for t in mc_tracks)
out["rigid_from_tracks"] = call(bpy.ops.mirrorcap.rigid_from_tracks, frame=0)
out["rigid_region"] = list(s.rigid_region)
out["rigid_track"] = call(bpy.ops.mirrorcap.track, take=str(work / "rigid.c3d"), import_result=False)
rep = json.loads((work / "rigid_report.json").read_text()) if (work / "rigid_report.json").is_file() else {}
out["rigid_report"] = {k: rep.get("markers", {}).get(k) for k in ("rigid_source", "rigid", "labels")}
for t in mc_tracks:
    t.select = False
direct[0].select = direct[1].select = True
out["rigid_too_few"] = call(bpy.ops.mirrorcap.rigid_from_tracks, frame=0)
s.rigid_region = (0, 0, 10, 10)               # a box with no marker: one clear error
out["rigid_nowhere"] = call(bpy.ops.mirrorcap.track, take=str(work / "rigid_bad.c3d"), import_result=False)
s.rigid_region = (0, 0, 0, 0)

# Blender's own 2D tracks as the input: every detection of 12 frames as a one-frame track
from mirrorcap.core.capture.markers import ColorClasses, MarkerExtractor  # noqa: E402
from mirrorcap.core.capture.rig import load_rig_views  # noqa: E402
from mirrorcap.core.capture.video import open_source  # noqa: E402

src = open_source(sample / "clip.mp4")
layout = load_rig_views(sample / "rig.json")
ext = MarkerExtractor(ColorClasses.default())
tobj = clip.tracking.objects.new("hand_tracks")
w, h = src.size
for n, img in src.frames(0, 12, 1):
    det = ext(img)
    for i in range(len(det)):
        tr = tobj.tracks.new(name=f"t{n}_{i}", frame=n + 1)
        tr.markers.find_frame(n + 1).co = ((det.x[i] + 0.5) / w, 1.0 - (det.y[i] + 0.5) / h)
out["clip_tracks"] = call(bpy.ops.mirrorcap.track_clip_tracks, take=str(work / "from_tracks.c3d"),
                          tracking_object="hand_tracks", import_result=False)

# animation
out["generic_head"] = call(bpy.ops.mirrorcap.add_generic_head)
s.scan_file = str(sample / "scan.ply")
s.scan_landmarks = str(sample / "scan_landmarks.json")
out["fit"] = call(bpy.ops.mirrorcap.fit_head)
fitted = bpy.data.objects.get("generic_head_fitted")
out["fit_info"] = json.loads(fitted["mirrorcap_fit"]) if fitted is not None else None
out["bind"] = call(bpy.ops.mirrorcap.bind, take=str(work / "take.c3d"))
out["bound_group"] = fitted.vertex_groups.get("mirrorcap_bound") is not None if fitted else False
out["binding"] = json.loads(fitted["mirrorcap_binding"]) if fitted is not None and "mirrorcap_binding" in fitted else None

before = state()
out["bake_cancelled"] = call(bpy.ops.mirrorcap.bake, take=str(work / "take.c3d"), cancel_after_steps=2)
out["bake_cancelled_unchanged"] = state() == before
out["bake"] = call(bpy.ops.mirrorcap.bake, take=str(work / "take.c3d"))
out["baked_keys"] = len([k for k in fitted.data.shape_keys.key_blocks if k.name.startswith("frame_")])
out["bake_missing"] = call(bpy.ops.mirrorcap.bake, take=str(work / "missing.c3d"))
# a stretch of the take, in a scene that starts at 1001 (a pipeline's shot): keyed from there
scene.frame_start = 1001
out["bake_stretch"] = call(bpy.ops.mirrorcap.bake, take=str(work / "take.c3d"), take_start=3, take_end=10)
out["stretch_keys"] = len([k for k in fitted.data.shape_keys.key_blocks if k.name.startswith("frame_")])
out["stretch_scene_frames"] = [scene.frame_start, scene.frame_end]
first_key = [fc for fc in fitted.data.shape_keys.animation_data.action.layers[0].strips[0].channelbags[0].fcurves
             if fc.data_path == 'key_blocks["frame_00001"].value'][0]
out["stretch_first_key"] = [first_key.evaluate(f) for f in (1000, 1001, 1002)]
objects_before = set(bpy.data.objects)
out["import_take"] = call(bpy.ops.mirrorcap.import_take, filepath=str(work / "take.c3d"))
out["scene_frames"] = [scene.frame_start, scene.frame_end]
marker = next(o for o in bpy.data.objects if o not in objects_before and "mirrorcap_label" in o and o.animation_data)
out["take_key_frames"] = sorted({int(k.co[0]) for fc in marker.animation_data.action.layers[0].strips[0].channelbags[0].fcurves
                                 for k in fc.keyframe_points})[:2]
print("RESULT " + json.dumps(out))
