"""Retargeting through the ARKit-52 shapes (#19): weights recovered from a marker take of a
performance with known weights, no left-to-right leak, a still neutral, the Live Link Face
CSV, and the whole `mirrorcap retarget` onto a character of another topology and proportions,
read back from OUT.blend with bpy (evaluated mesh)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT

from mirrorcap.core.common.errors import InputError
from mirrorcap.core.face.headfit import subdivide
from mirrorcap.core.face.headio import load_head_npz, save_head_npz
from mirrorcap.core.face.head import REGIONS, HeadModel
from mirrorcap.core.retarget.arkit import ARKIT_SHAPES, match_shape_names, retarget_take
from mirrorcap.core.retarget.livelink import (BLEND_SHAPE_COUNT, HEADER, livelink_csv, read_livelink_csv, timecode,
                                              timecode_rate)
from mirrorcap.core.take.c3d import write_c3d
from mirrorcap.synthetic.headsim import ARKIT_CHANNELS as CHANNELS
from mirrorcap.synthetic.headsim import arkit_take

HEAD_NPZ = ROOT / "sample_scenes" / "generic_head" / "head.npz"
HEAD_BLEND = ROOT / "sample_scenes" / "generic_head" / "head.blend"
# the header row of a Live Link Face take, as the app writes it
APP_HEADER = (
    "Timecode,BlendShapeCount,EyeBlinkLeft,EyeLookDownLeft,EyeLookInLeft,EyeLookOutLeft,EyeLookUpLeft,"
    "EyeSquintLeft,EyeWideLeft,EyeBlinkRight,EyeLookDownRight,EyeLookInRight,EyeLookOutRight,EyeLookUpRight,"
    "EyeSquintRight,EyeWideRight,JawForward,JawRight,JawLeft,JawOpen,MouthClose,MouthFunnel,MouthPucker,"
    "MouthRight,MouthLeft,MouthSmileLeft,MouthSmileRight,MouthFrownLeft,MouthFrownRight,MouthDimpleLeft,"
    "MouthDimpleRight,MouthStretchLeft,MouthStretchRight,MouthRollLower,MouthRollUpper,MouthShrugLower,"
    "MouthShrugUpper,MouthPressLeft,MouthPressRight,MouthLowerDownLeft,MouthLowerDownRight,MouthUpperUpLeft,"
    "MouthUpperUpRight,BrowDownLeft,BrowDownRight,BrowInnerUp,BrowOuterUpLeft,BrowOuterUpRight,CheekPuff,"
    "CheekSquintLeft,CheekSquintRight,NoseSneerLeft,NoseSneerRight,TongueOut,HeadYaw,HeadPitch,HeadRoll,"
    "LeftEyeYaw,LeftEyePitch,LeftEyeRoll,RightEyeYaw,RightEyePitch,RightEyeRoll")
@pytest.fixture(scope="module")
def head_and_keys():
    return load_head_npz(HEAD_NPZ, with_shape_keys=True)


def _solve(head, keys, labels, pts):
    return retarget_take(head, keys, labels, pts)[1]


def _full(W, channels, names):
    out = np.zeros((W.shape[0], len(names)))
    for k, n in enumerate(channels):
        out[:, names.index(n)] = W[:, k]
    return out


def test_arkit_weights_are_recovered_from_a_marker_take(head_and_keys):
    """27 channels, head motion, 0.1 mm noise, 150 markers: RMS <= 0.05, max <= 0.2."""
    head, keys = head_and_keys
    labels, pts, W = arkit_take(head, keys, seed=12)       # the solver's defaults were set on seeds 2-8
    sol = _solve(head, keys, labels, pts)
    truth = _full(W, CHANNELS, sol.names)
    err = sol.weights - truth
    print(f"arkit: RMS {np.sqrt(np.mean(err ** 2)):.4f}, max {np.abs(err).max():.3f}, {sol.iterations} iterations")
    assert np.sqrt(np.mean(err ** 2)) <= 0.05 and np.abs(err).max() <= 0.2
    assert W.max() > 0.8                                    # the performance uses the range
    assert np.all((sol.weights >= 0) & (sol.weights <= 1))
    assert {"tongueOut", "eyeLookInLeft"} <= set(sol.unobservable)
    close, jaw = sol.names.index("mouthClose"), sol.names.index("jawOpen")
    assert np.all(sol.weights[:, close] <= sol.weights[:, jaw] + 1e-12)
    assert np.all(np.minimum(sol.weights[:, sol.names.index("jawLeft")], sol.weights[:, sol.names.index("jawRight")]) == 0)


def test_left_expressions_do_not_leak_right_and_a_held_neutral_is_still(head_and_keys):
    head, keys = head_and_keys
    left = [n for n in CHANNELS if n.endswith("Left")]
    labels, pts, W = arkit_take(head, keys, channels=left, frames=150, seed=14)
    sol = _solve(head, keys, labels, pts)
    right = [sol.names.index(n.replace("Left", "Right")) for n in left]
    assert np.abs(sol.weights[:, right]).max() < 0.05
    err = sol.weights - _full(W, left, sol.names)
    # the issue's bounds are for the >= 20-channel take above; here the left shapes' RMS. (The worst
    # single value, 0.21 on this take, is eyeBlinkLeft: the markers avoid the lids, so a blink is seen
    # only through its neighbours; README.)
    assert np.sqrt(np.mean(err ** 2)) <= 0.05
    labels, pts, _ = arkit_take(head, keys, frames=90, seed=15, still=True)
    sol = _solve(head, keys, labels, pts)
    print(f"left-only: right max {np.abs(sol.weights[:, right]).max():.3f}; neutral: jitter (sd) "
          f"{sol.weights.std(axis=0).max():.4f}, max {sol.weights.max():.3f}")
    assert sol.weights.std(axis=0).max() < 0.01 and sol.weights.max() < 0.05


def test_live_link_csv_header_rows_and_reader(tmp_path):
    assert HEADER == APP_HEADER and BLEND_SHAPE_COUNT == 61 and len(APP_HEADER.split(",")) == 63
    assert timecode(0, 30.0) == "00:00:00:00.000" and timecode(95, 30.0) == "00:00:03:05.000"
    assert timecode(3600 * 60 + 7, 60.0) == "01:00:00:07.000"
    rng = np.random.default_rng(0)
    names = ARKIT_SHAPES[::2]
    W = rng.uniform(0, 1, (40, len(names)))
    head = rng.uniform(-0.3, 0.3, (40, 3))
    text = livelink_csv(W, names, 30.0, head=head)
    lines = text.splitlines()
    assert lines[0] == APP_HEADER and len(lines) == 41
    assert all(ln.split(",")[1] == "61" and len(ln.split(",")) == 63 for ln in lines[1:])
    (tmp_path / "take.csv").write_text(text)
    back = read_livelink_csv(tmp_path / "take.csv")
    assert np.allclose(back["weights"][:, [ARKIT_SHAPES.index(n) for n in names]], W, atol=1e-6)
    assert np.allclose(back["rotations"][:, :3], head, atol=1e-6) and not back["rotations"][:, 3:].any()
    (tmp_path / "bad.csv").write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="not a Live Link Face CSV"):
        read_livelink_csv(tmp_path / "bad.csv")


def test_shape_names_match_case_insensitively():
    found, missing = match_shape_names(["Basis", "JAWOPEN", "eyeblinkleft", "Smile"], ["jawOpen", "eyeBlinkLeft", "cheekPuff"])
    assert found == {"jawOpen": "JAWOPEN", "eyeBlinkLeft": "eyeblinkleft"} and missing == ["cheekPuff"]


def _exported(name: str) -> str:
    """An ARKit name as a character exported from another tool may carry it: a blend-shape node's namespace, and a
    side written _L / _R."""
    for side, short in (("Left", "_L"), ("Right", "_R")):
        if name.endswith(side):
            name = name[: -len(side)] + short
    return "blendShape1." + name


def test_shape_names_match_as_other_tools_spell_them():
    """Names as characters from other tools carry them: a namespace (Maya's blend-shape node, ``ns:``, ``|``), a
    side written ``_L`` / ``.R`` / ``_left``, snake case. Each ARKit shape finds its key, and no key serves two."""
    spelled = {"jawOpen": "blendShape1.jawOpen", "eyeBlinkLeft": "Face:eyeBlink_L", "eyeBlinkRight": "eyeBlink.R",
               "mouthSmileLeft": "mouth_smile_left", "mouthLeft": "head|mouth_L", "cheekPuff": "CheekPuff"}
    found, missing = match_shape_names(["Basis", "mouthRollUpper_x", *spelled.values()], list(spelled) + ["mouthRight"])
    assert found == spelled and missing == ["mouthRight"]
    every = [_exported(n) for n in ARKIT_SHAPES]
    found, missing = match_shape_names(every, ARKIT_SHAPES)
    assert missing == [] and [found[n] for n in ARKIT_SHAPES] == every
    # an exact name wins over another spelling of it
    assert match_shape_names(["blendShape1.jawOpen", "jawOpen"], ["jawOpen"])[0] == {"jawOpen": "jawOpen"}


def _run(args):
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=900, cwd=ROOT,
                          env=dict(os.environ))


def _character(head, keys, tmp_path, landmarks: bool = False, with_keys: bool = True):
    """Another topology (one midpoint subdivision: 4x the triangles) and proportions (12 % wider,
    12 % shorter), carrying the same 52 shapes (its own expressions; written as shape keys only
    ``with_keys``), and the head's ``lm_*`` landmarks (``landmarks``: the subdivision keeps the
    head's vertices first); written as TARGET.blend with bpy."""
    T = head.triangles()
    V2, T2 = subdivide(head.vertices, T, 1)
    scale = np.array([1.12, 0.88, 1.0])                      # core x: across the face, y: down
    keys2 = {n: (subdivide(head.vertices + off, T, 1)[0] - V2) * scale for n, off in keys.items()}
    pad = len(V2) - len(head.vertices)
    groups = {g: np.r_[w, np.zeros(pad)] for g, w in head.groups.items() if g.startswith("lm_")} if landmarks else {}
    char = HeadModel(vertices=V2 * scale, polygons=T2.ravel(), polygon_sizes=np.full(len(T2), 3),
                     groups=groups, name="Character")
    save_head_npz(tmp_path / "character.npz", char, keys2 if with_keys else None)
    code = ("import sys\nfrom mirrorcap.core.face.headio import load_head_npz\n"
            "from mirrorcap.addon.common.headio import write_head_blend\n"
            f"h, k = load_head_npz({str(tmp_path / 'character.npz')!r}, with_shape_keys=True)\n"
            f"write_head_blend(h, {str(tmp_path / 'target.blend')!r}, k)\n")
    res = _run(["-c", code])
    assert res.returncode == 0, res.stdout + res.stderr
    return char, keys2


def test_retarget_command_onto_another_character(tmp_path, head_and_keys):
    head, keys = head_and_keys
    labels, pts, W = arkit_take(head, keys, frames=60, seed=6)
    write_c3d(tmp_path / "take.c3d", labels, pts, 30.0)
    char, keys2 = _character(head, keys, tmp_path)
    out = tmp_path / "out.blend"
    res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.c3d", "--head", HEAD_BLEND, "--target",
                tmp_path / "target.blend", "-o", out, "--csv", tmp_path / "take.csv", "--report", tmp_path / "r.json"])
    assert res.returncode == 0, res.stdout + res.stderr
    assert "retargeted 60 frames onto Character" in res.stdout
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["missing_shape_names"] == [] and len(report["shapes_keyed"]) == 52
    rb_out = tmp_path / "rb.npz"
    r = _run([ROOT / "tests" / "blender" / "readback.py", out, "Character", rb_out])
    assert r.returncode == 0, r.stdout + r.stderr
    rb = np.load(rb_out)
    to_core = lambda p: 1000.0 * np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)  # noqa: E731
    seen = to_core(rb["evaluated"])                          # what a user sees at frames 1..60
    truth = char.vertices[None] + np.einsum("fk,kvd->fvd", W, np.stack([keys2[n] for n in CHANNELS]))
    err = np.sqrt(np.mean(np.sum((seen - truth) ** 2, axis=2), axis=1))
    print(f"retarget onto the character: per-frame RMS max {err.max():.3f} mm, mean {err.mean():.3f} mm")
    assert seen.shape == truth.shape and err.max() < 0.5
    moving = np.linalg.norm(truth - char.vertices[None], axis=2).max()
    assert moving > 3.0                                        # the character does move
    # the CSV's values equal the keyed F-curves frame by frame
    csv = read_livelink_csv(tmp_path / "take.csv")
    names = list(rb["names"])
    keyed = rb["values"]                                       # (F, K) evaluated F-curves
    cols = [ARKIT_SHAPES.index(n) for n in names]
    assert np.abs(csv["weights"][:, cols] - keyed).max() < 1e-5
    assert (tmp_path / "take.csv").read_text().splitlines()[0] == APP_HEADER
    # the reverse: the CSV (as an iPhone take would come) keys the character the same way
    out2 = tmp_path / "from_csv.blend"
    res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.csv", "--target", tmp_path / "target.blend",
                "-o", out2, "--rate", "30"])
    assert res.returncode == 0 and "keyed 60 frames" in res.stdout, res.stdout + res.stderr
    r = _run([ROOT / "tests" / "blender" / "readback.py", out2, "Character", tmp_path / "rb2.npz"])
    assert r.returncode == 0, r.stdout + r.stderr
    rb2 = np.load(tmp_path / "rb2.npz")
    assert list(rb2["names"]) == names and np.abs(rb2["values"] - keyed).max() < 1e-5
    assert int(rb2["fps"]) == 30 and np.abs(rb2["evaluated"] - rb["evaluated"]).max() < 1e-5


