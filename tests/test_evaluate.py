"""Scoring a take against its truth (core.evaluate): identity switches versus bad measurements."""

from __future__ import annotations

import numpy as np

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
