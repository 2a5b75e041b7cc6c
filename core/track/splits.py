"""Split labels merged back (Lin 2003, section 5.8, offline, after the final pass): one dot tracked under two labels
-- lost and picked up again later as a new chain -- becomes one marker, by its learned neighbour relations
(:func:`merge_split_labels`) or by the 2D tracks that follow its dot through the gap (:func:`merge_along_2d_tracks`);
:func:`merge_labels` does the merging for both and for :mod:`.singleview`."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .motion import RELATION_CORRELATION, conjecture_gaps, neighbours
from .result import TrackResult, TrackSettings


MERGE_MM = 1.0          # a later chain continues a marker when it lies this near the marker's conjecture
# (the takes' conjectures are 0.2-0.3 mm RMS off where measured: 1 mm is over 3 sigma)
MERGE_SEARCH_MM = 15.0  # ... among the markers whose neutral positions lie this near
#: in place of MERGE_MM, how near the earlier label's conjecture must lie when the two labels are the only ones
#: measured on one direct-view 2D track (merge_split_labels): the held-out hx4's chin dot was lost through mirror 0
#: at frame 35 and found again at frame 60 on the same direct track with a new mirror track, under a second label;
#: over the 30 frames of a fast expression the first label's conjecture lay 1.07 mm (median) from the second's points
SOLE_TRACK_MERGE_MM = 2.0


def measured_together(measured) -> np.ndarray:
    """``(N, N)`` bool: which labels are measured in the same frame somewhere (``measured (F, N)``)
    -- two such labels are two dots, never a split of one (one matrix product; float for BLAS)."""
    m = np.asarray(measured, np.float32)
    return (m.T @ m) > 0.5


def merge_split_labels(result: TrackResult, s: TrackSettings, direct_track=None) -> TrackResult:
    """Offline, a marker picked up again later as a new chain (a *split*: one dot, two labels) is
    merged back. Two labels that are never measured in the same frame, whose neutral positions lie
    within :data:`MERGE_SEARCH_MM`, where the earlier one's conjecture at the later one's measured
    frames (the learned neighbour relations of :func:`.gapfill.fill_gaps`, eq. 5.8) lies within
    :data:`MERGE_MM` of them (median), and no other label comes within twice that: the later chain's
    measurements become the earlier marker's. With ``direct_track`` (each clip candidate's direct-view 2D track,
    :func:`.pairing.candidate_tracks`), two such labels that are the only ones measured on one direct track
    (:func:`_shared_track_pairs`) merge within :data:`SOLE_TRACK_MERGE_MM`: the direct view followed one dot
    from one label to the other, and a fast expression's conjecture drifts further."""
    measured = result.assigned_blob >= 0
    F, N = measured.shape
    if N < 3:
        return result
    sole_track = set(_shared_track_pairs(result, direct_track)) if direct_track is not None else set()
    motion = result.head_frame - result.neutral[None]
    first = np.where(measured.any(axis=0), np.argmax(measured, axis=0), F)
    nidx, _ = neighbours(result.neutral, s.neighbour_radius_mm)
    near, _ = neighbours(result.neutral, MERGE_SEARCH_MM)
    together = measured_together(measured)
    pairs = []
    for b in np.flatnonzero(measured.sum(axis=0) >= s.min_measured_frames):
        cands = [a for a in near[b] if a >= 0 and first[a] < first[b] and not together[a, b]]
        if not cands:
            continue
        gaps = np.zeros((F, N), bool)
        gaps[np.ix_(measured[:, b], cands)] = True
        est, _ = conjecture_gaps(motion, measured, gaps, nidx[:, :12], 1.0, s.min_measured_frames,
                                 correlation=RELATION_CORRELATION)
        frames = np.flatnonzero(measured[:, b])
        d = np.array([np.nanmedian(np.linalg.norm(result.neutral[a] + est[frames, a] - result.head_frame[frames, b],
                                                  axis=1)) if np.isfinite(est[frames, a, 0]).any() else np.inf
                      for a in cands])
        order = np.argsort(d)
        if d[order[0]] <= MERGE_MM and (d.size == 1 or d[order[1]] > 2.0 * MERGE_MM):
            pairs.append((cands[order[0]], b))
            continue
        on_track = [i for i, a in enumerate(cands) if (a, b) in sole_track and d[i] <= SOLE_TRACK_MERGE_MM]
        if on_track:
            pairs.append((cands[on_track[0]], b))
    return merge_labels(result, pairs)