def test_retarget_keys_a_character_whose_shape_names_another_tool_spelled(tmp_path, head_and_keys):
    """A character exported from another tool, its 52 keys named ``blendShape1.eyeBlink_L`` and the like, is found
    in its file and keyed with every shape of a Live Link Face take (before: refused, "no mesh with ARKit-named
    shape keys")."""
    head, keys = head_and_keys
    char, keys2 = _character(head, {_exported(n): off for n, off in keys.items()}, tmp_path)
    rng = np.random.default_rng(3)
    W = np.clip(rng.normal(0.3, 0.2, (12, len(ARKIT_SHAPES))), 0.0, 1.0)
    (tmp_path / "take.csv").write_text(livelink_csv(W, ARKIT_SHAPES, 30.0))
    out = tmp_path / "out.blend"
    res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.csv", "--target", tmp_path / "target.blend", "-o", out,
                "--rate", "30", "--report", tmp_path / "r.json"])
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["missing_shape_names"] == [] and len(report["shapes_keyed"]) == 52
    r = _run([ROOT / "tests" / "blender" / "readback.py", out, "Character", tmp_path / "rb.npz"])
    assert r.returncode == 0, r.stdout + r.stderr
    rb = np.load(tmp_path / "rb.npz")
    cols = [[_exported(n) for n in ARKIT_SHAPES].index(name) for name in rb["names"]]
    assert len(cols) == 52 and np.abs(rb["values"] - W[:, cols]).max() < 1e-4      # each key carries its shape


