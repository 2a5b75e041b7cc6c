"""Run with the venv's python: read a baked .blend back with bpy and print JSON.

argv: OUT.blend OBJECT_NAME OUT.npz -> basis, keys, names, values (each shape key's animated value
at every scene frame, F-curves evaluated by Blender), frames, fps, rate (fps / fps_base: what Blender plays), and ``evaluated``: the mesh a user
sees at every scene frame (the depsgraph's evaluated object, all shape keys and modifiers applied) in the
object's own frame, and ``world``: the same in world space (the object's animated transform applied).
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
scene = bpy.context.scene
frames = list(range(scene.frame_start, scene.frame_end + 1))
fcurves = {}
for layer in key.animation_data.action.layers:
    for strip in layer.strips:
        for bag in strip.channelbags:
            for fc in bag.fcurves:
                fcurves[fc.data_path.split('"')[1]] = fc
# a bake's keys (frame_/mode_), else every animated key (a retarget's ARKit shapes)
names = [kb.name for kb in key.key_blocks if kb.name.startswith(("frame_", "mode_"))] or \
    [kb.name for kb in key.key_blocks if kb.name in fcurves]
values = np.array([[fcurves[nm].evaluate(f) for nm in names] for f in frames])
evaluated = np.empty((len(frames), n, 3), np.float32)
world = np.empty((len(frames), n, 3))
for i, f in enumerate(frames):
    scene.frame_set(f)
    ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
    mesh = ev.to_mesh()
    co = np.empty(3 * n, np.float32)
    mesh.vertices.foreach_get("co", co)
    evaluated[i] = co.reshape(-1, 3)
    M = np.array(ev.matrix_world, float)
    world[i] = co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]
    ev.to_mesh_clear()
np.savez(out, basis=blocks[key.reference_key.name], keys=np.stack([blocks[nm] for nm in names]), names=np.array(names),
         values=values, frames=np.array(frames), fps=scene.render.fps, rate=scene.render.fps / scene.render.fps_base,
         evaluated=evaluated, world=world)
print(json.dumps({"keys": len(names), "frames": len(frames)}))
