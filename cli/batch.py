"""``mirrorcap batch``: many takes baked in parallel worker processes (one Blender session
each). A worker says which take it starts before baking it, so a take that kills its process
is reported as such and a new worker bakes the rest; each take's own output (Blender's C
messages too) goes to ``DIR/<take>.log``."""

from __future__ import annotations

import sys


def _bake_one(job):
    """One take of a batch, in a worker process (a Blender session of its own)."""
    import os
    import time
    import traceback

    take, head, out_dir, options = job
    from pathlib import Path

    from ..core.common.errors import MirrorCapError
    from ..core.face.facerig import RigSettings

    stem = Path(take).stem
    t0 = time.perf_counter()
    try:
        from ..addon.bake.bake import run_bake  # Blender starts here (once per worker)

        t0 = time.perf_counter()
        settings = RigSettings(k=options["k"], blinks=not options["no_blinks"], blink_seed=options["blink_seed"],
                               blink_interval_s=options["blink_interval"])
        res = run_bake(take, head, Path(out_dir) / f"{stem}.blend", object_name=options["object"],
                       mode=options["mode"], n_modes=options["modes"], neutral_frame=options["neutral_frame"],
                       head_motion=options["head_motion"], settings=settings,
                       report=Path(out_dir) / f"{stem}.bake.json", unseen=options.get("unseen", "conjecture"),
                       marker_map=options.get("marker_map"), frames=options.get("frames"),
                       frame_start=options.get("frame_start", 1))
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
    import signal
    import time
    from multiprocessing.connection import wait
    from pathlib import Path

    from ..core.common.errors import InputError
    from ..core.common.files import output_folder, write_files_atomically
    from .interrupts import interrupts_held

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
    out_dir = output_folder(out_dir)
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
        # Ctrl-C reaches the whole process group: a worker still starting (before _batch_worker ignores it) died
        # of it with "Fatal Python error: init_import_site" on the terminal (seen under load). It starts with
        # SIGINT blocked -- the mask survives the spawn's exec -- and here a Ctrl-C waits until it has started
        # and is registered (to be stopped below): raised between the spawn and the write of what the worker is
        # to run, it left the worker reading an empty pipe (cli/interrupts.py).
        with interrupts_held():
            reader, writer = ctx.Pipe(duplex=False)
            blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) \
                if hasattr(signal, "pthread_sigmask") else None
            try:
                proc = ctx.Process(target=_batch_worker, args=(tasks, writer, bake), daemon=True,
                                   name=f"mirrorcap-batch-{started}")
                proc.start()                # the child inherits the environment here
            finally:
                if blocked is not None:
                    signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
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