def test_retarget_keys_from_a_pipelines_start_frame(tmp_path, head_and_keys):
    """`--frame-start 1001`: a take's first row is keyed at scene frame 1001 and its last at 1000 + rows, the
    scene's range set to them (before: always 1..rows)."""
    head, keys = head_and_keys
    _character(head, keys, tmp_path)
    W = np.clip(np.random.default_rng(5).normal(0.3, 0.2, (15, len(ARKIT_SHAPES))), 0.0, 1.0)
    (tmp_path / "take.csv").write_text(livelink_csv(W, ARKIT_SHAPES, 30.0))
    out = tmp_path / "out.blend"
    res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.csv", "--target", tmp_path / "target.blend", "-o", out,
                "--frame-start", "1001", "--report", tmp_path / "r.json"])
    assert res.returncode == 0, res.stdout + res.stderr
    assert json.loads((tmp_path / "r.json").read_text())["frame_start"] == 1001
    r = _run([ROOT / "tests" / "blender" / "readback.py", out, "Character", tmp_path / "rb.npz"])
    assert r.returncode == 0, r.stdout + r.stderr
    rb = np.load(tmp_path / "rb.npz")
    assert list(rb["frames"]) == list(range(1001, 1016))
    cols = [ARKIT_SHAPES.index(name) for name in rb["names"]]
    assert len(cols) == 52 and np.abs(rb["values"] - W[:, cols]).max() < 1e-4    # row f at frame 1001 + f


