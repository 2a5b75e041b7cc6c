"""The tracker assembled (issue 4, in progress): detections over time -> labelled 3D
trajectories with head motion separated, on a synthetic performance with truth."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.tracking import score
from core.simulate import face_rig, rig_performance, synthetic_detections
from core.track import TrackSettings, track


def _score(frames, perf, result):
    """The benchmark's scoring (benchmarks/tracking.py), under the tests' short names."""
    r = score(frames, perf, result)
    return {"ids": r["ids"], "switches": r["identity_switches"], "measured": r["measured"], "rms": r["rms_mm"],
            "conj_rms": r["conjectured_rms_mm"], "conj_p99": r["conjectured_p99_mm"],
            "reported_of_visible": r["reported_of_visible"]}


@pytest.fixture(scope="module")
def performance():
    rig = face_rig(n_markers=300, seed=3, layout="even")
    return rig, rig_performance(rig, 80, head_motion_deg=10, expression_mm=5)


def test_clean_performance_is_tracked_without_identity_switches(performance):
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=1, performance=perf, noise_px=0.05)
    result = track(frames, rig.camera, rig.planes)
    s = _score(frames, perf, result)
    assert len(result.labels) > 190
    assert s["switches"] == 0
    assert s["rms"] < 0.1  # mm, markers at 600 mm
    assert s["conj_rms"] < 1.0 and s["conj_p99"] < 2.0  # measured 0.47 and 1.65 mm
    assert s["reported_of_visible"] >= 0.98  # measured 98.5 %
    assert len(set(s["ids"].tolist())) == len(s["ids"])  # one marker per label
    # head pose from automatically found rigid markers follows the true turn (up to 10 deg);
    # fitting all markers instead is biased by the expression (measured ~1 deg)
    import cv2

    from core.motion import rotation_zyx

    true_rv = np.array([cv2.Rodrigues(R)[0].ravel() for R in perf[2]])
    est_rv = np.array([cv2.Rodrigues(rotation_zyx(h[:3]))[0].ravel() for h in result.head_pose])
    assert np.degrees(np.max(np.linalg.norm(est_rv - true_rv, axis=1))) < 0.2
    assert np.allclose(result.head_pose[:, 3:], np.array(perf[3]), atol=1.0)  # translation, mm
    # the rigid markers really moved least: the upper face
    assert np.mean(np.linalg.norm(perf[4][:, s["ids"][result.rigid]], axis=2)) < 0.1


def test_faults_missing_and_false_blobs(performance):
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=2, performance=perf, noise_px=0.1, missing=0.1, false_blobs=0.2)
    result = track(frames, rig.camera, rig.planes, TrackSettings())
    s = _score(frames, perf, result)
    assert s["switches"] <= 0.001 * s["measured"]
    assert s["rms"] < 0.2
    assert s["reported_of_visible"] >= 0.98 and s["conj_p99"] < 2.5  # measured 98.4 % and 1.98 mm
    assert result.conjectured.sum() > 0 and result.stats["false_tracking"].sum() > 0
    assert np.all(result.camera_mask[result.conjectured] == 0)
    measured = np.all(np.isfinite(result.points), axis=2) & ~result.conjectured
    assert np.all(result.camera_mask[measured] & 1)


def test_stress_harness_occlusions_false_candidates(performance):
    """The issue's stress faults, harsher: 10 % of detections missing, half as many false
    blobs as markers (~2.9 candidates per measured marker; the issue asks 1.2-2.3x),
    twelve 10-frame occlusions of marker groups (20 mm), 10 deg head turn."""
    rig, _ = performance
    perf = rig_performance(rig, 150, head_motion_deg=10, expression_mm=5)
    _, frames = synthetic_detections(rig, 150, seed=4, performance=perf, noise_px=0.1, missing=0.1, false_blobs=0.5,
                                     occlusions=12, occlusion_frames=10)
    result = track(frames, rig.camera, rig.planes)
    s = _score(frames, perf, result)
    ratio = result.stats["candidates"][1:].sum() / result.stats["measured"][1:].sum()
    assert ratio > 2.3
    assert s["rms"] < 0.2  # mm; measured 0.075
    assert s["switches"] <= 0.0005 * s["measured"]  # measured 8 in 25,001, all to false blobs
    assert s["reported_of_visible"] >= 0.98  # measured 99.3 %
    assert s["conj_p99"] < 2.0  # measured 1.83 mm


def test_a_blank_frame_mid_clip_is_bridged(performance):
    """A frame with no detections at all (a dropped frame, a blink of the lamps) must not
    break tracking: markers are conjectured or held, and found again afterwards."""
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=5, performance=perf, noise_px=0.05)
    blank = frames[40]
    blank.direct, blank.direct_color, blank.direct_id = np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int)
    for k in range(2):
        blank.mirror[k], blank.mirror_color[k], blank.mirror_id[k] = np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int)
    result = track(frames, rig.camera, rig.planes)
    assert result.stats["measured"][40] == 0 and result.stats["measured"][41] > 0.9 * result.stats["measured"][39]
    s = _score(frames, perf, result)
    assert s["switches"] == 0 and s["rms"] < 0.1
