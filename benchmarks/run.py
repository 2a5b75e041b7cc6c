"""``make bench``: speed of the mirror core and the section 6.2 simulations.

    python -m benchmarks.run --out bench_results [--trials 100] [--workers 2] [--skip-simulation]
        [--skip-extraction] [--skip-tracking] [--skip-animation] [--skip-batch] [--skip-takes]
        [--long-take FRAMES]

Writes (atomically) into the output folder:

* ``speed.json`` -- median microseconds per call (see benchmarks/speed.py);
* ``simulation.csv`` -- experiment, setting, method, rms, median, failures, trials;
* ``fig6_1_points.png`` ... ``fig6_4_orientation.png`` -- the four figures;
* ``expected_error.csv`` -- Monte-Carlo check of eq. 3.26;
* ``extraction.json`` -- marker extraction accuracy under faults, speed, memory;
* ``tracking.json`` -- tracking accuracy and speed from detections;
* ``track_command.json`` -- the whole ``mirrorcap track`` on a rendered 1280x720 MP4 (speed, accuracy);
* ``track_under_load.json`` -- the whole ``mirrorcap track`` on three clips with both cores kept busy by
  other processes, with one BLAS thread and with BLAS's own count;
* ``long_take.json`` -- with ``--long-take FRAMES``: the whole ``mirrorcap track`` on a FRAMES-frame take
  (speed, peak memory, accuracy);
* ``stress_clips.json`` -- the whole ``mirrorcap track`` on each Cycles stress clip of ``sample_scenes/stress``
  (speed, accuracy, completeness against the truth's visibility);
* ``animation.json`` -- bake of 1,000 frames, head fit, rig accuracy, PCA error vs modes;
* ``batch.json`` -- `mirrorcap batch` of 4 sample takes with 1 and 2 workers;
* ``stabilize.json`` -- `mirrorcap stabilize` on synthetic 23-marker takes (accuracy over 20 noise draws, speed);
* ``arkit.json`` -- ARKit-52 weights from a 1,000-frame, 150-marker take (accuracy, solve time);
* ``transfer.json`` -- `mirrorcap retarget --method transfer` of 1,000 frames onto an 18k-vertex character;
* ``summary.md`` -- the tables quoted in the README (a skipped part reuses its last JSON).
"""

from __future__ import annotations

import argparse
import csv
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
import io
import json
import platform
import sys
import time
from pathlib import Path

from mirrorcap.core.common.files import write_files_atomically

from .animation import animation_summary, run_animation_benchmark
from .batch import batch_summary, run_batch_benchmark
from .takes import (arkit_summary, run_arkit_benchmark, run_stabilize_benchmark, run_transfer_benchmark,
                    stabilize_summary, transfer_summary)
from .extraction import run_extraction_benchmark
from .tracking import (run_loaded_track_benchmark, run_long_take_benchmark, run_stress_clip_benchmark,
                       run_track_command_benchmark, run_tracking_benchmark)
from .simulation import EXPERIMENTS, METHOD_LABELS, METHODS, expected_error_check, run_simulations
from .speed import run_speed


def _csv(rows, columns) -> str:
    out = io.StringIO()
    w = csv.DictWriter(out, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items() if k in columns})
    return out.getvalue()


def _read_csv(path) -> list:
    """Rows of a results CSV with numbers parsed back (``15/0`` settings stay text)."""
    def value(v):
        try:
            return int(v)
        except ValueError:
            try:
                return float(v)
            except ValueError:
                return v

    with open(path, newline="") as fh:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(fh)]