@pytest.mark.parametrize("method", ["arkit", "transfer"])
def test_retarget_a_stretch_of_a_take_at_a_pipelines_start_frame(tmp_path, head_and_keys, method):
    """`--frames 12:30 --frame-start 1001`: the stretch is keyed at scene frames 1001..1018, and the character
    there looks as the whole take's retarget has it at its frames 13..30 (the whole take bound and solved), by
    both methods."""
    head, keys = head_and_keys
    labels, pts, _ = arkit_take(head, keys, frames=40, seed=12)
    write_c3d(tmp_path / "take.c3d", labels, pts, 30.0)
    _character(head, keys, tmp_path, landmarks=method == "transfer", with_keys=method == "arkit")
    seen = {}
    for name, extra in (("whole", []), ("part", ["--frames", "12:30", "--frame-start", "1001"])):
        res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.c3d", "--head", HEAD_BLEND, "--target",
                    tmp_path / "target.blend", "-o", tmp_path / f"{name}.blend", "--method", method,
                    "--report", tmp_path / f"{name}.json", *extra])
        assert res.returncode == 0, res.stdout + res.stderr
        r = _run([ROOT / "tests" / "blender" / "readback.py", tmp_path / f"{name}.blend", "Character",
                  tmp_path / f"{name}.npz"])
        assert r.returncode == 0, r.stdout + r.stderr
        seen[name] = np.load(tmp_path / f"{name}.npz")
    report = json.loads((tmp_path / "part.json").read_text())
    assert report["frames"] == 18 and report["take_frames"] == [12, 30] and report["frame_start"] == 1001
    # the fit's residuals are the keyed frames' (the whole take solved, the report of what was keyed)
    residual = json.loads((tmp_path / "whole.json").read_text())["residual_mm"]["per_frame"][12:30]
    assert report["residual_mm"]["per_frame"] == residual and len(residual) == 18
    assert report["residual_mm"]["max"] == pytest.approx(max(residual), abs=1e-4)
    assert list(seen["part"]["frames"]) == list(range(1001, 1019)) and list(seen["whole"]["frames"]) == list(range(1, 41))
    whole, part = seen["whole"]["evaluated"][12:30], seen["part"]["evaluated"]
    assert np.abs(whole - whole[:1]).max() > 2e-3                 # the stretch moves (metres)
    assert np.abs(part - whole).max() < 1e-6                       # 1 micrometre, at every keyed frame


