"""What each ``mirrorcap`` command does (the parser is :mod:`.parser`). Each command imports
what it needs when it runs, so the command line starts fast and the core commands work without
``bpy``."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..core import __version__
from ..core.common.errors import MirrorCapError
from .interrupts import interrupts_held


def reconstruct(args) -> int:
    from ..core.common.files import write_files_atomically
    from ..core.geometry.camera import Camera
    from ..core.geometry.reconstruct import KnownLength, reconstruct_pairs
    from ..core.take.pairs import format_points, read_pairs

    camera = Camera.load(args.camera)
    table = read_pairs(args.pairs)
    known = _known_length(args)
    known = None if known is None else KnownLength(*known)
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


def _known_length(args) -> tuple | None:
    """``--known-length A B MM`` as ``(A, B, mm)``, or None when not given."""
    if not args.known_length:
        return None
    a, b, mm = args.known_length
    try:
        return a, b, float(mm)
    except ValueError:
        raise MirrorCapError(f"--known-length: {mm!r} is not a number of millimetres") from None


def _progress_line(text: str, final: bool) -> None:
    """A progress line on stderr, rewritten in place until the last."""
    print(f"\r{text}", end="\n" if final else "", file=sys.stderr, flush=True)


def _open(args):
    from ..core.capture.video import open_source, parse_frame_range

    source = open_source(args.source, fps=getattr(args, "fps", None))
    start, end = parse_frame_range(getattr(args, "frames", None))
    return source, start, end


def calibrate(args) -> int:
    from ..core.capture.calibrate import Board, calibrate_camera
    from ..core.common.files import write_files_atomically

    board = Board.parse(args.board)
    source, _, _ = _open(args)
    if not args.max_focal_sd > 0:
        raise MirrorCapError("--max-focal-sd must be a positive percentage")
    result = calibrate_camera(source, board, max_views=args.max_views, min_views=args.min_views,
                              max_rms_px=args.max_rms, max_focal_sd_percent=args.max_focal_sd)
    write_files_atomically({Path(args.output): json.dumps(result.to_dict(), indent=2) + "\n"})
    if not args.quiet:
        K = result.camera.K
        print(f"calibrated from {result.views_used} of {result.views_tried} views, RMS reprojection error "
              f"{result.rms_px:.3f} px -> {args.output}")
        print(f"  fx {K[0, 0]:.2f}  fy {K[1, 1]:.2f} (+-{result.focal_sd_percent:.2f} %)  cx {K[0, 2]:.2f}  "
              f"cy {K[1, 2]:.2f}  dist {' '.join(f'{v:+.4f}' for v in result.camera.dist)}; the board turned "
              f"{result.board_turn_deg:.0f} deg between views")
    return 0


def _colours_and_light(args, source=None, start: int = 0):
    """The capture's colour classes and light from ``--colors`` and ``--light``; with neither saying the light,
    frame ``start`` of ``source`` shows it (:func:`core.capture.markers.capture_light`), and a line says so."""
    from ..core.capture.markers import ColorClasses, capture_light, frame_says_light

    colors = ColorClasses.load(args.colors) if getattr(args, "colors", None) else None
    light = capture_light(args.light, colors, source, start)
    if source is not None and frame_says_light(args.light, colors) and not args.quiet:
        print(f"light: {'ordinary (coloured dots)' if light == 'normal' else 'UV'}, as frame {start} shows it "
              f"(--light {'uv' if light == 'normal' else 'normal'} to say otherwise)")
    return colors or ColorClasses.default(light), light


def detect(args) -> int:
    from ..core.capture.detect import between_classes_warning, dot_px_text, run_detection, small_dot_warning
    from ..core.capture.markers import ExtractionSettings
    from ..core.capture.rig import load_rig, view_boundary_warnings
    from ..core.geometry.camera import Camera

    source, start, end = _open(args)
    layout = load_rig(args.rig).views
    camera = Camera.load(args.camera) if args.camera else None
    if args.threshold < 0 or args.threshold >= 255:
        raise MirrorCapError("--threshold must be in 0..254")
    if args.min_area < 1 or (args.marker_diameter is not None and args.marker_diameter < 0):
        raise MirrorCapError("--min-area must be at least 1 and --marker-diameter non-negative")
    colors, light = _colours_and_light(args, source, start)
    settings = ExtractionSettings(light=light, threshold=args.threshold, min_area=args.min_area,
                                  marker_diameter_px=args.marker_diameter, washed_out=args.washed_out)
    report = run_detection(source, args.output, colors=colors, settings=settings, layout=layout, camera=camera,
                           start=start, end=end, step=args.step,
                           progress=None if args.quiet else _progress_line)
    if not args.quiet:
        c = report["counts"]
        n = report["frames"]["processed"]
        print(f"{n} frames -> {args.output}: per frame {c['direct'] / n:.1f} direct, {c['mirror0'] / n:.1f} mirror0, "
              f"{c['mirror1'] / n:.1f} mirror1, dots {dot_px_text(report['dot_px'])} px across "
              f"({report['frames_per_second']:.0f} frames/s)")
        for text in view_boundary_warnings(report["view_layout"]):
            print(f"  warning: {text}")
        for text in (small_dot_warning(light, report["dot_px"]),
                     between_classes_warning(light, report["between_classes"])):
            if text:
                print(f"  warning: {text}")
    return 0


def track(args) -> int:
    import numpy as np

    from ..core.capture.boardcal import load_mirrors
    from ..core.capture.markers import ExtractionSettings
    from ..core.capture.rig import load_rig, rigid_markers
    from ..core.geometry.camera import Camera
    from ..core.capture.video import check_frame_step
    from ..core.track.pipeline import check_known_length, run_track
    from ..core.track.seeds import read_seeds
    from ..core.track.tracker import TrackSettings

    camera = Camera.load(args.camera)
    source, start, end = _open(args)
    rig = load_rig(args.rig)
    mirrors = load_mirrors(args.mirrors) if args.mirrors else None
    known = _known_length(args)
    if not args.face_distance > 0:
        raise MirrorCapError("--face-distance must be a positive number of millimetres")
    if not args.conjecture_limit >= 0:
        raise MirrorCapError("--conjecture-limit must be a number of millimetres, 0 or more (or inf)")
    settings = TrackSettings.with_conjecture_limit(args.conjecture_limit)
    seeds = read_seeds(args.seeds, camera.image_size) if args.seeds else None
    check_frame_step(args.step)      # refused before any frame is read (the light's), as the outputs are (main)
    check_known_length(known)
    colors, light = _colours_and_light(args, source, start)
    rigid, rigid_source = rigid_markers((0, 0, 0, 0), (), rig, colors)
    report = run_track(source, camera, Path(args.output), report=Path(args.report) if args.report else None,
                       colors=colors, extraction=ExtractionSettings(light=light, washed_out=args.washed_out),
                       layout=rig.views, mirrors=mirrors,
                       known_length=known, start=start, end=end,
                       step=args.step, face_distance_mm=args.face_distance, settings=settings, rigid=rigid,
                       rigid_source=rigid_source, seeds=seeds)
    if not args.quiet:
        pf = report["per_frame"]
        n = report["frames"]["count"]
        print(f"{report['markers']['count']} markers over {n} frames -> {args.output} [{report['units']}]")
        followed, bridged = (np.mean(pf[key]) if key in pf else 0.0 for key in ("followed_through_gaps", "bridged"))
        print(f"  per frame: {np.mean(pf['measured']):.1f} measured ({followed:.1f} of them followed through gaps, "
              f"{bridged:.1f} bridged along their 2D tracks), "
              f"{np.mean(pf['conjectured']):.1f} conjectured, "
              f"{np.mean(pf['false_tracking']):.2f} false tracking, {np.mean(pf['conflicts']):.2f} conflicts, "
              f"{np.mean(pf['withheld']):.1f} conjectures withheld; "
              f"tracking {report['timings_s']['tracking_frames_per_s']:.0f} frames/s")
        repaired, doubted, merged = (int(np.sum(pf.get(key, 0))) for key in ("repaired", "doubted", "merged_images"))
        if repaired or doubted:
            print(f"  measurements from one mirror disowned: {repaired} re-paired onto another mirror image, {doubted} "
                  f"left to the gap fill" + (f" ({merged} of them through one blob of two dots' images)" if merged else ""))
        for text in report["warnings"]:
            print(f"  warning: {text}")
    return 0


def mirrors(args) -> int:
    from ..core.capture.boardcal import calibrate_mirrors_from_board, write_mirrors_json
    from ..core.capture.calibrate import Board
    from ..core.capture.rig import load_rig
    from ..core.common.files import write_files_atomically
    from ..core.geometry.camera import Camera

    board = Board.parse(args.board)
    camera = Camera.load(args.camera)
    layout = load_rig(args.rig).views
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


def colors_learn(args) -> int:
    from ..core.capture.detect import learn_color_classes
    from ..core.common.files import write_files_atomically

    source, start, end = _open(args)
    light = _colours_and_light(args, source, start)[1]
    names = [n.strip() for n in args.names.split(",")] if args.names else None
    classes = learn_color_classes(source, args.classes, names=names, start=start, end=end, step=args.step,
                                  threshold=args.threshold, light=light)
    write_files_atomically({Path(args.output): json.dumps(classes.to_dict(), indent=2) + "\n"})
    if not args.quiet:
        print(f"{len(classes.names)} colour classes -> {args.output}: {', '.join(classes.names)}")
    return 0


def demo_mirrors(args) -> int:
    from ..demo.mirrors import run_demo

    return run_demo(Path(args.out), quiet=args.quiet)


def _take_frames(args) -> tuple[int, int | None]:
    """``--frames START:END`` of ``bake``, ``batch`` and ``retarget``, read before Blender starts."""
    from ..core.capture.video import parse_frame_range

    return parse_frame_range(args.frames)


def bake(args) -> int:
    frames = _take_frames(args)
    with interrupts_held():     # Blender loads here (cli/interrupts.py)
        from ..addon.bake.bake import run_bake
    from ..core.face.facerig import RigSettings

    if args.modes < 1:
        raise SystemExit("mirrorcap: error: --modes must be at least 1")
    if args.blink_interval is not None and not args.blink_interval > 0:
        raise MirrorCapError("--blink-interval must be a positive number of seconds")
    settings = RigSettings(k=args.k, blinks=not args.no_blinks, blink_seed=args.blink_seed,
                           blink_interval_s=args.blink_interval)
    if (args.take is None) == (args.fap is None):
        raise MirrorCapError("give either a take (TAKE.c3d) or --fap TAKE.fap")
    res = run_bake(args.take, args.head, args.output, object_name=args.object, mode=args.mode, n_modes=args.modes,
                   neutral_frame=args.neutral_frame, head_pose_report=args.head_pose, head_motion=args.head_motion,
                   settings=settings, report=args.report, unseen=args.unseen, marker_map=args.marker_map, fap=args.fap,
                   frames=frames, frame_start=args.frame_start)
    if not args.quiet:
        first, end = res["take_frames"]
        line = (f"baked {res['frames']} frames{'' if (first, end) == (0, res['take_length']) else f' ({first}:{end})'} "
                f"onto {res['object']} ({res['vertices']} vertices) at scene frames {res['frame_start']}-"
                f"{res['frame_start'] + res['frames'] - 1} as "
                f"{'one shape key per frame' if res['mode'] == 'frames' else str(res['modes']) + ' PCA modes'}")
        if res["mode"] == "pca":
            line += f"; PCA error max {res['pca_max_error_mm']:.3f} mm, mean {res['pca_mean_error_mm']:.4f} mm"
        print(line)
        how = ("landmarks " + ", ".join(res["landmarks_used"]) if res["registration"] == "landmarks"
               else "the skin surface")
        print(f"  {res['markers']} markers registered by {how} (RMS {res['landmark_rms_mm']:.2f} mm), "
              f"binding distance max {res['binding_distance_mm']['max']:.2f} mm")
        print(f"  {res['timings_s']['total_s']:.2f} s -> {res['output']}")
        for warning in res["warnings"]:
            print(f"  warning: {warning}")
    return 0


def _print_missing_shapes(res) -> None:
    if res["missing_shape_names"]:
        print(f"  the target lacks {len(res['missing_shape_names'])} shapes (skipped): "
              f"{', '.join(res['missing_shape_names'])}")


def retarget(args) -> int:
    frames = _take_frames(args)
    with interrupts_held():     # Blender loads here (cli/interrupts.py)
        from ..addon.retarget.retarget import run_livelink, run_retarget

    if str(args.take).lower().endswith(".csv"):
        if args.csv:
            raise MirrorCapError("--csv writes the CSV of a C3D take; the take is already a CSV")
        res = run_livelink(args.take, args.target, args.output, target_object=args.target_object, rate=args.rate,
                           report=args.report, frames=frames, frame_start=args.frame_start)
        if not args.quiet:
            print(f"keyed {res['frames']} frames of {args.take} onto {res['target_object']}: "
                  f"{len(res['shapes_keyed'])} ARKit shapes at {res['rate']:.3g} frames/s"
                  f"{' (from its timecodes)' if res['rate_source'] == 'timecodes' else ''} -> {res['output']}")
            _print_missing_shapes(res)
            for warning in res["warnings"]:
                print(f"  warning: {warning}")
        return 0
    if not args.head:
        raise MirrorCapError("--head HEAD.blend (the actor's head with the ARKit shape keys) is needed for a C3D take")
    if args.smoothness is not None and not args.smoothness >= 0:
        raise MirrorCapError("--smoothness must be 0 or more")
    res = run_retarget(args.take, args.head, args.target, args.output, target_object=args.target_object,
                       method=args.method, csv=args.csv, head_pose_report=args.head_pose, report=args.report,
                       marker_map=args.marker_map, neutral_frame=args.neutral_frame, smoothness=args.smoothness,
                       head_object=args.head_object, unseen=args.unseen, mode=args.mode, n_modes=args.modes,
                       frames=frames, frame_start=args.frame_start)
    if args.method == "transfer":
        if not args.quiet:
            sc = res["region_scales"]
            print(f"transferred {res['frames']} frames onto {res['target_object']} ({res['mode']} keys): scales "
                  f"upper {'/'.join(f'{v:.2f}' for v in sc['upper'])}, lower "
                  f"{'/'.join(f'{v:.2f}' for v in sc['lower'])} (lateral/down/forward) -> {res['output']}")
        return 0
    if not args.quiet:
        print(f"retargeted {res['frames']} frames onto {res['target_object']}: {len(res['shapes_keyed'])} ARKit shapes "
              f"keyed, fit residual {res['residual_mm']['rms']:.3f} mm RMS -> {res['output']}")
        _print_missing_shapes(res)
        if res["unobservable"]:
            print(f"  not observable from the markers (kept at 0): {', '.join(res['unobservable'])}")
    return 0


def fap(args) -> int:
    with interrupts_held():     # Blender loads here (cli/interrupts.py)
        from ..addon.retarget.fap import run_fap

    res = run_fap(args.take, args.head, args.output, head_object=args.object, head_pose_report=args.head_pose,
                  marker_map=args.marker_map, neutral_frame=args.neutral_frame, unseen=args.unseen,
                  high_level=not args.no_high_level, report=args.report)
    if not args.quiet:
        print(f"{len(res['faps_written'])} FAPs over {res['frames']} frames -> {res['output']} "
              f"(FAPU mm: {', '.join(f'{k} {v:.1f}' for k, v in res['fapu_mm'].items())}; "
              f"open_jaw up to {res['open_jaw_max']})")
    return 0


def batch(args) -> int:
    options = {"object": args.object, "mode": args.mode, "modes": args.modes, "neutral_frame": args.neutral_frame,
               "head_motion": args.head_motion, "no_blinks": args.no_blinks, "blink_seed": args.blink_seed,
               "blink_interval": args.blink_interval, "k": args.k, "unseen": args.unseen,
               "marker_map": args.marker_map,
               "frames": _take_frames(args), "frame_start": args.frame_start}
    from .batch import run_batch

    summary = run_batch(args.takes, args.head, args.out, workers=args.workers, options=options, quiet=args.quiet)
    if not args.quiet:
        print(f"{summary['takes'] - summary['failed']} of {summary['takes']} takes baked in "
              f"{summary['wall_seconds']:.1f} s with {summary['processes']} worker"
              f"{'s' if summary['processes'] > 1 else ''} -> {args.out}/batch.json")
    return 1 if summary["failed"] else 0


def demo(args) -> int:
    with interrupts_held():     # Blender loads here (cli/interrupts.py)
        from ..demo.rig import run_demo

    return run_demo(args.out, quiet=args.quiet)


def info(args) -> int:
    from ..core.take.c3d import read_c3d, take_info

    rep = take_info(read_c3d(args.take))
    if args.json:
        print(json.dumps(rep, indent=1))
        return 0
    units = rep["units"] if rep["source_units"] in (rep["units"], "mm (not given)") else \
        f"{rep['units']} (the file's {rep['source_units']} converted)"
    print(f"{args.take}: {rep['frames']} frames at {rep['rate']:g} frames/s (frames {rep['first_frame']}-"
          f"{rep['last_frame']}), {rep['markers']} markers, {units}, {rep['processor']} processor format")
    a = rep["analog"]
    print(f"  analog: {a['channels']} channels at {a['rate']:g} Hz (not used): {', '.join(a['labels'])}"
          if a["channels"] else "  analog: none")
    print(f"  gaps: {100 * rep['gap_fraction']:.1f} % of marker-frames")
    width = max((len(s) for s in rep["labels"]), default=5)
    for label, n in rep["gaps_per_label"].items():
        print(f"  {label:<{width}}  {n} gap frames")
    for r in rep["renamed"]:
        print(f"  renamed: marker {r['index']} {r['from']!r} -> {r['to']!r} (labels must be unique and non-empty)")
    return 0


def export(args) -> int:
    from ..core.common.files import write_files_atomically
    from ..core.take.c3d import points_csv, read_c3d

    take = read_c3d(args.take)
    write_files_atomically({Path(args.output): points_csv(take)})
    if not args.quiet:
        print(f"{take['points'].shape[0]} frames x {len(take['labels'])} markers -> {args.output} [{take['units']}]")
    return 0


def stabilize(args) -> int:
    import numpy as np

    from ..core.take.stabilize import stabilize_file

    pivot = args.pivot.strip().lower()
    if pivot not in ("auto", "none"):
        try:
            pivot = [float(v) for v in pivot.split(",")]
        except ValueError:
            raise MirrorCapError(f"--pivot must be auto, none or X,Y,Z in mm, not {args.pivot!r}") from None
        if len(pivot) != 3 or not np.all(np.isfinite(pivot)):
            raise MirrorCapError(f"--pivot must be auto, none or X,Y,Z in mm, not {args.pivot!r}")
    elif pivot == "none":
        pivot = None
    if not args.smooth >= 0:
        raise MirrorCapError("--smooth must be 0 or more seconds")
    _, st, report = stabilize_file(args.take, Path(args.output), Path(args.report) if args.report else None,
                                   rigid=args.rigid, method=args.method, pivot=pivot, smooth_s=args.smooth)
    if not args.quiet:
        piv = report["pivot_mm"]
        where = "no pivot" if piv is None else f"pivot ({piv[0]:.1f}, {piv[1]:.1f}, {piv[2]:.1f}) mm [{st.pivot_status}]"
        print(f"{len(st.labels)} markers over {len(st.points)} frames -> {args.output}: head motion by {st.method} "
              f"from {', '.join(st.rigid)} ({st.rigid_source}); {where}; rigid residual "
              f"{report['rigid_residual_rms_mm'] or 0:.3f} mm RMS")
        for text in st.warnings:
            print(f"  warning: {text}")
    return 0
