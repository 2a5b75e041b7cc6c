"""MPEG-4 FAPs (core.retarget.mpeg4): feature points and FAPU on the generic head, FAP values
from known motions, the .fap text form read back exactly, the replay through the face rig, the
pose library, and bad .fap files refused with one message."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT

from mirrorcap.core.common.errors import InputError
from mirrorcap.core.face.animate import animate_take
from mirrorcap.core.face.facerig import RigSettings
from mirrorcap.core.face.headio import load_head_npz
from mirrorcap.core.geometry.rigid import rotation_zyx
from mirrorcap.core.retarget import mpeg4
from mirrorcap.core.retarget.arkit import head_angles
from mirrorcap.synthetic.headsim import performance

HEAD_NPZ = ROOT / "sample_scenes" / "generic_head" / "head.npz"


@pytest.fixture(scope="module")
def generic():
    head, keys = load_head_npz(HEAD_NPZ, with_shape_keys=True)
    return head, keys, mpeg4.feature_points(head, keys["jawOpen"])


def _face(head, points, pid):
    ax = head.face_axes()
    return (head.vertices[points[pid]] - ax["origin"]) @ np.stack([ax["lateral"], ax["down"], ax["forward"]]).T


def test_feature_points_sit_where_mpeg4_puts_them(generic):
    head, keys, pts = generic
    assert set(mpeg4._ALL_POINTS) <= set(pts)
    units = mpeg4.fap_units(head, pts)
    # an adult face: eyes ~64 mm apart, mouth ~50 mm wide, nose-to-mouth and eye opening of ~1 cm
    assert 55 < units["ES"] < 75 and 40 < units["MW"] < 60 and 30 < units["ENS"] < 55
    assert 10 < units["MNS"] < 25 and 6 < units["IRISD"] < 18
    f = {p: _face(head, pts, p) for p in pts}                      # x left, y down, z forward
    for left, right in (("2.4", "2.5"), ("3.5", "3.6"), ("4.1", "4.2"), ("4.5", "4.6"), ("8.3", "8.4"), ("9.1", "9.2")):
        assert f[left][0] > 5 and abs(f[left][0] + f[right][0]) < 1.0 and abs(f[left][1] - f[right][1]) < 1.0
    assert f["4.3"][1] < f["3.1"][1] < f["3.5"][1] < f["3.3"][1]    # brow above the lid above the pupil ...
    assert f["9.3"][1] < f["9.15"][1] < f["8.1"][1] < f["2.2"][1] <= f["2.3"][1] < f["8.2"][1] < f["2.10"][1] < f["2.1"][1]
    # the lower lip points move with the jaw, the upper ones do not
    drop = keys["jawOpen"] @ head.face_axes()["down"]
    chin = drop[pts["2.1"]]
    assert all(drop[pts[p]] > 0.3 * chin for p in ("2.3", "2.8", "2.9", "8.2", "8.7", "8.8"))
    assert all(abs(drop[pts[p]]) < 0.3 * chin for p in ("2.2", "2.6", "2.7", "8.1", "8.5", "8.6"))


def test_fap_values_follow_the_motion_in_the_faces_units(generic):
    head, keys, pts = generic
    units = mpeg4.fap_units(head, pts)
    w = np.linspace(0.0, 1.0, 11)
    track = mpeg4.faps_from_motion(head, w[:, None, None] * keys["jawOpen"][None], points=pts)
    down = keys["jawOpen"][pts["2.1"]] @ head.face_axes()["down"]
    assert np.allclose(track.values[:, 2], w * down / (units["MNS"] / 1024.0))   # FAP 3 open_jaw, MNS units
    assert track.values[-1, 2] > 1000
    # the lower lip rides on the jaw: relative to it, it hardly moves (FAP 5 is measured from the jaw)
    assert abs(track.values[-1, 4]) < 0.2 * track.values[-1, 2]
    smile = mpeg4.faps_from_motion(head, keys["mouthSmileLeft"][None], points=pts).values[0]
    assert smile[11] > 300 and smile[11] > 5 * abs(smile[12])      # raise_l_cornerlip, not the right one
    assert smile[5] > 100                                          # stretch_l_cornerlip (outward = left)
    brows = mpeg4.faps_from_motion(head, keys["browInnerUp"][None], points=pts).values[0]
    assert brows[30] > 40 and abs(brows[30] - brows[31]) < 5        # raise_l/r_i_eyebrow, symmetric


def test_head_rotation_faps_have_mpeg4_signs(generic):
    head, _, _ = generic
    ax = head.face_axes()
    C = np.stack([ax["lateral"], -ax["down"], ax["forward"]])       # rows: left, up, forward
    # a small pitch down (chin toward the chest): rotation about the lateral axis, forward turns down
    angle = 0.1
    R_pitch = C.T @ np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]]) @ C
    fwd = R_pitch @ ax["forward"]
    assert fwd @ ax["down"] > 0.09                                 # it does look down
    ypr = head_angles(R_pitch[None], ax)
    assert ypr[0, 1] == pytest.approx(angle, abs=1e-9) and abs(ypr[0, 0]) < 1e-9
    track = mpeg4.faps_from_motion(head, np.zeros((1, len(head.vertices), 3)), ypr[:, [1, 0, 2]])
    assert track.values[0, 47] == pytest.approx(angle / mpeg4.AU_RAD)    # FAP 48 head_pitch, positive down
    assert np.allclose(rotation_zyx(np.zeros((1, 3))), np.eye(3))


def test_fap_text_reads_back_exactly_and_replays_through_the_face_rig(generic, tmp_path):
    head, keys, pts = generic
    disp, _ = performance(head, keys, 45, 30.0, seed=5)
    track = mpeg4.faps_from_motion(head, disp, np.full((45, 3), 0.01), points=pts, name="take 5")
    text = mpeg4.fap_text(track)
    lines = text.splitlines()
    assert lines[0] == "2.1 take_5 30 45" and len(lines) == 1 + 2 * 45
    assert len(lines[1].split()) == 68 and lines[1].split()[18:30] == ["0"] * 12   # eyelids, eyeballs masked
    assert len(lines[2].split()) == 1 + 4 + 6 + int(track.mask[2:].sum())
    path = tmp_path / "take.fap"
    path.write_text(text)
    back = mpeg4.read_fap(path)
    assert back.fps == 30 and back.frames == 45 and np.array_equal(back.mask, track.mask)
    assert np.array_equal(back.values[:, track.mask], np.rint(track.values[:, track.mask]))
    assert np.array_equal(back.viseme, track.viseme) and np.array_equal(back.expression, track.expression)
    # replayed: the feature points move as the FAPs say, the rig fills in the face; measured again
    labels, points, mapping, pose = mpeg4.replay_take(back, head, pts)
    anim = animate_take(head, labels, points, back.fps, head_pose=pose, settings=RigSettings(blinks=False),
                        marker_map=mapping)
    again = mpeg4.faps_from_motion(head, anim.displacements, points=pts)
    low = [f.number - 1 for f in mpeg4.LOW_LEVEL_FAPS if back.mask[f.number - 1]]
    assert len(low) == 42
    assert np.abs(again.values[:, low] - back.values[:, low]).max() <= 1.0
    # the face between the feature points follows the performance it came from, as far as 44 FAPs
    # tell it (one axis per FAP: 2.0 mm RMS left of 3.3 mm of motion; no motion at all would leave 3.3)
    face = head.region_labels() >= 0
    err = np.sqrt(np.mean(np.linalg.norm(anim.displacements - disp, axis=2)[:, face] ** 2))
    motion = np.sqrt(np.mean(np.linalg.norm(disp, axis=2)[:, face] ** 2))
    assert err < 0.7 * motion


def test_the_pose_library_recognises_its_own_poses_and_leaves_neutral_alone():
    for table, column in ((mpeg4.VISEMES, 0), (mpeg4.EXPRESSIONS, 0)):
        values = np.zeros((len(table) + 1, 68))
        for row, (number, (_, faps)) in enumerate(sorted(table.items())):
            for fap, v in faps.items():
                values[row, fap - 1] = v
        vis, exp = mpeg4.classify_poses(values)
        got = (vis if table is mpeg4.VISEMES else exp)[:, column]
        assert got[:-1].tolist() == sorted(table) and got[-1] == 0
    half = np.zeros((1, 68))
    for fap, v in mpeg4.EXPRESSIONS[6][1].items():                 # surprise at half strength
        half[0, fap - 1] = 0.5 * v
    _, exp = mpeg4.classify_poses(half)
    assert exp[0, 0] == 6 and abs(exp[0, 1] - 32) <= 1


@pytest.mark.parametrize("body, message", [
    ("2.1 x 30 1\n" + " ".join(["1"] * 67) + "\n0 1\n", "68 bits"),
    ("2.1 x 30 2\n" + " ".join(["0"] * 68) + "\n0\n", "2 frames announced but 1 found"),
    ("2.1 x 30 1\n0 0 1" + " 0" * 65 + "\n0 5 6\n", "need 2 fields"),
    ("2.1 x 30 1\n0 0 1" + " 0" * 65 + "\n0 five\n", "integers"),
    ("hello\n", "2.1 NAME FPS FRAMES"),
    ("2.1 x -5 1\n", "FPS must be positive"),
])
def test_bad_fap_files_are_refused_with_one_message(tmp_path, body, message):
    path = tmp_path / "bad.fap"
    path.write_text(body)
    with pytest.raises(InputError, match=message):
        mpeg4.read_fap(path)


def test_a_fap_files_head_rotation_replays_as_the_heads_motion(generic):
    """FAPs 48-50 played back (`bake --fap`): the replayed take turns the head by them, the binding
    recovers that turn as the take's head motion (what `--head-motion` keys), and measuring it again
    gives the same three FAPs; the face's own FAPs are not disturbed by the turn."""
    from mirrorcap.core.retarget.arkit import rotations_from_angles

    head, keys, pts = generic
    F = 30
    t = np.linspace(0, 1, F)
    ypr = np.c_[0.25 * np.sin(2 * np.pi * t), 0.12 * t, -0.08 * t]          # yaw to 14 deg, pitch 7, roll -5
    R = rotations_from_angles(ypr, head.face_axes())
    assert np.allclose(head_angles(R, head.face_axes()), ypr, atol=1e-12)   # the exact inverse
    disp, _ = performance(head, keys, F, 30.0, seed=6)
    track = mpeg4.faps_from_motion(head, disp, ypr[:, [1, 0, 2]], points=pts)
    track.values = np.rint(track.values)
    labels, points, mapping, pose = mpeg4.replay_take(track, head, pts)
    anim = animate_take(head, labels, points, 30.0, head_pose=pose, settings=RigSettings(blinks=False),
                        marker_map=mapping)
    back = head_angles(anim.binding.head_motion[0], head.face_axes())
    print(f"head rotation replayed within {np.degrees(np.abs(back - ypr).max()):.4f} deg")
    assert np.degrees(np.abs(back - ypr).max()) < 0.01                     # FAP units are 1e-5 rad
    again = mpeg4.faps_from_motion(head, anim.displacements, back[:, [1, 0, 2]], points=pts)
    low = [f.number - 1 for f in mpeg4.LOW_LEVEL_FAPS if track.mask[f.number - 1]]
    assert np.abs(again.values[:, low] - track.values[:, low]).max() <= 1.0
    assert np.abs(again.values[:, 47:50] - track.values[:, 47:50]).max() <= 1.0