def test_timecodes_tell_a_csv_takes_rate():
    """The rows per second of the clock, over the seconds a take spans whole; None where they cannot tell."""
    for rate in (24.0, 30.0, 60.0):
        assert timecode_rate([timecode(f, rate) for f in range(int(4.5 * rate))]) == rate
    assert abs(timecode_rate([timecode(f + 17, 29.97) for f in range(400)]) - 29.97) < 0.05
    assert timecode_rate([timecode(f, 60.0) for f in range(50)]) is None            # not one whole second
    assert timecode_rate(["00:00:01:02.000", "00:00:00:03.000", "00:00:02:00.000"]) is None    # backwards
    assert timecode_rate(["1:2", "00:00:02:00.000"]) is None


def test_retarget_plays_a_csv_take_at_the_rate_its_timecodes_keep(tmp_path, head_and_keys):
    """A Live Link Face take recorded at 30 frames/s plays at 30 without --rate (before: at 60, twice as fast,
    silently); a --rate that disagrees with the timecodes is kept, with a warning."""
    head, keys = head_and_keys
    _character(head, keys, tmp_path)
    W = np.clip(np.random.default_rng(4).normal(0.3, 0.2, (100, len(ARKIT_SHAPES))), 0.0, 1.0)
    (tmp_path / "take.csv").write_text(livelink_csv(W, ARKIT_SHAPES, 30.0))
    for extra, rate, source in (([], 30.0, "timecodes"), (["--rate", "60"], 60.0, "--rate")):
        out = tmp_path / f"out{rate:g}.blend"
        res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.csv", "--target", tmp_path / "target.blend",
                    "-o", out, "--report", tmp_path / "r.json", *extra])
        assert res.returncode == 0, res.stdout + res.stderr
        report = json.loads((tmp_path / "r.json").read_text())
        assert report["rate"] == rate and report["rate_source"] == source and report["timecode_rate"] == 30.0
        assert bool(report["warnings"]) == (rate == 60.0) and ("warning: --rate 60" in res.stdout) == (rate == 60.0)
        r = _run([ROOT / "tests" / "blender" / "readback.py", out, "Character", tmp_path / "rb.npz"])
        assert r.returncode == 0, r.stdout + r.stderr
        assert abs(float(np.load(tmp_path / "rb.npz")["rate"]) - rate) < 1e-6


def test_retarget_bad_input_writes_nothing(tmp_path, head_and_keys):
    head, keys = head_and_keys
    labels, pts, _ = arkit_take(head, keys, frames=10, seed=7)
    write_c3d(tmp_path / "take.c3d", labels, pts, 30.0)
    holey = pts.copy()
    holey[0, 5] = np.nan
    write_c3d(tmp_path / "holey.c3d", labels, holey, 30.0)
    out = tmp_path / "out.blend"
    cases = [(["--target", HEAD_BLEND, "--target-object", "Nobody"], "no object named 'Nobody'"),
             (["--target", tmp_path / "missing.blend"], "does not exist"),
             (["--target", HEAD_BLEND, "--head", tmp_path / "take.c3d"], "not a readable .blend")]
    for extra, words in cases:
        args = ["-m", "mirrorcap", "retarget", tmp_path / "take.c3d", "--head", HEAD_BLEND, "-o", out,
                "--csv", tmp_path / "x.csv"]
        res = _run(args + extra)
        assert res.returncode == 2 and words in res.stderr, (extra, res.stderr)
        assert not out.exists() and not (tmp_path / "x.csv").exists()
    res = _run(["-m", "mirrorcap", "retarget", tmp_path / "holey.c3d", "--head", HEAD_BLEND, "--target", HEAD_BLEND,
                "-o", out, "--refuse-unseen"])
    assert res.returncode == 2 and "neutral frame" in res.stderr and not out.exists()
    # as for bake, a tracker's late markers are placed from their neighbours unless said otherwise
    res = _run(["-m", "mirrorcap", "retarget", tmp_path / "holey.c3d", "--head", HEAD_BLEND, "--target", HEAD_BLEND,
                "-o", out])
    assert res.returncode == 0 and out.exists(), res.stdout + res.stderr


