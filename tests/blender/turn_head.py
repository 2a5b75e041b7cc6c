"""Run with the venv's python: HEAD.blend OUT.blend [OBJECT] [--parent] -- the head (OBJECT, else the mesh with
region_* groups) as an FBX import from a Y-up package in centimetres
leaves it: its data (vertices, every shape key, the jaw hinge) in centimetres and turned -90° about X, the object
scaled 0.01, turned back 90° and moved to (0.3, -0.2, 1.6) m; with --parent, parented (where it stands) to an empty
"Rig" that is turned and moved, as a character's meshes are to its armature. In world space it is the same head."""
import sys

import bpy
import mathutils
import numpy as np

args = [a for a in sys.argv[1:] if not a.startswith("--")]
src, dst = args[0], args[1]
bpy.ops.wm.open_mainfile(filepath=src, load_ui=False)
obj = bpy.data.objects[args[2]] if len(args) > 2 else \
    next(o for o in bpy.data.objects if o.type == "MESH" and any(g.name.startswith("region_") for g in o.vertex_groups))
own = mathutils.Matrix.Rotation(-np.pi / 2, 4, "X") @ mathutils.Matrix.Scale(100.0, 4)
obj.data.transform(own, shape_keys=obj.data.shape_keys is not None)
hinge = obj.get("mirrorcap_jaw_hinge")
if hinge is not None:
    pts = np.asarray(hinge, float).reshape(-1, 3)
    obj["mirrorcap_jaw_hinge"] = (pts @ np.array(own)[:3, :3].T).ravel().tolist()
obj.matrix_world = mathutils.Matrix.Translation((0.3, -0.2, 1.6)) @ own.inverted()
if "--parent" in sys.argv:
    rig = bpy.data.objects.new("Rig", None)
    bpy.context.scene.collection.objects.link(rig)
    rig.location, rig.rotation_euler = (0.1, 0.4, 0.9), (0.0, 0.2, 0.5)
    bpy.context.view_layer.update()
    stands = obj.matrix_world.copy()
    obj.parent = rig
    obj.matrix_world = stands
bpy.ops.wm.save_as_mainfile(filepath=dst)
