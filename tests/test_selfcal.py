"""Mirror self-calibration from detections alone (issue 4, step 2)."""

from __future__ import annotations

import numpy as np
import pytest

from mirrorcap.core.geometry.camera import angle_deg
from mirrorcap.core.capture.views import ClipDetections
from mirrorcap.core.common.errors import DegenerateError
from mirrorcap.core.track.mirrorscale import both_mirror_samples, link_mirror_scales
from mirrorcap.core.track.selfcal import build_candidates, self_calibrate_mirror
from mirrorcap.synthetic.simulate import face_rig, synthetic_detections


@pytest.fixture(scope="module")
def rig():
    return face_rig(n_markers=300, seed=3, layout="even")


def _precision(frames, rig, k, result):
    cand = build_candidates(ClipDetections.from_frames(frames, rig.camera), k)
    did = np.concatenate([fr.direct_id for fr in frames])
    mid = np.concatenate([fr.mirror_id[k] for fr in frames])
    chosen = np.flatnonzero(result.plane.inliers)
    ok = (did[cand.direct_blob[chosen]] == mid[cand.mirror_blob[chosen]]) & (did[cand.direct_blob[chosen]] >= 0)
    return ok.mean()


def test_both_mirrors_from_300_markers_without_a_calibration_object(rig):
    """Dense layout (300 markers, 4 colours; true pairs are ~1.5 % of the candidates)."""
    _, frames = synthetic_detections(rig, 10, noise_px=0.1, seed=1)
    results = [self_calibrate_mirror(frames, rig.camera, k) for k in range(2)]
    for k, r in enumerate(results):
        assert angle_deg(r.plane.normal, rig.planes[k][0]) < 0.05  # the note's "within 0.05 deg"
        assert r.plane.normal[2] < 0 and r.plane.d < 0
        assert r.pairs < 0.03 * r.candidates
        assert _precision(frames, rig, k, r) > 0.9
        assert r.plane.noise_px == pytest.approx(0.1, rel=0.3)
    normals = [r.plane.normal for r in results]
    samples = both_mirror_samples(ClipDetections.from_frames(frames, rig.camera), rig.camera, normals)
    ds, figures = link_mirror_scales(samples, normals, [r.plane.d for r in results])
    assert figures["markers"] > 40 and figures["relative_spread"] < 0.01  # 57 of 300 in both mirrors here
    assert ds[1] / ds[0] == pytest.approx(rig.planes[1][1] / rig.planes[0][1], rel=1e-3)


def test_robust_to_missing_and_false_blobs(rig):
    _, frames = synthetic_detections(rig, 10, noise_px=0.3, seed=2, missing=0.1, false_blobs=0.2)
    for k in range(2):
        r = self_calibrate_mirror(frames, rig.camera, k, seed=k)
        assert angle_deg(r.plane.normal, rig.planes[k][0]) < 0.1


def test_deterministic_for_a_seed(rig):
    _, frames = synthetic_detections(rig, 4, noise_px=0.1, seed=3)
    a = self_calibrate_mirror(frames, rig.camera, 0, seed=5)
    b = self_calibrate_mirror(frames, rig.camera, 0, seed=5)
    assert np.array_equal(a.plane.normal, b.plane.normal)


def test_mirror_not_visible_is_an_error(rig):
    _, frames = synthetic_detections(rig, 3, noise_px=0.1, seed=4)
    for fr in frames:  # mirror 1 shows only a handful of stray blobs of one colour
        fr.mirror[1] = fr.mirror[1][:2]
        fr.mirror_color[1] = fr.mirror_color[1][:2]
    with pytest.raises(DegenerateError, match="mirror 1"):
        self_calibrate_mirror(frames, rig.camera, 1)


def test_one_marker_in_both_mirrors_neither_links_the_scales_nor_judges_the_mirrors(rig):
    """A marker wrongly paired in one mirror puts the ratio of the mirrors' distances wherever its depth
    lands (mirror35: one marker's 15 sightings gave 1.22 where the truth is 1.00; the take's RMS 21 mm).
    The link and the agreement test take at least MIN_BOTH_MIRROR_MARKERS markers; the pipeline relates
    the scales through head motion instead."""
    from mirrorcap.core.track.mirrorscale import MIN_BOTH_MIRROR_MARKERS, BothMirrorSamples, mirror_agreement

    _, frames = synthetic_detections(rig, 10, noise_px=0.1, seed=1)
    normals = [np.asarray(n, float) for n, _ in rig.planes]
    ds = [float(d) for _, d in rig.planes]
    samples = both_mirror_samples(ClipDetections.from_frames(frames, rig.camera), rig.camera, normals)
    markers = np.unique(samples.marker)

    def only(chosen):
        keep = np.isin(samples.marker, chosen)
        return BothMirrorSamples(samples.p[keep], samples.pm[:, keep], samples.marker[keep], samples.noise_px)

    one = only(markers[:1])
    assert len(one.p) >= 10 and not one.enough_to_link
    assert mirror_agreement(one, normals, ds, rig.camera.focal_px)["consistent"] is None
    few = only(markers[:MIN_BOTH_MIRROR_MARKERS])
    assert few.enough_to_link
    assert mirror_agreement(few, normals, ds, rig.camera.focal_px)["consistent"] is True
    assert link_mirror_scales(few, normals, ds)[1]["ratio"] == pytest.approx(1.0, abs=2e-3)
