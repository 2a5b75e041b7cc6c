"""`mirrorcap track`: rig video -> TAKE.c3d + REPORT.json."""

from __future__ import annotations

import json

import cv2
import ezc3d
import numpy as np
import pytest

from mirrorcap.cli import parser as cli
from conftest import write_rig_clip
from mirrorcap.synthetic.simulate import rig_motion

N_FRAMES = 30


@pytest.fixture(scope="module")
def rig_clip(tmp_path_factory):
    root = tmp_path_factory.mktemp("trackclip")
    rig, _ = write_rig_clip(root, N_FRAMES)
    mirrors = {"mirrors": [{"mirror": k, "normal": n.tolist(), "d": float(d)} for k, (n, d) in enumerate(rig.planes)]}
    (root / "mirrors.json").write_text(json.dumps(mirrors))
    return root, rig


def _run(args, capsys):
    code = cli.main([str(a) for a in args])
    return code, capsys.readouterr().err


def test_track_with_metric_mirrors_matches_the_truth(rig_clip, capsys, tmp_path):
    root, rig = rig_clip
    out, rep = tmp_path / "take.c3d", tmp_path / "report.json"
    code, err = _run(["track", root / "png", "--camera", root / "camera.json", "--mirrors", root / "mirrors.json",
                      "-o", out, "--report", rep, "-q"], capsys)
    assert code == 0, err
    report = json.loads(rep.read_text())
    assert report["units"] == "mm" and report["markers"]["count"] > 190
    assert len(report["per_frame"]["withheld"]) == N_FRAMES
    c = ezc3d.c3d(str(out))
    pts = np.transpose(c["data"]["points"][:3], (2, 1, 0))  # (frames, markers, 3)
    assert pts.shape[0] == N_FRAMES and c["parameters"]["POINT"]["RATE"]["value"][0] == pytest.approx(30.0)
    truth = np.stack([rig_motion(rig, f, N_FRAMES)[0] for f in range(N_FRAMES)])
    reported = np.all(np.isfinite(pts), axis=2)
    first = np.argmax(reported, axis=0)  # each label's first reported frame (late markers start later)
    at_first = pts[first, np.arange(pts.shape[1])]
    ids = np.argmin(np.linalg.norm(at_first[:, None] - truth[first][:, :, :], axis=2), axis=1)
    assert len(set(ids.tolist())) == len(ids)  # every label is a different marker
    err = np.linalg.norm(pts - truth[:, ids], axis=2)
    ok = np.isfinite(err)
    assert ok.mean() > 0.97
    assert np.sqrt(np.mean(err[ok] ** 2)) < 0.5  # mm (the bound)


def test_track_self_calibrated_with_known_length(rig_clip, capsys, tmp_path):
    root, rig = rig_clip
    out, rep = tmp_path / "take.c3d", tmp_path / "report.json"
    code, err = _run(["track", root / "png", "--camera", root / "camera.json", "-o", out, "--report", rep, "-q"],
                     capsys)
    assert code == 0, err
    report = json.loads(rep.read_text())
    assert report["units"] == "relative" and report["mirrors"][0]["source"] == "self-calibration"
    c = ezc3d.c3d(str(out))
    pts = np.transpose(c["data"]["points"][:3], (2, 1, 0))
    a, b = 0, 1
    truth0 = rig_motion(rig, 0, N_FRAMES)[0]
    ia, ib = (np.argmin(np.linalg.norm(truth0 * (pts[0, i, 2] / truth0[:, 2:3]) - pts[0, i], axis=1))
              for i in (a, b))
    true_len = float(np.linalg.norm(truth0[ia] - truth0[ib]))
    out2 = tmp_path / "take_mm.c3d"
    code, err = _run(["track", root / "png", "--camera", root / "camera.json", "-o", out2, "-q",
                      "--known-length", "m000", "m001", true_len], capsys)
    assert code == 0, err
    mm = np.transpose(ezc3d.c3d(str(out2))["data"]["points"][:3], (2, 1, 0))
    ids = np.argmin(np.linalg.norm(mm[0][:, None] - truth0[None], axis=2), axis=1)
    assert np.sqrt(np.nanmean(np.linalg.norm(mm[0] - truth0[ids], axis=1) ** 2)) < 1.0


