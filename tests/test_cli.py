"""``mirrorcap reconstruct`` end to end, and every bad input it must refuse."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, SAMPLE
from mirrorcap.cli import parser as cli
from mirrorcap.synthetic import simulate as sim
from mirrorcap.core.take.pairs import format_pairs, read_points


def _run(args, capsys):
    code = cli.main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture
def sample(tmp_path):
    for name in ("pairs.csv", "camera.json", "truth.csv", "truth.json"):
        shutil.copy(SAMPLE / name, tmp_path / name)
    return tmp_path


def _truth(sample):
    return json.loads((sample / "truth.json").read_text())


def test_reconstruct_sample_in_mm(sample, capsys):
    truth = _truth(sample)
    a, b, mm = truth["known_length"]
    out = sample / "points.csv"
    code, stdout, err = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json",
                              "-o", out, "--known-length", a, b, mm], capsys)
    assert code == 0, err
    assert "points" in stdout and "mirror 0" in stdout
    ids, pts = read_points(out)
    header = out.read_text().splitlines()[0]
    assert header == "id,x,y,z,mirrors"
    true_ids, true_pts = read_points(sample / "truth.csv")
    lookup = dict(zip(true_ids, true_pts))
    err3d = np.linalg.norm(pts - np.array([lookup[i] for i in ids]), axis=1)
    assert np.sqrt(np.mean(err3d**2)) < 0.3  # mm, 0.15 px noise at 600 mm
    report = json.loads(out.with_suffix(".json").read_text())
    assert report["units"] == "mm"
    assert len(report["mirrors"]) == 2
    for m, true in zip(report["mirrors"], truth["mirrors"]):
        assert set(m) >= {"normal", "d", "inliers", "pairs", "expected_normal_error_deg", "noise_px"}
        assert np.degrees(np.arccos(np.clip(np.dot(m["normal"], true["normal"]), -1, 1))) < 0.2
        assert m["d"] == pytest.approx(true["d"], rel=0.01)
    assert report["fused_points"] > 10
    wrong = {(w["id"], w["mirror"]) for w in truth["wrong_pairs"]}
    rejected = {(r["id"], r["mirror"]) for r in report["rejected_pairs"]}
    assert wrong <= rejected


def test_relative_units_refine_and_no_ransac(sample, capsys):
    out = sample / "rel.csv"
    code, _, err = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json", "-o", out,
                         "--refine", "-q"], capsys)
    assert code == 0, err
    report = json.loads(out.with_suffix(".json").read_text())
    assert report["units"] == "relative"
    assert report["mirrors"][0]["d"] == pytest.approx(-1.0)
    assert report["refinement"]["rms_px_after"] <= report["refinement"]["rms_px_before"]
    # the closed form on every pair, wrong ones included, is measurably worse
    out2 = sample / "naive.csv"
    code, _, _ = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json", "-o", out2,
                       "--no-ransac", "-q"], capsys)
    assert code == 0
    naive = json.loads(out2.with_suffix(".json").read_text())
    assert naive["rejected_pairs"] == []
    assert naive["mirrors"][0]["noise_px"] > 5 * report["mirrors"][0]["noise_px"]


def test_single_mirror_file(tmp_path, capsys):
    rig = sim.face_rig(n_markers=120, seed=5)
    direct, mirrored = sim.observe(rig.points, rig.planes, rig.camera, noise_px=0.1,
                                   rng=np.random.default_rng(0))
    vis = rig.visible_mirror & rig.visible_direct[None]
    vis[1] = False
    ids = [f"p{i}" for i in range(len(rig.points))]
    (tmp_path / "pairs.csv").write_text(format_pairs(ids, direct, mirrored, vis))
    (tmp_path / "camera.json").write_text(json.dumps(rig.camera.to_dict()))
    code, _, err = _run(["reconstruct", tmp_path / "pairs.csv", "--camera", tmp_path / "camera.json",
                         "-o", tmp_path / "out.csv"], capsys)
    assert code == 0, err
    report = json.loads((tmp_path / "out.json").read_text())
    assert len(report["mirrors"]) == 1 and report["points"] == int(vis[0].sum())


def test_python_dash_m_entry_point(sample):
    """The documented `python -m mirrorcap` works (installed package); there is no second command line."""
    for module in ("mirrorcap",):
        res = subprocess.run([sys.executable, "-m", module, "reconstruct", str(sample / "pairs.csv"),
                              "--camera", str(sample / "camera.json"), "-o", str(sample / f"{module}.csv"), "-q"],
                             capture_output=True, text=True, cwd=ROOT)
        assert res.returncode == 0, res.stderr
        assert (sample / f"{module}.csv").is_file()


# ----------------------------------------------------------------- bad input
def _pairs_text(sample):
    return (sample / "pairs.csv").read_text()


def _rows(text):
    lines = text.strip().splitlines()
    return lines[0], lines[1:]


def _moved_outside(row):
    fields = row.split(",")
    fields[2] = "5000"
    return ",".join(fields)


def _bad_cases(sample):
    text = _pairs_text(sample)
    header, rows = _rows(text)
    truth = _truth(sample)
    mirror0 = [r for r in rows if r.split(",")[1] == "0"]
    mirror1 = [r for r in rows if r.split(",")[1] == "1"]
    counts = {}
    for r in rows:
        counts[r.split(",")[0]] = counts.get(r.split(",")[0], 0) + 1
    single = [r for r in rows if counts[r.split(",")[0]] == 1]  # markers in one mirror only
    only0 = [r for r in single if r.split(",")[1] == "0"]
    # collinear: a synthetic set of pairs whose direct points lie on one image line
    line_rows = []
    for i in range(12):
        x = 500 + 10 * i
        line_rows.append(f"c{i},0,{x},{300 + 5 * i},{150 + 3 * i},{300 + 4.9 * i}")
    return {
        "missing column": ("id,mirror,x,y,xm\n" + "\n".join(r.rsplit(",", 1)[0] for r in rows) + "\n",
                           [], "missing column"),
        "too few": ("\n".join([header] + mirror0[:4] + mirror1) + "\n", [], "at least 6"),
        "collinear": ("\n".join([header] + line_rows) + "\n", [], "one image line"),
        "mirror with no pairs": ("\n".join([header] + [r.replace(",0,", ",1,", 1) for r in mirror0]) + "\n", [],
                                 "mirror 0 has no pairs"),
        "non-finite": ("\n".join([header, rows[0].rsplit(",", 1)[0] + ",nan"] + rows[1:]) + "\n", [], "not finite"),
        "not a number": ("\n".join([header, rows[0].rsplit(",", 1)[0] + ",abc"] + rows[1:]) + "\n", [],
                         "not a number"),
        "unknown id": (text, ["--known-length", "nobody", truth["known_length"][1], "50"], "unknown id"),
        "same id twice": (text, ["--known-length", truth["known_length"][0], truth["known_length"][0], "50"],
                          "two different ids"),
        "negative length": (text, ["--known-length", *truth["known_length"][:2], "-3"], "positive"),
        "length not a number": (text, ["--known-length", *truth["known_length"][:2], "ten"], "not a number"),
        "mirror id 2": ("\n".join([header, rows[0].replace(",0,", ",2,", 1)] + rows[1:]) + "\n", [],
                        "mirror must be 0 or 1"),
        "duplicate row": ("\n".join([header, rows[0], rows[0]] + rows[1:]) + "\n", [], "appears twice"),
        "empty file": ("", [], "empty"),
        "header only": (header + "\n", [], "no correspondences"),
        "outside image": ("\n".join([header] + [_moved_outside(r) if r == single[0] else r for r in rows]) + "\n",
                          [], "outside"),
        "inconsistent direct": ("\n".join([header] + rows + [only0[0].split(",")[0] + ",1,1.0,1.0,900,300"])
                                + "\n", [], "differs"),
        "no shared markers": ("\n".join([header] + mirror0 + [r for r in mirror1 if r.split(",")[0] not in
                                                              {m.split(",")[0] for m in mirror0}]) + "\n", [],
                              "both mirrors"),
    }


@pytest.mark.parametrize("case", [
    "missing column", "too few", "collinear", "mirror with no pairs", "non-finite", "not a number", "unknown id",
    "same id twice", "negative length", "length not a number", "mirror id 2", "duplicate row", "empty file",
    "header only", "outside image", "inconsistent direct", "no shared markers",
])
def test_bad_input_exits_nonzero_with_one_message_and_writes_nothing(sample, capsys, case):
    text, extra, message = _bad_cases(sample)[case]
    bad = sample / "bad.csv"
    bad.write_text(text)
    out = sample / "out" / "points.csv"
    out.parent.mkdir()
    code, stdout, err = _run(["reconstruct", bad, "--camera", sample / "camera.json", "-o", out, *extra], capsys)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("mirrorcap: error:"), err
    assert message in lines[0]
    assert list(out.parent.iterdir()) == []  # nothing written, no temporary files


def test_bad_camera_and_paths(sample, capsys):
    out = sample / "points.csv"
    (sample / "cam_bad.json").write_text('{"K": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}')
    for args, message in [
        (["--camera", sample / "cam_bad.json"], "missing key"),
        (["--camera", sample / "nope.json"], "cannot read camera"),
    ]:
        code, _, err = _run(["reconstruct", sample / "pairs.csv", *args, "-o", out], capsys)
        assert code == 2 and message in err
    code, _, err = _run(["reconstruct", sample / "missing.csv", "--camera", sample / "camera.json", "-o", out], capsys)
    assert code == 2 and "cannot read pairs" in err
    code, _, err = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json",
                         "-o", sample / "no_such_dir" / "p.csv"], capsys)
    assert code == 2 and "does not exist" in err
    assert not out.exists()
    # a camera for another image size puts points outside the image
    other = json.loads((sample / "camera.json").read_text())
    other["image_size"] = [640, 360]
    (sample / "cam_small.json").write_text(json.dumps(other))
    code, _, err = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "cam_small.json", "-o", out],
                        capsys)
    assert code == 2 and "outside" in err


def test_failure_keeps_previous_output(sample, capsys):
    out = sample / "points.csv"
    out.write_text("precious\n")
    out.with_suffix(".json").write_text("{}\n")
    (sample / "bad.csv").write_text("id,mirror,x,y,xm,ym\n")
    code, _, _ = _run(["reconstruct", sample / "bad.csv", "--camera", sample / "camera.json", "-o", out], capsys)
    assert code == 2
    assert out.read_text() == "precious\n" and out.with_suffix(".json").read_text() == "{}\n"


def test_a_ctrl_c_while_the_command_sets_up_stops_it_as_interrupted(sample, capsys, monkeypatch):
    """Stop 49: a Ctrl-C while the command loaded OpenCV and threadpoolctl raised inside their code: threadpoolctl's
    ctypes callback swallowed it, and the command ran to its end and exited 0 (inside ``import cv2`` it was an
    ImportError traceback instead). Here the setup swallows the Ctrl-C the same way: the command now stops with
    "interrupted", exit 130, and writes nothing."""
    import contextlib
    import os
    import signal
    import time

    @contextlib.contextmanager
    def setup_that_swallows_a_ctrl_c():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.5)             # Python runs its handler here, at once
        except KeyboardInterrupt:
            pass                        # as a ctypes callback does with it
        yield

    monkeypatch.setattr(cli, "limited_threads", setup_that_swallows_a_ctrl_c)
    code, out, err = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json",
                           "-o", sample / "points.csv"], capsys)
    assert (code, err.strip()) == (130, "mirrorcap: interrupted")
    assert not (sample / "points.csv").exists()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_an_import_cut_short_by_a_ctrl_c_is_an_interruption_and_a_real_import_error_is_not(sample, capsys,
                                                                                           monkeypatch):
    """Stop 49: a Ctrl-C during the import a command makes as it starts turned into "ImportError: initialization
    failed" (SciPy) and a traceback, exit 1. An error raised from a Ctrl-C now stops the command as interrupted;
    any other error is raised as before."""
    from mirrorcap.cli import commands

    def reconstruct_whose_import_a_ctrl_c_cut_short(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    def reconstruct_with_a_broken_install(args):
        raise ImportError("initialization failed")

    args = ["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json", "-o", sample / "points.csv"]
    monkeypatch.setattr(commands, "reconstruct", reconstruct_whose_import_a_ctrl_c_cut_short)
    code, _, err = _run(args, capsys)
    assert (code, err.strip()) == (130, "mirrorcap: interrupted")
    monkeypatch.setattr(commands, "reconstruct", reconstruct_with_a_broken_install)
    with pytest.raises(ImportError, match="initialization failed"):
        _run(args, capsys)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("blender", [False, True])
def test_the_entry_point_ignores_a_ctrl_c_once_the_command_is_done(blender):
    """Stop 49: a Ctrl-C while the process exited after a finished ``bake`` (Blender's teardown) killed it by SIGINT;
    after an interrupted one, Blender's teardown could end the process by SIGINT although "interrupted" had been
    printed. The entry point (``mirrorcap``, ``python -m mirrorcap``) ignores a Ctrl-C once the command is done, and
    with Blender loaded leaves at once after an interruption, with the command's exit status."""
    code = ("import os, signal, sys, time\n"
            "from mirrorcap.cli import parser\n"
            + ("import bpy\n"
               "parser.main = lambda: 130\n"
               "sys.exit(10 + parser.entry())\n" if blender else
               "parser.main = lambda: 0\n"
               "status = parser.entry()\n"
               "os.kill(os.getpid(), signal.SIGINT)\n"
               "time.sleep(0.5)\n"
               "print('exiting', flush=True)\n"
               "sys.exit(status)\n"))
    import signal

    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300,
                         # a shell's background job inherits SIGINT ignored; a user's terminal has it on
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    if blender:
        assert res.returncode == 130, res.stdout + res.stderr       # left at once: not 140
    else:
        assert (res.returncode, res.stdout) == (0, "exiting\n"), res.stderr


def test_ctrl_c_ignored_stays_ignored(sample, capsys, monkeypatch):
    """A command started as a shell's background job (SIGINT ignored) leaves it ignored: a SIGINT during its setup
    changes nothing, and it runs to its end."""
    import contextlib
    import os
    import signal
    import time

    @contextlib.contextmanager
    def setup_sent_a_sigint():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)
        yield

    monkeypatch.setattr(cli, "limited_threads", setup_sent_a_sigint)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        code, _, err = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json",
                             "-o", sample / "points.csv"], capsys)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
    assert code == 0, err
    assert (sample / "points.csv").exists()


