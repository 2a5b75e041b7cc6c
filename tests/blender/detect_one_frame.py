"""Detect Markers on one frame of a normal-light clip, headless, in a factory-settings session, the scene's Light
left at Auto (the frame shows it); the operator's reports go to stdout (tests/test_addon.py reads them).

    python tests/blender/detect_one_frame.py CLIP_DIR [WASHED_OUT]

``WASHED_OUT``: the scene's Washed-out Dots (auto, keep or drop; default its default, auto).
"""

import sys
from pathlib import Path

import bpy

import mirrorcap

clip = Path(sys.argv[1])
bpy.ops.wm.read_factory_settings(use_empty=True)
mirrorcap.register()
s = bpy.context.scene.mirrorcap
s.video = str(clip / "clip.mp4")
s.camera = str(clip / "camera.json")
s.rig = str(clip / "rig.json")
if len(sys.argv) > 2:
    s.washed_out = sys.argv[2]
bpy.ops.mirrorcap.open_clip(filepath=s.video)
print("RESULT", sorted(bpy.ops.mirrorcap.detect_markers(frame=0)))