def _plot(rows, experiment) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    label, settings = EXPERIMENTS[experiment]
    sel = [r for r in rows if r["experiment"] == experiment]
    if experiment == "fig6_4_orientation":
        fig, axes = plt.subplots(1, 4, figsize=(14, 3.6), sharey=True)
        for ax, lon in zip(axes, (15, 30, 45, 60)):
            for m in METHODS:
                pts = [(int(r["setting"].split("/")[1]), r["rms"]) for r in sel
                       if r["method"] == m and r["setting"].startswith(f"{lon}/")]
                ax.plot(*zip(*pts), marker="o", ms=3, label=METHOD_LABELS[m])
            ax.set_title(f"longitude {lon} deg")
            ax.set_xlabel("latitude (deg)")
            ax.set_yscale("log")
            ax.grid(alpha=0.3)
        axes[0].set_ylabel("RMS 3D error (units; 1 = 0.05 mm at 2 m)")
        axes[-1].legend(fontsize=7)
    else:
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for m in METHODS:
            xs = [float(r["setting"]) for r in sel if r["method"] == m]
            ys = [r["rms"] for r in sel if r["method"] == m]
            ax.plot(xs, ys, marker="o", ms=3, label=METHOD_LABELS[m])
        ax.set_xlabel(label)
        ax.set_ylabel("RMS 3D error (units; 1 = 0.05 mm at 2 m)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle({"fig6_1_points": "Figure 6.1: error vs number of correspondences (1 px noise)",
                  "fig6_2_noise": "Figure 6.2: error vs image noise (60 points)",
                  "fig6_3_resolution": "Figure 6.3: error vs resolution (quantisation only, 60 points)",
                  "fig6_4_orientation": "Figure 6.4: error vs mirror orientation (1 px noise, 60 points)"}[experiment],
                 fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def _extraction_summary(ext) -> list:
    lines = ["## Marker extraction (1280 x 720, 300 markers, 2.5 mm dots at 600 mm, one core)", "",
             "| condition | centre RMS error | colour class correct | missed | false |", "| --- | --- | --- | --- | --- |"]
    for name, r in ext["conditions"].items():
        lines.append(f"| {name} | {r['rms_px']:.3f} px | {r['color'] * 100:.2f} % | {r['missed'] * 100:.2f} % | "
                     f"{r['false'] * 100:.2f} % |")
    s = ext["stream"]
    rss = s["rss_mb_at_10_50_100_percent"]
    lines += ["", f"- extraction alone: {ext['extract_ms_per_frame']:.2f} ms per frame = "
                  f"**{ext['extract_frames_per_s']:.0f} frames/s** on one core "
                  f"({ext['detections_per_frame']:.0f} dots per frame, 40 distinct frames cycled)",
              f"- MP4 decode alone: {ext['decode_ms_per_frame']:.2f} ms per frame",
              f"- whole `detect` on a {s['frames']}-frame MP4 (decode, extraction, CSV): "
              f"{s['frames_per_s']:.0f} frames/s; resident memory {rss[0]:.1f} / {rss[1]:.1f} / {rss[2]:.1f} MB at "
              f"10 / 50 / 100 % (growth after warm-up {s['rss_growth_mb_after_first_10_percent']:.2f} MB)"]
    nl = ext.get("normal_light")
    if nl:
        lines += [f"- normal light, the light clip ({nl['frames']} frames, 1280 x 720 H.264): extraction alone "
                  f"{nl['extract_ms_per_frame']:.1f} ms per frame on one core; whole `detect` "
                  f"{nl['detect_frames_per_s_one_thread']:.0f} frames/s frame after frame, "
                  f"**{nl['detect_frames_per_s']:.0f} frames/s** on {nl['threads']} threads "
                  "(`MIRRORCAP_DETECT_THREADS`)"]
    return lines + [""]


