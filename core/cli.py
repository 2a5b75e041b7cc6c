"""The ``mirrorcap`` command line (also ``python -m mirrorcap``).

Commands:

``mirrorcap reconstruct PAIRS.csv --camera CAMERA.json -o POINTS.csv [--known-length ID_A ID_B MM]``
    mirror planes + 3D points from one frame of correspondences.
``mirrorcap demo [--out DIR]``
    the main job on the embedded sample.

Bad input exits with status 2 and one line ``mirrorcap: error: ...`` on stderr;
no output file is written.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from . import __version__
from .errors import MirrorCapError


def _cmd_reconstruct(args) -> int:
    from .atomic import write_files_atomically
    from .camera import Camera
    from .pairs import format_points, read_pairs
    from .reconstruct import KnownLength, reconstruct_pairs

    camera = Camera.load(args.camera)
    table = read_pairs(args.pairs)
    known = None
    if args.known_length is not None:
        a, b, mm = args.known_length
        try:
            mm = float(mm)
        except ValueError:
            raise MirrorCapError(f"--known-length: {mm!r} is not a number of millimetres") from None
        known = KnownLength(a, b, mm)
    result = reconstruct_pairs(table, camera, known_length=known, refine=args.refine,
                               robust=not args.no_ransac, threshold_px=args.threshold, seed=args.seed)
    out = Path(args.output)
    report = result.report()
    report["inputs"] = {"pairs": str(args.pairs), "camera": str(args.camera)}
    report["mirrorcap_version"] = __version__
    write_files_atomically({
        out.with_suffix(".json"): json.dumps(report, indent=2) + "\n",
        out: format_points(result.ids, result.points, result.mirrors_label),
    })
    if not args.quiet:
        print(f"{len(result.ids)} points ({report['fused_points']} seen in both mirrors) -> {out} "
              f"[{result.units}]")
        for k, pl in enumerate(result.planes):
            err = pl.expected_error_deg
            print(f"  mirror {k}: normal ({pl.normal[0]:+.5f}, {pl.normal[1]:+.5f}, {pl.normal[2]:+.5f}) "
                  f"d={pl.d:.6g}  inliers {pl.n_inliers}/{pl.inliers.size}  noise {pl.noise_px:.3f} px  "
                  f"expected normal error {err:.4f} deg")
        for w in result.warnings:
            print(f"  warning: {w}")
    return 0


def _cmd_demo(args) -> int:
    from .demo import run_demo

    return run_demo(Path(args.out), quiet=args.quiet)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mirrorcap",
        description="MirrorCap: facial capture from one camera and two mirrors.",
    )
    parser.add_argument("--version", action="version", version=f"mirrorcap {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    rec = sub.add_parser(
        "reconstruct", help="mirror planes and 3D points from real-vs-mirrored pairs",
        description="Estimate each mirror plane from PAIRS.csv (closed form, eq. 3.8, with RANSAC) and "
                    "reconstruct the markers (eq. 3.10-3.12). Writes POINTS.csv and POINTS.json.",
    )
    rec.add_argument("pairs", help="PAIRS.csv with columns id,mirror,x,y,xm,ym (pixels)")
    rec.add_argument("--camera", required=True, help="CAMERA.json with K, dist and image_size")
    rec.add_argument("-o", "--output", required=True, help="POINTS.csv to write (a .json report goes beside it)")
    rec.add_argument("--known-length", nargs=3, metavar=("ID_A", "ID_B", "MM"),
                     help="distance between two markers in millimetres; sets the output units to mm")
    rec.add_argument("--refine", action="store_true",
                     help="maximum-likelihood refinement of planes and points by reprojection error")
    rec.add_argument("--threshold", type=float, default=2.0,
                     help="RANSAC inlier threshold: symmetric epipolar distance in pixels (default 2)")
    rec.add_argument("--no-ransac", action="store_true",
                     help="use every pair in the closed-form estimate (the paper's eq. 3.8 as is)")
    rec.add_argument("--seed", type=int, default=0, help="random seed of RANSAC (default 0)")
    rec.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")
    rec.set_defaults(func=_cmd_reconstruct)

    demo = sub.add_parser("demo", help="run the main job on the embedded sample and print its accuracy")
    demo.add_argument("--out", default="out", help="folder for the demo's outputs (default out/)")
    demo.add_argument("-q", "--quiet", action="store_true")
    demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "threshold", 1.0) <= 0:
        parser.error("--threshold must be positive")
    try:
        return args.func(args)
    except MirrorCapError as exc:
        print(f"mirrorcap: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
