"""The ``mirrorcap`` command line: the core's commands plus the ones that need Blender (``bpy``).

``mirrorcap bake TAKE.c3d --head HEAD.blend -o OUT.blend [--object NAME] [--mode frames|pca] [--modes K]
[--neutral-frame N] [--head-pose REPORT.json] [--head-motion] [--report BAKE.json] [--no-blinks]
[--blink-seed S] [--blink-interval SECONDS] [--k MM]``
    bind the take to the head, run the face rig on every frame and write the head with
    shape keys to OUT.blend (atomically).

``mirrorcap batch TAKES... --head HEAD.blend --out DIR [--workers N] [bake options]``
    bake many takes in parallel processes (one Blender session each): a progress bar, one
    result line per take, ``DIR/<take>.blend`` and ``DIR/<take>.bake.json`` per take and
    ``DIR/batch.json``; a failing take is reported and the others go on (exit status 1 then).

``mirrorcap demo [--out DIR]``
    the main job on the embedded sample clip: track -> fit the generic head to the sample
    scan -> bind -> bake; writes ``DIR/demo.blend``, ``DIR/report.html``, ``DIR/preview.mp4``.

Everything else is documented in :mod:`core.cli`. ``bpy`` is imported only when a Blender
command runs, so the core commands work without it.
"""

from __future__ import annotations

import sys

from .core.cli import main as core_main


def _cmd_bake(args) -> int:
    from .core.facerig import RigSettings
    from .mirrorcap_addon.bake import run_bake

    if args.modes < 1:
        raise SystemExit("mirrorcap: error: --modes must be at least 1")
    settings = RigSettings(k=args.k, blinks=not args.no_blinks, blink_seed=args.blink_seed,
                           blink_interval_s=args.blink_interval)
    res = run_bake(args.take, args.head, args.output, object_name=args.object, mode=args.mode, n_modes=args.modes,
                   neutral_frame=args.neutral_frame, head_pose_report=args.head_pose, head_motion=args.head_motion,
                   settings=settings, report=args.report, drop_unseen=args.drop_unseen,
                   conjecture_unseen=args.conjecture_unseen)
    if not args.quiet:
        line = (f"baked {res['frames']} frames onto {res['object']} ({res['vertices']} vertices) as "
                f"{'one shape key per frame' if res['mode'] == 'frames' else str(res['modes']) + ' PCA modes'}")
        if res["mode"] == "pca":
            line += f"; PCA error max {res['pca_max_error_mm']:.3f} mm, mean {res['pca_mean_error_mm']:.4f} mm"
        print(line)
        how = ("landmarks " + ", ".join(res["landmarks_used"]) if res["registration"] == "landmarks"
               else "the skin surface")
        print(f"  {res['markers']} markers registered by {how} (RMS {res['landmark_rms_mm']:.2f} mm), "
              f"binding distance max {res['binding_distance_mm']['max']:.2f} mm")
        print(f"  {res['timings_s']['total_s']:.2f} s -> {res['output']}")
    return 0


