"""Re-encode a rig clip's video at a lower H.264 quality -- `make compressed-clips`.

A camera or a screen recorder seldom keeps a video as faithfully as `make_rig_clip.py` does
(H.264 at constant rate factor 17, "perceptually lossless"). This writes a copy of a clip folder
(its truth, camera and rig files as they are) whose ``clip.mp4`` holds the same frames through
Blender's FFmpeg at another constant rate factor: HIGH (CRF 20), MEDIUM (23), LOW (26), VERYLOW (29)
or LOWEST (32). ``clip.json`` records it under ``"reencoded"`` (``from``: the source folder's name,
``quality`` and ``crf``). The copy appears whole or not at all.

    python sample_scenes/reencode_clip.py sample_scenes/normal/hd sample_scenes/normal/hd_crf26 --quality LOW
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

CRF = {"HIGH": 20, "MEDIUM": 23, "LOW": 26, "VERYLOW": 29, "LOWEST": 32}


def fail(message: str):
    """One ``error:`` line on stderr and exit status 2, as the product's commands end on bad input."""
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(2)


def read_frames(video: Path, work: Path) -> tuple[int, int, int]:
    """Every frame of ``video`` as ``work/frame_NNNN.png``; returns (frames, width, height)."""
    import cv2

    capture = cv2.VideoCapture(str(video))
    if not capture.isOpened():
        fail(f"cannot read {video}")
    frames, width, height = 0, 0, 0
    while True:
        ok, image = capture.read()
        if not ok:
            break
        cv2.imwrite(str(work / f"frame_{frames:04d}.png"), image)
        height, width = image.shape[:2]
        frames += 1
    if frames == 0:
        fail(f"no frame in {video}")
    return frames, width, height


def encode_frames(work: Path, frames: int, size: tuple, fps: int, video: Path, quality: str) -> None:
    """``work/frame_NNNN.png`` (``frames`` of them, ``size`` (w, h)) to ``video``: H.264 through
    Blender's FFmpeg at the constant-rate preset ``quality`` (a GOP of a second)."""
    import bpy

    from mirrorcap.addon.common.video_out import h264_output

    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.fps = fps
    scene.frame_start, scene.frame_end = 1, frames
    scene.view_settings.view_transform = "Standard"
    editor = scene.sequence_editor_create()
    strips = editor.strips if hasattr(editor, "strips") else editor.sequences
    strip = strips.new_image("frames", str(work / "frame_0000.png"), channel=1, frame_start=1)
    for f in range(1, frames):
        strip.elements.append(f"frame_{f:04d}.png")
    h264_output(scene.render, video, quality, gop_size=fps)
    bpy.ops.render.render(animation=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="a clip folder of make_rig_clip.py")
    parser.add_argument("out", type=Path, help="the folder to write (replaced when it exists)")
    parser.add_argument("--quality", choices=sorted(CRF, key=CRF.get), default="LOW",
                        help="Blender's constant-rate preset (default LOW: CRF 26)")
    args = parser.parse_args(argv)

    made = json.loads((args.source / "clip.json").read_text())
    work = Path(tempfile.mkdtemp(prefix="reencode-"))
    try:
        frames, width, height = read_frames(args.source / "clip.mp4", work)
        staged = work / "clip"
        staged.mkdir()
        encode_frames(work, frames, (width, height), int(made.get("fps", 30)), staged / "clip.mp4", args.quality)
        for f in args.source.iterdir():
            if f.is_file() and f.name not in ("clip.mp4", "clip.json"):
                shutil.copy2(f, staged / f.name)
        made["reencoded"] = {"from": args.source.name, "quality": args.quality, "crf": CRF[args.quality]}
        (staged / "clip.json").write_text(json.dumps(made, indent=2) + "\n")
        shutil.rmtree(args.out, ignore_errors=True)
        shutil.move(str(staged), str(args.out))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    size = (args.out / "clip.mp4").stat().st_size
    print(f"{args.out / 'clip.mp4'}: {size / 1e6:.2f} MB, {frames} frames at CRF {CRF[args.quality]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
