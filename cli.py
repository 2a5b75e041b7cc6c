"""The ``mirrorcap`` command line: the core's commands plus the ones that need Blender (``bpy``).

``mirrorcap bake TAKE.c3d --head HEAD.blend -o OUT.blend [--object NAME] [--mode frames|pca] [--modes K]
[--neutral-frame N] [--head-pose REPORT.json] [--head-motion] [--report BAKE.json] [--no-blinks]
[--blink-seed S] [--blink-interval SECONDS] [--k MM]``
    bind the take to the head, run the face rig on every frame and write the head with
    shape keys to OUT.blend (atomically).

``mirrorcap batch TAKES... --head HEAD.blend --out DIR [--workers N] [bake options]``
    bake many takes in parallel processes (one Blender session each): a progress bar, one
    result line per take, ``DIR/<take>.blend``, ``DIR/<take>.bake.json`` and ``DIR/<take>.log``
    per take and ``DIR/batch.json``; a failing take -- even one that kills its worker -- is
    reported and the others go on (exit status 1 then).

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
    """One take of a batch, in a worker process (a Blender session of its own)."""
    import os
    import time
    import traceback

    take, head, out_dir, options = job
    from pathlib import Path

    from .core.errors import MirrorCapError
    from .core.facerig import RigSettings

    stem = Path(take).stem
    t0 = time.perf_counter()
    try:
        from .mirrorcap_addon.bake import run_bake  # Blender starts here (once per worker)

        t0 = time.perf_counter()
        settings = RigSettings(k=options["k"], blinks=not options["no_blinks"], blink_seed=options["blink_seed"],
                               blink_interval_s=options["blink_interval"])
        res = run_bake(take, head, Path(out_dir) / f"{stem}.blend", object_name=options["object"],
                       mode=options["mode"], n_modes=options["modes"], neutral_frame=options["neutral_frame"],
                       head_motion=options["head_motion"], settings=settings,
                       report=Path(out_dir) / f"{stem}.bake.json", drop_unseen=options["drop_unseen"],
                       conjecture_unseen=options.get("conjecture_unseen", False))
        out = {"take": str(take), "ok": True, "output": res["output"], "frames": res["frames"]}
    except MirrorCapError as exc:
        out = {"take": str(take), "ok": False, "error": str(exc)}
    except Exception as exc:  # a bug: one line here, the traceback in batch.json and the take's log
        traceback.print_exc()
        out = {"take": str(take), "ok": False, "error": f"internal error ({type(exc).__name__}: {exc})",
               "traceback": traceback.format_exc()}
    return {**out, "seconds": time.perf_counter() - t0, "pid": os.getpid()}


class _output_to:
    """Send this process's stdout and stderr -- Python's and the C library's, so Blender's
    own messages too -- to ``path`` while inside the block."""

    def __init__(self, path):
        self.path = path

    def __enter__(self):
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        self.saved = (os.dup(1), os.dup(2))
        fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        return self

    def __exit__(self, *exc):
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        for fd, saved in zip((1, 2), self.saved):
            os.dup2(saved, fd)
            os.close(saved)
        return False


def _batch_worker(tasks, events, bake) -> None:
    """A batch worker process: bake the takes it is handed until told to stop. It says which
    take it starts before baking it (``events`` is its own pipe: a send is written at once),
    so a take that kills its process is known."""
    import os
    import signal
    from pathlib import Path

    # Ctrl-C reaches the whole process group: the batch command stops its workers itself
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        job = tasks.get()
        if job is None:
            # Every take's files are written and closed: leave without Blender's teardown at
            # interpreter exit (0.1-0.2 s per worker, paid at the end of every batch).
            sys.stdout.flush()
            sys.stderr.flush()
            events.close()
            os._exit(0)
        index, job = job
        log = Path(job[2]) / f"{Path(job[0]).stem}.log"
        events.send(("start", index))
        with _output_to(log):       # Blender's messages and any crash report: DIR/<take>.log
            result = bake(job)
        events.send(("done", index, {**result, "log": str(log)}))


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def run_batch(takes, head, out_dir, workers: int = 1, options: dict | None = None, quiet: bool = False,
              bake=None) -> dict:
    """Bake ``takes`` onto ``head`` with ``workers`` processes; returns the batch summary.

    Each worker is a spawned process with its own Blender session that bakes takes one after
    another. A take that raises is reported and the worker goes on; a take that kills its
    process (a crash inside Blender) is reported as such and a new worker takes over the
    takes not yet baked. ``bake(job)`` is the per-take function (default :func:`_bake_one`;
    the tests pass one that crashes)."""
    import json
    import multiprocessing
    import os
    import time
    from multiprocessing.connection import wait
    from pathlib import Path

    from .core.atomic import write_files_atomically
    from .core.errors import InputError

    bake = bake or _bake_one
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
    ctx = multiprocessing.get_context("spawn")       # each worker starts its own Blender session
    n_proc = min(workers, len(jobs))
    tasks = ctx.Queue()
    for item in enumerate(jobs):
        tasks.put(item)
    for _ in range(n_proc):
        tasks.put(None)                 # one stop signal per worker; a replacement takes a dead one's
    results: dict[int, dict] = {}
    workers_now: dict = {}              # process sentinel -> [process, its pipe's read end, take index or None]
    started = 0

    def start_worker():
        nonlocal started
        # each worker's numpy/BLAS gets its share of the cores: N workers x all cores oversubscribes
        threads = str(max(1, (os.cpu_count() or 1) // n_proc))
        saved = {k: os.environ.get(k) for k in THREAD_VARIABLES}
        os.environ.update({k: threads for k in THREAD_VARIABLES})
        reader, writer = ctx.Pipe(duplex=False)
        try:
            proc = ctx.Process(target=_batch_worker, args=(tasks, writer, bake), daemon=True,
                               name=f"mirrorcap-batch-{started}")
            proc.start()                # the child inherits the environment here
        finally:
            writer.close()
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        workers_now[proc.sentinel] = [proc, reader, None]
        started += 1

    def record(index, r):
        results[index] = r
        if not quiet:
            done = len(results)
            bar = "#" * int(24 * done / len(jobs))
            line = (f"ok    {r['frames']} frames in {r['seconds']:.1f} s -> {r['output']}" if r["ok"]
                    else f"FAIL  {r['error']}" + (f" (log: {r['log']})" if r.get("log") else ""))
            print(f"[{bar:<24}] {done}/{len(jobs)}  {Path(r['take']).name}: {line}", flush=True)

    def read_messages(entry):
        proc, reader, _ = entry
        try:
            while reader.poll():
                msg = reader.recv()
                if msg[0] == "start":
                    entry[2] = msg[1]
                else:
                    entry[2] = None
                    record(msg[1], msg[2])
        except EOFError:            # the worker is gone; its sentinel says how
            pass

    finished = False
    try:
        for _ in range(n_proc):
            start_worker()
        while workers_now and len(results) < len(jobs):
            ready = wait([e[1] for e in workers_now.values()] + list(workers_now), timeout=1.0)
            for entry in list(workers_now.values()):
                read_messages(entry)
            for sentinel in [s for s in ready if s in workers_now]:
                entry = workers_now.pop(sentinel)
                read_messages(entry)            # what it said before it went
                proc, reader, index = entry
                proc.join()
                reader.close()
                if index is not None and index not in results:
                    log = out_dir / f"{Path(jobs[index][0]).stem}.log"
                    record(index, {"take": jobs[index][0], "ok": False, "seconds": None,
                                   "error": f"its worker process died (exit code {proc.exitcode}) while baking it",
                                   "log": str(log) if log.exists() else None})
                    start_worker()      # a new worker takes the takes not yet baked
        for i in range(len(jobs)):      # only if every worker died between takes: should not happen
            if i not in results:
                record(i, {"take": jobs[i][0], "ok": False, "seconds": None,
                           "error": "not baked: every worker process stopped"})
        finished = True
    finally:
        for proc, reader, _ in workers_now.values():
            if finished:        # the workers leave once their stop signal is read
                proc.join(timeout=10)
            if proc.is_alive():     # interrupted (Ctrl-C) or stuck: stop them now
                proc.terminate()
                proc.join()
            reader.close()
        tasks.cancel_join_thread()
        tasks.close()
    wall = time.perf_counter() - t0
    ordered = [results[i] for i in range(len(jobs))]
    summary = {"workers": workers, "processes": n_proc, "processes_started": started, "takes": len(jobs),
               "failed": sum(not r["ok"] for r in ordered), "wall_seconds": wall, "results": ordered}
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