def _bake_one(job):
    """One take of a batch, in its own process (a fresh Blender session)."""
    import os
    import time
    import traceback

    take, head, out_dir, options = job
    from pathlib import Path

    from .core.errors import MirrorCapError
    from .core.facerig import RigSettings
    from .mirrorcap_addon.bake import run_bake

    stem = Path(take).stem
    t0 = time.perf_counter()
    try:
        settings = RigSettings(k=options["k"], blinks=not options["no_blinks"], blink_seed=options["blink_seed"],
                               blink_interval_s=options["blink_interval"])
        res = run_bake(take, head, Path(out_dir) / f"{stem}.blend", object_name=options["object"],
                       mode=options["mode"], n_modes=options["modes"], neutral_frame=options["neutral_frame"],
                       head_motion=options["head_motion"], settings=settings,
                       report=Path(out_dir) / f"{stem}.bake.json", drop_unseen=options["drop_unseen"],
                       conjecture_unseen=options.get("conjecture_unseen", False))
        return {"take": str(take), "ok": True, "output": res["output"], "frames": res["frames"],
                "seconds": time.perf_counter() - t0, "pid": os.getpid()}
    except MirrorCapError as exc:
        return {"take": str(take), "ok": False, "error": str(exc), "seconds": time.perf_counter() - t0}
    except Exception as exc:  # a bug: one line here, the traceback in batch.json
        return {"take": str(take), "ok": False, "error": f"internal error ({type(exc).__name__}: {exc})",
                "traceback": traceback.format_exc(), "seconds": time.perf_counter() - t0}


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def run_batch(takes, head, out_dir, workers: int = 1, options: dict | None = None, quiet: bool = False) -> dict:
    """Bake ``takes`` onto ``head`` with ``workers`` processes; returns the batch summary."""
    import json
    import multiprocessing
    import os
    import time
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from pathlib import Path

    from .core.atomic import write_files_atomically
    from .core.errors import InputError

    out_dir = Path(out_dir)
    if not takes:
        raise InputError("give at least one take")
    if not Path(head).is_file():
        raise InputError(f"{head} does not exist")
    stems = [Path(t).stem for t in takes]
    if len(set(stems)) != len(stems):
        dup = sorted({s for s in stems if stems.count(s) > 1})
        raise InputError(f"takes with the same name would overwrite each other's output: {', '.join(dup)}")
    if workers < 1:
        raise InputError("--workers must be at least 1")
    out_dir.mkdir(parents=True, exist_ok=True)
    options = dict(options or {})
    jobs = [(str(t), str(head), str(out_dir), options) for t in takes]
    t0 = time.perf_counter()
    results = []
    ctx = multiprocessing.get_context("spawn")       # each worker starts its own Blender session
    n_proc = min(workers, len(jobs))
    # each worker's numpy/BLAS gets its share of the cores: N workers x all cores oversubscribes
    threads = str(max(1, (os.cpu_count() or 1) // n_proc))
    saved = {k: os.environ.get(k) for k in THREAD_VARIABLES}
    os.environ.update({k: threads for k in THREAD_VARIABLES})
    try:
        pool = ProcessPoolExecutor(max_workers=n_proc, mp_context=ctx)
        futures = [pool.submit(_bake_one, job) for job in jobs]      # workers start (and inherit) here
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    with pool:
        for fut in as_completed(futures):
            r = fut.result()
            results.append(r)
            if not quiet:
                done = len(results)
                bar = "#" * int(24 * done / len(jobs))
                line = (f"ok    {r['frames']} frames in {r['seconds']:.1f} s -> {r['output']}" if r["ok"]
                        else f"FAIL  {r['error']}")
                print(f"[{bar:<24}] {done}/{len(jobs)}  {Path(r['take']).name}: {line}", flush=True)
    wall = time.perf_counter() - t0
    order = {str(t): i for i, t in enumerate(takes)}
    results.sort(key=lambda r: order[r["take"]])
    summary = {"workers": workers, "processes": n_proc, "takes": len(jobs), "failed": sum(not r["ok"] for r in results),
               "wall_seconds": wall, "results": results}
    write_files_atomically({out_dir / "batch.json": json.dumps(summary, indent=1) + "\n"})
    return summary


def _cmd_batch(args) -> int:
    options = {"object": args.object, "mode": args.mode, "modes": args.modes, "neutral_frame": args.neutral_frame,
               "head_motion": args.head_motion, "no_blinks": args.no_blinks, "blink_seed": args.blink_seed,
               "blink_interval": args.blink_interval, "k": args.k, "drop_unseen": args.drop_unseen,
               "conjecture_unseen": args.conjecture_unseen}
    summary = run_batch(args.takes, args.head, args.out, workers=args.workers, options=options, quiet=args.quiet)
    if not args.quiet:
        print(f"{summary['takes'] - summary['failed']} of {summary['takes']} takes baked in "
              f"{summary['wall_seconds']:.1f} s with {summary['processes']} worker"
              f"{'s' if summary['processes'] > 1 else ''} -> {args.out}/batch.json")
    return 1 if summary["failed"] else 0


def _cmd_demo(args) -> int:
    from .mirrorcap_addon.demo import run_demo

    return run_demo(args.out, quiet=args.quiet)


def _bake_options(parser) -> None:
    parser.add_argument("--object", help="the head object's name (default: the only head in the file)")
    parser.add_argument("--mode", choices=("frames", "pca"), default="frames",
                        help="frames: one shape key per frame; pca: K eigen-deformation keys (default frames)")
    parser.add_argument("--modes", type=int, default=8, help="number of PCA modes (default 8)")
    parser.add_argument("--neutral-frame", type=int, default=0, help="take frame of the neutral face (default 0)")
    parser.add_argument("--head-motion", action="store_true", help="key the head motion as the object's transform")
    unseen = parser.add_mutually_exclusive_group()
    unseen.add_argument("--drop-unseen", action="store_true",
                        help="leave out markers not seen in the neutral frame (default: refuse the take)")
    unseen.add_argument("--conjecture-unseen", action="store_true",
                        help="place markers not seen in the neutral frame (a tracker's markers first seen later) "
                             "from their neighbours' learned relations; those expected off by more than 2 mm "
                             "(3 sigma) are left out")
    parser.add_argument("--no-blinks", action="store_true", help="no synthetic eyelid blinks")
    parser.add_argument("--blink-seed", type=int, default=0, help="seed of the blink process (default 0)")
    parser.add_argument("--blink-interval", type=float, default=2.5, help="mean seconds between blinks (default 2.5)")
    parser.add_argument("--k", type=float, default=16.0, help="RBF kernel constant k of eq. 7.1 in mm (default 16)")
    parser.add_argument("-q", "--quiet", action="store_true")


def add_blender_commands(sub) -> None:
    bake = sub.add_parser("bake", help="bake a take onto a head as shape keys (needs bpy)",
                          description="Register TAKE.c3d to the head (by markers labelled lm_<name>, else by the skin surface), run the face rig "
                                      "(regions, jaw, inner lip, blinks) and write the head with shape keys.")
    bake.add_argument("take", help="TAKE.c3d (from `mirrorcap track` or any C3D with landmark labels)")
    bake.add_argument("--head", required=True, help="HEAD.blend with a head mesh (region_*, lm_* vertex groups)")
    bake.add_argument("-o", "--output", required=True, help="OUT.blend to write")
    _bake_options(bake)
    bake.add_argument("--head-pose", help="REPORT.json of `mirrorcap track` (default: estimate the head motion)")
    bake.add_argument("--report", help="BAKE.json to write with the figures of the bake")
    bake.set_defaults(func=_cmd_bake)

    batch = sub.add_parser("batch", help="bake many takes in parallel processes (needs bpy)",
                           description="Bake every TAKE.c3d onto the head, N at a time, each in its own process. "
                                       "A failing take is reported and does not stop the others.")
    batch.add_argument("takes", nargs="+", help="TAKE.c3d files")
    batch.add_argument("--head", required=True, help="HEAD.blend with a head mesh")
    batch.add_argument("--out", required=True, help="output folder: <take>.blend, <take>.bake.json, batch.json")
    batch.add_argument("--workers", type=int, default=2, help="parallel processes (default 2)")
    _bake_options(batch)
    batch.set_defaults(func=_cmd_batch)

    demo = sub.add_parser("demo", help="the whole job on the embedded sample clip (needs bpy)",
                          description="Track the sample rig clip, fit the generic head to the sample scan, bind, "
                                      "bake, and write DIR/demo.blend, DIR/report.html and DIR/preview.mp4.")
    demo.add_argument("--out", default="out", help="output folder (default out/)")
    demo.add_argument("-q", "--quiet", action="store_true")
    demo.set_defaults(func=_cmd_demo)


def main(argv=None) -> int:
    return core_main(argv, extra_commands=add_blender_commands)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
