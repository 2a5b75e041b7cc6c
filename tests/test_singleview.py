"""Conjectured markers measured where their dot is seen after all (core.track.singleview):
one view refines a conjecture along its ray, two views measure a cell the passes left."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.tracking import score
from mirrorcap.core.track.tracker import TrackSettings, track
from mirrorcap.synthetic.simulate import face_rig, rig_performance, synthetic_detections


@pytest.fixture(scope="module")
def performance():
    rig = face_rig(n_markers=300, seed=3, layout="even")
    return rig, rig_performance(rig, 80, head_motion_deg=10, expression_mm=5)


def _without_mirror_images(frames, markers, first, last):
    """Drop the mirror images of ``markers`` in frames ``first..last-1`` (a cheek hides them)."""
    for f in frames[first:last]:
        for k in range(len(f.mirror)):
            keep = ~np.isin(f.mirror_id[k], markers)
            f.mirror[k], f.mirror_color[k], f.mirror_id[k] = f.mirror[k][keep], f.mirror_color[k][keep], f.mirror_id[k][keep]


def test_a_marker_seen_in_the_direct_view_only_is_refined_along_its_ray(performance):
    """A patch of twenty markers loses both mirror images for 30 frames mid-take while the face moves: the
    passes conjecture them from their neighbours; their direct-view dots then fix them across
    the ray, so they land nearer the truth, and they stay flagged as conjectures."""
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=7, performance=perf, noise_px=0.1)
    # a patch of neighbours (a cheek over their mirror images): the conjectures come from further off
    seen = rig.visible_direct & rig.visible_mirror.any(axis=0)
    cheek = np.percentile(rig.points[seen], [75, 50, 50], axis=0).diagonal()
    centre = rig.points[seen][np.argmin(np.linalg.norm(rig.points[seen] - cheek, axis=1))]
    hidden = np.argsort(np.linalg.norm(rig.points - centre, axis=1))[:20]
    _without_mirror_images(frames, hidden, 30, 60)
    off = track(frames, rig.camera, rig.planes, TrackSettings(single_views=False))
    on = track(frames, rig.camera, rig.planes)
    s_off, s_on = score(frames, perf, off), score(frames, perf, on)
    ids = s_on["ids"]
    assert np.array_equal(ids, s_off["ids"]) and s_on["identity_switches"] == 0
    labels = np.flatnonzero(np.isin(ids, hidden))
    assert labels.size >= 15
    cells = np.zeros(off.conjectured.shape, bool)
    cells[30:60, labels] = True
    cells &= off.conjectured
    assert cells.sum() > 300
    assert on.conjectured[cells].all() and (on.camera_mask[cells] == 0).all()   # still conjectures
    # refined: the point lies on the ray of a direct-view blob (its image on the blob)
    from scipy.spatial import cKDTree

    refined = np.zeros_like(cells)
    for t in np.unique(np.nonzero(cells)[0]):
        m = np.flatnonzero(cells[t])
        refined[t, m] = cKDTree(frames[t].direct).query(rig.camera.project(on.points[t, m]))[0] < 0.01
    assert refined.sum() > 0.95 * cells.sum()                                      # measured 434 of 435
    cells = refined
    truth = perf[0][:, ids][cells]
    ray = truth / np.linalg.norm(truth, axis=1, keepdims=True)

    def along_and_across(points):
        e = points[cells] - truth
        along = np.sum(e * ray, axis=1)
        return np.sqrt(np.mean(along ** 2)), np.sqrt(np.mean(np.sum((e - along[:, None] * ray) ** 2, axis=1)))

    along_off, across_off = along_and_across(off.points)
    along_on, across_on = along_and_across(on.points)
    # across the ray the dot's image fixes the point -- to the detections' noise, 0.1 px per axis --
    # where the conjecture was off by its own error; along the ray the depth is still the conjecture's
    noise_mm = 0.1 * np.sqrt(2.0) * np.median(truth[:, 2]) / rig.camera.focal_px
    # (the conjectures themselves lay 0.114 mm off across the ray before stop 37 and 0.078 mm since: each relation
    # now meets the marker's measurements on its own, motion.conjecture_gaps; the refinement gives 0.053 either way)
    assert across_on < 1.2 * noise_mm and across_on < 0.75 * across_off, (noise_mm, across_off, across_on)
    assert abs(along_on - along_off) < 0.2 * along_off + 0.01, (along_off, along_on)
    print(f"across the ray {across_off:.3f} -> {across_on:.3f} mm (noise {noise_mm:.3f}), along {along_off:.3f} -> "
          f"{along_on:.3f} mm")
    assert on.stats["measured_in_one_view"].sum() >= cells.sum()


def test_two_views_measure_what_the_passes_left_with_the_markers_own_blobs(performance):
    """A quarter of the detections missing: where the passes lost a marker whose dot is back in
    the direct view and a mirror, its dots followed from the ends of the gap, or found at its
    conjecture's image, measure it by two rays -- its own blobs, the measurement as good as the
    passes' -- including cells whose conjecture had been withheld."""
    rig, perf = performance
    _, frames = synthetic_detections(rig, 80, seed=6, performance=perf, noise_px=0.1, missing=0.25,
                                     false_blobs=0.2)
    off = track(frames, rig.camera, rig.planes, TrackSettings(single_views=False))
    on = track(frames, rig.camera, rig.planes)
    s_off, s_on = score(frames, perf, off), score(frames, perf, on)
    ids = s_on["ids"]
    assert s_on["identity_switches"] == 0 and s_on["duplicates"] == 0
    two = (off.assigned_blob < 0) & (on.assigned_blob >= 0)
    followed = on.stats["followed_through_gaps"].sum()
    found = on.stats["measured_in_two_views_after_gap_fill"].sum()
    assert two.sum() == followed + found and followed > 30 and found > 0          # measured 92 and 7
    assert (two & np.isnan(off.points[..., 0])).sum() > 0                               # withheld before
    f, i = np.nonzero(two)
    own = np.array([frames[t].direct_id[b] for t, b in zip(f, on.assigned_blob[f, i])])
    assert np.array_equal(own, ids[i])
    assert not on.conjectured[two].any() and (on.camera_mask[two] & 1).all()
    assert ((on.camera_mask[two] & 6) > 0).all()
    err = np.linalg.norm(on.points - perf[0][:, ids], axis=2)[two]
    assert np.sqrt(np.mean(err ** 2)) < 0.15 and err.max() < 0.3
    print(f"{followed} followed, {found} found at the conjecture; RMS {np.sqrt(np.mean(err ** 2)):.3f}, max {err.max():.3f} mm")
    assert s_on["reported_of_visible"] > s_off["reported_of_visible"]
    # the passes' own measurements are untouched: a cell may differ only where the gap fill re-paired it
    # onto another mirror image of its direct blob in one of the runs (its relations, learned from the
    # take's measurements, differ once the single views added theirs; stop 36: one cell, which the run
    # without single views re-paired onto both mirrors 0.73 mm off, the pass's own 0.09 mm)
    kept = off.assigned_blob >= 0
    assert np.array_equal(on.assigned_blob[kept], off.assigned_blob[kept])
    moved = kept & ~np.all(np.isclose(on.points, off.points), axis=2)
    repaired = on.stats["repaired"] + off.stats["repaired"]
    assert moved.sum() <= repaired.sum() and np.all(repaired[np.flatnonzero(moved.any(axis=1))] > 0)
    assert not np.any(on.candidate[moved] == off.candidate[moved])
