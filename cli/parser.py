"""The ``mirrorcap`` command line: the one parser (also ``python -m mirrorcap``).

Commands (each documented in the README):

``mirrorcap reconstruct PAIRS.csv --camera CAMERA.json -o POINTS.csv [--known-length ID_A ID_B MM]``
    mirror planes + 3D points from one frame of correspondences.
``mirrorcap calibrate IMAGES_OR_VIDEO --board SPEC -o CAMERA.json``
    camera intrinsics and distortion from views of a chessboard or ChArUco board.
``mirrorcap detect VIDEO [--camera CAMERA.json] [--colors COLORS.json] [--light uv|normal] [--rig RIG.json] -o DETECTIONS.csv``
    markers in every frame, in the direct view and both mirrors.
``mirrorcap track VIDEO --camera CAMERA.json -o TAKE.c3d [--report REPORT.json] [--mirrors MIRRORS.json]``
    labelled 3D marker trajectories with head motion separated.
``mirrorcap mirrors VIDEO --camera CAMERA.json --board charuco:... -o MIRRORS.json``
    mirror planes (in mm) from a ChArUco board seen directly and in both mirrors.
``mirrorcap colors learn VIDEO --classes K [--light uv|normal] -o COLORS.json``
    colour classes learned from sample frames.
``mirrorcap bake TAKE.c3d --head HEAD.blend -o OUT.blend [--mode frames|pca] [--modes K] [--frames S:E] ...``
    bind the take to the head, run the face rig on every frame, write the head with shape keys.
``mirrorcap retarget TAKE.c3d --head HEAD.blend --target TARGET.blend -o OUT.blend [--method arkit|transfer] [--csv LIVELINK.csv]``
    ARKit-52 weights of the take keyed on another character's shape keys.
``mirrorcap fap TAKE.c3d --head HEAD.blend -o TAKE.fap`` / ``mirrorcap bake --fap TAKE.fap --head HEAD.blend -o OUT.blend``
    MPEG-4 FAPs of a take / a .fap file played on a head.
``mirrorcap batch TAKES... --head HEAD.blend --out DIR [--workers N] [bake options]``
    bake many takes in parallel worker processes (:mod:`.batch`).
``mirrorcap info TAKE.c3d [--json]`` / ``mirrorcap export TAKE.c3d -o POINTS.csv``
    what a C3D take holds / its points as ``frame,label,x,y,z`` CSV.
``mirrorcap stabilize TAKE.c3d -o OUT.c3d [--rigid LABEL ...] [--method invariants|arun] [--pivot auto|none|X,Y,Z]``
    head motion removed about the rotation pivot (seed 001, eq. 1-9).
``mirrorcap demo [--out DIR]`` / ``mirrorcap demo-mirrors [--out DIR]``
    the whole job on the embedded sample clip / the mirror core on the two-mirror sample.

The parser imports nothing heavy: each command's module imports what it needs when it runs
(numpy for ``track``, ``bpy`` only for ``bake``, ``batch`` and ``demo``). Bad input exits with
status 2 and one line ``mirrorcap: error: ...`` on stderr; no output file is written.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
from contextlib import ExitStack

from ..core import __version__
from ..core.common.errors import MirrorCapError
from ..core.common.files import check_output_paths
from ..core.common.threads import limited_threads
from . import commands
from .interrupts import caused_by_ctrl_c, interrupts_held


def _source_options(parser, what: str = "video file, image folder or glob", frames: bool = True):
    """The options every command reading a rig video shares."""
    parser.add_argument("source", help=what)
    if frames:
        parser.add_argument("--frames", help="START:END frame range (END exclusive)")
        parser.add_argument("--step", type=int, default=1, help="use every STEP-th frame")
    parser.add_argument("--fps", type=float, help="frame rate of an image sequence (default 30)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print nothing on success")


def _light_option(parser) -> None:
    parser.add_argument("--light", choices=("uv", "normal"),
                        help="uv: fluorescent markers under black light; normal: coloured dots under ordinary "
                             "lamps (default: what COLORS.json says, else what the first frame shows -- a dark "
                             "frame with bright dots is uv, a lit face normal)")


def _washed_out_option(parser) -> None:
    parser.add_argument("--washed-out", choices=("auto", "keep", "drop"), default="auto",
                        help="normal light: dots whose colour compression washed out between the colour classes -- "
                             "kept (classed by their colour less the skin's), dropped, or auto: kept when the first "
                             "30 frames hold more than 2 %% as many of them as other dots (default auto)")


def _unseen_options(parser) -> None:
    """What happens to markers not seen in the neutral frame (a tracker's markers first seen later): one ``unseen``
    (:func:`core.face.bind.bind_take`), placed from their neighbours unless said otherwise, as in the add-on."""
    unseen = parser.add_mutually_exclusive_group()
    unseen.add_argument("--conjecture-unseen", dest="unseen", action="store_const", const="conjecture",
                        help="place markers not seen in the neutral frame (a tracker's markers first seen later) "
                             "from their neighbours' learned relations; those expected off by more than 2 mm "
                             "(3 sigma) are left out (the default)")
    unseen.add_argument("--drop-unseen", dest="unseen", action="store_const", const="drop",
                        help="leave out markers not seen in the neutral frame")
    unseen.add_argument("--refuse-unseen", dest="unseen", action="store_const", const="error",
                        help="refuse a take with markers not seen in the neutral frame")
    parser.set_defaults(unseen="conjecture")


def _binding_options(parser) -> None:
    """How a C3D take is bound to the actor's head (``retarget``, ``fap``)."""
    parser.add_argument("--head-pose", help="REPORT.json of `mirrorcap track` (default: estimate the head motion)")
    parser.add_argument("--marker-map", metavar="MAP.json", help="bind markers by name (as for bake)")
    parser.add_argument("--neutral-frame", type=int, default=0, help="take frame of the neutral face (default 0)")
    _unseen_options(parser)


def _scene_frame(text: str) -> int:
    """``--frame-start``: a Blender frame number (0 or more)."""
    try:
        frame = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a frame number: {text!r}") from None
    if frame < 0:
        raise argparse.ArgumentTypeError(f"a Blender scene starts at frame 0 or later, not {frame}")
    return frame


def _keying_options(parser, take_range: bool = False) -> None:
    """Which take frames are keyed, and at which scene frames (``bake``, ``batch``, ``retarget``)."""
    parser.add_argument("--frame-start", type=_scene_frame, default=1,
                        help="scene frame of the first keyed frame; the scene's frame range is set to the keys "
                             "(default 1; e.g. 1001 for a pipeline's shots)")
    if take_range:
        parser.add_argument("--frames", metavar="START:END",
                            help="the take frames to key, 0-based, END exclusive (default: all); the whole take is "
                                 "bound, and its frames come out as they do from the whole take, blinks included")


def _bake_options(parser) -> None:
    parser.add_argument("--object", help="the head object's name (default: the only head in the file)")
    parser.add_argument("--mode", choices=("frames", "pca"), default="frames",
                        help="frames: one shape key per frame; pca: K eigen-deformation keys (default frames)")
    parser.add_argument("--modes", type=int, default=8, help="number of PCA modes (default 8)")
    parser.add_argument("--neutral-frame", type=int, default=0, help="take frame of the neutral face (default 0)")
    parser.add_argument("--head-motion", action="store_true", help="key the head motion as the object's transform")
    _keying_options(parser, take_range=True)
    _unseen_options(parser)
    parser.add_argument("--no-blinks", action="store_true", help="no synthetic eyelid blinks")
    parser.add_argument("--blink-seed", type=int, default=0, help="seed of the blink process (default 0)")
    parser.add_argument("--blink-interval", type=float, default=None,
                        help="mean seconds between blinks (default 2.5; 4 for a sparse take of <= 40 bound markers)")
    parser.add_argument("--marker-map", metavar="MAP.json",
                        help='bind markers by name: {"LABEL": "lm_<name>" | vertex index | "rigid" | "ignore"} '
                             "(a sparse layout without landmark labels; rigid markers carry the head motion)")
    parser.add_argument("--k", type=float, default=16.0, help="RBF kernel constant k of eq. 7.1 in mm (default 16)")
    parser.add_argument("-q", "--quiet", action="store_true")


def build_parser() -> argparse.ArgumentParser:
    """The parser of every ``mirrorcap`` command."""
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
    rec.set_defaults(func=commands.reconstruct)

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
    cal.add_argument("--max-focal-sd", type=float, default=0.5, metavar="PERCENT",
                     help="largest acceptable standard deviation of the focal length, %% of it (default 0.5)")
    cal.set_defaults(func=commands.calibrate)

    det = sub.add_parser("detect", help="find the markers in every frame of a rig video",
                         description="Marker extraction (threshold, colour 1-NN, connected components, merging, "
                                     "specks removed, sub-pixel centres) in the direct view and both mirrors.")
    _source_options(det)
    det.add_argument("-o", "--output", required=True, help="DETECTIONS.csv to write (a .json report goes beside it)")
    det.add_argument("--camera", help="CAMERA.json; its image size must match the video")
    det.add_argument("--colors", help="COLORS.json colour classes (default: the light's four colours)")
    _light_option(det)
    _washed_out_option(det)
    det.add_argument("--rig", help="RIG.json with view rectangles (default: split at the two widest gaps)")
    det.add_argument("--threshold", type=float, default=60.0, help="brightness threshold on max(R,G,B), 0..254")
    det.add_argument("--min-area", type=int, default=4, help="smallest marker in pixels (default 4)")
    det.add_argument("--marker-diameter", type=float, default=None,
                     help="fragments of one colour closer than this many pixels merge (default: each frame's "
                          "typical dot -- the diameter of a disc of its median blob area -- at most 6)")
    det.set_defaults(func=commands.detect)

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
    trk.add_argument("--colors", help="COLORS.json colour classes (default: the light's four colours)")
    _light_option(trk)
    _washed_out_option(trk)
    trk.add_argument("--rig", help="RIG.json view rectangles, and optionally the rigid markers (\"rigid\")")
    trk.add_argument("--seeds", metavar="SEEDS.csv",
                     help="markers designated by hand in the first tracked frame (id,view,x,y): each id's "
                          "direct and mirror points are paired as given and the id becomes its label")
    trk.set_defaults(func=commands.track)

    mir = sub.add_parser("mirrors", help="mirror planes in mm from a ChArUco board seen in all three views",
                         description="Detect a ChArUco board directly and (flipped) in both mirrors, estimate each "
                                     "mirror plane (eq. 3.8 with RANSAC) and fix the scale from the board's size.")
    _source_options(mir, "video file, image folder or glob of the board in the rig")
    mir.add_argument("--camera", required=True, help="CAMERA.json")
    mir.add_argument("--board", required=True, help="charuco:COLSxROWS:SQUARE_MM:MARKER_MM[:DICT]")
    mir.add_argument("-o", "--output", required=True, help="MIRRORS.json to write")
    mir.add_argument("--rig", help="RIG.json view rectangles (default: the image's thirds)")
    mir.add_argument("--threshold", type=float, default=2.0, help="RANSAC threshold in pixels (default 2)")
    mir.set_defaults(func=commands.mirrors)

    colors = sub.add_parser("colors", help="colour classes for marker labelling")
    colors_sub = colors.add_subparsers(dest="colors_command", required=True, metavar="ACTION")
    learn = colors_sub.add_parser("learn", help="learn colour classes from sample frames (k-means)")
    _source_options(learn)
    learn.add_argument("--classes", type=int, required=True, help="number of colour classes")
    learn.add_argument("-o", "--output", required=True, help="COLORS.json to write")
    learn.add_argument("--names", help="comma-separated class names, in hue order")
    learn.add_argument("--threshold", type=float, default=60.0, help="UV: brightness threshold on max(R,G,B)")
    _light_option(learn)
    learn.set_defaults(func=commands.colors_learn)

    demo = sub.add_parser("demo-mirrors", help="mirror planes and 3D points of the embedded two-mirror sample",
                          description="Reconstruct sample_scenes/mirror_demo (pairs -> mirror planes -> 3D points "
                                      "in mm) and compare with its ground truth. (`mirrorcap demo` runs the whole "
                                      "capture-to-animation job; it needs bpy.)")
    demo.add_argument("--out", default="out", help="folder for the outputs (default out/)")
    demo.add_argument("-q", "--quiet", action="store_true")
    demo.set_defaults(func=commands.demo_mirrors)
    _take_commands(sub)
    _blender_commands(sub)
    return parser


def _take_commands(sub) -> None:
    """The commands on any C3D take (from `track` or another motion-capture system)."""
    info = sub.add_parser("info", help="what a C3D take holds: frames, rate, units, labels, gaps, analog channels",
                          description="Read TAKE.c3d (any vendor's C3D) and print its frames, rate, first frame, "
                                      "units, labels with their gaps, and analog channels.")
    info.add_argument("take", help="TAKE.c3d")
    info.add_argument("--json", action="store_true", help="print the same as JSON")
    info.set_defaults(func=commands.info)

    exp = sub.add_parser("export", help="a C3D take as CSV: frame,label,x,y,z in mm",
                         description="Write one row per frame and label, frames numbered as in the file, "
                                     "coordinates in mm, a gap as empty cells.")
    exp.add_argument("take", help="TAKE.c3d")
    exp.add_argument("-o", "--output", required=True, help="POINTS.csv to write")
    exp.add_argument("-q", "--quiet", action="store_true")
    exp.set_defaults(func=commands.export)

    stab = sub.add_parser("stabilize", help="remove the head motion from a C3D take (rigid markers, rotation pivot)",
                          description="Head motion from >= 3 rigid markers (eq. 1-3 of Huang, Lin & Ouhyoung 2000, "
                                      "or Arun's fit), the rotation pivot (eq. 4-8), and every marker written in the "
                                      "head frame of the first frame (eq. 9).")
    stab.add_argument("take", help="TAKE.c3d")
    stab.add_argument("-o", "--output", required=True, help="OUT.c3d to write (the stabilised take)")
    stab.add_argument("--rigid", nargs="+", metavar="LABEL",
                      help="labels of >= 3 markers on a rigid part of the head (default: the 4 that deform least)")
    stab.add_argument("--method", choices=("invariants", "arun"), default="invariants",
                      help="invariants: eq. 1-3 from three rigid markers; arun: SVD fit of all (default invariants)")
    stab.add_argument("--pivot", default="auto",
                      help="auto (eq. 4-8), none, or X,Y,Z in mm in the take's coordinates (default auto)")
    stab.add_argument("--smooth", type=float, default=0.2, metavar="SECONDS",
                      help="smooth the head pose over this window (local quadratic; 0: none; default 0.2)")
    stab.add_argument("--report", help="R.json to write: pivot_mm, per-frame pose, residuals, warnings")
    stab.add_argument("-q", "--quiet", action="store_true")
    stab.set_defaults(func=commands.stabilize)


def _blender_commands(sub) -> None:
    """The commands that run inside Blender (``bpy``)."""
    bake = sub.add_parser("bake", help="bake a take onto a head as shape keys (needs bpy)",
                          description="Register TAKE.c3d to the head (by markers labelled lm_<name>, else by the skin surface), run the face rig "
                                      "(regions, jaw, inner lip, blinks) and write the head with shape keys.")
    bake.add_argument("take", nargs="?", help="TAKE.c3d (from `mirrorcap track` or any C3D with landmark labels)")
    bake.add_argument("--fap", metavar="TAKE.fap",
                      help="play an MPEG-4 FAP file on the head instead of a take (its feature points move, the face "
                           "rig does the rest)")
    bake.add_argument("--head", required=True, help="HEAD.blend with a head mesh (region_*, lm_* vertex groups)")
    bake.add_argument("-o", "--output", required=True, help="OUT.blend to write")
    _bake_options(bake)
    bake.add_argument("--head-pose", help="REPORT.json of `mirrorcap track` (default: estimate the head motion)")
    bake.add_argument("--report", help="BAKE.json to write with the figures of the bake")
    bake.set_defaults(func=commands.bake)

    batch = sub.add_parser("batch", help="bake many takes in parallel processes (needs bpy)",
                           description="Bake every TAKE.c3d onto the head, N at a time, each in its own process. "
                                       "A failing take is reported and does not stop the others.")
    batch.add_argument("takes", nargs="+", help="TAKE.c3d files")
    batch.add_argument("--head", required=True, help="HEAD.blend with a head mesh")
    batch.add_argument("--out", required=True, help="output folder: <take>.blend, <take>.bake.json, batch.json")
    batch.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    _bake_options(batch)
    batch.set_defaults(func=commands.batch)

    ret = sub.add_parser("retarget", help="a take onto another character: ARKit-52 weights or motion transfer "
                                          "(needs bpy)",
                         description="arkit: bind TAKE.c3d to the actor's head (its ARKit shape keys), solve "
                                     "per-frame ARKit weights in [0, 1] (bounded least squares with temporal "
                                     "smoothness), key the target's shape keys of the same names, write OUT.blend "
                                     "(and a Live Link Face CSV). transfer: carry the actor's motion onto a target "
                                     "with lm_<name> landmarks and no shape keys (landmark RBF and projection, "
                                     "feature-distance scaling), keyed as bake keys a head.")
    ret.add_argument("take", help="TAKE.c3d, or a Live Link Face CSV (an iPhone take: its weights are keyed as they are)")
    ret.add_argument("--head", help="HEAD.blend: the actor's head with the 52 ARKit shape keys (for a C3D take)")
    ret.add_argument("--rate", type=float, help="frames/s of a CSV take (default: the rows per second its timecodes "
                     "keep, else 60)")
    ret.add_argument("--head-object", help="the actor's head object (default: the only head in HEAD.blend)")
    ret.add_argument("--target", required=True, help="TARGET.blend: the character")
    ret.add_argument("--target-object", help="the character's mesh (default: the only mesh with ARKit shape keys; "
                                             "with --method transfer the only mesh with lm_* landmark groups)")
    ret.add_argument("-o", "--output", required=True, help="OUT.blend to write (the target file, animated)")
    ret.add_argument("--method", choices=("arkit", "transfer"), default="arkit",
                     help="arkit: ARKit-52 weights on the target's shape keys (default); transfer: the motion "
                          "itself onto a target with landmarks")
    ret.add_argument("--mode", choices=("frames", "pca"), default="frames",
                     help="transfer: one shape key per frame (default) or PCA keys, as bake writes them")
    ret.add_argument("--modes", type=int, default=8, help="transfer --mode pca: number of keys (default 8)")
    ret.add_argument("--csv", help="LIVELINK.csv to write (Live Link Face format)")
    _keying_options(ret, take_range=True)
    _binding_options(ret)
    ret.add_argument("--smoothness", type=float, help="temporal smoothness lambda in mm^2 (default 8)")
    ret.add_argument("--report", help="RETARGET.json to write")
    ret.add_argument("-q", "--quiet", action="store_true")
    ret.set_defaults(func=commands.retarget)

    fap = sub.add_parser("fap", help="MPEG-4 facial animation parameters of a take (needs bpy)",
                         description="Bind TAKE.c3d to the head as bake does, run the face rig, and measure the "
                                     "low-level FAPs 3-64 at the head's MPEG-4 feature points in its FAPU, the head "
                                     "rotation (48-50), and the viseme and expression (FAP 1-2) by nearest pose; "
                                     "write them in the MPEG-4 FAP text form.")
    fap.add_argument("take", help="TAKE.c3d")
    fap.add_argument("--head", required=True, help="HEAD.blend with a head mesh (lm_*, region_* and optionally "
                                                   "fp_<id> vertex groups)")
    fap.add_argument("--object", help="the head object's name (default: the only head in the file)")
    fap.add_argument("-o", "--output", required=True, help="TAKE.fap to write")
    _binding_options(fap)
    fap.add_argument("--no-high-level", action="store_true", help="leave FAP 1 (viseme) and 2 (expression) out")
    fap.add_argument("--report", help="FAP.json to write: feature points, FAPU, FAPs written")
    fap.add_argument("-q", "--quiet", action="store_true")
    fap.set_defaults(func=commands.fap)

    demo = sub.add_parser("demo", help="the whole job on the embedded sample clip (needs bpy)",
                          description="Track the sample rig clip, fit the generic head to the sample scan, bind, "
                                      "bake, and write DIR/demo.blend, DIR/report.html and DIR/preview.mp4.")
    demo.add_argument("--out", default="out", help="output folder (default out/)")
    demo.add_argument("-q", "--quiet", action="store_true")
    demo.set_defaults(func=commands.demo)


def main(argv=None) -> int:
    try:
        with ExitStack() as work:
            with interrupts_held():     # a Ctrl-C before the work starts takes effect when it does
                parser = build_parser()
                args = parser.parse_args(argv)
                if getattr(args, "threshold", 1.0) <= 0:
                    parser.error("--threshold must be positive")
                # an output that could not be written is refused before the work, not after it
                check_output_paths(*(getattr(args, name, None) for name in ("output", "report", "csv")))
                # one BLAS and one OpenCV thread (core/common/threads.py): tiny solves stall on more; a Ctrl-C
                # while OpenCV and threadpoolctl load raised inside their code (cli/interrupts.py)
                work.enter_context(limited_threads())
            return args.func(args)
    except MirrorCapError as exc:
        print(f"mirrorcap: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:         # the reader went away (`mirrorcap info TAKE.c3d | head`): stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())   # no second error at exit's flush
        return 141
    except (KeyboardInterrupt, Exception) as exc:
        # Ctrl-C, or an error raised from one (an import it cut short: ImportError); outputs are written
        # atomically: nothing half-written is left
        if not caused_by_ctrl_c(exc):
            raise
        print("mirrorcap: interrupted", file=sys.stderr)
        return 130


def entry() -> int:
    """The process's entry point (``mirrorcap``, ``python -m mirrorcap``): :func:`main`, then a Ctrl-C
    while the process exits is ignored -- the command has finished and its outputs are complete.
    (Stop 49: a Ctrl-C during Blender's teardown after ``bake`` had written its .blend killed the
    process, 2 of 18 interrupts.) Callers of :func:`main` within a program keep their handlers."""
    code = main()
    if code == 130 and "bpy" in sys.modules:
        # Interrupted with Blender loaded: leave now. Blender's teardown at exit after a cut-short bake could
        # end the process by SIGINT after "interrupted" was printed (1 in 20 interrupts 1.2-1.6 s into a bake);
        # its outputs are written atomically, so there is nothing of Blender's to keep.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(entry())