def _slit_pairs(head):
    """Pairs (upper-lip vertex, lower-lip vertex) of the lips' visible (forward-facing) surfaces in the
    same column (within 1 mm across), at most 6 mm apart at rest, away from the corners: the lips have
    crossed when a lower one rises above its partner."""
    lab = head.region_labels()
    V, lm = head.vertices, head.landmarks()
    half = 0.8 * abs(V[lm["mouth_corner_l"], 0] - V[lm["mouth_corner_r"], 0]) / 2
    outer = (head.vertex_normals() @ head.face_axes()["forward"] > 0.5) & (np.abs(V[:, 0]) < half)
    up = np.flatnonzero(outer & (lab == REGIONS.index("upper_lip")))
    low = np.flatnonzero(outer & (lab == REGIONS.index("lower_lip")))
    u, l_ = np.meshgrid(up, low, indexing="ij")
    sep0 = V[l_, 1] - V[u, 1]
    keep = (np.abs(V[u, 0] - V[l_, 0]) < 1.0) & (sep0 < 6.0)
    return u[keep], l_[keep]


def test_transfer_onto_a_character_without_shape_keys(tmp_path, head_and_keys):
    """`retarget --method transfer` onto a character of another topology and proportions that has
    landmarks and no shape keys, read back from OUT.blend with bpy (evaluated mesh): moving vertices
    within 1 mm mean of the character's own expression; the lids close where the actor's do; the
    lips never cross."""
    head, keys = head_and_keys
    labels, pts, W = arkit_take(head, keys, frames=90, seed=9, full_blinks=True)
    write_c3d(tmp_path / "take.c3d", labels, pts, 30.0)
    char, keys2 = _character(head, keys, tmp_path, landmarks=True, with_keys=False)
    out = tmp_path / "out.blend"
    res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.c3d", "--head", HEAD_BLEND, "--target",
                tmp_path / "target.blend", "-o", out, "--method", "transfer", "--report", tmp_path / "r.json"])
    assert res.returncode == 0, res.stdout + res.stderr
    assert "transferred 90 frames onto Character" in res.stdout
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["mode"] == "frames" and report["lids"] == "actor's eyeBlink weights"
    assert report["region_scales"]["upper"][0] == pytest.approx(1.12, abs=0.01)      # 12 % wider
    assert report["region_scales"]["lower"][1] == pytest.approx(0.88, abs=0.015)     # 12 % shorter
    r = _run([ROOT / "tests" / "blender" / "readback.py", out, "Character", tmp_path / "rb.npz"])
    assert r.returncode == 0, r.stdout + r.stderr
    to_core = lambda p: 1000.0 * np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)  # noqa: E731
    seen = to_core(np.load(tmp_path / "rb.npz")["evaluated"])
    truth = char.vertices[None] + np.einsum("fk,kvd->fvd", W, np.stack([keys2[n] for n in CHANNELS]))
    err = np.linalg.norm(seen - truth, axis=2)
    moving = np.linalg.norm(truth - char.vertices[None], axis=2) > 1.0
    print(f"transfer: moving vertices {err[moving].mean():.3f} mm mean (p95 {np.percentile(err[moving], 95):.3f}, "
          f"max {err.max():.2f}); all vertices {np.sqrt(np.mean(err ** 2)):.3f} mm RMS")
    assert moving.sum() > 1000 and err[moving].mean() < 1.0
    # the lids: where the actor's blink is full, the character's upper-lid margin is where its own
    # blink puts it; where the actor's lid is open, it stays open
    for side, name in (("l", "eyeBlinkLeft"), ("r", "eyeBlinkRight")):
        margin = int(np.argmax(head.groups[f"eyelid_upper_{side}"]))
        w = W[:, CHANNELS.index(name)]
        travel = np.linalg.norm(keys2[name][margin])
        shut, open_ = w > 0.95, w < 0.05
        assert shut.sum() >= 2 and open_.sum() >= 10 and travel > 5.0
        gap = np.linalg.norm(seen[:, margin] - truth[:, margin], axis=1)
        closed = 1.0 - np.linalg.norm(seen[shut, margin] - (char.vertices[margin] + keys2[name][margin]), axis=1) / travel
        print(f"lid {side}: closed {closed.min():.3f} of the way on the {shut.sum()} full-blink frames; "
              f"open frames within {gap[open_].max():.2f} mm")
        assert closed.min() > 0.9 and gap[open_].max() < 1.0
    # the lips never cross
    up, low = _slit_pairs(head)
    down = np.array([0.0, 1.0, 0.0])                                           # core y: down
    sep = np.einsum("fpd,d->fp", seen[:, low] - seen[:, up], down)
    sep_true = np.einsum("fpd,d->fp", truth[:, low] - truth[:, up], down)
    print(f"lips: {len(up)} slit pairs, least separation {sep.min():.2f} mm (the character's own: {sep_true.min():.2f})")
    # the character's own shapes roll and press the lips (its lower lip's face rises up to ~0.9 mm over the
    # upper's in some frames): the transfer may go as far as they do, never further, in every frame
    assert len(up) >= 5 and np.all(sep.min(1) > np.minimum(sep_true.min(1), 0.0) - 0.3)