def test_track_bad_input(rig_clip, capsys, tmp_path):
    root, rig = rig_clip
    dark = tmp_path / "dark"
    dark.mkdir()
    for f in range(10):  # the mirrors show nothing (10 frames: the shortest take tracked)
        img = cv2.imread(str(root / "png" / f"{f:03d}.png"))
        img[:, :420] = 0
        img[:, 860:] = 0
        cv2.imwrite(str(dark / f"{f}.png"), img)
    few = tmp_path / "few"
    few.mkdir()
    for f in range(10):  # an 8-pixel strip of the face: too few markers anywhere
        img = cv2.imread(str(root / "png" / f"{f:03d}.png"))
        strip = np.zeros_like(img)
        strip[300:308] = img[300:308]
        cv2.imwrite(str(few / f"{f}.png"), strip)
    small = json.loads((root / "camera.json").read_text())
    small["image_size"] = [640, 480]
    (tmp_path / "small.json").write_text(json.dumps(small))
    out = tmp_path / "out" / "take.c3d"
    out.parent.mkdir()
    rig_file = tmp_path / "rig.json"
    rig_file.write_text(json.dumps({"views": {"mirror0": [0, 0, 420, 720], "direct": [420, 0, 860, 720],
                                              "mirror1": [860, 0, 1280, 720]}}))
    rigid_files = {}
    for name, entry in {"nowhere": {"region": [0, 0, 10, 10]}, "unknown": {"colors": ["ultraviolet"]},
                        "empty": {"region": [50, 50, 10, 10]}, "typo": {"regoin": [0, 0, 10, 10]}}.items():
        rigid_files[name] = tmp_path / f"rigid_{name}.json"
        rigid_files[name].write_text(json.dumps({"rigid": entry}))
    clip = [root / "png", "--camera", root / "camera.json", "--mirrors", root / "mirrors.json", "--rig"]
    cases = [
        ([dark, "--camera", root / "camera.json", "--rig", rig_file], "mirror"),
        ([few, "--camera", root / "camera.json"], "fewer than 6"),
        ([few, "--camera", root / "camera.json", "--mirrors", root / "mirrors.json"], "could be paired"),
        ([*clip, rigid_files["nowhere"]], "at least 4 are needed"),
        ([*clip, rigid_files["unknown"]], "ultraviolet"),
        ([*clip, rigid_files["empty"]], "empty rectangle"),
        ([*clip, rigid_files["typo"]], "\"rigid\" must be"),
        ([root / "png", "--camera", tmp_path / "small.json"], "640x480"),
        # a take shorter than a marker must be measured to be reported: one message, not an empty take (stop 58)
        ([root / "png", "--camera", root / "camera.json", "--frames", "0:1"], "track at least 10 frames"),
        ([root / "png", "--camera", root / "camera.json", "--mirrors", root / "mirrors.json", "--frames", "0:9"],
         "the take has 9 frame(s) that show the face, and a marker must be measured in 10 frames"),
        ([root / "png", "--camera", root / "camera.json", "--mirrors", root / "mirrors.json",
          "--known-length", "nobody", "m001", "20"], "not in the take"),
        ([root / "png", "--camera", root / "camera.json", "--conjecture-limit", "-1"], "--conjecture-limit"),
    ]
    for args, message in cases:
        code, err = _run(["track", *args, "-o", out, "--report", out.with_suffix(".json"), "-q"], capsys)
        assert code == 2, (args, err)
        assert message in err, (args, err)
        assert list(out.parent.iterdir()) == []


