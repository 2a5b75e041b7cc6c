"""The end-to-end demo on the embedded rendered clip, and `mirrorcap batch`."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT

from mirrorcap.core.face.scanio import read_landmarks, read_scan


def _run(args, timeout=900):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=timeout, cwd=ROOT,
                          env=dict(os.environ))


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    code = ("from mirrorcap.demo.rig import run_demo\n"
            f"run_demo({str(out)!r}, quiet=True, preview=False)\n")
    res = _run(["-c", code])
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    return out, json.loads((out / "demo.json").read_text())


def test_demo_tracks_fits_binds_and_bakes_the_sample_accurately(demo):
    out, d = demo
    trk = d["tracking"]
    assert trk["markers_tracked"] >= 115 and trk["markers_matched"] == trk["markers_tracked"]
    assert trk["rms_mm"] < 0.3                       # 0.12 mm measured; a wrong scale or pairing gives mm
    assert trk["max_mm"] < 3.0
    assert trk["identity_switches"] == 0             # 6 measurements of one grazing marker are > 2 px off: not switches
    # every marker-frame is measured, conjectured, or a conjecture withheld as a gap because its
    # expected error (3 sigma) passes 2 mm (the take then meets the 2 mm for conjectures)
    assert trk["reported_fraction"] + trk["withheld_fraction"] > 0.98
    assert trk["conjectured_max_mm"] < 2.0 and trk["withheld_fraction"] < 0.06
    assert abs(trk["scale_to_mm"] - 1.0) < 0.1       # the face-distance prior puts the take near mm
    assert d["fit"]["residual_to_scan_rms_mm"] < 0.3 and d["fit"]["error_to_true_face_rms_mm"] < 1.5
    assert d["bind"]["registration"] == "surface" and d["bind"]["surface_rms_mm"] < 0.5
    an = d["animation"]
    assert an["shape_keys"] == d["clip"]["frames"] == 120
    assert an["displacement_error_rms_mm"] < an["true_displacement_rms_mm"]
    page = (out / "report.html").read_text()
    assert "3D RMS error of the take" in page and f"{trk['rms_mm']:.3f} mm" in page and page.count("<svg") >= 5
    assert (out / "demo.blend").stat().st_size > 100_000 and (out / "fitted_head.blend").is_file()


def test_demo_retargets_the_take_onto_the_second_character(demo, tmp_path):
    """The take's motion transferred onto sample_scenes/character (other proportions and topology,
    landmarks only): keyed in demo.blend beside the actor, and near the character's own expression
    of the same performance (1.24 mm mean measured; no motion at all would be off by its whole motion)."""
    out, d = demo
    rt = d["retarget"]
    print(f"retarget: {rt['moving_vertex_error_mean_mm']:.2f} mm mean on moving vertices "
          f"(their motion {rt['own_motion_mean_mm']:.2f} mm)")
    assert rt["moving_vertex_error_mean_mm"] < min(2.0, 0.5 * rt["own_motion_mean_mm"])
    assert rt["region_scales"]["lower"][0] > 1.15            # the character's mouth is wider: its motion too
    res = _run([ROOT / "tests" / "blender" / "readback.py", out / "demo.blend", "Character", tmp_path / "rb.npz"])
    assert res.returncode == 0, res.stdout + res.stderr
    rb = np.load(tmp_path / "rb.npz")
    assert rb["keys"].shape[0] == 120 and rb["evaluated"].shape[0] == 120
    moved = np.abs(rb["evaluated"] - rb["basis"][None]).max(axis=(1, 2)) * 1000     # mm, per frame
    assert moved.max() > 5.0 and moved.min() < moved.max()    # the character moves, frame by frame


def test_batch_bakes_takes_in_parallel_and_reports_a_failing_one(demo, tmp_path):
    out, _ = demo
    good = [tmp_path / f"take_{i}.c3d" for i in range(2)]
    for g in good:
        g.write_bytes((out / "take.c3d").read_bytes())
    bad = tmp_path / "broken.c3d"
    bad.write_bytes(b"not a take" * 50)
    res = _run(["-m", "mirrorcap", "batch", *good, bad, "--head", out / "fitted_head.blend", "--out",
                tmp_path / "baked", "--workers", "2", "--drop-unseen", "--frames", "20:", "--frame-start", "1001"])
    assert res.returncode == 1, res.stdout + res.stderr
    lines = [ln for ln in res.stdout.splitlines() if "] " in ln and ("ok " in ln or "FAIL" in ln)]
    assert len(lines) == 3 and sum("FAIL" in ln for ln in lines) == 1
    assert any("broken.c3d: FAIL" in ln and "not a C3D file" in ln for ln in lines)
    summary = json.loads((tmp_path / "baked" / "batch.json").read_text())
    assert summary["failed"] == 1 and summary["takes"] == 3
    assert [r["ok"] for r in summary["results"]] == [True, True, False]
    assert len({r["pid"] for r in summary["results"] if r["ok"]}) >= 1
    for g in good:
        assert (tmp_path / "baked" / f"{g.stem}.blend").stat().st_size > 100_000
        report = json.loads((tmp_path / "baked" / f"{g.stem}.bake.json").read_text())
        assert report["frames"] == 100 and report["take_frames"] == [20, 120] and report["frame_start"] == 1001
    assert not (tmp_path / "baked" / "broken.blend").exists()
    # Blender's own messages go to the take's log, not into the batch's output
    assert "Read blend" not in res.stdout + res.stderr
    assert "Read blend" in (tmp_path / "baked" / "take_0.log").read_text()


def bake_or_crash(job):
    """A batch's per-take function that kills its process on takes named crash*, as a crash
    inside Blender would (module level: the spawned workers import it by name)."""
    from pathlib import Path

    if Path(job[0]).stem.startswith("crash"):
        print("crashing on purpose", flush=True)
        os._exit(70)
    from mirrorcap.cli.batch import _bake_one

    return _bake_one(job)


def report_sigint_mask(job):
    """A batch's per-take function that reports whether its worker process has SIGINT blocked (module level: the
    spawned workers import it by name)."""
    import signal

    blocked = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, set())
    return {"take": job[0], "ok": False, "seconds": None, "error": f"SIGINT blocked: {blocked}"}


@pytest.mark.skipif(not hasattr(__import__("signal"), "pthread_sigmask"), reason="POSIX signal masks")
def test_batch_workers_start_with_ctrl_c_blocked(tmp_path):
    """Stop 47: Ctrl-C reaches the batch command's whole process group, and a worker still starting up -- before
    it ignores SIGINT -- died of it printing "Fatal Python error: init_import_site" (test_batch_stops_cleanly_on_ctrl_c
    failed so once, on a loaded machine). A worker is now spawned with SIGINT blocked (the mask survives the spawn's
    exec), and the command's own mask is restored at once: the command stops the workers itself."""
    import signal

    from mirrorcap.cli.batch import run_batch

    head = tmp_path / "head.blend"
    head.write_bytes(b"not read")
    summary = run_batch([tmp_path / "a.c3d", tmp_path / "b.c3d"], head, tmp_path / "out", workers=2, quiet=True,
                        bake=report_sigint_mask)
    assert [r["error"] for r in summary["results"]] == ["SIGINT blocked: True"] * 2
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX spawn and signals")
def test_a_ctrl_c_while_a_batch_worker_starts_stops_it_without_a_traceback(tmp_path, monkeypatch, capfd):
    """Stop 49: a Ctrl-C between the spawn of a worker and the write of what it is to run left the worker reading
    an empty pipe: "EOFError: Ran out of input" on the terminal after "interrupted" (1 in 60 interrupts under
    load). The Ctrl-C arrives here at that very moment; the batch now stops with the worker started and then
    stopped, and nothing printed."""
    import multiprocessing.util
    import signal

    from mirrorcap.cli.batch import run_batch

    spawned = []
    spawn = multiprocessing.util.spawnv_passfds

    def spawn_then_ctrl_c(path, args, passfds):
        pid = spawn(path, args, passfds)
        if any("spawn_main" in os.fsdecode(a) for a in args):      # a worker, not the resource tracker
            spawned.append(pid)
            os.kill(os.getpid(), signal.SIGINT)
        return pid

    monkeypatch.setattr(multiprocessing.util, "spawnv_passfds", spawn_then_ctrl_c)
    head = tmp_path / "head.blend"
    head.write_bytes(b"not read")
    with pytest.raises(KeyboardInterrupt):
        run_batch([tmp_path / "a.c3d", tmp_path / "b.c3d"], head, tmp_path / "out", workers=1, quiet=True,
                  bake=report_sigint_mask)
    assert len(spawned) == 1
    try:                                # a worker left running would print its traceback, then exit
        os.waitpid(spawned[0], 0)
    except ChildProcessError:           # the batch stopped it and collected it
        pass
    err = capfd.readouterr().err
    assert "Traceback" not in err and "EOFError" not in err, err
    assert not (tmp_path / "out" / "batch.json").exists()


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_ctrl_c_while_blender_loads_stops_bake_as_interrupted(demo, tmp_path):
    """Stop 49: a Ctrl-C while ``mirrorcap bake`` loaded Blender (``import bpy``) raised inside Blender's start-up
    scripts; Blender was left half-registered and the process died of a segmentation fault (3 of 14 interrupts
    0.1-6 s after the start). Here the Ctrl-C comes as Blender imports its UI scripts: the command now stops with
    "interrupted", exit 130, and writes nothing."""
    out, _ = demo
    code = ("import os, signal, sys\n"
            "class CtrlCWhileBlenderLoads:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name == 'bl_ui':\n"
            "            os.kill(os.getpid(), signal.SIGINT)\n"
            "        return None\n"
            "sys.meta_path.insert(0, CtrlCWhileBlenderLoads())\n"
            "from mirrorcap.cli.parser import main\n"
            f"sys.exit(main(['bake', {str(out / 'take.c3d')!r}, '--head', {str(out / 'fitted_head.blend')!r}, "
            f"'-o', {str(tmp_path / 'o.blend')!r}, '--drop-unseen']))\n")
    res = _run(["-c", code], timeout=300)
    assert (res.returncode, res.stderr.strip()) == (130, "mirrorcap: interrupted"), res.stdout + res.stderr
    assert not list(tmp_path.iterdir())


