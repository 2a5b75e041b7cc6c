"""The tracker assembled (issue 4, in progress): detections over time -> labelled 3D
trajectories with head motion separated, on a synthetic performance with truth."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.tracking import score
from mirrorcap.synthetic.simulate import face_rig, rig_performance, synthetic_detections
from mirrorcap.core.track.tracker import TrackSettings, track


def _score(frames, perf, result):
    """The benchmark's scoring (benchmarks/tracking.py), under the tests' short names."""
    r = score(frames, perf, result)
    return {"ids": r["ids"], "switches": r["identity_switches"], "measured": r["measured"], "rms": r["rms_mm"],
            "conj_rms": r["conjectured_rms_mm"], "conj_p99": r["conjectured_p99_mm"], "conj_max": r["conjectured_max_mm"],
            "reported_of_visible": r["reported_of_visible"], "duplicates": r["duplicates"]}


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
    # measured 0.16 and 0.59 mm with the learned neighbour relations (0.38 and 1.48 mm with
    # eq. 5.8 alone)
    assert s["conj_rms"] < 0.3 and s["conj_p99"] < 1.0
    assert s["conj_max"] < 2.0  # the target; measured 1.48 mm
    # markers that turn into view later are found (measured 99.8 %; 98.5 % when a late
    # marker entered at its first-seen position, expression and all, and then failed
    # the neighbour test)
    assert s["reported_of_visible"] >= 0.99
    assert len(set(s["ids"].tolist())) == len(s["ids"])  # one marker per label
    # head pose from automatically found rigid markers follows the true turn (up to 10 deg);
    # fitting all markers instead is biased by the expression (measured ~1 deg)
    import cv2

    from mirrorcap.core.geometry.rigid import rotation_zyx

    true_rv = np.array([cv2.Rodrigues(R)[0].ravel() for R in perf[2]])
    est_rv = np.array([cv2.Rodrigues(rotation_zyx(h[:3]))[0].ravel() for h in result.head_pose])
    assert np.degrees(np.max(np.linalg.norm(est_rv - true_rv, axis=1))) < 0.2
    assert np.allclose(result.head_pose[:, 3:], np.array(perf[3]), atol=1.0)  # translation, mm
    # the rigid markers really moved least: the upper face
    assert np.mean(np.linalg.norm(perf[4][:, s["ids"][result.rigid]], axis=2)) < 0.1


def test_rigid_markers_named_by_region_carry_the_head_pose(performance):
    """RIG.json's "rigid": the markers in a box around the forehead carry the head pose;
    a box around the whole face (expression and all) biases it, and a box holding fewer
    than 4 markers is refused."""
    import cv2

    from mirrorcap.core.common.errors import DegenerateError
    from mirrorcap.core.geometry.rigid import rotation_zyx
    from mirrorcap.core.track.tracker import rigid_by_image

    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=1, performance=perf, noise_px=0.05)
    true_rv = np.array([cv2.Rodrigues(R)[0].ravel() for R in perf[2]])

    def pose_error_deg(result):
        est = np.array([cv2.Rodrigues(rotation_zyx(h[:3]))[0].ravel() for h in result.head_pose])
        return np.degrees(np.max(np.linalg.norm(est - true_rv, axis=1)))

    y = np.quantile(rig.camera.project(perf[0][0])[:, 1], 0.25)  # the top quarter of the face: no expression
    upper = track(frames, rig.camera, rig.planes, rigid=((0, 0, 1280, y), None))
    s = _score(frames, perf, upper)
    assert s["switches"] == 0 and s["rms"] < 0.1
    assert np.all(np.linalg.norm(perf[4][:, s["ids"][upper.rigid]], axis=2) == 0)  # only markers that never moved
    assert len(upper.rigid) > 40
    assert pose_error_deg(upper) < 0.1  # measured 0.04 deg (0.12 found automatically)
    whole = track(frames, rig.camera, rig.planes, rigid=((0, 0, 1280, 720), None))
    assert pose_error_deg(whole) > 0.5  # measured 1.0 deg: the expression pulls the fit
    # colour classes narrow the region: the synthetic markers' classes split the forehead
    colour0 = rigid_by_image(rig.camera, upper.neutral, upper.colour, (0, 0, 1280, y), (0,))
    assert 4 <= len(colour0) < len(upper.rigid)
    assert np.all(upper.colour[colour0] == 0)
    with pytest.raises(DegenerateError, match="at least 4"):
        track(frames, rig.camera, rig.planes, rigid=((0, 0, 1280, 100), None))


def test_markers_that_cannot_be_decided_are_reported(performance):
    """Procedure step 2: a direct-view marker with no mirror image, and one whose mirror
    image has a same-colour twin on its mirrored epipolar line, cannot be given a 3D
    position; the result lists both, where they were first seen and why."""
    import dataclasses

    from mirrorcap.core.geometry.mirror import reflect_points

    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=1, performance=perf, noise_px=0.05)
    ids0 = [set(np.asarray(f.direct_id).tolist()) for f in frames[:15]]
    in_m = [[set(np.asarray(f.mirror_id[k]).tolist()) for f in frames[:15]] for k in range(2)]
    everywhere = set.intersection(*ids0)
    # a marker seen directly and in both mirrors throughout: its mirror images are removed
    lost = min(m for m in everywhere if all(m in s for k in range(2) for s in in_m[k]))
    # one seen directly and in mirror 0 only: its mirror 0 image gets a twin 15 mm deeper along the ray
    twin = min(m for m in everywhere if all(m in s for s in in_m[0]) and not any(m in s for s in in_m[1]))
    n0, d0 = rig.planes[0]
    edited = []
    for f, fr in enumerate(frames):
        mirror, colour, mid = list(fr.mirror), list(fr.mirror_color), list(fr.mirror_id)
        for k in range(2):
            keep = np.asarray(mid[k]) != lost
            mirror[k], colour[k], mid[k] = np.asarray(mirror[k])[keep], np.asarray(colour[k])[keep], np.asarray(mid[k])[keep]
        sel = np.flatnonzero(np.asarray(mid[0]) == twin)
        if sel.size:
            X = perf[0][f][twin]  # camera frame, mm
            deeper = X * (1 + 15.0 / np.linalg.norm(X))
            px = rig.camera.project(reflect_points(deeper[None], n0, d0))
            mirror[0] = np.r_[mirror[0], px]
            colour[0] = np.r_[colour[0], np.asarray(colour[0])[sel]]
            mid[0] = np.r_[mid[0], [-1]]
        edited.append(dataclasses.replace(fr, mirror=mirror, mirror_color=colour, mirror_id=mid))
    # the first frames' pairing leaves both undecided, the twin as ambiguous in mirror 0
    from mirrorcap.core.capture.views import ClipDetections
    from mirrorcap.core.track.pairing import paired_tracks
    from mirrorcap.core.track.initial import undecided_tracks

    normals = np.stack([n for n, _ in rig.planes])
    first_frames = ClipDetections.from_frames(edited[:15], rig.camera)
    dids, n_dt, partner, _, ambiguous, _ = paired_tracks(first_frames, rig.camera, normals, 1.0, 5)
    first = undecided_tracks(first_frames, dids, n_dt, partner, ambiguous, 5)
    track_of = {m: dids[0][np.flatnonzero(np.asarray(frames[0].direct_id) == m)[0]] for m in (lost, twin)}
    assert set(first["track"].tolist()) == set(track_of.values())
    amb = dict(zip(first["track"].tolist(), first["ambiguous_in"].tolist()))
    assert amb[track_of[twin]] == [True, False] and amb[track_of[lost]] == [False, False]
    # the tracker: the marker with no mirror image is reported undecided, where it was seen;
    # the twin's marker is taken up later (late markers: its true chain) at its true position
    result = track(edited, rig.camera, rig.planes)
    assert len(result.undecided) == 1, result.undecided
    r = result.undecided[0]
    assert r["reason"] == "no mirror partner" and r["frame"] == 0 and r["frames_seen"] == 15
    at = np.flatnonzero(np.asarray(frames[0].direct_id) == lost)[0]
    assert np.hypot(r["x"] - frames[0].direct[at, 0], r["y"] - frames[0].direct[at, 1]) < 0.01
    assert r["colour"] == frames[0].direct_color[at]
    err = np.nanmin(np.nanmedian(np.linalg.norm(result.points - perf[0][:, twin][:, None], axis=2), axis=0))
    assert err < 0.1  # mm: the true position, not the twin's 15 mm deeper
    # the clean clip has none
    assert track(frames, rig.camera, rig.planes).undecided == []


def test_faults_missing_and_false_blobs(performance):
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=2, performance=perf, noise_px=0.1, missing=0.1, false_blobs=0.2)
    result = track(frames, rig.camera, rig.planes, TrackSettings())
    s = _score(frames, perf, result)
    # the 1 switch measured before (a one-frame false blob 3.4 px from the image of a marker
    # turned away, taken as the marker came back from a gap) is gone: a marker back from a
    # gap takes only a candidate that lasts (a like one within 3 mm a frame or two away)
    assert s["switches"] == 0
    assert s["rms"] < 0.2
    # measured 99.05 % and p99 / max 0.37 / 1.70 mm (0.83 / 2.63 mm with every conjecture
    # kept, core.track.TrackSettings.conjecture_max_sd_mm = inf)
    assert s["reported_of_visible"] >= 0.985 and s["conj_p99"] < 0.8 and s["conj_max"] < 2.0
    assert s["duplicates"] == 0
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
    assert ratio > 2.3  # measured 2.34
    assert s["rms"] < 0.2  # mm; measured 0.075
    # the target; the 6 switches measured before were all to false blobs the
    # generator placed within 2 px of a hidden marker's image, where they reconstruct the
    # marker itself (core.simulate.synthetic_detections now keeps them 3 px off)
    assert s["switches"] == 0
    assert s["reported_of_visible"] >= 0.99  # measured 99.64 %
    assert s["duplicates"] == 0  # two chains of one late marker are one marker (were 4)
    # measured p99 / max 0.41 / 1.17 mm (0.90 / 3.27 with every conjecture kept; p99 1.24
    # with eq. 5.8 alone)
    assert s["conj_p99"] < 0.8 and s["conj_max"] < 2.0
    # conjectures inside a gap from the learned neighbour relations, meeting both ends
    # (measured 0.20 mm RMS; 0.25 mm with eq. 5.8 from both ends, 0.43 mm from the last
    # sighting alone)
    measured = result.assigned_blob >= 0
    frames_i = np.arange(measured.shape[0])[:, None]
    seen_before = np.maximum.accumulate(np.where(measured, frames_i, -1), axis=0) >= 0
    seen_after = np.minimum.accumulate(np.where(measured, frames_i, 10**9)[::-1], axis=0)[::-1] < 10**9
    inside = result.conjectured & seen_before & seen_after
    err = np.linalg.norm(result.points - perf[0][:, s["ids"]], axis=2)
    assert inside.sum() > 5000 and np.sqrt(np.mean(err[inside] ** 2)) < 0.2  # measured 6,755 and 0.12 mm


def test_conjectures_expected_off_by_more_than_the_limit_are_left_as_gaps(performance):
    """A conjecture is reported only where its expected error -- the learned relations'
    standard deviation grown with the frames to the marker's nearest measurement -- is
    within ``conjecture_max_sd_mm`` (2/3 mm: 3 sigma within the issue's 2 mm); the rest
    are gaps, counted per frame in ``stats["withheld"]``."""
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=2, performance=perf, noise_px=0.1, missing=0.1, false_blobs=0.2)
    kept = track(frames, rig.camera, rig.planes, TrackSettings(conjecture_max_sd_mm=np.inf))
    limited = track(frames, rig.camera, rig.planes, TrackSettings())
    s_all, s_lim = _score(frames, perf, kept), _score(frames, perf, limited)
    assert kept.stats["withheld"].sum() == 0
    gone = kept.conjectured & ~limited.conjectured
    assert gone.sum() == limited.stats["withheld"].sum() > 0  # measured 142 of 4,114
    assert gone.sum() < 0.1 * kept.conjectured.sum()
    assert not (limited.conjectured & ~kept.conjectured).any()
    assert np.isnan(limited.points[gone]).all() and (limited.assigned_blob[gone] < 0).all()
    assert (limited.stats["conjectured"] == limited.conjectured.sum(axis=1)).all()
    measured = kept.assigned_blob >= 0
    assert np.array_equal(measured, limited.assigned_blob >= 0)  # measurements are untouched
    assert np.allclose(kept.points[measured], limited.points[measured])
    # the withheld ones are where the worst conjectures were: measured 2.63 -> 1.70 mm
    assert s_all["conj_max"] > 2.0 > s_lim["conj_max"]


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


def test_false_blobs_keep_off_every_markers_image(performance):
    """The generator's false blobs stay 3 px from the image of every marker in the view --
    detected, dropped by ``missing``, occluded or turned away -- since a blob there would
    merge with the marker's own or stand in for it exactly."""
    from mirrorcap.core.geometry.mirror import reflect_points
    from mirrorcap.synthetic.simulate import visibility

    rig, perf = performance
    _, frames = synthetic_detections(rig, 6, seed=9, performance=perf, noise_px=0.0, missing=0.3, false_blobs=0.5,
                                     occlusions=3, occlusion_frames=4)
    dropped = 0
    for t, fr in enumerate(frames):
        vis = visibility(rig.camera, rig.planes, perf[0][t], perf[1][t])
        views = [(fr.direct, fr.direct_id, rig.camera.project(perf[0][t]), vis[0])]
        views += [(fr.mirror[k], fr.mirror_id[k], rig.camera.project(reflect_points(perf[0][t], *rig.planes[k])),
                   vis[1 + k]) for k in range(len(rig.planes))]
        for px, ids, every, seen in views:
            false = px[ids < 0]
            assert len(false) > 0.3 * np.sum(ids >= 0)
            gap = np.min(np.linalg.norm(false[:, None] - every[None], axis=2), axis=1)
            assert gap.min() > 3.0
            dropped += int(np.sum(seen)) - int(np.sum(ids >= 0))
    assert dropped > 0  # some markers were in view but not detected


def _labelled_take(measured, neutral, candidate):
    """A TrackResult of ``measured (F, N)`` cells on clip candidates ``candidate (F, N)``."""
    from mirrorcap.core.track.result import TrackResult

    F, N = measured.shape
    points = np.where(measured[..., None], np.asarray(neutral, float)[None], np.nan)
    return TrackResult(labels=[f"m{i:03d}" for i in range(N)], points=points.copy(), conjectured=np.zeros((F, N), bool),
                       camera_mask=np.where(measured, 3, 0), head_pose=np.zeros((F, 6)),
                       neutral=np.asarray(neutral, float), first_blob=np.full(N, -1),
                       assigned_blob=np.where(measured, candidate, -1), colour=np.zeros(N, int),
                       head_frame=points.copy(), candidate=np.where(measured, candidate, -1), rigid=np.arange(N))


def test_of_two_labels_on_one_mirror_track_the_one_off_the_face_is_undone():
    """#18, stop 52, hr2: a forehead dot seen only directly paired, from the first frames, with a like dot's grazing
    image on its line (22 mm off the face along its ray), and the image's own dot took the image in other frames
    (on the face): the first label's frames on that mirror track are undone. Both labels on the face (a track that
    passes from one dot to another), or both off it, stay; so do frames on other tracks."""
    from mirrorcap.core.track.onface import off_face_on_shared_tracks

    F, N = 10, 26
    g = np.stack(np.meshgrid(np.arange(-2, 3), np.arange(-2, 3)), -1).reshape(-1, 2) * 10.0
    face = np.c_[g, 600.0 + 0.002 * (g ** 2).sum(axis=1)]                 # 25 markers on a gently curved face
    ray = face[12] / np.linalg.norm(face[12])

    def case(off_a, off_b):
        neutral = np.vstack([face, face[12]])
        measured = np.ones((F, N), bool)
        measured[5:, 12] = False                                          # label 12: frames 0-4, label 25: 5-9
        measured[:5, 25] = False
        candidate = np.arange(F * N).reshape(F, N)
        take = _labelled_take(measured, neutral, candidate)
        take.points[:5, 12] += off_a * ray
        take.points[5:, 25] += off_b * ray
        mirror_track = np.full((F * N, 2), -1)
        mirror_track[:, 0] = np.tile(np.arange(N), F)                     # each label on its own mirror-0 track ...
        mirror_track[candidate[:, 25], 0] = 12                            # ... but 12 and 25 on one
        mirror_track[candidate[:2, 12], 0] = 40                           # frames 0-1: label 12 on another track
        return off_face_on_shared_tracks(take, mirror_track, 10.0)

    drop = case(22.0, 0.0)
    assert drop[2:5, 12].all() and drop.sum() == 3                        # not frames 0-1 (another track)
    drop = case(0.0, -22.0)
    assert drop[5:, 25].all() and drop.sum() == 5
    assert not case(0.0, 0.0).any() and not case(22.0, 22.0).any() and not case(6.0, 0.0).any()


def test_labels_on_one_pair_of_2d_tracks_are_one_marker():
    """#18, the jaw clip: a chin dot moving 4-8 mm a frame along the line of sight was measured by
    turns under two labels while the direct view's and a mirror's 2D tracks followed it throughout.
    Two labels, never measured together, that are the only ones on one (direct track, mirror track)
    pair merge; a third label on the pair, labels measured in one frame, or labels far apart do not."""
    from mirrorcap.core.track.splits import _shared_track_pairs, merge_along_2d_tracks

    F = 12
    # candidate c of frame f is c = f * 10 + slot; slot s lies on direct track s and mirror-0 track s
    dtrack = np.tile(np.arange(10), F)
    mtrack = np.c_[dtrack, np.full(10 * F, -1)]
    cand = lambda slot: np.arange(F) * 10 + slot          # noqa: E731
    neutral = [[0, 0, 600], [1, 0, 600], [0, 40, 600], [0, 41.5, 600], [0, 80, 600], [0, 81, 600], [0, 82, 600]]
    measured = np.zeros((F, 7), bool)
    candidate = np.full((F, 7), -1)
    # labels 0 and 1: one dot, by turns (0 in frames 0-3 and 6-7, 1 in 4-5 and 8-11), on slot 0's
    # tracks -- but in frames 0-3 on slot 5's (its 2D tracks broke at frame 4, in the fast motion),
    # so label 1's first measurement does not continue label 0's last tracks (rule 2 does not apply)
    for label, frames in ((0, [0, 1, 2, 3, 6, 7]), (1, [4, 5, 8, 9, 10, 11])):
        measured[frames, label] = True
        candidate[frames, label] = cand(0)[frames]
    candidate[:4, 0] = cand(5)[:4]
    # labels 2 and 3: on slot 1 by turns, but measured together in frame 5 (two dots)
    for label, frames in ((2, [0, 1, 2, 5]), (3, [5, 6, 7, 8])):
        measured[frames, label] = True
        candidate[frames, label] = cand(1)[frames] if label == 2 else cand(2)[frames]
    candidate[5, 3] = cand(2)[5]
    mtrack[cand(2), 0] = 1                                   # slot 2's mirror track is slot 1's
    dtrack[cand(2)] = 1
    # labels 4, 5, 6: three labels on slot 3 by turns (rule 1 cannot tell which two are one; the
    # handover along the mirror's track, rule 2, may join them in order)
    for label, frames in ((4, [0, 1, 2, 3]), (5, [4, 5, 6, 7]), (6, [8, 9, 10, 11])):
        measured[frames, label] = True
        candidate[frames, label] = cand(3)[frames]
    take = _labelled_take(measured, neutral, candidate)
    assert _shared_track_pairs(take, dtrack, mtrack) == [(0, 1)]
    # on the direct tracks alone (merge_split_labels' looser test): 0 and 1 share slot 0's, 2 and 3 are measured
    # together, 4-6 are three on one
    assert _shared_track_pairs(take, dtrack) == [(0, 1)]
    merged = merge_along_2d_tracks(take, (dtrack, mtrack))
    assert merged.labels[:3] == ["m000", "m002", "m003"]                          # 1 went into 0; 2, 3 stay
    assert np.array_equal(merged.assigned_blob[:, 0] >= 0, np.ones(F, bool))     # the dot in every frame
    assert np.array_equal(merged.candidate[:, 0], np.r_[cand(5)[:4], cand(0)[4:]])
    # the same two labels far apart (beyond MERGE_SEARCH_MM) are two dots
    far = _labelled_take(measured, [[0, 0, 600], [30, 0, 600], *neutral[2:]], candidate)
    assert _shared_track_pairs(far, dtrack, mtrack) == []


def test_a_mirror_track_handover_is_vetoed_where_the_direct_view_follows_the_dot_elsewhere():
    """merge_along_2d_tracks, rule 2 (a gap the direct view alone lost: the earlier label's last
    mirror track is the later label's first) and its veto: the dense clip's dot 218 and dot 139,
    11 mm apart, imaged a pixel apart grazing in a mirror, where one mirror track ran from one to
    the other. Labels 0 (frames 0-4) and 1 (frames 7-11), on direct tracks 0 and 1 and both on
    mirror track 0, merge -- unless label 0's direct track has a blob in label 1's first frame
    (``direct_frames``): the direct view followed the dot on elsewhere, so label 1 is another dot."""
    from mirrorcap.core.track.splits import merge_along_2d_tracks

    F = 12
    dtrack = np.tile(np.arange(10), F)                     # candidate f * 10 + slot: direct track = slot
    mtrack = np.c_[np.zeros(10 * F, int), np.full(10 * F, -1)]
    mtrack[dtrack != 0] = -1
    mtrack[np.arange(F) * 10 + 1, 0] = 0                   # slot 1 is on mirror track 0 too
    measured = np.zeros((F, 2), bool)
    measured[:5, 0] = measured[7:, 1] = True
    candidate = np.c_[np.arange(F) * 10, np.arange(F) * 10 + 1]
    take = lambda: _labelled_take(measured, [[0, 0, 600], [4, 0, 600]], candidate)  # noqa: E731
    assert len(merge_along_2d_tracks(take(), (dtrack, mtrack)).labels) == 1           # rule 2: one dot
    direct_only_to_4 = np.unique(np.r_[np.arange(5), F + np.arange(F)])                # track 0 ends at frame 4
    assert len(merge_along_2d_tracks(take(), (dtrack, mtrack), direct_only_to_4).labels) == 1
    direct_on = np.unique(np.r_[np.arange(F), F + np.arange(F)])                      # track 0 goes on
    assert len(merge_along_2d_tracks(take(), (dtrack, mtrack), direct_on).labels) == 2


def test_a_lost_markers_measurements_stay_only_on_the_path_of_the_label_they_joined():
    """core.track.late.settle_lost_markers: the measurements of markers lost for good (codes of
    (frame, direct blob)) go with a label that holds nothing else; where another label's measurements
    joined them they stay when, bracketed by those, they lie on its path -- a chin dot's first frames
    before its later label -- and go when they lie off it: a wrong pairing interleaved with the
    true marker, 7 mm away."""
    from mirrorcap.core.track.late import BLOB_CODE, settle_lost_markers
    from mirrorcap.core.track.result import TrackResult

    F, N = 30, 3
    t = np.arange(F, dtype=float)
    head_frame = np.stack([np.c_[t, 0 * t, 0 * t] + [0.0, 10.0 * n, 0.0] for n in range(N)], axis=1)  # 1 mm a frame
    blob = np.tile(np.arange(N), (F, 1))
    lost = np.zeros((F, N), bool)
    lost[:6, 0] = True                    # marker 0: its first label's 6 frames, then a gap, then its later label
    blob[6:8, 0] = -1
    lost[11:20:2, 1] = True               # marker 1: a wrong pairing, every other frame, 7 mm off the path
    head_frame[11:20:2, 1, 2] += 7.0
    blob[:, 2] = np.where(t < 12, 2, -1)  # marker 2: lost for good, nothing joined it
    lost[:12, 2] = True
    measured = blob >= 0
    head_frame[~measured] = np.nan
    result = TrackResult(labels=["m000", "m001", "m002"], points=head_frame.copy(), conjectured=~measured,
                         camera_mask=np.where(measured, 3, 0), head_pose=np.zeros((F, 6)), neutral=head_frame[0].copy(),
                         first_blob=np.arange(N), assigned_blob=blob, colour=np.zeros(N, int),
                         head_frame=head_frame, candidate=np.where(measured, 0, -1), rigid=np.arange(N))
    f, m = np.nonzero(lost)
    out = settle_lost_markers(result, f * BLOB_CODE + blob[f, m], gate_mm=3.0)
    assert len(out.labels) == 2                                   # marker 2 went
    kept = out.assigned_blob >= 0
    assert kept[:6, 0].all() and kept[8:, 0].all()                # marker 0's first frames stayed
    assert not kept[11:20:2, 1].any() and kept[10:21:2, 1].all()  # the wrong pairing went, the marker stayed
    assert np.isnan(out.points[11:20:2, 1]).all() and not out.conjectured[11:20:2, 1].any()


def test_a_dot_at_the_silhouette_is_on_the_face_as_the_mirror_sees_it():
    """#18, stop 35: a late marker is not added where its point lies off the face -- a direct blob paired
    with another dot's mirror image lands tens of mm along its ray. The face there is the plane through
    the markers nearest its ray; a dot at the silhouette (wide576's dots 9 and 155, dots720's dot 9, beyond
    every tracked marker on the side of the head) lies where that plane, extrapolated, misses the face
    curving away, 13-31 mm. The mirror sees such a dot face on: reflected in the mirror's plane (eq. 3.9)
    among the markers measured through that mirror, it lies on the face. A point moved 30-45 mm along
    the dot's direct ray either way -- a wrong pairing -- is off the face in both views."""
    from mirrorcap.core.track.onface import off_in_mirrors, off_the_face

    centre, radius = np.array([0.0, 0.0, 650.0]), 75.0          # a head, its face turned to the camera
    tilt, turn = np.meshgrid(np.radians(np.arange(0, 64, 8)), np.radians(np.arange(0, 360, 20)))
    out = np.unique(np.round(np.c_[(np.sin(tilt) * np.cos(turn)).ravel(), (np.sin(tilt) * np.sin(turn)).ravel(),
                                   -np.cos(tilt).ravel()], 9), axis=0)
    out = np.vstack([out, [-np.sin(np.radians(75)), 0.0, -np.cos(np.radians(75))]])   # the last: the side dot
    points = centre + radius * out
    normal, d = np.array([0.766, 0.0, -0.643]) / np.linalg.norm([0.766, 0.0, -0.643]), -493.8
    eye = 2.0 * d * normal                                      # the mirror's virtual camera
    to_eye = eye - points
    facing = np.einsum("ij,ij->i", to_eye / np.linalg.norm(to_eye, axis=1, keepdims=True), out) > np.cos(np.radians(80))
    views = 1 | np.where(facing, 2, 0)                          # every marker direct, some through the mirror
    face, dot = points[:-1], points[-1]
    planes = (normal[None], np.array([d]))
    used = np.array([True])
    assert off_the_face(face, dot, 10.0)                       # the plane through its neighbours misses it
    assert not off_in_mirrors(face, views[:-1], dot, used, planes, 10.0)
    ray = dot / np.linalg.norm(dot)
    for step in (-45.0, -30.0, 30.0, 45.0):
        wrong = dot + step * ray
        assert off_the_face(face, wrong, 10.0) and off_in_mirrors(face, views[:-1], wrong, used, planes, 10.0)
    # the mirror's face is the markers measured through it: with none, the mirror clears nothing
    assert off_in_mirrors(face, np.ones(len(face), int), dot, used, planes, 10.0)


def _bridge_case(step_mm=3.0, facing=(-1.0, 0.0, -1.0), missing_frame=None, held_frame=None,
                 measured_frames=(0, 1, 2, 7, 8, 9)):
    """A marker measured in frames 0-2 and 7-9 (``measured_frames``) of 10 on a patch of 25 markers 600 mm away; in every
    frame slot 0 is its candidate (direct track 5; mirror-0 track 7 to frame 4, then 8: that track
    breaks), slot 1 another dot's (direct track 6, mirror track 7), slot 2 its direct blob with a
    stray mirror blob (mirror track 9). Returns the take after :func:`bridge.bridge_gaps_along_2d_tracks`."""
    from types import SimpleNamespace

    from mirrorcap.core.track.bridge import bridge_gaps_along_2d_tracks
    from mirrorcap.core.track.candidates import ClipCandidates

    F, S = 10, 3
    normal = np.asarray(facing, float) / np.linalg.norm(facing)
    across = np.cross(normal, [0.0, 1.0, 0.0])
    grid = np.stack(np.meshgrid(np.arange(-2, 3), np.arange(-2, 3)), axis=-1).reshape(-1, 2) * 8.0
    neutral = np.array([-40.0, 0.0, 600.0]) + grid[:, :1] * across + grid[:, 1:] * [0.0, 1.0, 0.0]
    m = 12                                                     # the patch's centre
    path = neutral[m] + np.arange(F)[:, None] * [0.0, step_mm, 0.0]
    slot = np.tile(np.arange(S), F)
    frame = np.repeat(np.arange(F), S)
    points = path[frame] + np.where(slot[:, None] == 0, 0.0, 20.0) * [1.0, 0.0, 0.0]
    direct = frame * S + np.where(slot == 2, 0, slot)          # slot 2 shares slot 0's direct blob
    mirror = np.c_[frame * S + slot, np.full(F * S, -1)]
    keep = np.ones(F * S, bool)
    if missing_frame is not None:
        keep &= ~((frame == missing_frame) & (slot == 0))
    cands = ClipCandidates(points[keep], direct[keep], mirror[keep], np.zeros(keep.sum()), frame=frame[keep],
                           start=np.r_[0, np.cumsum(np.bincount(frame[keep], minlength=F))])
    dtrack = np.where(slot == 1, 6, 5)[keep]
    mtrack = np.c_[np.where(slot == 0, np.where(frame <= 4, 7, 8), np.where(slot == 1, 7, 9)), np.full(F * S, -1)][keep]
    measured = np.zeros((F, 25), bool)
    measured[list(measured_frames), m] = True
    index = cands.start[:-1]                                   # each frame's slot-0 candidate (first of it)
    candidate = np.zeros((F, 25), int)
    candidate[:, m] = index
    take = _labelled_take(measured, neutral, candidate)
    take.assigned_blob[measured] = 0
    take.points[measured[:, m], m] = path[measured[:, m]]
    take.head_frame = take.points.copy()
    if held_frame is not None:                                 # another marker measures slot 0's mirror blob
        other = 0
        take.candidate[held_frame, other] = index[held_frame]
        take.assigned_blob[held_frame, other] = 0
    planes = (np.array([[0.766, 0.0, -0.643], [-0.766, 0.0, -0.643]]), np.array([-493.8, -493.8]))
    # the clip's blobs as the bridge counts them: S direct and S mirror-0 blobs a frame, none in mirror 1
    det = SimpleNamespace(start=[np.arange(F + 1) * S, np.arange(F + 1) * S, np.zeros(F + 1, int)],
                          frame=[np.repeat(np.arange(F), S), np.repeat(np.arange(F), S), np.zeros(0, int)])
    return bridge_gaps_along_2d_tracks(take, det, cands, (dtrack, mtrack), planes), path, m


def test_a_fast_dots_gap_is_bridged_where_its_2d_tracks_bracket_it():
    """#18, stop 35, fast540's lips: a dot moving 3-7 mm a frame outruns the passes' gate and the 2D
    following's prediction; its mirror track breaks, its direct track runs through. Between two
    measurements whose direct track (or one mirror's track) is the same, a gap whose every frame has
    one candidate on the marker's own tracks at either end, its blobs nobody else's, is measured --
    not a stray mirror blob on the direct track nor another dot's candidate on the mirror track. Not
    bridged: a frame with no such candidate, a blob another marker measures, a slow dot (the gap is
    the passes' verdict), a dot the mirror sees at a grazing angle (its image drifts off the dot), and
    (stop 36, vga480: a chin dot's bridge took its direct blob merged with a dot 29 mm behind it) a dot
    the camera sees at a grazing angle though the mirror sees it face on."""
    take, path, m = _bridge_case()
    gap = np.arange(3, 7)
    assert (take.assigned_blob[gap, m] >= 0).all() and take.stats["bridged"][gap].tolist() == [1, 1, 1, 1]
    assert np.allclose(take.points[gap, m], path[gap]) and not take.conjectured[gap, m].any()
    assert (take.camera_mask[gap, m] == 3).all() and take.assigned_blob[5, m] == 0
    for case in ({"missing_frame": 5}, {"held_frame": 4}, {"step_mm": 0.3}, {"facing": (0.0, 0.0, -1.0)},
                 {"facing": (-1.0, 0.0, -0.16)}):
        take, path, m = _bridge_case(**case)
        assert not (take.assigned_blob[3:7, m] >= 0).any() and take.stats["bridged"].sum() == 0, case


def test_a_dot_lost_for_good_is_followed_on_along_all_its_2d_tracks():
    """#18, stop 52, hq1: a dot by the nose rising 10 mm and falling back in 5 frames was lost at its peak
    (the prediction overshot by a frame's motion) and its conjecture stayed 5-11 mm off the dot, beyond the
    gate, for the take's last 60 frames, though its direct and mirror 2D tracks ran on. After a marker's last
    measurement, the candidates on its direct track *and* on the mirror tracks it was measured on (only one end
    vouches) are its own while there is one a frame: followed to frame 4, where the mirror track breaks (not
    onto the stray mirror blob on the direct track, nor the other dot on the mirror track). Not followed: a
    blob another marker measures, a slow dot, a dot a view sees at a grazing angle, a chain shorter than two
    frames (its dot missed in frame 4)."""
    take, path, m = _bridge_case(measured_frames=(0, 1, 2))
    assert take.stats["bridged"].tolist() == [0, 0, 0, 1, 1, 0, 0, 0, 0, 0]
    assert np.allclose(take.points[[3, 4], m], path[[3, 4]]) and not take.conjectured[[3, 4], m].any()
    assert (take.camera_mask[[3, 4], m] == 3).all() and (take.assigned_blob[5:, m] < 0).all()
    for case in ({"held_frame": 4}, {"step_mm": 0.3}, {"facing": (0.0, 0.0, -1.0)}, {"facing": (-1.0, 0.0, -0.16)},
                 {"missing_frame": 4}):
        take, path, m = _bridge_case(measured_frames=(0, 1, 2), **case)
        assert take.stats["bridged"].sum() == 0, case


def test_a_dot_seen_in_both_mirrors_is_followed_on_by_its_fused_candidate():
    """Stop 52: a dot measured through both mirrors has three candidates a frame on its tracks -- the fused one
    and one through each mirror alone. The follow-on takes the one sharing the most of its tracks: the fused
    candidate while both mirror tracks run (frames 3-4), then, mirror 0's track broken, the one through mirror 1
    (frames 5-7). Taken as three candidates a frame, nothing was followed."""
    from types import SimpleNamespace

    from mirrorcap.core.track.bridge import bridge_gaps_along_2d_tracks
    from mirrorcap.core.track.candidates import ClipCandidates

    F, m = 8, 12
    grid = np.stack(np.meshgrid(np.arange(-2, 3), np.arange(-2, 3)), axis=-1).reshape(-1, 2) * 8.0
    neutral = np.c_[grid[:, 0] - 40.0, grid[:, 1], np.full(25, 600.0)]      # a patch facing the camera
    path = neutral[m] + np.arange(F)[:, None] * [0.0, 3.0, 0.0]
    frame = np.repeat(np.arange(F), 3)
    slot = np.tile(np.arange(3), F)                                          # fused, mirror 0 only, mirror 1 only
    mirror = np.c_[np.where(slot == 2, -1, frame), np.where(slot == 1, -1, frame)]
    cands = ClipCandidates(path[frame], frame.copy(), mirror, np.zeros(3 * F), frame=frame,
                           start=np.arange(F + 1) * 3)
    dtrack = np.full(3 * F, 5)
    mtrack = np.c_[np.where(mirror[:, 0] < 0, -1, np.where(frame <= 4, 7, 8)), np.where(mirror[:, 1] < 0, -1, 11)]
    measured = np.zeros((F, 25), bool)
    measured[:3, m] = True
    candidate = np.zeros((F, 25), int)
    candidate[:, m] = cands.start[:-1]                                       # the fused candidates
    take = _labelled_take(measured, neutral, candidate)
    take.assigned_blob[measured] = 0
    take.points[:3, m] = path[:3]
    take.head_frame = take.points.copy()
    planes = (np.array([[0.5, 0.0, -0.866], [-0.5, 0.0, -0.866]]), np.array([-300.0, -300.0]))
    det = SimpleNamespace(start=[np.arange(F + 1)] * 3, frame=[np.arange(F)] * 3)
    take = bridge_gaps_along_2d_tracks(take, det, cands, (dtrack, mtrack), planes)
    assert take.stats["bridged"].tolist() == [0, 0, 0, 1, 1, 1, 1, 1]
    assert take.candidate[3:, m].tolist() == [9, 12, 17, 20, 23]             # fused twice, then mirror 1's
    assert take.camera_mask[3:, m].tolist() == [7, 7, 5, 5, 5]
    assert np.allclose(take.points[3:, m], path[3:])


def test_a_view_sees_a_dot_face_on_within_the_angle_of_its_surface_normal():
    """geometry.surface: the normals of a bent sheet of markers by principal components point to the
    camera side; seen_face_on compares each camera's direction with the normal (the camera at the
    origin, a mirror's virtual camera beside the face)."""
    from mirrorcap.core.geometry.surface import seen_face_on, surface_normals

    g = np.stack(np.meshgrid(np.arange(-3, 4), np.arange(-3, 4)), -1).reshape(-1, 2) * 6.0
    points = np.c_[g, 600.0 + 0.004 * (g ** 2).sum(axis=1)]                # a bowl opening towards the camera
    normals = surface_normals(points)
    centre = np.flatnonzero((g == 0).all(axis=1))[0]
    assert np.allclose(normals[centre], [0.0, 0.0, -1.0], atol=1e-6)
    assert np.all(normals[:, 2] < -0.8)                                      # all turned towards the camera
    cams = np.array([[0.0, 0.0, 0.0], [-1200.0, 0.0, 600.0], [-900.0, 0.0, -300.0]])
    on = seen_face_on(normals[centre], points[centre], cams, 80.0)
    assert on.tolist() == [True, False, True]                               # 0, 90 and 45 deg off the normal
    assert seen_face_on(normals[centre], points[centre], cams, 40.0).tolist() == [True, False, False]
    assert not seen_face_on(np.full(3, np.nan), points[centre], cams, 80.0).any()


def _waving_face(rng, N, F):
    """``N`` markers on a shallow face 600 mm away and their motion over ``F`` frames, the head still: one
    wave of expression that each marker follows with its own gain. Returns ``neutral (N, 3)``, ``truth (F, N, 3)``."""
    neutral = rng.uniform(-30, 30, (N, 3)) * [1, 1, 0.2] + [0, 0, 600]
    gain = 1.0 + 0.5 * (neutral[:, :1] / 30.0)
    wave = np.sin(np.linspace(0, 3 * np.pi, F))[:, None, None] * np.array([0.0, 3.0, 1.0])
    return neutral, neutral[None] + gain[None] * wave


def test_a_single_mirror_measurement_its_neighbours_disown_becomes_a_conjecture():
    """#18, dense clip: a dot seen directly paired with another dot's grazing mirror image (their images
    merged) lands 2-3 mm along the direct ray for a frame or a few, a move no neighbour makes. The gap
    fill's learned relations (eq. 5.8) estimate the marker from its neighbours; a direct + one-mirror
    measurement more than OUTLIER_SD of the estimate's sd off it is doubted and conjectured, on the
    neighbours' motion. The same offset through both mirrors stays (their depths check each other); no
    other cell of the take is doubted, not even of a marker measured with 0.7 mm noise, up to 2 mm off its
    estimate: its relations' sd, not a fixed limit, sets how far is too far (at 2 sd it fails)."""
    from mirrorcap.core.track.gapfill import doubt_outlying_measurements, fill_gaps

    rng = np.random.default_rng(5)
    N, F = 40, 120
    neutral, truth = _waving_face(rng, N, F)
    take = _labelled_take(np.ones((F, N), bool), neutral, np.arange(F * N).reshape(F, N))
    take.points = truth + rng.normal(0, 0.05, truth.shape)
    take.points[:, 12] += rng.normal(0, 0.7, (F, 3))                    # a noisy marker: judged on its own sd
    take.camera_mask[:, 5] = 7                                           # marker 5 seen through both mirrors
    wrong = np.zeros((F, N), bool)
    wrong[60:63, [5, 7]] = True
    take.points[wrong] += [0.0, 0.0, 2.5]                                # 2.5 mm along the ray
    take.head_frame = take.points.copy()
    take = doubt_outlying_measurements(take, 40.0)
    doubted = take.assigned_blob < 0
    assert doubted[60:63, 7].all() and take.conjectured[60:63, 7].all()
    assert doubted.sum() == 3 and take.stats["doubted"].sum() == 3      # marker 5 kept, nothing else doubted
    fill_gaps(take, 40.0)
    assert np.linalg.norm(take.points[60:63, 7] - truth[60:63, 7], axis=1).max() < 0.3
    assert take.camera_mask[60, 7] == 0 and take.camera_mask[60, 5] == 7


def test_a_blobs_area_is_read_against_its_neighbours_dots():
    """capture.views.ClipDetections.area_share: a blob's area over the median of its frame's nearest blobs
    in its view, as the detector reads a typical dot. A mirror's images shrink towards the face's edge:
    a blob of two small dots' images there is twice its neighbours' area though no larger than the
    frame's median dot; a large single dot where the dots are large is one dot. Without areas: None."""
    from mirrorcap.core.capture.views import ClipDetections

    gx, gy = np.meshgrid(np.arange(10) * 10.0, np.arange(10) * 10.0)
    xy = np.c_[gx.ravel(), gy.ravel()]
    area = 20.0 - 1.3 * gx.ravel() / 10.0                              # dots shrink along the view, 20 to 8 px
    merged = 8 * 10 + 8                                                # two images run together near the edge
    area[merged] *= 2.0
    det = ClipDetections(2, [np.r_[xy, xy]], [np.r_[xy, xy] / 1000.0], [np.zeros(200, int)],
                         [np.repeat([0, 1], 100)], [np.array([0, 100, 200])], [np.r_[area, np.full(100, 10.0)]])
    share = det.area_share(0)
    assert share[merged] == pytest.approx(2.0, rel=0.05) and area[merged] < 1.3 * np.median(area[:100])
    assert np.all(np.abs(np.delete(share[:100], merged) - 1.0) < 0.2) and np.allclose(share[100:], 1.0)
    assert np.allclose(det.area_share(0, [merged, 150]), share[[merged, 150]])
    assert np.allclose(det.window(1, 2).area_share(0), 1.0)            # a window keeps its frames' areas
    assert ClipDetections(2, det.xy, det.norm, det.colour, det.frame, det.start).area_share(0) is None


def test_which_blobs_are_two_dots_images_is_read_the_same_with_or_without_the_area_shortcut():
    """stop 56: ClipDetections.merged skips the area share of a blob too small, against its frame's least typical
    area, to be two dots' images; it answers exactly as the share does, frames of fewer blobs than the neighbours
    it takes (which borrow another frame's) included, for all blobs or some."""
    from mirrorcap.core.capture.views import MERGED_SHARE, ClipDetections

    rng = np.random.default_rng(3)
    counts = np.r_[rng.integers(20, 60, 30), [3, 8, 1, 9]]                # four frames of few blobs
    F, n = counts.size, int(counts.sum())
    frame = np.repeat(np.arange(F), counts)
    xy = rng.uniform(0, 400, (n, 2))
    area = rng.uniform(6, 14, n)
    area[rng.random(n) < 0.08] *= rng.uniform(1.5, 3.0)                  # some blobs of two dots' images
    # a frame whose small dots are few: five of 4 px and two images of them run together (9 px) among large dots
    # (20 px) -- its typical area there is a small dot's, though the frame's sixth smallest blob is large
    edge = np.r_[np.full(5, 4.0), 9.0, np.full(14, 20.0)]
    edge_xy = np.r_[rng.uniform(0, 10, (6, 2)), rng.uniform(200, 400, (14, 2))]
    xy, area = np.r_[xy, edge_xy], np.r_[area, edge]
    frame, counts = np.r_[frame, np.full(edge.size, F)], np.r_[counts, edge.size]
    F, n = F + 1, n + edge.size
    start = np.r_[0, np.cumsum(counts)]
    det = ClipDetections(F, [xy], [xy / 1000.0], [np.zeros(n, int)], [frame], [start], [area])
    truth = det.area_share(0) >= MERGED_SHARE
    assert 0 < truth.sum() < n and truth[n - edge.size + 5]
    fresh = ClipDetections(F, [xy], [xy / 1000.0], [np.zeros(n, int)], [frame], [start], [area])
    some = rng.choice(n, 300, replace=False)
    assert np.array_equal(fresh.merged(0, some), truth[some]) and np.array_equal(fresh.merged(0), truth)


def test_a_single_mirror_measurement_through_a_blob_of_two_dots_images_becomes_a_conjecture():
    """#18, stop 37, dense clip: dot 192's image grazing in mirror 1 ran into its neighbour's for five
    frames at a time; the blob's centre lay between the two images and the point 1.4-2.0 mm along the
    direct ray, each frame within its neighbours' estimate (2.4 sd at most). A direct + one-mirror
    measurement through a mirror blob of MERGED_SHARE times its typical dot's area is doubted however near
    its estimate and conjectured on its neighbours' motion; one through both mirrors is kept (the two
    depths check each other), and so is everything when the detections carry no areas."""
    from mirrorcap.core.capture.views import MERGED_SHARE, ClipDetections
    from mirrorcap.core.track.candidates import ClipCandidates
    from mirrorcap.core.track.gapfill import doubt_outlying_measurements, fill_gaps

    rng = np.random.default_rng(7)
    N, F = 40, 120
    neutral, truth = _waving_face(rng, N, F)
    # one candidate per marker and frame: direct blob = mirror-0 blob = f * N + m (marker 5: mirror 1's too)
    blob = (np.arange(F)[:, None] * N + np.arange(N)[None]).reshape(-1)
    mirror = np.c_[blob, np.where(blob % N == 5, blob, -1)]
    frame = np.repeat(np.arange(F), N)
    cands = ClipCandidates(truth.reshape(-1, 3), blob, mirror, np.zeros(F * N), frame, np.arange(F + 1) * N)
    own = blob.reshape(F, N)
    area = np.full(F * N, 12.0)
    area[own[60:63, [5, 7]].ravel()] = 12.0 * MERGED_SHARE * 1.1        # markers 5 and 7: two images in one blob
    xy = np.c_[np.tile(neutral[:, :2] * 2.0, (F, 1))]                  # each frame's blobs where its dots are
    views = [xy, xy, xy]
    det = ClipDetections(F, views, [v / 1000.0 for v in views], [np.zeros(F * N, int)] * 3, [frame] * 3,
                         [np.arange(F + 1) * N] * 3, [area] * 3)

    def take_of(with_area):
        take = _labelled_take(np.ones((F, N), bool), neutral, own)
        take.points = truth + rng.normal(0, 0.05, truth.shape)
        take.points[60:63, [5, 7]] += [0.0, 0.0, 1.2]                 # 1.2 mm along the ray: under OUTLIER_MIN_MM
        take.camera_mask[:, 5] = 7                                     # marker 5 seen through both mirrors
        take.head_frame = take.points.copy()
        return doubt_outlying_measurements(take, 40.0, cands, det=det if with_area else
                                           ClipDetections(F, views, det.norm, det.colour, det.frame, det.start))

    take = take_of(True)
    doubted = take.assigned_blob < 0
    assert doubted[60:63, 7].all() and take.conjectured[60:63, 7].all() and doubted.sum() == 3
    assert take.stats["merged_images"].sum() == 3 and take.stats["doubted"].sum() == 3
    fill_gaps(take, 40.0)
    assert np.linalg.norm(take.points[60:63, 7] - truth[60:63, 7], axis=1).max() < 0.3
    assert take.camera_mask[60, 5] == 7                                # through both mirrors: kept
    plain = take_of(False)
    assert (plain.assigned_blob >= 0).all() and plain.stats["merged_images"].sum() == 0


def test_a_single_mirror_measurement_through_a_direct_blob_of_two_dots_images_is_doubted_when_off_its_estimate():
    """#18, stop 56, held-out hx4: a cheek dot found again on a clump of three like dots' images at the face's
    silhouette was measured 2.0-2.5 mm off for 13 frames, 1.1-1.8 mm from its learned relations' estimate (under
    OUTLIER_MIN_MM). A direct + one-mirror measurement through a direct blob of MERGED_SHARE times its typical dot's
    area is doubted when more than CLUMP_OFF_MM from the estimate, and kept when nearer; such measurements teach the
    relations nothing (the estimate comes from the frames the marker's own dot was measured in)."""
    from mirrorcap.core.capture.views import MERGED_SHARE, ClipDetections
    from mirrorcap.core.track.candidates import ClipCandidates
    from mirrorcap.core.track.gapfill import CLUMP_OFF_MM, OUTLIER_MIN_MM, doubt_outlying_measurements, fill_gaps

    rng = np.random.default_rng(11)
    N, F = 40, 120
    neutral, truth = _waving_face(rng, N, F)
    blob = (np.arange(F)[:, None] * N + np.arange(N)[None]).reshape(-1)
    frame = np.repeat(np.arange(F), N)
    cands = ClipCandidates(truth.reshape(-1, 3), blob, np.c_[blob, np.full(F * N, -1)], np.zeros(F * N), frame,
                           np.arange(F + 1) * N)
    own = blob.reshape(F, N)
    direct_area, mirror_area = np.full(F * N, 12.0), np.full(F * N, 12.0)
    direct_area[own[60:66, [7, 9]].ravel()] = 12.0 * MERGED_SHARE * 1.2     # a clump in the direct view only
    xy = np.tile(neutral[:, :2] * 2.0, (F, 1))
    det = ClipDetections(F, [xy] * 3, [xy / 1000.0] * 3, [np.zeros(F * N, int)] * 3, [frame] * 3,
                         [np.arange(F + 1) * N] * 3, [direct_area, mirror_area, mirror_area])
    take = _labelled_take(np.ones((F, N), bool), neutral, own)
    take.points = truth + rng.normal(0, 0.05, truth.shape)
    off = 0.5 * (CLUMP_OFF_MM + OUTLIER_MIN_MM)
    take.points[60:66, 7] += [0.0, 0.0, off]                            # off its estimate, under OUTLIER_MIN_MM
    take.points[60:66, 9] += [0.0, 0.0, 0.5 * CLUMP_OFF_MM]             # a clump's measurement near its estimate
    take.head_frame = take.points.copy()
    take = doubt_outlying_measurements(take, 40.0, cands, det=det)
    doubted = take.assigned_blob < 0
    assert doubted[60:66, 7].all() and take.conjectured[60:66, 7].all()
    assert doubted.sum() == 6 and take.stats["doubted"].sum() == 6 and take.stats["merged_images"].sum() == 6
    fill_gaps(take, 40.0)
    assert np.linalg.norm(take.points[60:66, 7] - truth[60:66, 7], axis=1).max() < 0.3
    plain = _labelled_take(np.ones((F, N), bool), neutral, own)          # the same take, no areas: nothing doubted
    plain.points = take.points.copy()
    plain.points[60:66, 7] = truth[60:66, 7] + [0.0, 0.0, off]
    plain.head_frame = plain.points.copy()
    plain = doubt_outlying_measurements(plain, 40.0, cands, det=ClipDetections(F, det.xy, det.norm, det.colour,
                                                                               det.frame, det.start))
    assert (plain.assigned_blob >= 0).all()


def test_a_measurement_its_neighbours_disown_is_re_paired_onto_its_dots_own_image():
    """#18, dense clip: dot 268's marker took a mirror blob of two grazing images merged (2.1 mm off)
    while the dot's own image lay in the band beside it. A direct + one-mirror measurement more than
    REPAIR_SD of its estimate's sd off the learned relations' estimate moves to the candidate of its
    direct blob that puts it within half that distance (and REPAIR_SD sd) -- unless another marker
    takes that candidate's mirror blob in the frame; then it is doubted as before."""
    from mirrorcap.core.track.candidates import ClipCandidates
    from mirrorcap.core.track.gapfill import doubt_outlying_measurements

    rng = np.random.default_rng(6)
    N, F = 40, 120
    neutral, truth = _waving_face(rng, N, F)
    measured_points = truth + rng.normal(0, 0.05, truth.shape)
    # candidates: per frame one per marker (direct blob = mirror-0 blob = f * N + m), then marker 7's rival
    # in frames 60-62: its direct blob with another mirror blob at the true point (frame 62: marker 3's blob)
    points, direct, mirror, frame = [], [], [], []
    for f in range(F):
        points.append(measured_points[f]), direct.append(f * N + np.arange(N)), frame.append(np.full(N, f))
        mirror.append(np.c_[f * N + np.arange(N), np.full(N, -1)])
        if 60 <= f <= 62:
            points.append(measured_points[f, 7:8]), direct.append([f * N + 7]), frame.append([f])
            mirror.append([[f * N + 3 if f == 62 else F * N + f, -1]])
    points, direct, frame = np.concatenate(points), np.concatenate(direct), np.concatenate(frame)
    cands = ClipCandidates(points, direct, np.concatenate(mirror), np.zeros(len(direct)), frame,
                           np.searchsorted(frame, np.arange(F + 1)))
    own = np.searchsorted(frame, np.arange(F))[:, None] + np.arange(N)[None]    # (F, N) each marker's candidate
    take = _labelled_take(np.ones((F, N), bool), neutral, own)
    take.points = measured_points.copy()
    take.points[60:63, 7] += [0.0, 0.0, 2.5]                              # the merged image: 2.5 mm along the ray
    take.head_frame = take.points.copy()
    take = doubt_outlying_measurements(take, 40.0, cands)
    assert take.stats["repaired"].sum() == 2 and take.stats["doubted"].sum() == 1
    assert (take.candidate[60:62, 7] == cands.start[60:62] + N).all()      # the rival candidates
    assert np.linalg.norm(take.points[60:62, 7] - truth[60:62, 7], axis=1).max() < 0.3
    assert (take.assigned_blob[60:62, 7] >= 0).all() and not take.conjectured[60:62, 7].any()
    assert take.assigned_blob[62, 7] < 0 and take.conjectured[62, 7]      # its rival's blob is marker 3's
    assert take.camera_mask[60, 7] == 3
    both = _labelled_take(np.ones((4, 3), bool), neutral[:3], np.arange(12).reshape(4, 3))
    both.camera_mask[:] = 7                                              # every measurement through both mirrors
    both = doubt_outlying_measurements(both, 40.0, cands)
    assert both.stats["repaired"].tolist() == [0] * 4 and both.stats["doubted"].tolist() == [0] * 4


def test_coverage_of_a_take_counts_frames_with_dots_and_names_sizes_only_when_known():
    """core.track.coverage: the share is a median over the frames whose direct view shows a dot (a frame without
    one does not drag it to 0), the warning comes under MIN_MEASURED_SHARE only, and detections without areas (the
    add-on's 2D tracks) give no sizes rather than made-up ones."""
    from mirrorcap.core.capture.views import ClipDetections, FrameDets
    from mirrorcap.core.geometry.camera import Camera
    from mirrorcap.core.track.coverage import MIN_MEASURED_SHARE, coverage_warning, take_coverage

    camera = Camera.ideal(1000.0, (640, 480))
    xy = np.c_[np.arange(10) * 20.0 + 100, np.full(10, 240.0)]

    def frames(n_direct, with_area):
        out = []
        for n in n_direct:
            area = dict(direct_area=np.full(n, 12.0), mirror_area=[np.full(4, 7.0), np.full(3, 7.0)]) if with_area \
                else {}
            out.append(FrameDets(xy[:n], np.zeros(n, int), [xy[:4], xy[:3]], [np.zeros(4, int), np.zeros(3, int)],
                                 **area))
        return out

    det = ClipDetections.of(frames([10, 0, 0, 0, 10], True), camera)   # three frames show no dot
    measured = np.zeros((5, 12), bool)
    measured[[0, 4], :2] = True                              # 2 of 10 direct dots measured: 20 %
    cov = take_coverage(det, measured)
    assert cov["measured_share"] == pytest.approx(0.2) and cov["direct_dots"] == 10 and cov["mirror_dots"] == [4, 3]
    assert cov["enough"] is False and cov["dot_px"][0] == pytest.approx(2 * np.sqrt(12 / np.pi))
    text = coverage_warning(cov)
    assert "measures 2 of the 10 dots" in text and "3.9 px across in the direct view, 3.0 and 3.0 px" in text
    measured[[0, 4], :int(np.ceil(10 * MIN_MEASURED_SHARE))] = True
    assert coverage_warning(take_coverage(det, measured)) is None
    bare = ClipDetections.of(frames([10, 10], False), camera)
    cov = take_coverage(bare, np.zeros((2, 12), bool))
    assert cov["dot_px"] == [None, None, None] and "the dots measure" not in coverage_warning(cov)


def test_a_frame_out_of_place_is_left_out_and_a_jump_is_followed(performance, tmp_path):
    """Stop 44. A frame from another moment of the take (a glitch: frame 10's detections at frame 40) had the
    tracker follow the face there and lose most markers for the rest of the take (43 identity switches, 105 of
    208 markers measured a frame at its end): the head is looked for where the frame's conflicts jump
    (:func:`core.track.relocate.relocate_head`), and a frame whose face is back where it was in the next frame is
    left out. A take that jumps and stays (60 frames cut out of a 300-frame performance: the face 6.4 mm away) had
    500 switches; the head found again at the jump, 100 (the rendered 600-frame bench take with 100 frames cut
    out: 263 -> 0)."""
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=1, performance=perf, noise_px=0.05)
    glitched = list(frames)
    glitched[40] = frames[10]
    result = track(glitched, rig.camera, rig.planes)
    assert np.flatnonzero(result.stats["out_of_place"]).tolist() == [40]
    # left out by the passes (the dots followed through gaps take up a few of its blobs, each on its own dot)
    assert result.stats["measured"][40] < 0.2 * result.stats["measured"][39]
    assert np.all(result.stats["measured"][41:] > 0.9 * result.stats["measured"][39])
    s = _score(glitched, perf, result)
    assert s["switches"] == 0 and s["rms"] < 0.1
    from mirrorcap.core.track.pipeline import track_detections

    from mirrorcap.core.geometry.mirror import MirrorPlane

    planes = [MirrorPlane(normal=np.asarray(n, float), d=float(d)) for n, d in rig.planes]
    report = track_detections(list(range(80)), glitched, rig.camera, 30.0, tmp_path / "t.c3d", mirrors=planes)
    said = [w for w in report["warnings"] if w.startswith("the face jumps in the video")]
    assert len(said) == 1 and "frame(s) 40 show(s) it elsewhere" in said[0], report["warnings"]
    long_perf = rig_performance(rig, 300, head_motion_deg=10, expression_mm=5)
    _, frames = synthetic_detections(rig, 300, seed=1, performance=long_perf, noise_px=0.05)
    keep = np.r_[np.arange(100), np.arange(160, 300)]
    result = track([frames[i] for i in keep], rig.camera, rig.planes)
    assert np.flatnonzero(result.stats["relocated"]).tolist() == [100]
    s = _score([frames[i] for i in keep], tuple(np.asarray(x)[keep] for x in long_perf), result)
    assert s["switches"] <= 150 and s["rms"] < 0.8
