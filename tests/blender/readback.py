"""Run with the venv's python: read a baked .blend back with bpy and print JSON.

argv: OUT.blend MODE OBJECT_NAME -> {"basis": [...], "keys": {name: co}, "values": [[...per frame]], "frames": [...]}
Values are each shape key's animated value at every scene frame (F-curves evaluated by Blender).
"""
import json
import sys

import bpy
import numpy as np

path, obj_name, out = sys.argv[1], sys.argv[2], sys.argv[3]
bpy.ops.wm.open_mainfile(filepath=path, load_ui=False)
obj = bpy.data.objects[obj_name]
key = obj.data.shape_keys
n = len(obj.data.vertices)
blocks = {}
for kb in key.key_blocks:
    co = np.empty(3 * n, np.float32)
    kb.data.foreach_get("co", co)
    blocks[kb.name] = co.reshape(-1, 3)
names = [kb.name for kb in key.key_blocks if kb.name.startswith(("frame_", "mode_"))]
scene = bpy.context.scene
frames = list(range(scene.frame_start, scene.frame_end + 1))
fcurves = {}
for layer in key.animation_data.action.layers:
    for strip in layer.strips:
        for bag in strip.channelbags:
            for fc in bag.fcurves:
                fcurves[fc.data_path.split('"')[1]] = fc
values = np.array([[fcurves[nm].evaluate(f) for nm in names] for f in frames])
np.savez(out, basis=blocks["Basis"], keys=np.stack([blocks[nm] for nm in names]), names=np.array(names),
         values=values, frames=np.array(frames), fps=scene.render.fps)
print(json.dumps({"keys": len(names), "frames": len(frames)}))
