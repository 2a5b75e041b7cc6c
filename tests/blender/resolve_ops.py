"""Fix-ups and Re-solve headless (#21): the take written to the clip as tracks, five tracks fixed as a
user fixes them in the Movie Clip Editor (renamed to the designation they lost; a lost stretch
re-placed on its dot), Re-solve; prints JSON (tests/test_normal_light.py asserts on it).

    python tests/blender/resolve_ops.py WORK_DIR CLIP_DIR
    (WORK_DIR/fixes.json: {"rename": {designation: track label}, "track": {designation: {view: [[f, x, y]]}},
     "delete": [track label]})
"""

import json
import sys
from pathlib import Path

import bpy

import mirrorcap

work, clip_dir = Path(sys.argv[1]), Path(sys.argv[2])
fixes = json.loads((work / "fixes.json").read_text())
out = {}
bpy.ops.wm.read_factory_settings(use_empty=True)
mirrorcap.register()
s = bpy.context.scene.mirrorcap
s.camera, s.video, s.take = str(clip_dir / "camera.json"), str(clip_dir / "clip.mp4"), str(work / "take.c3d")


def call(op, **kw):
    try:
        return sorted(op(**kw))
    except RuntimeError as exc:
        return ["ERROR", str(exc).strip().splitlines()[-1]]


out["resolve_first"] = call(bpy.ops.mirrorcap.resolve)          # no take tracks in the clip yet
out["to_clip"] = call(bpy.ops.mirrorcap.take_to_clip)
clip = bpy.data.movieclips[0]
tracks = clip.tracking.objects["MirrorCap Take"].tracks
out["tracks"] = len(tracks)
# the user's fixes: the tracks of each marker that lost its designation get the designation's name back
renamed = 0
for name, label in fixes["rename"].items():
    for t in tracks:
        if t.name.rpartition(".")[0] == label:
            t.name = f"{name}.{t.name.rpartition('.')[2]}"
            renamed += 1
out["renamed_tracks"] = renamed
# ... a marker no track followed: tracked anew from a click, one track per view (<designation>.<view>)
w, h = clip.size
for name, views in fixes["track"].items():
    for view, rows in views.items():
        track = tracks.new(name=f"{name}.{view}", frame=int(rows[0][0]) + 1)
        for f, x, y in rows:
            track.markers.insert_frame(int(f) + 1, co=((x + 0.5) / w, 1.0 - (y + 0.5) / h))
# ... and a track the user deletes because it jumps between dots (muted markers are left out by Re-solve)
for t in tracks:
    if t.name.rpartition(".")[0] in fixes["delete"]:
        for m in t.markers:
            m.mute = True
before = {o.name for o in bpy.data.objects}
out["resolve_cancel"] = call(bpy.ops.mirrorcap.resolve, cancel_after_steps=1)
out["cancel_unchanged"] = {o.name for o in bpy.data.objects} == before
out["resolve"] = call(bpy.ops.mirrorcap.resolve)
out["report"] = json.loads((work / "take_report.json").read_text())["resolve"]
print("RESULT " + json.dumps(out))