def test_batch_goes_on_when_a_take_kills_its_worker(demo, tmp_path):
    from mirrorcap.cli.batch import run_batch

    out, _ = demo
    names = ["take_a", "crash_b", "take_c", "take_d"]
    takes = [tmp_path / f"{n}.c3d" for n in names]
    for t in takes:
        t.write_bytes((out / "take.c3d").read_bytes())
    options = {"object": None, "mode": "frames", "modes": 8, "neutral_frame": 0, "head_motion": False,
               "no_blinks": False, "blink_seed": 0, "blink_interval": 2.5, "k": 16.0, "unseen": "drop"}
    summary = run_batch(takes, out / "fitted_head.blend", tmp_path / "baked", workers=2, options=options, quiet=True,
                        bake=bake_or_crash)
    res = {r["take"]: r for r in summary["results"]}
    crashed = res[str(takes[1])]
    assert not crashed["ok"] and "worker process died (exit code 70)" in crashed["error"]
    assert "crashing on purpose" in (tmp_path / "baked" / "crash_b.log").read_text()
    assert [res[str(t)]["ok"] for t in takes] == [True, False, True, True]
    assert summary["failed"] == 1 and summary["processes_started"] == 3    # one replacement worker
    for n in ("take_a", "take_c", "take_d"):
        assert (tmp_path / "baked" / f"{n}.blend").stat().st_size > 100_000
    assert json.loads((tmp_path / "baked" / "batch.json").read_text())["failed"] == 1


