"""Scoring a take against its truth (core.evaluate): identity switches versus bad measurements."""

from __future__ import annotations

import numpy as np
import pytest

from mirrorcap.core.common.errors import InputError

from mirrorcap.synthetic.evaluate import score_take
from mirrorcap.synthetic.simulate import face_rig


def test_switches_count_other_markers_and_off_marker_counts_bad_measurements():
    rig = face_rig(n_markers=60, seed=2)
    F = 20
    rng = np.random.default_rng(0)
    truth = rig.points[None] + rng.normal(0, 0.5, (F, 1, 3))  # the face drifting a little
    take = truth.copy()
    depth = truth[..., 2:]
    pair = np.argsort(np.linalg.norm(rig.points - rig.points[0], axis=1))[1]  # marker 0's nearest neighbour
    take[5:8, 0] = truth[5:8, pair]  # marker 0 follows its neighbour for 3 frames: switches
    take[12, 3, 0] += 3.0 * depth[12, 3, 0] / rig.camera.focal_px  # marker 3 measured 3 px off: not a switch
    take[15, 4] = np.nan  # a gap is neither
    s = score_take(take, truth, rig.camera)
    assert s["identity_switches"] == 3
    assert s["off_marker"] == 1
    assert s["markers_matched"] == 60 and (s["ids"] == np.arange(60)).all()
    assert s["measured_marker_frames"] == F * 60 - 1
    assert abs(s["scale_to_mm"] - 1.0) < 1e-3


def test_completeness_counts_seen_marker_frames_reported_under_the_markers_labels():
    """``seen`` (the truth's visibility): the share of seen marker-frames reported, a marker
    split over two labels, and a marker seen but never tracked."""
    rig = face_rig(n_markers=40, seed=4)
    F = 30
    truth = np.repeat(rig.points[None], F, axis=0)
    take = truth.copy()
    seen = np.ones((F, 40), bool)
    seen[:, 39] = False  # never seen: its gaps do not count
    take[:, 39] = np.nan
    take[10:20, 5] = np.nan  # 10 seen frames lost
    take[:, 7] = np.nan  # marker 7 never tracked, though seen in every frame
    split = np.full((F, 1, 3), np.nan)
    split[20:, 0] = truth[20:, 9]  # marker 9's last 10 frames under a second label ...
    take[20:, 9] = np.nan  # ... and not under its own
    take = np.concatenate([take, split], axis=1)
    s = score_take(take, truth, rig.camera, seen=seen)
    assert s["seen_marker_frames"] == F * 39
    assert s["seen_reported_fraction"] == pytest.approx(1 - (10 + F) / (F * 39))
    assert s["split_markers"] == 1
    assert s["never_tracked"] == [7]
    assert s["unreported_seen"][10:20, 5].all() and s["unreported_seen"].sum() == 10 + F
    with pytest.raises(InputError):
        score_take(take, truth, rig.camera, seen=seen[:, :10])


def test_identity_found_in_the_image_is_checked_in_3d():
    """A dot hidden in the direct view (13 mm deeper on the tracked point's ray: behind the nose)
    projects nearer the point than the dot the point measures, 0.3 mm off it in 3D. The label is
    the dot it measures: no switch, a 0.3 mm error, the image's pick kept in ``ids_image``. A
    point measured 10 mm too deep keeps its own dot, though another lies 3 mm from it in 3D: the
    image tells those two apart."""
    rig = face_rig(n_markers=60, seed=3)
    F = 12
    truth = np.repeat(rig.points[None], F, axis=0)
    take = truth.copy()
    k, j = 17, 40
    take[:, k] += np.array([0.3, 0.0, 0.0])
    ray_k = take[0, k] / np.linalg.norm(take[0, k])
    hidden = take[:, k] + 13.0 * ray_k  # on the point's own ray: projects onto it
    ray_j = truth[0, j] / np.linalg.norm(truth[0, j])
    take[:, j] += 10.0 * ray_j  # a depth error (a mirror plane off)
    beside = take[:, j] + 3.0 * np.cross(ray_j, [0.0, 1.0, 0.0]) / np.linalg.norm(np.cross(ray_j, [0.0, 1.0, 0.0]))
    assert np.linalg.norm(rig.camera.project(beside[:1]) - rig.camera.project(take[:1, j])) > 3.0
    truth = np.concatenate([truth, hidden[:, None], beside[:, None]], axis=1)
    s = score_take(take, truth, rig.camera)
    assert s["ids_image"][k] == 60 and s["ids"][k] == k
    assert s["ids"][j] == j and s["ids_reassigned_in_3d"] == 1
    assert s["identity_switches"] == F  # marker j's frames, nearer the dot beside it
    err = s["error_mm"]
    # the similarity takes up a little of marker j's error
    assert np.allclose(err[:, k], 0.3, atol=0.05) and np.allclose(err[:, j], 10.0, atol=0.5)