def merge_along_2d_tracks(result: TrackResult, tracks, direct_frames=None) -> TrackResult:
    """Offline, labels of one dot merged where the 2D tracks say so (:func:`.pairing.track_2d`, per
    view over the clip; ``tracks``: :func:`.pairing.candidate_tracks`, each clip candidate's direct
    track ``(C,)`` and track per mirror ``(C, K)``, -1 none; None: nothing merged). Two labels never
    measured in the same frame, whose neutral positions lie within :data:`MERGE_SEARCH_MM`, are one
    dot when

    1. they measure the same pair of 2D tracks -- the direct view's and a mirror's -- and no other
       label does (:func:`_shared_track_pairs`): a chin dot that moves 4-8 mm a frame along the
       line of sight during a fast jaw opening is lost and found again by turns, under two
       labels, while both views follow it; or
    2. the earlier label's last measurement before the later label's first and that first
       measurement sit on one unbroken 2D track of the same mirror, no label measures that track
       in between, and only one earlier label ends on it. Such a gap is the direct view's alone --
       a lower lip behind the upper one while the mouth moves sideways 8 mm in as many frames,
       which the neighbour relations cannot follow. Unless the direct view followed the earlier
       label's dot on to another blob in the later label's first frame (``direct_frames``:
       :func:`.pairing.direct_track_frames`): grazing in a mirror, two dots 11 mm apart image a
       pixel or two apart and one mirror track can run from one to the other."""
    cand = result.candidate
    if cand is None or tracks is None or len(tracks[0]) == 0:
        return result
    result = merge_labels(result, _shared_track_pairs(result, *tracks))
    cand, (direct_track, mirror_track) = result.candidate, tracks
    measured = (result.assigned_blob >= 0) & (cand >= 0)
    F, N = measured.shape
    K = mirror_track.shape[1]
    track = np.where(measured[..., None], mirror_track[np.maximum(cand, 0)], -1)   # (F, N, K)
    near, _ = neighbours(result.neutral, MERGE_SEARCH_MM)
    together = measured_together(measured)
    first = np.where(measured.any(axis=0), np.argmax(measured, axis=0), F)
    pairs = []
    for b in np.flatnonzero((first > 0) & (first < F)):
        fb = first[b]
        found = set()
        for k in range(K):
            tk = track[fb, b, k]
            if tk < 0:
                continue
            before = track[:fb, :, k] == tk                        # (fb, N): labels on the track earlier
            ended = [a for a in np.flatnonzero(before.any(axis=0)) if a != b]
            for a in ended:
                fa = np.flatnonzero(measured[:fb, a])[-1]           # a's last measurement before b's first
                if track[fa, a, k] != tk or together[a, b] or a not in near[b]:
                    continue
                if (track[fa + 1:fb, :, k] == tk).any():           # someone measured the track in between
                    continue
                if direct_frames is not None and _direct_view_follows_on(direct_track, direct_frames, cand,
                                                                         a, fa, b, fb, F):
                    continue
                found.add(int(a))
        if len(found) == 1:
            pairs.append((found.pop(), int(b)))
    return merge_labels(result, pairs)


def _direct_view_follows_on(direct_track, direct_frames, cand, a, fa, b, fb, F) -> bool:
    """Whether label ``a``'s direct 2D track at its frame ``fa`` has a blob in frame ``fb`` that is
    not on label ``b``'s direct track there (the dot went on elsewhere; rule 2's veto)."""
    ta, tb = direct_track[cand[fa, a]], direct_track[cand[fb, b]]
    if ta < 0 or ta == tb:
        return False
    code = np.int64(ta) * F + fb
    at = np.searchsorted(direct_frames, code)
    return bool(at < direct_frames.size and direct_frames[at] == code)


