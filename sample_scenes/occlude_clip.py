"""Pass an object in front of a rig clip's face -- `make occluded-clips`.

A performer's hand goes to the mouth, a microphone swings past the chin: for a while markers vanish
from a view and come back, some of them half covered at the object's edge. This writes a copy of a
clip folder of `make_rig_clip.py` with a dark sphere (a hand or a microphone under black light:
nothing on it fluoresces) swept sideways in front of the lower face for frames ``A``..``B``:
``--radius-mm`` (default 30), ``--ahead-mm`` (how far in front of the lower face's markers, towards the
camera; default 70) and ``--sweep-mm`` (the sideways travel, default 120). The sphere is drawn
where the camera sees it directly and, inside each mirror's view, where it sees its mirror image.

The truth follows: ``visible`` loses each marker whose image the sphere covers in that view (the
real sphere covers whatever lies behind it in the image; the mirror image covers a marker's mirror
image it stands in front of), so completeness is measured against what the camera saw. ``clip.json``
records ``"occluded": {"from", "frames", "radius_mm", "ahead_mm", "sweep_mm"}``; the video is
re-encoded as `make_rig_clip.py` encodes (H.264, perceptually lossless). The copy appears whole or
not at all.

    python sample_scenes/occlude_clip.py sample_scenes/stress/motion sample_scenes/stress/occluded --frames 30 70
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

from mirrorcap.core.geometry.camera import Camera  # noqa: E402
from mirrorcap.core.geometry.mirror import reflect_points  # noqa: E402
from reencode_clip import encode_frames, fail, read_frames  # noqa: E402

LOWER_FACE_SHARE = 0.3     # the sphere runs in front of the lowest 30 % of the markers (mouth and chin)
SPHERE_BGR = (24, 12, 18)  # skin or a foam cover, dimly lit by the black light


def sphere_path(points, frames, ahead_mm: float, sweep_mm: float) -> np.ndarray:
    """The sphere's centre ``(F, 3)`` (camera frame, mm; NaN outside ``frames`` = (first, last)):
    in front of the lower face's markers -- followed as the head moves -- by ``ahead_mm``, swept
    sideways over ``sweep_mm`` from the first frame to the last."""
    first, last = frames
    rest = points[0]
    lower = rest[:, 1] >= np.quantile(rest[:, 1], 1.0 - LOWER_FACE_SHARE)   # y is down in the camera frame
    centre = np.full((len(points), 3), np.nan)
    span = np.arange(first, last + 1)
    along = (span - first) / max(last - first, 1) - 0.5                     # -0.5 .. 0.5
    centre[span] = points[span][:, lower].mean(axis=1) + np.stack(
        [along * sweep_mm, np.zeros_like(along), np.full_like(along, -ahead_mm)], axis=1)
    return centre


def disc(camera: Camera, centre, radius_mm: float):
    """A sphere's image as a disc: its centre's pixel ``(..., 2)`` and its apparent radius in pixels
    (the silhouette's, f r / sqrt(z^2 - r^2))."""
    z = centre[..., 2]
    return camera.project(centre), camera.focal_px * radius_mm / np.sqrt(np.maximum(z ** 2 - radius_mm ** 2, 1e-9))


def hidden_markers(camera: Camera, normals, ds, points, centre, radius_mm: float) -> np.ndarray:
    """``(F, 3, M)``: each marker hidden in the direct view and each mirror's by the sphere at ``centre``
    (``(F, 3)``, NaN: none). The real sphere stands in front of all it covers in the image; a mirror image
    of the sphere covers the mirror images of markers behind it."""
    F, M = points.shape[:2]
    hidden = np.zeros((F, 3, M), bool)
    on = np.isfinite(centre[:, 0])
    if not on.any():
        return hidden
    c_px, c_r = disc(camera, centre[on], radius_mm)
    hidden[on, 0] = np.linalg.norm(camera.project(points[on]) - c_px[:, None], axis=2) < c_r[:, None]
    for k, (n, d) in enumerate(zip(normals, ds)):
        image = reflect_points(points[on], n, d)
        px = camera.project(image)
        behind_real = np.linalg.norm(px - c_px[:, None], axis=2) < c_r[:, None]
        mirrored = reflect_points(centre[on], n, d)
        m_px, m_r = disc(camera, mirrored, radius_mm)
        behind_image = ((np.linalg.norm(px - m_px[:, None], axis=2) < m_r[:, None])
                        & (np.linalg.norm(image, axis=2) > np.linalg.norm(mirrored, axis=1)[:, None]))
        hidden[on, k + 1] = behind_real | behind_image
    return hidden


def draw_sphere(image, camera: Camera, normals, ds, centre, radius_mm: float, views: dict) -> None:
    """Paint the sphere's image, and inside each mirror's view rectangle its mirror image, on
    ``image`` (BGR, in place, anti-aliased to a sixteenth of a pixel)."""
    import cv2

    layer = np.zeros(image.shape[:2], np.uint8)
    shift = 4

    def fill(target, px, r):
        cv2.circle(target, tuple(int(round(v * 2 ** shift)) for v in px), int(round(r * 2 ** shift)), 255, -1,
                   cv2.LINE_AA, shift)

    for k, (n, d) in enumerate(zip(normals, ds)):
        x0, y0, x1, y1 = (int(round(v)) for v in views[f"mirror{k}"])
        mirrored = np.zeros_like(layer)
        fill(mirrored, *disc(camera, reflect_points(centre, n, d), radius_mm))
        layer[y0:y1, x0:x1] = np.maximum(layer[y0:y1, x0:x1], mirrored[y0:y1, x0:x1])
    fill(layer, *disc(camera, centre, radius_mm))
    alpha = layer[..., None] / 255.0
    image[:] = np.round(image * (1 - alpha) + np.array(SPHERE_BGR) * alpha).astype(np.uint8)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("source", type=Path, help="a clip folder of make_rig_clip.py")
    parser.add_argument("out", type=Path, help="the folder to write (replaced when it exists)")
    parser.add_argument("--frames", type=int, nargs=2, metavar=("A", "B"), required=True,
                        help="the first and last frame the sphere passes in front of the face")
    parser.add_argument("--radius-mm", type=float, default=30.0)
    parser.add_argument("--ahead-mm", type=float, default=70.0,
                        help="how far in front of the lower face's markers the sphere passes")
    parser.add_argument("--sweep-mm", type=float, default=120.0, help="its sideways travel over the frames")
    args = parser.parse_args(argv)

    import cv2

    made = json.loads((args.source / "clip.json").read_text())
    camera = Camera.from_dict(json.loads((args.source / "camera.json").read_text()))
    views = json.loads((args.source / "rig.json").read_text())["views"]
    truth = dict(np.load(args.source / "truth.npz"))
    points = truth["points"].astype(float)
    first, last = args.frames
    if not 0 <= first <= last < len(points):
        parser.error(f"--frames must lie within the clip's {len(points)} frames, the first not after the last")
    if args.radius_mm <= 0 or args.ahead_mm <= args.radius_mm:
        parser.error("--radius-mm must be positive and --ahead-mm larger than it (the sphere in front of the face)")
    centre = sphere_path(points, (first, last), args.ahead_mm, args.sweep_mm)
    normals, ds = truth["mirror_normals"], truth["mirror_d"]
    work = Path(tempfile.mkdtemp(prefix="occlude-"))
    try:
        frames, width, height = read_frames(args.source / "clip.mp4", work)
        if frames != len(points):
            fail(f"the video holds {frames} frames and the truth {len(points)}")
        for f in range(first, last + 1):
            png = work / f"frame_{f:04d}.png"
            image = cv2.imread(str(png))
            draw_sphere(image, camera, normals, ds, centre[f], args.radius_mm, views)
            cv2.imwrite(str(png), image)
        staged = work / "clip"
        staged.mkdir()
        encode_frames(work, frames, (width, height), int(made.get("fps", 30)), staged / "clip.mp4", "PERC_LOSSLESS")
        hidden = hidden_markers(camera, normals, ds, points, centre, args.radius_mm)
        covered = int((truth["visible"] & hidden).sum())
        truth["visible"] = truth["visible"] & ~hidden
        np.savez_compressed(staged / "truth.npz", **truth)
        for f in args.source.iterdir():
            if f.is_file() and f.name not in ("clip.mp4", "clip.json", "truth.npz"):
                shutil.copy2(f, staged / f.name)
        made["occluded"] = {"from": args.source.name, "frames": [first, last], "radius_mm": args.radius_mm,
                            "ahead_mm": args.ahead_mm, "sweep_mm": args.sweep_mm}
        (staged / "clip.json").write_text(json.dumps(made, indent=2) + "\n")
        shutil.rmtree(args.out, ignore_errors=True)
        shutil.move(str(staged), str(args.out))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"{args.out / 'clip.mp4'}: the sphere in frames {first}-{last} covered {covered} seen marker-views")
    return 0


if __name__ == "__main__":
    sys.exit(main())