def test_transfer_onto_a_character_imported_in_centimetres_and_y_up(tmp_path, head_and_keys):
    """The character as an FBX import from a Y-up package in centimetres leaves it (tests/blender/turn_head.py:
    data in cm and Y-up, the object scaled 0.01, turned 90° and standing elsewhere) takes the same motion as the
    character untouched: the world-space evaluated meshes agree within 0.01 mm at every frame."""
    head, keys = head_and_keys
    labels, pts, _ = arkit_take(head, keys, frames=20, seed=5)
    write_c3d(tmp_path / "take.c3d", labels, pts, 30.0)
    _character(head, keys, tmp_path, landmarks=True, with_keys=False)
    turned = tmp_path / "turned.blend"
    res = _run([ROOT / "tests" / "blender" / "turn_head.py", tmp_path / "target.blend", turned, "Character"])
    assert res.returncode == 0, res.stdout + res.stderr
    world = {}
    for name, target in (("plain", tmp_path / "target.blend"), ("turned", turned)):
        out = tmp_path / f"{name}.blend"
        res = _run(["-m", "mirrorcap", "retarget", tmp_path / "take.c3d", "--head", HEAD_BLEND, "--target", target,
                    "-o", out, "--method", "transfer"])
        assert res.returncode == 0, res.stdout + res.stderr
        r = _run([ROOT / "tests" / "blender" / "readback.py", out, "Character", tmp_path / f"{name}.npz"])
        assert r.returncode == 0, r.stdout + r.stderr
        world[name] = np.load(tmp_path / f"{name}.npz")["world"]
    assert np.linalg.norm(world["plain"] - world["plain"][:1], axis=2).max() > 2e-3          # the face moves
    placed = np.array([0.3, -0.2, 1.6])                                                     # turn_head.py's place
    assert np.abs(world["turned"] - placed - world["plain"]).max() < 1e-5


def test_transfer_bad_input_writes_nothing(tmp_path, head_and_keys):
    head, keys = head_and_keys
    labels, pts, _ = arkit_take(head, keys, frames=10, seed=7)
    write_c3d(tmp_path / "take.c3d", labels, pts, 30.0)
    _character(head, keys, tmp_path, landmarks=False, with_keys=False)          # no landmarks
    out = tmp_path / "out.blend"
    base = ["-m", "mirrorcap", "retarget", tmp_path / "take.c3d", "--head", HEAD_BLEND, "-o", out,
            "--method", "transfer", "--report", tmp_path / "r.json"]
    res = _run(base + ["--target", tmp_path / "target.blend"])
    assert res.returncode == 2 and "no mesh with landmark vertex groups" in res.stderr, res.stdout + res.stderr
    res = _run(base + ["--target", tmp_path / "target.blend", "--target-object", "Character"])
    assert res.returncode == 2 and "lacks the landmark vertex groups lm_nose_tip" in res.stderr, res.stderr
    res = _run(base + ["--target", HEAD_BLEND, "--target-object", "Nobody"])
    assert res.returncode == 2 and "no object named 'Nobody'" in res.stderr, res.stderr
    res = _run(base + ["--target", HEAD_BLEND, "--csv", tmp_path / "x.csv"])
    assert res.returncode == 2 and "--csv writes ARKit weights" in res.stderr, res.stderr
    assert not out.exists() and not (tmp_path / "r.json").exists() and not (tmp_path / "x.csv").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_closest_points_on_triangles_match_a_dense_search():
    """The correspondence's nearest point on a triangle (vertex, edge and face regions) against a brute-force
    search over 20,000 samples of each triangle."""
    from mirrorcap.core.retarget.transfer import _closest_on_triangles

    rng = np.random.default_rng(3)
    A, B, C = (rng.normal(0, 5, (200, 3)) for _ in range(3))
    P = rng.normal(0, 8, (200, 3))
    bary, dist = _closest_on_triangles(P, A, B, C)
    assert np.allclose(bary.sum(1), 1) and (bary >= -1e-12).all()
    u, v = rng.uniform(0, 1, (2, 20000))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    S = A[:, None] + u[None, :, None] * (B - A)[:, None] + v[None, :, None] * (C - A)[:, None]   # (200, 20000, 3)
    brute = np.linalg.norm(S - P[:, None], axis=2).min(1)
    edge = np.max([np.linalg.norm(B - A, axis=1), np.linalg.norm(C - B, axis=1), np.linalg.norm(A - C, axis=1)], 0)
    assert np.all(dist <= brute + 1e-9) and np.all(brute - dist < 0.02 * edge)    # the samples' spacing


