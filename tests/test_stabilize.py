"""`mirrorcap stabilize`: head motion from a rigid headband (eq. 1-3 and Arun), the rotation
pivot (eq. 4-8) and compensation (eq. 9), measured against a synthetic 23-marker take."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mirrorcap.cli.parser import main
from mirrorcap.core.common.errors import DegenerateError, InputError
from mirrorcap.core.geometry.rigid import rotation_zyx
from mirrorcap.core.take.c3d import read_c3d, write_c3d
from mirrorcap.core.take.stabilize import find_pivot, motion_by_invariants, pivot_objective, stabilize
from mirrorcap.synthetic.sparse_take import FOREHEAD_TRIANGLE, sparse_take


def _rms(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=-1))))


def test_invariants_recover_an_exact_motion():
    """Eq. 1-3 with the pseudo-correspondence m3 = m1 x m2: exact for three noiseless points."""
    rng = np.random.default_rng(0)
    ref = rng.normal(0, 50, (3, 3))
    R = rotation_zyx(rng.uniform(-0.5, 0.5, (40, 3)))
    t = rng.normal(0, 100, (40, 3))
    Re, te = motion_by_invariants(ref, ref @ np.swapaxes(R, 1, 2) + t[:, None])
    assert np.abs(Re - R).max() < 1e-9 and np.abs(te - t).max() < 1e-7


def test_the_pivot_objective_is_zero_at_a_fixed_point_and_the_descent_finds_it():
    """Eq. 5 vanishes at the point the markers rotate about; eq. 7-8 walk to it from 40 mm away."""
    rng = np.random.default_rng(1)
    pivot = np.array([10.0, -120.0, 40.0])
    markers = rng.normal(0, 40, (3, 3)) + [0, 0, 0]
    R = rotation_zyx(np.stack([0.2 * np.sin(np.linspace(0, 6, 200)), 0.35 * np.sin(np.linspace(0, 4, 200)),
                               0.1 * np.cos(np.linspace(0, 5, 200))], 1))
    tracks = np.einsum("fij,nj->fni", R, markers - pivot) + pivot
    e = pivot_objective(np.array([pivot, pivot + [5, 0, 0]]), tracks)
    assert e[0] < 1e-9 and e[1] > 0.5
    found, _, its = find_pivot(tracks, pivot + [25.0, -20.0, 25.0])
    assert np.linalg.norm(found - pivot) < 0.5 and its > 10


def test_a_23_marker_take_is_stabilised_about_its_pivot():
    """The issue's take (headband triangle, 20 face markers, +-20 deg about a pivot at the top
    of the neck, <= 0.5 mm sway, 0.15 mm noise, 60 frames/s) over ten noise draws: the pivot
    within 5 mm in every one; the face markers in the first frame's head frame within
    0.45 mm RMS in every draw, by both methods (the first frame's pose fixes that head frame for
    the whole take; with the pivot's sway smoothed over 0.5 s only, 3 of 20 draws were 0.50-0.52 mm);
    invariants and Arun within the noise of each other; the pivot and the pose smoothing each
    lowering the error; the slow sway smoothed over the longest window (3 s)."""
    errors = {"invariants": [], "arun": [], "no pivot": [], "raw": []}
    for seed in range(10):
        take = sparse_take(seed)
        out = {}
        for method in ("invariants", "arun"):
            st = stabilize(take.points, take.labels, rigid=take.labels[:3], method=method, rate=take.rate)
            assert st.pivot_status == "estimated" and not st.warnings
            assert np.linalg.norm(st.pivot_mm - take.pivot) < 5.0
            # the true sway is <= 0.5 mm; a pivot e off adds up to |R - I| e (~0.4 e at 20 deg), and the noise
            assert np.nanmax(np.linalg.norm(st.sway_mm, axis=1)) < 0.5 + 0.4 * 5.0
            assert st.sway_window_s == pytest.approx(3.0, abs=0.02)
            errors[method].append(_rms(st.points[:, 3:], take.head_frame0[:, 3:]))
            out[method] = st.points
        assert _rms(out["invariants"], out["arun"]) < 0.15          # the noise is 0.15 mm per coordinate
        no_pivot = stabilize(take.points, take.labels, rigid=take.labels[:3], pivot=None, rate=take.rate)
        raw = stabilize(take.points, take.labels, rigid=take.labels[:3], pivot=None, smooth_s=0.0)
        errors["no pivot"].append(_rms(no_pivot.points[:, 3:], take.head_frame0[:, 3:]))
        errors["raw"].append(_rms(raw.points[:, 3:], take.head_frame0[:, 3:]))
    median = {k: float(np.median(v)) for k, v in errors.items()}
    assert max(errors["invariants"] + errors["arun"]) < 0.45
    assert median["arun"] < median["no pivot"] < median["raw"]


def test_a_fast_large_sway_is_followed_with_a_short_window():
    """The sway window is chosen by the data: a neck swaying 1 mm at 1 Hz (twice the issue's
    sway, twenty times as fast) is followed over 0.5 s, and the take stays within 0.75 mm."""
    take = sparse_take(3, sway_mm=1.0, sway_hz=1.0)
    st = stabilize(take.points, take.labels, rigid=take.labels[:3], rate=take.rate)
    assert st.sway_window_s == pytest.approx(0.5, abs=0.02)
    assert _rms(st.points[:, 3:], take.head_frame0[:, 3:]) < 0.75
    assert st.report()["sway_window_s"] == st.sway_window_s


def test_automatic_rigid_markers_are_the_headband():
    take = sparse_take(4)
    st = stabilize(take.points, take.labels, rate=take.rate)
    assert sorted(st.rigid) == sorted(take.labels[:3]) and st.rigid_source == "automatic"
    assert np.linalg.norm(st.pivot_mm - take.pivot) < 5.0


def test_a_lost_headband_marker_is_stood_in_for_by_the_pivot():
    take = sparse_take(5)
    pts = take.points.copy()
    pts[200:230, 1] = np.nan
    st = stabilize(pts, take.labels, rigid=take.labels[:3], rate=take.rate)
    assert np.all(st.pose_source[200:230] == "rigid+pivot") and np.isfinite(st.points[200:230, 3:]).all()
    assert _rms(st.points[200:230, 3:], take.head_frame0[200:230, 3:]) < 0.6


def test_one_axis_of_rotation_leaves_the_pivot_undetermined_along_it():
    take = sparse_take(6, pitch_deg=0.0, roll_deg=0.0)
    st = stabilize(take.points, take.labels, rigid=take.labels[:3], rate=take.rate)
    assert st.pivot_status == "undetermined" and st.warnings
    assert _rms(st.points[:, 3:], take.head_frame0[:, 3:]) < 0.6         # the motion does not need the pivot
    still = sparse_take(6, yaw_deg=0.5, pitch_deg=0.5, roll_deg=0.2)
    st = stabilize(still.points, still.labels, rigid=still.labels[:3], rate=still.rate)
    assert st.pivot_mm is None and "too little rotation" in st.warnings[0]
    assert _rms(st.points[:, 3:], still.head_frame0[:, 3:]) < 0.6


def test_bad_rigid_markers_are_refused():
    take = sparse_take(0, frames=60)
    with pytest.raises(InputError, match="at least 3"):
        stabilize(take.points, take.labels, rigid=take.labels[:2])
    with pytest.raises(InputError, match="not in the take: nose"):
        stabilize(take.points, take.labels, rigid=["band_left", "band_right", "nose"])
    line = take.points.copy()
    line[:, 2] = 0.5 * (line[:, 0] + line[:, 1])                         # band_top between the other two
    with pytest.raises(DegenerateError, match="collinear"):
        stabilize(line, take.labels, rigid=take.labels[:3])


def test_stabilize_command(tmp_path, capsys):
    take = sparse_take(2, band=FOREHEAD_TRIANGLE)
    src = tmp_path / "take.c3d"
    write_c3d(src, take.labels, take.points, take.rate, first_frame=41)
    out, rep = tmp_path / "stable.c3d", tmp_path / "r.json"
    assert main(["stabilize", str(src), "-o", str(out), "--rigid", "band_left", "band_right", "band_top",
                 "--method", "arun", "--report", str(rep)]) == 0
    assert "pivot" in capsys.readouterr().out
    result = read_c3d(out)
    report = json.loads(rep.read_text())
    assert result["labels"] == take.labels and result["first_frame"] == 42 and result["rate"] == take.rate
    assert _rms(result["points"][:, 3:], take.head_frame0[:, 3:]) < 0.5
    assert np.linalg.norm(np.array(report["pivot_mm"]) - take.pivot) < 5.0
    assert report["method"] == "arun" and len(report["per_frame"]["rotation"]) == len(take.points)
    # bad input: one message, exit 2, nothing written
    for argv, words in ((["--rigid", "band_left", "band_right"], "at least 3"),
                        (["--rigid", "band_left", "band_right", "nose"], "nose"),
                        (["--pivot", "1,2"], "--pivot"), (["--smooth", "-1"], "--smooth")):
        bad = tmp_path / "bad.c3d"
        assert main(["stabilize", str(src), "-o", str(bad), *argv]) == 2
        err = capsys.readouterr().err
        assert words in err and err.count("\n") == 1
        assert not bad.exists()
    (tmp_path / "junk.c3d").write_bytes(b"junk" * 300)
    assert main(["stabilize", str(tmp_path / "junk.c3d"), "-o", str(tmp_path / "bad.c3d")]) == 2
    assert "not a C3D" in capsys.readouterr().err and not (tmp_path / "bad.c3d").exists()
