"""The ``mirrorcap`` command line (also ``python -m mirrorcap``).

Commands:

``mirrorcap reconstruct PAIRS.csv --camera CAMERA.json -o POINTS.csv [--known-length ID_A ID_B MM]``
    mirror planes + 3D points from one frame of correspondences.
``mirrorcap calibrate IMAGES_OR_VIDEO --board SPEC -o CAMERA.json``
    camera intrinsics and distortion from views of a chessboard or ChArUco board.
``mirrorcap detect VIDEO [--camera CAMERA.json] [--colors COLORS.json] [--rig RIG.json] -o DETECTIONS.csv``
    markers in every frame, in the direct view and both mirrors.
``mirrorcap track VIDEO --camera CAMERA.json -o TAKE.c3d [--report REPORT.json] [--mirrors MIRRORS.json]``
    labelled 3D marker trajectories with head motion separated.
``mirrorcap mirrors VIDEO --camera CAMERA.json --board charuco:... -o MIRRORS.json``
    mirror planes (in mm) from a ChArUco board seen directly and in both mirrors.
``mirrorcap colors learn VIDEO --classes K -o COLORS.json``
    colour classes learned from sample frames.
``mirrorcap demo [--out DIR]``
    the main job on the embedded sample.
``mirrorcap bake TAKE.c3d --head HEAD.blend -o OUT.blend [--mode frames|pca] [--modes K]``
    (needs bpy; defined in the package's ``cli.py``) the take as shape keys on the head.

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


def _open(args):
    from .video import open_source, parse_frame_range

    source = open_source(args.source, fps=getattr(args, "fps", None))
    start, end = parse_frame_range(getattr(args, "frames", None))
    return source, start, end


def _cmd_calibrate(args) -> int:
    from .atomic import write_files_atomically
    from .calibrate import Board, calibrate_camera

    board = Board.parse(args.board)
    source, _, _ = _open(args)
    result = calibrate_camera(source, board, max_views=args.max_views, min_views=args.min_views,
                              max_rms_px=args.max_rms)
    write_files_atomically({Path(args.output): json.dumps(result.to_dict(), indent=2) + "\n"})
    if not args.quiet:
        K = result.camera.K
        print(f"calibrated from {result.views_used} of {result.views_tried} views, RMS reprojection error "
              f"{result.rms_px:.3f} px -> {args.output}")
        print(f"  fx {K[0, 0]:.2f}  fy {K[1, 1]:.2f}  cx {K[0, 2]:.2f}  cy {K[1, 2]:.2f}  "
              f"dist {' '.join(f'{v:+.4f}' for v in result.camera.dist)}")
    return 0


def _cmd_detect(args) -> int:
    from .camera import Camera
    from .detect import run_detection
    from .markers import ColorClasses, ExtractionSettings, load_rig_views

    colors = ColorClasses.load(args.colors) if args.colors else ColorClasses.default()
    layout = load_rig_views(args.rig) if args.rig else None
    camera = Camera.load(args.camera) if args.camera else None
    if args.threshold < 0 or args.threshold >= 255:
        raise MirrorCapError("--threshold must be in 0..254")
    if args.min_area < 1 or args.marker_diameter < 0:
        raise MirrorCapError("--min-area must be at least 1 and --marker-diameter non-negative")
    settings = ExtractionSettings(threshold=args.threshold, min_area=args.min_area,
                                  marker_diameter_px=args.marker_diameter)
    source, start, end = _open(args)
    report = run_detection(source, args.output, colors=colors, settings=settings, layout=layout, camera=camera,
                           start=start, end=end, step=args.step, progress=not args.quiet)
    if not args.quiet:
        c = report["counts"]
        n = report["frames"]["processed"]
        print(f"{n} frames -> {args.output}: per frame {c['direct'] / n:.1f} direct, {c['mirror0'] / n:.1f} mirror0, "
              f"{c['mirror1'] / n:.1f} mirror1 ({report['frames_per_second']:.0f} frames/s)")
    return 0


def _cmd_track(args) -> int:
    import numpy as np

    from .boardcal import load_mirrors
    from .camera import Camera
    from .markers import ColorClasses, load_rig_rigid, load_rig_views
    from .take import rigid_selection, run_track
    from .track import TrackSettings

    camera = Camera.load(args.camera)
    colors = ColorClasses.load(args.colors) if args.colors else None
    layout = load_rig_views(args.rig) if args.rig else None
    rigid = rigid_selection(load_rig_rigid(args.rig) if args.rig else None, colors or ColorClasses.default())
    mirrors = load_mirrors(args.mirrors) if args.mirrors else None
    known = None
    if args.known_length:
        a, b, mm = args.known_length
        try:
            known = (a, b, float(mm))
        except ValueError:
            raise MirrorCapError(f"--known-length: {mm!r} is not a number of millimetres") from None
    if not args.face_distance > 0:
        raise MirrorCapError("--face-distance must be a positive number of millimetres")
    if not args.conjecture_limit >= 0:
        raise MirrorCapError("--conjecture-limit must be a number of millimetres, 0 or more (or inf)")
    settings = TrackSettings.with_conjecture_limit(args.conjecture_limit)
    source, start, end = _open(args)
    report = run_track(source, camera, Path(args.output), report=Path(args.report) if args.report else None,
                       colors=colors, layout=layout, mirrors=mirrors, known_length=known, start=start, end=end,
                       step=args.step, face_distance_mm=args.face_distance, settings=settings, rigid=rigid)
    if not args.quiet:
        pf = report["per_frame"]
        n = report["frames"]["count"]
        print(f"{report['markers']['count']} markers over {n} frames -> {args.output} [{report['units']}]")
        print(f"  per frame: {np.mean(pf['measured']):.1f} measured, {np.mean(pf['conjectured']):.1f} conjectured, "
              f"{np.mean(pf['false_tracking']):.2f} false tracking, {np.mean(pf['conflicts']):.2f} conflicts, "
              f"{np.mean(pf['withheld']):.1f} conjectures withheld; "
              f"tracking {report['timings_s']['tracking_frames_per_s']:.0f} frames/s")
        undecided = report["markers"]["undecided"]
        if undecided:
            print(f"  {len(undecided)} direct-view markers of the first frames could not be paired with a mirror "
                  f"image (no 3D position): REPORT.json markers.undecided lists where they are")
    return 0


def _cmd_mirrors(args) -> int:
    from .atomic import write_files_atomically
    from .boardcal import calibrate_mirrors_from_board, write_mirrors_json
    from .calibrate import Board
    from .camera import Camera
    from .markers import load_rig_views

    board = Board.parse(args.board)
    camera = Camera.load(args.camera)
    layout = load_rig_views(args.rig) if args.rig else None
    source, start, end = _open(args)
    if camera.image_size != source.size:
        raise MirrorCapError(f"the camera file is for {camera.image_size[0]}x{camera.image_size[1]} images but "
                             f"{source.path} is {source.size[0]}x{source.size[1]}")
    frames = (img for _, img in source.frames(start, end, args.step))
    result = calibrate_mirrors_from_board(frames, camera, board, layout=layout, threshold_px=args.threshold)
    write_files_atomically({Path(args.output): write_mirrors_json(result, board)})
    if not args.quiet:
        print(f"mirror planes from {result.frames_used} frames -> {args.output}")
        for k, pl in enumerate(result.planes):
            print(f"  mirror {k}: normal ({pl.normal[0]:+.5f}, {pl.normal[1]:+.5f}, {pl.normal[2]:+.5f}) "
                  f"d {pl.d:.2f} mm  corners {pl.n_inliers}/{pl.inliers.size}  noise {pl.noise_px:.3f} px")
    return 0


def _cmd_colors_learn(args) -> int:
    from .atomic import write_files_atomically
    from .detect import learn_color_classes

    source, start, end = _open(args)
    names = [n.strip() for n in args.names.split(",")] if args.names else None
    classes = learn_color_classes(source, args.classes, names=names, start=start, end=end, step=args.step,
                                  threshold=args.threshold)
    write_files_atomically({Path(args.output): json.dumps(classes.to_dict(), indent=2) + "\n"})
    if not args.quiet:
        print(f"{len(classes.names)} colour classes -> {args.output}: {', '.join(classes.names)}")
    return 0


def _cmd_demo(args) -> int:
    from .demo import run_demo

    return run_demo(Path(args.out), quiet=args.quiet)


def _source_options(parser, what: str = "video file, image folder or glob", frames: bool = True):
    """The options every command reading a rig video shares."""
    parser.add_argument("source", help=what)
    if frames:
        parser.add_argument("--frames", help="START:END frame range (END exclusive)")
        parser.add_argument("--step", type=int, default=1, help="use every STEP-th frame")
    parser.add_argument("--fps", type=float, help="frame rate of an image sequence (default 30)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def build_parser(extra_commands=None) -> argparse.ArgumentParser:
    """The parser of every core command; ``extra_commands(sub)`` adds more (the Blender ones)."""
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

    cal = sub.add_parser("calibrate", help="camera intrinsics from views of a calibration board",
                         description="Calibrate the camera from a video or images of a chessboard or ChArUco board.")
    _source_options(cal, frames=False)
    cal.add_argument("--board", required=True,
                     help="chessboard:COLSxROWS:SQUARE_MM (inner corners) or "
                          "charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT] (squares)")
    cal.add_argument("-o", "--output", required=True, help="CAMERA.json to write")
    cal.add_argument("--max-views", type=int, default=40, help="frames sampled evenly from the source (default 40)")
    cal.add_argument("--min-views", type=int, default=6, help="fewest views with the board found (default 6)")
    cal.add_argument("--max-rms", type=float, default=1.0, help="largest acceptable RMS reprojection error, px")
    cal.set_defaults(func=_cmd_calibrate)

    det = sub.add_parser("detect", help="find the markers in every frame of a rig video",
                         description="Marker extraction (threshold, colour 1-NN, connected components, merging, "
                                     "specks removed, sub-pixel centres) in the direct view and both mirrors.")
    _source_options(det)
    det.add_argument("-o", "--output", required=True, help="DETECTIONS.csv to write (a .json report goes beside it)")
    det.add_argument("--camera", help="CAMERA.json; its image size must match the video")
    det.add_argument("--colors", help="COLORS.json colour classes (default: the four blacklight colours)")
    det.add_argument("--rig", help="RIG.json with view rectangles (default: split at the two widest gaps)")
    det.add_argument("--threshold", type=float, default=60.0, help="brightness threshold on max(R,G,B), 0..254")
    det.add_argument("--min-area", type=int, default=4, help="smallest marker in pixels (default 4)")
    det.add_argument("--marker-diameter", type=float, default=6.0,
                     help="marker diameter in pixels; closer fragments of one colour merge (default 6)")
    det.set_defaults(func=_cmd_detect)

    trk = sub.add_parser("track", help="labelled 3D marker trajectories from a rig video (C3D)",
                         description="Detect markers, calibrate the mirrors (MIRRORS.json or self-calibration from "
                                     "the markers), track them in 3D with head motion separated, and write a C3D take.")
    _source_options(trk, "rig video file, image folder or glob")
    trk.add_argument("--camera", required=True, help="CAMERA.json")
    trk.add_argument("-o", "--output", required=True, help="TAKE.c3d to write")
    trk.add_argument("--report", help="REPORT.json to write beside the take")
    trk.add_argument("--mirrors", help="MIRRORS.json (from `mirrorcap mirrors`); default: self-calibration")
    trk.add_argument("--known-length", nargs=3, metavar=("LABEL_A", "LABEL_B", "MM"),
                     help="distance between two tracked markers (labels m000..) in mm; sets the units to mm")
    trk.add_argument("--face-distance", type=float, default=600.0, metavar="MM",
                     help="without --mirrors: the face's distance from the camera that sets the take's scale "
                          "(default 600; --known-length makes the scale exact)")
    trk.add_argument("--conjecture-limit", type=float, default=2.0, metavar="MM",
                     help="report a hidden marker's conjectured position only where its expected error (3 sigma) "
                          "is within MM; the rest stay gaps (default 2; 'inf' keeps every conjecture, 0 none)")
    trk.add_argument("--colors", help="COLORS.json colour classes")
    trk.add_argument("--rig", help="RIG.json view rectangles, and optionally the rigid markers (\"rigid\")")
    trk.set_defaults(func=_cmd_track)

    mir = sub.add_parser("mirrors", help="mirror planes in mm from a ChArUco board seen in all three views",
                         description="Detect a ChArUco board directly and (flipped) in both mirrors, estimate each "
                                     "mirror plane (eq. 3.8 with RANSAC) and fix the scale from the board's size.")
    _source_options(mir, "video file, image folder or glob of the board in the rig")
    mir.add_argument("--camera", required=True, help="CAMERA.json")
    mir.add_argument("--board", required=True, help="charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT]")
    mir.add_argument("-o", "--output", required=True, help="MIRRORS.json to write")
    mir.add_argument("--rig", help="RIG.json view rectangles (default: the image's thirds)")
    mir.add_argument("--threshold", type=float, default=2.0, help="RANSAC threshold in pixels (default 2)")
    mir.set_defaults(func=_cmd_mirrors)

    colors = sub.add_parser("colors", help="colour classes for marker labelling")
    colors_sub = colors.add_subparsers(dest="colors_command", required=True, metavar="ACTION")
    learn = colors_sub.add_parser("learn", help="learn colour classes from sample frames (k-means)")
    _source_options(learn)
    learn.add_argument("--classes", type=int, required=True, help="number of colour classes")
    learn.add_argument("-o", "--output", required=True, help="COLORS.json to write")
    learn.add_argument("--names", help="comma-separated class names, in hue order")
    learn.add_argument("--threshold", type=float, default=60.0)
    learn.set_defaults(func=_cmd_colors_learn)

    demo = sub.add_parser("demo-mirrors", help="mirror planes and 3D points of the embedded two-mirror sample",
                          description="Reconstruct sample_scenes/mirror_demo (pairs -> mirror planes -> 3D points "
                                      "in mm) and compare with its ground truth. (`mirrorcap demo` runs the whole "
                                      "capture-to-animation job; it needs bpy.)")
    demo.add_argument("--out", default="out", help="folder for the outputs (default out/)")
    demo.add_argument("-q", "--quiet", action="store_true")
    demo.set_defaults(func=_cmd_demo)
    if extra_commands is not None:
        extra_commands(sub)
    return parser


def main(argv=None, extra_commands=None) -> int:
    parser = build_parser(extra_commands)
    args = parser.parse_args(argv)
    if getattr(args, "threshold", 1.0) <= 0:
        parser.error("--threshold must be positive")
    try:
        return args.func(args)
    except MirrorCapError as exc:
        print(f"mirrorcap: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:       # outputs are written atomically: nothing half-written is left
        print("mirrorcap: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