def test_feature_distance_scales_follow_a_characters_proportions(head_and_keys):
    """Seed 001's scaling: a character 12 % wider and 12 % shorter gets lateral scales 1.12 and down
    scales ~0.88 in both halves of the face; the generic head onto itself is 1 everywhere."""
    from mirrorcap.core.retarget.transfer import region_scales

    head, _ = head_and_keys
    same = region_scales(head, head)
    assert np.allclose(same["upper"], 1) and np.allclose(same["lower"], 1)
    wide = HeadModel(vertices=head.vertices * [1.12, 0.88, 1.0], polygons=head.polygons,
                     polygon_sizes=head.polygon_sizes, groups=head.groups, name="wide")
    sc = region_scales(head, wide)
    assert sc["upper"][0] == pytest.approx(1.12, abs=0.005) and sc["lower"][0] == pytest.approx(1.12, abs=0.005)
    assert 0.87 < sc["upper"][1] < 0.9 and 0.87 < sc["lower"][1] < 0.9


def test_a_characters_skin_never_takes_the_actors_teeth(head_and_keys):
    """The demo's character (its own mesh: skin, teeth and eyes as separate pieces): behind its thin lower
    lip the actor's lower teeth lay nearer than the actor's inner lip, so the character's inner lip took the
    teeth's motion and stayed while its lip moved -- a jagged crumple below the lip in every frame of the
    demo's preview. The character's skin now takes only the actor's skin, and its teeth the actor's teeth.
    On a 150-marker take of a faceunit performance its moving vertices are 1.00 mm mean from the
    character's own expression (1.22 mm before)."""
    from mirrorcap.core.retarget.transfer import DETACHED_PARTS, _mesh_pieces, transfer_take
    from mirrorcap.synthetic.headsim import performance, synthetic_take

    head, keys = head_and_keys
    char, char_keys = load_head_npz(ROOT / "sample_scenes" / "character" / "character.npz", with_shape_keys=True)
    labels, pts, _, _, _ = synthetic_take(head, keys, n_markers=150, n_frames=60, seed=5)
    tr = transfer_take(head, keys, char, labels, pts, 30.0)
    parts = np.zeros(len(head.vertices), bool)
    for g in DETACHED_PARTS:
        parts[head.members(g)] = True
    piece = _mesh_pieces(char)
    skin = piece == np.argmax(np.bincount(piece))
    T = tr.correspondence.transport.tocsr()
    takes_parts = np.asarray(T[:, parts].sum(axis=1)).ravel() > 0
    assert not takes_parts[skin].any()
    teeth = [p for p in np.unique(piece[~skin]) if abs(char.vertices[piece == p, 0].mean()) < 5]  # on the midline
    assert len(teeth) == 2 and all(takes_parts[piece == p].mean() > 0.9 for p in teeth)
    own, _ = performance(char, char_keys, 60, 30.0, 5)
    moving = np.linalg.norm(own, axis=2) > 1.0
    assert np.linalg.norm(tr.displacements - own, axis=2)[moving].mean() < 1.1


def test_a_sample_spot_that_triangles_share_brings_them_all():
    """stop 56: the transfer's candidate triangles for a target vertex come from the sample spots nearest it; a
    vertex or an edge point is sampled once per triangle that holds it, and such a spot brings every one of them,
    so k nearest spots are not k copies of one point chosen among by float rounding (a character made from the
    head by subdivision, imported in centimetres, took another triangle 0.37 mm away for one vertex)."""
    from mirrorcap.core.retarget.transfer import _candidate_triangles

    ring = np.c_[np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4), np.zeros(8)] * 10.0
    V = np.r_[[[0.0, 0.0, 0.0]], ring]
    T = np.c_[np.zeros(8, int), 1 + np.arange(8), 1 + (np.arange(8) + 1) % 8]     # a fan of 8 around vertex 0
    rows, tris = _candidate_triangles(V, T, np.array([[0.0, 0.0, 0.5], [5.0, 0.0, 0.0]]), k=1, sample_mm=2.5)
    assert sorted(tris[rows == 0].tolist()) == list(range(8))                  # the centre: all eight
    assert sorted(tris[rows == 1].tolist()) == [0, 7]                           # mid-edge 0-1: its two triangles
    assert np.all(np.diff(rows) >= 0)