def _tracking_summary(trk) -> list:
    lines = ["## Tracking from detections (300 markers, 150 frames unless stated, 10 deg head turn, 5 mm expressions)",
             "", "| scenario | markers | RMS | identity switches | reported of visible | conjectured RMS / p99 / max "
             "| conjectured / withheld | candidates per marker | frames/s fastest / median |", "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    cmd = trk.get("_command")
    trk = {k: v for k, v in trk.items() if k != "_command"}
    for name, r in trk.items():
        lines.append(f"| {name} | {r['markers']} | {r['rms_mm']:.3f} mm | {r['identity_switches']} of "
                     f"{r['measured']} | {r['reported_of_visible'] * 100:.1f} % | {r['conjectured_rms_mm']:.2f} / "
                     f"{r['conjectured_p99_mm']:.2f} / {r['conjectured_max_mm']:.2f} mm | "
                     f"{r.get('conjectured', '-')} / {r.get('withheld', '-')} | "
                     f"{r['candidates_per_measured']:.2f} | {r['frames_per_s']:.0f} / "
                     f"{r.get('frames_per_s_median', r['frames_per_s']):.0f} |")
    stages = [(name, r["stages_ms"]) for name, r in trk.items() if "stages_ms" in r]
    if stages:
        keys = list(stages[0][1])
        lines += ["", "Stages of the fastest run (ms):", "", "| scenario | " + " | ".join(k.replace("_", " ") for k in keys)
                  + " |", "| --- |" + " --- |" * len(keys)]
        lines += [f"| {name} | " + " | ".join(f"{st.get(k, 0):.0f}" for k in keys) + " |" for name, st in stages]
    if cmd:
        st = cmd["stages_s"]
        lines += ["", f"Whole `mirrorcap track` on a rendered {cmd['size'][0]}x{cmd['size'][1]} MP4 of {cmd['frames']} "
                  f"frames (same performance; decode, extraction, mirror self-calibration, tracking, outputs): "
                  f"**{cmd['frames_per_s']:.0f} frames/s** fastest, {cmd['frames_per_s_median']:.0f} median "
                  f"(detect {st['detect']:.2f} s, track {st['track']:.2f} s, the rest {st['other']:.2f} s); "
                  f"{cmd['markers']} markers, RMS {cmd['rms_mm']:.3f} mm after one similarity, "
                  f"{cmd['identity_switches']} identity switches in {cmd['measured_marker_frames']} measured "
                  f"marker-frames, conjectured {cmd['conjectured_rms_mm']:.2f} / {cmd['conjectured_max_mm']:.2f} mm "
                  f"RMS / max."]
    return lines + [""]


def _summary(speed, rows, expected, trials, seconds, ext=None, trk=None) -> str:
    sims = (f"{trials} trials per simulation setting, simulations took {seconds:.0f} s." if seconds else
            "Simulation results reused from the previous full run (`--skip-simulation`).")
    lines = ["# MirrorCap benchmark results", "",
             f"Machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}. {sims}", ""]
    if speed:
        lines += ["## Speed (one frame, 300 markers; fastest and median of repeated runs)", "",
                  "| operation | fastest | median |", "| --- | --- | --- |"]
        for k, v in speed.items():
            if k.endswith("_us") and not k.endswith("_median_us"):
                lines.append(f"| {k[:-3].replace('_', ' ')} | {v:,.1f} us | {speed[k[:-3] + '_median_us']:,.1f} us |")
        lines.append("")
    if rows:
        lines += ["## Section 6.2 simulations: RMS 3D error (cube units; 1 unit = 0.05 mm at 2 m)", ""]
        pick = {"fig6_1_points": [10, 30, 60, 100], "fig6_2_noise": [0.0, 1.0, 2.0, 3.0],
                "fig6_3_resolution": [1 / 3, 0.5, 1.0], "fig6_4_orientation": ["15/0", "30/0", "45/0", "60/0",
                                                                                 "45/-45", "45/45"]}
        for exp, settings in pick.items():
            label = EXPERIMENTS[exp][0]
            lines += [f"### {exp} ({label})", "", "| setting | " + " | ".join(METHOD_LABELS[m] for m in METHODS)
                      + " | (b)/(a) | OpenCV/(a) |", "|" + " --- |" * (len(METHODS) + 3)]
            for s in settings:
                key = s if isinstance(s, str) else s
                vals = {r["method"]: r for r in rows if r["experiment"] == exp and
                        (r["setting"] == key or (not isinstance(key, str) and not isinstance(r["setting"], str)
                                                 and abs(float(r["setting"]) - key) < 1e-4))}
                if not vals:
                    continue
                cells = [f"{vals[m]['rms']:.3g}" + (f" ({vals[m]['failures']} failed)" if vals[m]["failures"] else "")
                         for m in METHODS]
                a = vals["mirror"]["rms"]
                ratio_b = vals["two_view_linear"]["rms"] / a if a > 0 else float("nan")
                ratio_cv = vals["opencv"]["rms"] / a if a > 0 else float("nan")
                name = f"{s:.3g}" if isinstance(s, float) else str(s)
                lines.append(f"| {name} | " + " | ".join(cells) + f" | {ratio_b:.2f} | {ratio_cv:.2f} |")
            lines.append("")
    if ext:
        lines += _extraction_summary(ext)
    if trk:
        lines += _tracking_summary(trk)
    if expected:
        lines += ["## Expected normal error (eq. 3.26) vs Monte Carlo (60 points, Gaussian noise)", "",
                  "| noise (px) | predicted (deg) | Monte Carlo (deg) | MC / predicted | worst configuration |",
                  "| --- | --- | --- | --- | --- |"]
        for r in expected:
            lines.append(f"| {r['sigma_px']:g} | {r['predicted_deg']:.4f} | {r['monte_carlo_deg']:.4f} | "
                         f"{r['ratio']:.3f} | {r['worst_configuration_ratio']:.3f} |")
        lines.append("")
    return "\n".join(lines) + "\n"


def stress_summary(stress) -> list:
    lines = ["## Stress clips (Cycles, `make stress-clips`; whole `mirrorcap track`, mirrors self-calibrated)", "",
             "| clip | frames | markers (true) | RMS / p95 / max | points > 2 mm | identity switches | split labels "
             "| seen marker-frames reported | never tracked | mirror ratio error | frames/s "
             "| without a rig file: reported / switches / points > 2 mm |",
             "| --- |" + " --- |" * 11]
    for name, r in stress.items():
        if "refused" in r:
            lines.append(f"| {name} ({r['size'][0]}x{r['size'][1]}) | {r['frames']} | refused: {r['refused']} |"
                         + " |" * 9)
            continue
        seen = r.get("seen_reported_fraction")
        lines.append(f"| {name} ({r['size'][0]}x{r['size'][1]}) | {r['frames']} | {r['markers']} ({r['markers_true']}) "
                     f"| {r['rms_mm']:.2f} / {r['p95_mm']:.2f} / {r['max_mm']:.1f} mm | {r['points_over_2mm']} | "
                     f"{r['identity_switches']} | {r['split_markers']} | "
                     f"{'-' if seen is None else f'{100 * seen:.1f} %'} | {r.get('never_tracked', '-')} | "
                     f"{100 * r['mirror_ratio_error']:+.2f} % | {r['frames_per_s']:.0f} | "
                     f"{_without_rig_file(r.get('without_rig_file'))} |")
    return lines + [""]


def _without_rig_file(w) -> str:
    """A stress clip's figures tracked without its rig file (``without_rig_file``), for the summary."""
    if w is None:
        return "-"
    if "refused" in w:
        return "refused"
    seen = w.get("seen_reported_fraction")
    return f"{'-' if seen is None else f'{100 * seen:.1f} %'} / {w['identity_switches']} / {w['points_over_2mm']}"


def loaded_summary(loaded: dict) -> list:
    """track_under_load.json as a table."""
    lines = ["**The whole `mirrorcap track` with both cores kept busy by two other processes** "
             "(`track_under_load.json`; seconds, tracking alone in brackets):", "",
             "| clip | frames | one BLAS thread (default) | BLAS's own threads (`MIRRORCAP_BLAS_THREADS=0`) |",
             "| --- | --- | --- | --- |"]
    for name, r in loaded.items():
        one, own = r["one_blas_thread"], r["blas_default"]
        lines.append(f"| {name} | {r['frames']} | {one['seconds']:.1f} s ({one['track_s']:.1f} s) | "
                     f"{own['seconds']:.1f} s ({own['track_s']:.1f} s) |")
    return lines + [""]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.run", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default="bench_results")
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--skip-simulation", action="store_true", help="no section 6.2 simulations")
    parser.add_argument("--skip-extraction", action="store_true", help="no marker-extraction benchmark")
    parser.add_argument("--stream-frames", type=int, default=10000, help="frames of the memory/stream test")
    parser.add_argument("--skip-tracking", action="store_true", help="no tracking benchmark")
    parser.add_argument("--skip-animation", action="store_true", help="no head/fit/rig/bake benchmark")
    parser.add_argument("--skip-batch", action="store_true", help="no `mirrorcap batch` benchmark")
    parser.add_argument("--skip-takes", action="store_true", help="no stabilize / ARKit benchmarks")
    parser.add_argument("--long-take", type=int, default=0, metavar="FRAMES",
                        help="also track a FRAMES-frame take (3600: a minute; ~5 minutes) -> long_take.json")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    files = {}

    print("speed ...", flush=True)
    speed = run_speed()
    files[out / "speed.json"] = json.dumps(speed, indent=2) + "\n"
    for k, v in speed.items():
        if k.endswith("_us") and not k.endswith("_median_us"):
            print(f"  {k[:-3]:40s} {v:10.1f} us (median {speed[k[:-3] + '_median_us']:.1f})")

    rows, expected, seconds = [], [], 0.0
    if not args.skip_simulation:
        t0 = time.perf_counter()

        def progress(done, total):
            print(f"\r  simulations: {done}/{total} settings", end="", flush=True)

        print(f"section 6.2 simulations, {args.trials} trials per setting ...", flush=True)
        rows = run_simulations(trials=args.trials, workers=args.workers, progress=progress)
        print()
        expected = expected_error_check()
        seconds = time.perf_counter() - t0
        files[out / "simulation.csv"] = _csv(rows, ["experiment", "setting", "method", "rms", "median", "failures",
                                                    "trials"])
        files[out / "expected_error.csv"] = _csv(expected, list(expected[0]))
        for exp in EXPERIMENTS:
            files[out / f"{exp}.png"] = _plot(rows, exp)
    elif (out / "simulation.csv").is_file() and (out / "expected_error.csv").is_file():
        seconds = None
        rows = _read_csv(out / "simulation.csv")
        expected = _read_csv(out / "expected_error.csv")
        print("(simulations skipped: the summary reuses the existing simulation.csv)")
    ext = None
    if not args.skip_extraction:
        print("marker extraction (in a fresh process) ...", flush=True)
        # a fresh interpreter: timings unaffected by the simulations' memory and worker pools
        with ProcessPoolExecutor(max_workers=1, mp_context=get_context("spawn")) as pool:
            ext = pool.submit(run_extraction_benchmark, args.stream_frames).result()
        files[out / "extraction.json"] = json.dumps(ext, indent=2) + "\n"
    elif (out / "extraction.json").is_file():
        ext = json.loads((out / "extraction.json").read_text())  # the summary keeps the last measured figures
    def measure_or_reuse(skip, name, label, run):
        """Run one part and stage its JSON; when skipped, the summary reuses the last measured file."""
        if not skip:
            print(label, flush=True)
            result = run()
            files[out / name] = json.dumps(result, indent=2) + "\n"
            return result
        return json.loads((out / name).read_text()) if (out / name).is_file() else None

    trk = measure_or_reuse(args.skip_tracking, "tracking.json", "tracking from detections ...", run_tracking_benchmark)
    cmd = measure_or_reuse(args.skip_tracking, "track_command.json",
                           "whole `mirrorcap track` on a rendered 1280x720 MP4 ...", run_track_command_benchmark)
    if trk is not None and cmd is not None:
        trk = {**trk, "_command": cmd}
    stress = measure_or_reuse(args.skip_tracking, "stress_clips.json", "whole `mirrorcap track` on the stress clips ...",
                              run_stress_clip_benchmark)
    loaded = measure_or_reuse(args.skip_tracking, "track_under_load.json",
                              "whole `mirrorcap track` with every core kept busy by other processes ...",
                              run_loaded_track_benchmark)
    long_take = measure_or_reuse(not args.long_take, "long_take.json",
                                 f"whole `mirrorcap track` on a {args.long_take}-frame take ...",
                                 lambda: run_long_take_benchmark(args.long_take))
    anim = measure_or_reuse(args.skip_animation, "animation.json", "head fit, rig and bake ...",
                            run_animation_benchmark)
    batch = measure_or_reuse(args.skip_batch, "batch.json", "batch bake of 4 takes, 1 and 2 workers ...",
                             run_batch_benchmark)
    stab = measure_or_reuse(args.skip_takes, "stabilize.json", "stabilize: 23-marker takes, 20 noise draws ...",
                            run_stabilize_benchmark)
    arkit = measure_or_reuse(args.skip_takes, "arkit.json", "ARKit-52 solve: 1,000 frames, 150 markers ...",
                             run_arkit_benchmark)
    transfer = measure_or_reuse(args.skip_takes, "transfer.json", "retarget --method transfer: 1,000 frames ...",
                                run_transfer_benchmark)
    summary = _summary(speed, rows, expected, args.trials, seconds, ext, trk)
    if stress:
        summary = summary.rstrip("\n") + "\n\n" + "\n".join(stress_summary(stress)) + "\n"
    if loaded:
        summary = summary.rstrip("\n") + "\n\n" + "\n".join(loaded_summary(loaded)) + "\n"
    if long_take:
        summary = (summary.rstrip("\n") + f"\n\n**A long take** (`long_take.json`): {long_take['frames']} frames "
                   f"{long_take['size'][0]}x{long_take['size'][1]}, {long_take['markers_tracked']} markers: "
                   f"{long_take['frames_per_s']:.0f} frames/s, peak resident memory {long_take['peak_rss_mb']:.0f} MB, "
                   f"{long_take['rms_mm']:.3f} mm RMS, {long_take['identity_switches']} identity switches.\n")
    if anim is not None:
        summary = summary.rstrip("\n") + "\n" + "\n".join(animation_summary(anim)) + "\n"
    if batch is not None:
        summary = summary.rstrip("\n") + "\n\n" + "\n".join(batch_summary(batch)) + "\n"
    if stab is not None:
        summary = summary.rstrip("\n") + "\n\n" + "\n".join(stabilize_summary(stab)) + "\n"
    if arkit is not None:
        summary = summary.rstrip("\n") + "\n\n" + "\n".join(arkit_summary(arkit)) + "\n"
    if transfer is not None:
        summary = summary.rstrip("\n") + "\n\n" + "\n".join(transfer_summary(transfer)) + "\n"
    files[out / "summary.md"] = summary
    write_files_atomically(files)
    print(summary)
    return 0


if __name__ == "__main__":
    sys.exit(main())