def test_batch_stops_cleanly_on_ctrl_c(demo, tmp_path):
    import signal
    import time

    out, _ = demo
    takes = [tmp_path / f"take_{i}.c3d" for i in range(6)]
    for t in takes:
        t.write_bytes((out / "take.c3d").read_bytes())
    proc = subprocess.Popen([sys.executable, "-m", "mirrorcap", "batch", *map(str, takes), "--head",
                             str(out / "fitted_head.blend"), "--out", str(tmp_path / "baked"), "--workers", "2",
                             "--drop-unseen"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True,
                            # a shell's background job inherits SIGINT ignored; a user's terminal has it on
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(0.5)                                  # the workers are starting Blender
    os.killpg(proc.pid, signal.SIGINT)               # Ctrl-C in a terminal reaches the whole group
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 130, stdout + stderr
    assert stderr.strip() == "mirrorcap: interrupted"          # no traceback, from the command or a worker
    alive = None
    for _ in range(50):                              # every worker is gone (zombies wait for init)
        ps = subprocess.run(["ps", "-o", "pid=,stat=", "-g", str(proc.pid)], capture_output=True, text=True)
        alive = [ln for ln in ps.stdout.splitlines() if ln.split()[1][0] != "Z"]
        if not alive:
            break
        time.sleep(0.1)
    assert not alive
    assert not list((tmp_path / "baked").glob("*.tmp*"))


def test_scan_readers_agree_across_formats(tmp_path):
    V, T = read_scan(ROOT / "sample_scenes" / "rig_clip" / "scan.ply")
    assert V.shape[1] == 3 and T.shape[1] == 3 and T.max() < len(V)
    sub_v, sub_t = V[:300], T[np.all(T < 300, axis=1)][:200]
    ascii_ply = tmp_path / "a.ply"
    ascii_ply.write_text("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
                         "property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n"
                         % (len(sub_v), len(sub_t) // 2)
                         + "".join(f"{x} {y} {z}\n" for x, y, z in sub_v)
                         # quads: pairs of triangles sharing an edge are written as one polygon here
                         + "".join(f"4 {a} {b} {c} {a}\n" for a, b, c in sub_t[: len(sub_t) // 2]))
    va, ta = read_scan(ascii_ply)
    assert np.allclose(va, sub_v, atol=1e-4) and len(ta) == 2 * (len(sub_t) // 2)
    obj = tmp_path / "a.obj"
    obj.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in sub_v)
                   + "".join(f"f {a + 1}/1 {b + 1}/1 {c + 1}/1\n" for a, b, c in sub_t))
    vo, to = read_scan(obj)
    assert np.allclose(vo, sub_v, atol=1e-4) and np.array_equal(to, sub_t)
    lms = read_landmarks(ROOT / "sample_scenes" / "rig_clip" / "scan_landmarks.json")
    assert "nose_tip" in lms and lms["nose_tip"].shape == (3,)
    (tmp_path / "bad.ply").write_bytes(b"PLX garbage")
    with pytest.raises(Exception, match="not a PLY"):
        read_scan(tmp_path / "bad.ply")


def test_faps_of_the_sample_follow_its_true_jaw_and_a_played_fap_file_reproduces_them(demo, tmp_path):
    """`mirrorcap fap` on the tracked sample: open_jaw (FAP 3) against the rendered subject's true
    chin drop; `mirrorcap bake --fap` plays the file on the head, and the FAPs measured on the mesh
    Blender evaluates at every frame are the file's within 1 unit."""
    from mirrorcap.core.face.head import HeadModel
    from mirrorcap.core.face.headio import load_head_npz
    from mirrorcap.core.retarget import mpeg4
    from mirrorcap.synthetic.headsim import performance

    out, _ = demo
    fap, rep = tmp_path / "take.fap", tmp_path / "fap.json"
    res = _run(["-m", "mirrorcap", "fap", out / "take.c3d", "--head", out / "fitted_head.blend", "--head-pose",
                out / "take_report.json", "--conjecture-unseen", "-o", fap, "--report", rep])
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads(rep.read_text())
    track = mpeg4.read_fap(fap)
    assert track.frames == 120 and track.mask[2] and not track.mask[18:30].any()
    truth = np.load(ROOT / "sample_scenes" / "rig_clip" / "truth.npz")
    generic, keys = load_head_npz(ROOT / "sample_scenes" / "generic_head" / "head.npz", with_shape_keys=True)
    disp, _ = performance(generic, keys, 120, float(truth["fps"]), seed=int(truth["performance_seed"]))
    true_drop = disp[:, generic.landmarks()["chin"]] @ generic.face_axes()["down"]
    r = np.corrcoef(track.values[:, 2], true_drop)[0, 1]
    assert r >= 0.95, r                                          # 0.998 measured
    played = tmp_path / "played.blend"
    res = _run(["-m", "mirrorcap", "bake", "--fap", fap, "--head", out / "fitted_head.blend", "-o", played,
                "--no-blinks"])
    assert res.returncode == 0, res.stdout + res.stderr
    rb = tmp_path / "readback.npz"
    res = _run([ROOT / "tests" / "blender" / "readback.py", played, report["object"], rb])
    assert res.returncode == 0, res.stdout + res.stderr
    rb = np.load(rb)
    to_core = lambda p: 1000.0 * np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)  # noqa: E731
    basis = to_core(rb["basis"].astype(float))
    head = HeadModel(vertices=basis, polygons=generic.polygons, polygon_sizes=generic.polygon_sizes,
                     groups=generic.groups)
    seen = to_core(rb["evaluated"].astype(float)) - basis[None]
    again = mpeg4.faps_from_motion(head, seen, points=report["feature_points"], high_level=False)
    low = [f.number - 1 for f in mpeg4.LOW_LEVEL_FAPS if track.mask[f.number - 1]]
    assert np.abs(again.values[:, low] - track.values[:, low]).max() <= 1.0
    # with --head-motion the file's head rotation (FAPs 48-50) turns the object, frame by frame
    turned = tmp_path / "turned.blend"
    res = _run(["-m", "mirrorcap", "bake", "--fap", fap, "--head", out / "fitted_head.blend", "-o", turned,
                "--no-blinks", "--head-motion"])
    assert res.returncode == 0, res.stdout + res.stderr
    code = ("import bpy, json, numpy as np\n"
            f"bpy.ops.wm.open_mainfile(filepath={str(turned)!r})\n"
            f"obj = bpy.data.objects[{report['object']!r}]\n"
            "out = []\n"
            "for f in range(1, 121):\n"
            "    bpy.context.scene.frame_set(f)\n"
            "    out.append([list(r) for r in obj.matrix_world.to_3x3()])\n"
            "print('ROT ' + json.dumps(out))\n")
    res = _run(["-c", code])
    assert res.returncode == 0, res.stdout + res.stderr
    Rb = np.array(json.loads(res.stdout.split("ROT ", 1)[1]))
    C = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])                 # blender = C @ core
    R = np.einsum("ji,fjk,kl->fil", C, Rb, C)                           # back on core coordinates
    from mirrorcap.core.retarget.arkit import head_angles

    R0 = np.linalg.inv(R[0])                                            # the rotation the object had before
    turn = head_angles(np.einsum("fij,jk->fik", R, R0), head.face_axes())[:, [1, 0, 2]]
    want = (track.values[:, 47:50] - track.values[0, 47:50]) * mpeg4.AU_RAD
    print(f"head rotation keyed within {np.degrees(np.abs(turn - want).max()):.3f} deg of the file's "
          f"(it turns up to {np.degrees(np.abs(want).max()):.1f} deg)")
    assert track.mask[47:50].all() and np.degrees(np.abs(want).max()) > 1.0
    assert np.degrees(np.abs(turn - want).max()) < 0.05
