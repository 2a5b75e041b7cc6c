"""Render a contact sheet of baked frames: ``docs/contact_sheet.png``.

A 120-frame synthetic take (150 markers on the generic head performing the eight
faceunit expressions, with head motion) goes through ``mirrorcap bake`` (frames mode,
blinks on); six frames -- the neutral, the widest jaw opening, the fullest blink and the
three frames that move the face most -- are rendered headless with Cycles on the CPU
and tiled 3 x 2 with their frame numbers.

Run from the repository root:  python sample_scenes/make_contact_sheet.py
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
HEAD = ROOT / "sample_scenes" / "generic_head"
OUT = ROOT / "docs" / "contact_sheet.png"
SIZE = 360


def main() -> int:
    from mirrorcap.core.take.c3d import write_c3d
    from mirrorcap.core.face.headio import load_head_npz
    from mirrorcap.synthetic.headsim import synthetic_take

    head, keys = load_head_npz(HEAD / "head.npz", with_shape_keys=True)
    labels, pts, verts, disp, pose = synthetic_take(head, keys, n_markers=150, n_frames=120, seed=21)
    tmp = Path(tempfile.mkdtemp())
    write_c3d(tmp / "take.c3d", labels, pts, 30.0)
    (tmp / "report.json").write_text(json.dumps({"head_pose": pose.tolist()}))
    subprocess.run([sys.executable, "-m", "mirrorcap", "bake", tmp / "take.c3d", "--head", HEAD / "head.blend",
                    "-o", tmp / "baked.blend", "--head-pose", tmp / "report.json", "--blink-seed", "3"],
                   check=True, cwd=ROOT)
    import bpy

    bpy.ops.wm.open_mainfile(filepath=str(tmp / "baked.blend"), load_ui=False)
    obj = bpy.data.objects["GenericHead"]
    key = obj.data.shape_keys
    n = len(obj.data.vertices)
    basis = np.empty(3 * n, np.float32)
    key.reference_key.points.foreach_get("co", basis)
    move = []
    for i in range(120):
        co = np.empty(3 * n, np.float32)
        key.key_blocks[f"frame_{i + 1:05d}"].points.foreach_get("co", co)
        move.append(co.reshape(-1, 3) - basis.reshape(-1, 3))
    move = np.array(move) * 1000.0
    mag = np.linalg.norm(move, axis=2)
    chin = head.landmarks()["chin"]
    lid = int(np.argmax(head.groups["eyelid_upper_l"]))
    picks = [0, int(np.argmax(mag[:, chin])), int(np.argmax(mag[:, lid]))]
    for f in np.argsort(-mag.mean(1)):
        if len(picks) == 6:
            break
        if all(abs(int(f) - p) > 6 for p in picks):
            picks.append(int(f))
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 24
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.film_transparent = False
    world = bpy.data.worlds.new("w")
    world.color = (0.05, 0.05, 0.06)
    scene.world = world
    cam = bpy.data.objects.new("cam", bpy.data.cameras.new("cam"))
    cam.data.lens = 85
    cam.location = (0.26, -0.7, 0.02)                  # a three-quarter view from the subject's left
    cam.rotation_euler = (np.pi / 2, 0.0, np.deg2rad(20.0))
    scene.collection.objects.link(cam)
    scene.camera = cam
    for loc, energy in (((0.4, -0.6, 0.4), 9.0), ((-0.5, -0.4, 0.1), 3.5)):
        light = bpy.data.objects.new("l", bpy.data.lights.new("l", "POINT"))
        light.data.energy = energy
        light.location = loc
        scene.collection.objects.link(light)
    mat = bpy.data.materials.new("skin")
    mat.diffuse_color = (0.8, 0.62, 0.52, 1.0)
    obj.data.materials.append(mat)
    obj.location = (0, 0, 0)
    import cv2

    tiles = []
    for f in picks:
        scene.frame_set(f + 1)
        scene.render.filepath = str(tmp / f"f{f:03d}.png")
        bpy.ops.render.render(write_still=True)
        img = cv2.imread(str(tmp / f"f{f:03d}.png"))
        cv2.putText(img, f"frame {f + 1}", (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2)
        tiles.append(img)
    sheet = np.vstack([np.hstack(tiles[:3]), np.hstack(tiles[3:6])])
    OUT.parent.mkdir(exist_ok=True)
    ok, buf = cv2.imencode(".png", sheet)
    from mirrorcap.core.common.files import write_files_atomically

    write_files_atomically({OUT: buf.tobytes()})
    print(f"wrote {OUT} (frames {[p + 1 for p in picks]})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