def test_a_take_with_no_marker_kept_is_an_error_not_an_empty_file(rig_clip, capsys, tmp_path, monkeypatch):
    """Should every marker be dropped (none measured in TrackSettings.min_measured_frames frames), the command fails
    with one message and writes nothing, where it wrote an empty take and said "0 markers" (stop 58)."""
    from mirrorcap.core.track import pipeline
    from mirrorcap.core.track.result import keep_measured

    root, _ = rig_clip
    real = pipeline.track
    monkeypatch.setattr(pipeline, "track", lambda *a, **k: keep_measured(real(*a, **k), 10 ** 6))
    out = tmp_path / "out" / "take.c3d"
    out.parent.mkdir()
    code, err = _run(["track", root / "png", "--camera", root / "camera.json", "--mirrors", root / "mirrors.json",
                      "--frames", "0:10", "-o", out, "--report", out.with_suffix(".json"), "-q"], capsys)
    assert code == 2 and "no marker was measured in 10 frames or more" in err, err
    assert list(out.parent.iterdir()) == []


def test_track_refuses_bad_outputs_and_options_before_any_frame(rig_clip, capsys, tmp_path, monkeypatch):
    """An output that could not be written, a frame step of 0, a frame rate of 0, a known length that is not
    positive: one message before any frame is read (a long take would otherwise fail at its end, after minutes
    of work), and nothing written. Well formed, with no --light and no colour file saying it, frame 0 is read once
    for the light (stop 53), then the take's frames."""
    from mirrorcap.core.capture import video

    root, _ = rig_clip
    read = []
    original = video.VideoSource.frames

    def counted(self, *args, **kwargs):
        for item in original(self, *args, **kwargs):
            read.append(item[0])
            yield item

    monkeypatch.setattr(video.VideoSource, "frames", counted)
    out = tmp_path / "out" / "take.c3d"
    out.parent.mkdir()
    clip = [root / "png", "--camera", root / "camera.json", "--mirrors", root / "mirrors.json"]
    cases = [
        (["-o", tmp_path / "missing" / "take.c3d"], "output folder"),
        (["-o", out, "--report", tmp_path / "missing" / "report.json"], "output folder"),
        (["-o", out.parent], "is a folder"),
        (["-o", out, "--report", out], "named for two outputs"),
        (["-o", out, "--step", "0"], "frame step"),
        (["-o", out, "--fps", "0"], "frame rate"),
        (["-o", out, "--known-length", "m000", "m001", "-3"], "positive length"),
    ]
    for args, message in cases:
        code, err = _run(["track", *clip, *args, "-q"], capsys)
        assert code == 2, (args, err)
        assert message in err and err.count("\n") == 1, (args, err)
        assert read == [], (args, read)
        assert list(out.parent.iterdir()) == []
    code, err = _run(["track", *clip, "-o", out, "--frames", "0:10", "-q"], capsys)   # and the same run, well formed
    assert code == 0 and read == [0, *range(10)] and out.is_file(), err    # (stop 53) frame 0 first shows the light


def test_track_with_rigid_markers_named_in_the_rig_file(rig_clip, capsys, tmp_path):
    """A RIG.json with only "rigid" (the views split automatically): the markers imaged in
    the forehead box carry the head pose, and the report says so."""
    root, rig = rig_clip
    truth0 = rig_motion(rig, 0, N_FRAMES)[0]
    px = rig.camera.project(truth0)
    y = float(np.quantile(px[:, 1], 0.25))
    rig_file = tmp_path / "rig.json"
    rig_file.write_text(json.dumps({"rigid": {"region": [0, 0, 1280, y]}}))
    out, rep = tmp_path / "take.c3d", tmp_path / "report.json"
    code, err = _run(["track", root / "png", "--camera", root / "camera.json", "--mirrors", root / "mirrors.json",
                      "--rig", rig_file, "-o", out, "--report", rep, "-q"], capsys)
    assert code == 0, err
    report = json.loads(rep.read_text())
    assert report["markers"]["rigid_source"] == "rig file"
    labels = report["markers"]["labels"]
    rigid = [labels.index(name) for name in report["markers"]["rigid"]]
    pts = np.transpose(ezc3d.c3d(str(out))["data"]["points"][:3], (2, 1, 0))
    first = pts[np.argmax(np.all(np.isfinite(pts), axis=2), axis=0), np.arange(pts.shape[1])]
    rows = rig.camera.project(first[rigid])[:, 1]
    assert len(rigid) > 30 and np.all(rows < y + 1.0)  # every rigid marker is imaged in the box