def _shared_track_pairs(result: TrackResult, direct_track, mirror_track=None) -> list:
    """``(earlier, later)`` label pairs of :func:`merge_along_2d_tracks`, rule 1: the two labels
    are the only ones measured on some (direct track, mirror track) pair (``mirror_track`` None: on some direct
    track), never in the same frame, their neutral positions within :data:`MERGE_SEARCH_MM`; a label that would
    merge with two others is left alone."""
    cand = result.candidate
    measured = (result.assigned_blob >= 0) & (cand >= 0)
    N = measured.shape[1]
    f, m = np.nonzero(measured)
    c = cand[f, m]
    if mirror_track is None:
        keys, labels = [direct_track[c].astype(np.int64)], [m]
    else:
        K = mirror_track.shape[1]
        n_direct = int(direct_track.max(initial=-1)) + 1
        keys, labels = [], []
        for k in range(K):
            on = (mirror_track[c, k] >= 0) & (direct_track[c] >= 0)
            keys.append((mirror_track[c[on], k].astype(np.int64) * n_direct + direct_track[c[on]]) * K + k)
            labels.append(m[on])
    # the distinct (key, label) pairs, sorted by key, then label: one int64 each (a 1D unique, not a row unique)
    key_label = np.unique(np.concatenate(keys) * N + np.concatenate(labels))
    key, label = np.divmod(key_label, N)
    _, first_row, n_labels = np.unique(key, return_index=True, return_counts=True)
    two = first_row[n_labels == 2]                           # exactly two labels on the track pair
    if two.size == 0:
        return []
    a, b = label[two], label[two + 1]
    first = np.argmax(measured, axis=0)
    together = measured_together(measured)
    close = np.linalg.norm(result.neutral[a] - result.neutral[b], axis=1) <= MERGE_SEARCH_MM
    ok = ~together[a, b] & close
    early = np.where(first[a] <= first[b], a, b)[ok]
    late = np.where(first[a] <= first[b], b, a)[ok]
    pairs = np.unique(np.c_[early, late], axis=0)
    count = np.bincount(pairs.ravel(), minlength=N)
    return [(int(x), int(y)) for x, y in pairs if count[x] == 1 and count[y] == 1]


def merge_labels(result: TrackResult, pairs) -> TrackResult:
    """Each ``(a, b)`` of ``pairs``: label ``b``'s measurements become label ``a``'s and ``b`` goes
    (two labels of one dot, never measured in the same frame); a label already merged away is
    skipped. ``stats["merged_labels"]`` counts the labels gone."""
    measured = result.assigned_blob >= 0
    result.stats["merged_labels"] = result.stats.get("merged_labels", np.zeros(1, int)).copy()
    if not pairs:
        return result
    N = measured.shape[1]
    keep = np.ones(N, bool)
    for a, b in pairs:
        if not keep[a] or not keep[b]:
            continue
        take = measured[:, b]
        for name in ("points", "head_frame"):
            getattr(result, name)[take, a] = getattr(result, name)[take, b]
        result.assigned_blob[take, a] = result.assigned_blob[take, b]
        result.camera_mask[take, a] = result.camera_mask[take, b]
        result.conjectured[take, a] = False
        if result.candidate is not None:
            result.candidate[take, a] = result.candidate[take, b]
        keep[b] = False
    result.stats["merged_labels"] = result.stats["merged_labels"] + int((~keep).sum())
    idx = np.flatnonzero(keep)
    out = replace(result, labels=[result.labels[i] for i in idx], points=result.points[:, idx],
                  conjectured=result.conjectured[:, idx], camera_mask=result.camera_mask[:, idx],
                  neutral=result.neutral[idx], first_blob=result.first_blob[idx],
                  assigned_blob=result.assigned_blob[:, idx], colour=result.colour[idx],
                  head_frame=result.head_frame[:, idx],
                  candidate=None if result.candidate is None else result.candidate[:, idx])
    if result.rigid is not None:
        remap = -np.ones(N, int)
        remap[idx] = np.arange(idx.size)
        out.rigid = remap[np.asarray(result.rigid)][remap[np.asarray(result.rigid)] >= 0]
    return out