def test_usage_errors(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["reconstruct"])
    assert exc.value.code == 2
    with pytest.raises(SystemExit) as exc:
        cli.main(["reconstruct", "a.csv", "--camera", "c.json", "-o", "o.csv", "--threshold", "0"])
    assert exc.value.code == 2
    capsys.readouterr()


def test_demo_command(tmp_path, capsys):
    code, stdout, err = _run(["demo-mirrors", "--out", tmp_path], capsys)
    assert code == 0, err
    report = json.loads((tmp_path / "demo_points.json").read_text())
    acc = report["accuracy_against_truth"]
    assert acc["rms_3d_error_mm"] < 0.3
    assert acc["wrong_pairs_rejected"] == acc["wrong_pairs_injected"]
    assert "RMS" in stdout


def test_outputs_get_normal_file_permissions(sample, capsys):
    import os

    out = sample / "perm.csv"
    code, _, err = _run(["reconstruct", sample / "pairs.csv", "--camera", sample / "camera.json", "-o", out, "-q"],
                        capsys)
    assert code == 0, err
    umask = os.umask(0)
    os.umask(umask)
    assert (out.stat().st_mode & 0o777) == (0o666 & ~umask)
    assert (out.with_suffix(".json").stat().st_mode & 0o777) == (0o666 & ~umask)


def test_output_folders_and_takes_that_are_the_wrong_kind_of_path(tmp_path, capsys):
    """A file where a command's output folder goes (batch, demo-mirrors) and a folder where a take goes (info):
    one line each, nothing made (were: a traceback, and a take "that does not exist")."""
    taken = tmp_path / "taken.txt"
    taken.write_text("a file, not a folder")
    head = ROOT / "sample_scenes" / "generic_head" / "head.blend"
    for args, message in [
        (["batch", ROOT / "demo" / "missing.c3d", "--head", head, "--out", taken], "is a file"),
        (["demo-mirrors", "--out", taken], "is a file"),
        (["info", tmp_path], "is a folder"),
        (["export", tmp_path, "-o", tmp_path / "points.csv"], "is a folder"),
    ]:
        code, _, err = _run(args, capsys)
        assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, (args, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["taken.txt"] and taken.read_text() == "a file, not a folder"
