"""The tracker's offline gap filling (Lin 2003, eq. 5.8, with the whole take known): every gap of a
tracked take conjectured from the marker's learned neighbour relations, met with its measurements at
both ends, and withheld where it is expected too far off (:func:`fill_gaps`); before it, measurements
those relations say are wrongly paired, and those through a mirror blob of two dots' images, are made gaps
(:func:`doubt_outlying_measurements`)."""

from __future__ import annotations

import numpy as np

from ..geometry.rigid import rotation_zyx
from .motion import (RELATION_CORRELATION, RELATION_PRIOR_VAR, conjecture_gaps, grown_sd, learned_conjectures,
                     neighbours, previous_and_next)
from .result import TrackResult, camera_mask_of


#: a measurement from the direct view and one mirror further from its learned neighbour relations' estimate than
#: this many of the estimate's sd (and than OUTLIER_MIN_MM) is doubted: a gap for the gap fill. Over 18 clips,
#: points over 2 mm 215 -> 193 (dense 8 -> 2, close 6 -> 2, lip648 8 -> 4), no clip worse, completeness the same;
#: at 3 or 3.5 sd the jaw clip's wide jaw motion gets 5-6 points over 2 mm where it had none
OUTLIER_SD = 4.0
OUTLIER_MIN_MM = 1.5
#: ... and one more than this many sd (and REPAIR_MIN_MM) off is first re-paired where its direct blob has another
#: mirror blob in the band, unclaimed, that puts the point within half the distance and REPAIR_SD of the estimate
#: (dense: the dot's own image beside the merged one it had taken). Over 18 clips points over 2 mm 193 -> 175
#: (dense 2 -> 1, yaw540 5 -> 0, tilt630 65 -> 59), no clip worse, about 25 measurements re-paired; the same
#: at 1.5 sd
REPAIR_SD = 2.0
REPAIR_MIN_MM = 1.0
#: a measurement from the direct view and one mirror whose direct blob holds two dots' images or more (a clump of
#: like dots at the face's silhouette: its centre lies between them) teaches the neighbour relations nothing, and is
#: doubted when it lies this far from their estimate: held-out hx4's cheek dot, found again on a clump of three
#: like dots' images at the silhouette, was measured 2.0-2.5 mm off for 13 frames, 1.1-1.8 mm from the estimate
#: (hx4 46 -> 38 points over 2 mm). Over the 48 committed clips that track, points over 2 mm 649 -> 616 (ruddy540
#: 9 -> 3, umber600 at CRF 23 47 -> 41, blur540n 17 -> 13), RMS lower on 36, no clip worse in either
CLUMP_OFF_MM = 1.0


def doubt_outlying_measurements(result: TrackResult, radius_mm: float, cands=None, learned_neighbours: int = 12,
                                ridge_mm2: float = 1.0, min_frames: int = 10, det=None) -> TrackResult:
    """A measurement from the direct view and one mirror is only as good as its pairing: the mirror
    blob may be another dot's image on the same epipolar band (two grazing images merged, or a
    neighbour's image beside the dot's hidden one), which puts the point 2-3 mm along the direct
    ray, a move no neighbour makes. Each such measurement is compared with the marker's motion
    estimated from its neighbours measured in the same frame (eq. 5.8, the relations learned over
    the take, :func:`core.track.motion.learned_conjectures`); one further than :data:`OUTLIER_SD`
    of the estimate's sd (at least :data:`OUTLIER_MIN_MM`) becomes a gap, which :func:`fill_gaps`
    conjectures. Measurements through both mirrors check themselves (their two depths agree,
    :func:`.candidates.clip_candidates`) and are kept. Before that, with the clip's candidates
    ``cands`` (:class:`.candidates.ClipCandidates`), one more than :data:`REPAIR_SD` sd off is
    re-paired where another candidate of its direct blob -- a mirror blob in the band that no other
    marker takes in the frame -- lies within half its distance of the estimate and within
    :data:`REPAIR_SD` sd (:func:`_repair_from_rivals`). With the clip's detections ``det`` (and their
    areas), a measurement through a mirror blob of two dots' images (:data:`..capture.views.MERGED_SHARE`
    times its typical dot's area) is doubted whatever its distance (:func:`through_merged_blob`), and one through
    such a direct-view blob (a clump of like dots at the silhouette) teaches
    the relations nothing and is doubted beyond :data:`CLUMP_OFF_MM` of the estimate. In place;
    ``stats["doubted"]`` and ``stats["repaired"]`` count the measurements doubted and re-paired per frame,
    ``stats["merged_images"]`` the doubted ones through such a blob, in a mirror or the direct view."""
    measured = result.assigned_blob >= 0
    single = (result.camera_mask == 3) | (result.camera_mask == 5)  # direct and one mirror
    result.stats["doubted"] = np.zeros(measured.shape[0], int)
    result.stats["repaired"] = np.zeros(measured.shape[0], int)
    result.stats["merged_images"] = np.zeros(measured.shape[0], int)
    rows = np.flatnonzero((measured & single).any(axis=0))
    if rows.size == 0:
        return result
    motion = result.head_frame - result.neutral[None]
    nidx, _ = neighbours(result.neutral, radius_mm)
    clump = (through_merged_blob(result, det, cands, measured & single, direct=True) if det is not None
             and cands is not None else np.zeros(measured.shape, bool))     # a clump of like dots' direct images
    estimate, var = learned_conjectures(motion, measured & ~clump, nidx[:, :learned_neighbours], rows, ridge_mm2,
                                        min_frames, correlation=RELATION_CORRELATION, prior_var=RELATION_PRIOR_VAR)
    off = np.linalg.norm(motion[:, rows] - estimate, axis=2)                 # (F, P), NaN where no estimate
    sd = np.sqrt(var)
    if cands is not None:
        with np.errstate(invalid="ignore"):
            f, p = np.nonzero((measured & single)[:, rows] & (off > np.maximum(REPAIR_MIN_MM, REPAIR_SD * sd)))
        fixed = _repair_from_rivals(result, cands, f, rows[p], result.neutral[rows[p]] + estimate[f, p], off[f, p],
                                    sd[f, p])
        off[f[fixed], p[fixed]] = 0.0                                        # re-paired: near the estimate
        single = (result.camera_mask == 3) | (result.camera_mask == 5)
        np.add.at(result.stats["repaired"], f[fixed], 1)
    with np.errstate(invalid="ignore"):
        doubt = (measured & single)[:, rows] & (off > np.maximum(OUTLIER_MIN_MM, OUTLIER_SD * sd))
    if det is not None and cands is not None:
        with np.errstate(invalid="ignore"):
            merged = through_merged_blob(result, det, cands, measured & single)[:, rows] | (
                clump[:, rows] & (off > CLUMP_OFF_MM))
        result.stats["merged_images"] = merged.sum(axis=1)
        doubt |= merged
    f, p = np.nonzero(doubt)
    m = rows[p]
    result.assigned_blob[f, m] = -1
    result.camera_mask[f, m] = 0
    if result.candidate is not None:
        result.candidate[f, m] = -1
    result.conjectured[f, m] = True
    result.head_frame[f, m] = result.neutral[m] + estimate[f, p]             # a gap: fill_gaps conjectures it
    result.stats["doubted"] = doubt.sum(axis=1)
    return result


def through_merged_blob(result: TrackResult, det, cands, cells, direct: bool = False) -> np.ndarray:
    """``(F, N)``: which of the measurements ``cells`` ``(F, N)`` take, through their candidate
    (``result.candidate``, into the clip's candidates ``cands``), a mirror blob of two dots' images -- with
    ``direct``, a direct-view blob of two dots' images or more -- (:meth:`..capture.views.ClipDetections.merged`);
    all False without areas."""
    out = np.zeros(result.assigned_blob.shape, bool)
    if det.area is None or result.candidate is None:
        return out
    f, m = np.nonzero(cells & (result.candidate >= 0))
    if direct:
        out[f, m] = det.merged(0, cands.direct[result.candidate[f, m]])
        return out
    blob = cands.mirror_blob[result.candidate[f, m]]                           # (n, K), -1: not in that mirror
    for k in range(blob.shape[1]):
        has = blob[:, k] >= 0
        out[f[has], m[has]] |= det.merged(k + 1, blob[has, k])
    return out


def _repair_from_rivals(result: TrackResult, cands, frames, markers, expected_head, off, sd) -> np.ndarray:
    """Re-pair the measurements ``(frames, markers)`` -- ``off`` mm from their ``expected_head``
    positions (head frame), ``sd`` their estimate's sd -- onto another candidate of the same
    direct blob whose mirror blobs no other marker takes in that frame, where the best such lies
    within half of ``off`` and :data:`REPAIR_SD` ``sd`` of the expected position. Updates the
    result's candidate, points, head frame and camera mask in place; returns which were re-paired.
    A loop over the few cells a take has this far off (tens)."""
    K = cands.mirror_blob.shape[1]
    fixed = np.zeros(len(frames), bool)
    for n, (f, m) in enumerate(zip(frames, markers)):
        own = result.candidate[f, m]
        if own < 0:
            continue
        block = cands.at(f)                                                       # the frame's candidates
        rival = np.flatnonzero(cands.direct[block] == cands.direct[own]) + block.start
        rival = rival[rival != own]
        taken = result.candidate[f][(result.candidate[f] >= 0) & (np.arange(result.candidate.shape[1]) != m)]
        for k in range(K):
            blob = cands.mirror_blob[rival, k]
            rival = rival[(blob < 0) | ~np.isin(blob, cands.mirror_blob[taken, k])]
        if rival.size == 0:
            continue
        R = rotation_zyx(result.head_pose[f, :3])
        head = (cands.points[rival] - result.head_pose[f, 3:]) @ R                # R^T (X - T), row-wise
        dist = np.linalg.norm(head - expected_head[n], axis=1)
        best = int(np.argmin(dist))
        if dist[best] < 0.5 * off[n] and dist[best] < REPAIR_SD * sd[n]:
            c = rival[best]
            result.candidate[f, m] = c
            result.points[f, m] = cands.points[c]
            result.head_frame[f, m] = head[best]
            result.camera_mask[f, m] = camera_mask_of(cands.mirror_blob[c])
            fixed[n] = True
    return fixed


def fill_gaps(result: TrackResult, radius_mm: float, kc: float = 1.0, learned_neighbours: int = 12,
               ridge_mm2: float = 1.0, min_frames: int = 10, max_sd_mm: float = np.inf):
    """Conjectures redone with the whole take known (it is offline).

    1. Learned neighbour relations (:func:`core.track.motion.learned_conjectures`, eq. 5.8
       with each pair's relation fitted on the frames where both were measured; the
       ``learned_neighbours`` nearest within ``radius_mm``): a marker's motion at ``t``
       from the neighbours measured at ``t``. Each relation's error where the marker and
       that neighbour were both measured is blended linearly across the frames between and
       taken off, so the conjecture meets the measurements at both ends of a gap (at the one
       end of a gap still open at the end of the take), whichever neighbours the gap keeps
       (:func:`core.track.motion.conjecture_gaps`).
    2. Where no neighbour with a learned relation is measured: eq. 5.8 from both ends of
       the gap -- the marker's motion at its last measurement ``a`` plus its neighbours'
       motion since (eq. 5.8 weights), and the same from its next measurement ``b``,
       blended linearly across the gap. A gap still open at the end of the take keeps
       the pass's conjecture there.
    3. Each conjecture's expected error: the standard deviation of its learned estimate
       (the relations' residuals, their errors correlated by
       :data:`core.track.motion.RELATION_CORRELATION`, and the prior's uncertainty about each relation
       where the neighbour moves beyond what it was fitted on, :data:`core.track.motion.RELATION_PRIOR_VAR`)
       grown as a random walk with the frames to the nearest
       measurement of the marker, ``sd * sqrt(frames)`` (cells of step 2: the take's
       median ``sd``). A conjecture expected to be off by more than ``max_sd_mm`` is
       withheld: the marker is left as a gap there (``stats["withheld"]`` per frame), and so is
       every frame of the gap further from the measurement it is nearest to (the error does not
       shrink away from the measurements: the sample clip's lower lip, withheld 2-21 frames
       after its last measurement at the end of the take, was 5.9 mm off at 23 frames, where
       other neighbours' relations said 0.5 mm).

    Updates ``points``, ``head_frame``, ``conjectured`` in place; returns every gap cell's conjecture, withheld or
    not (F, N, 3; NaN elsewhere), and its expected error (F, N)."""
    measured = result.assigned_blob >= 0
    F = measured.shape[0]
    motion = result.head_frame - result.neutral[None]  # (F, N, 3), NaN where not reported
    gaps = result.conjectured & np.isfinite(motion[..., 0])
    rows = np.flatnonzero(gaps.any(axis=0))
    result.stats["withheld"] = np.zeros(F, int)
    result.stats["conjectured"] = result.conjectured.sum(axis=1)
    if rows.size == 0:
        return np.full(result.points.shape, np.nan), np.full(measured.shape, np.nan)
    nidx, ndist = neighbours(result.neutral, radius_mm)
    learned_motion, sd = conjecture_gaps(motion, measured, gaps, nidx[:, :learned_neighbours], ridge_mm2, min_frames,
                                         correlation=RELATION_CORRELATION, prior_var=RELATION_PRIOR_VAR)
    learned = np.isfinite(sd)
    new_motion = np.where(learned[..., None], learned_motion, motion)

    last, nxt = previous_and_next(measured)
    rest = gaps & ~learned
    t, i = np.nonzero(rest & (last >= 0) & (nxt < F))
    if t.size:
        a, b = last[t, i], nxt[t, i]
        j = np.maximum(nidx[i], 0)  # (M, K)
        ok = (nidx[i] >= 0) & measured[t[:, None], j]
        ok &= np.isfinite(motion[a[:, None], j, 0]) & np.isfinite(motion[b[:, None], j, 0])
        w = np.where(ok, 1.0 / (ndist[i] + kc), 0.0)
        total = np.maximum(w.sum(axis=1), 1e-12)[:, None]
        now = np.nan_to_num(motion[t[:, None], j])

        def since(anchor):  # the neighbours' weighted motion from the anchor frame to t (zero with none)
            return np.einsum("mk,mkd->md", w, now - np.nan_to_num(motion[anchor[:, None], j])) / total

        s = ((t - a) / (b - a))[:, None]
        new_motion[t, i] = (1.0 - s) * (motion[a, i] + since(a)) + s * (motion[b, i] + since(b))

    t, i = np.nonzero(gaps)
    head = result.neutral[i] + new_motion[t, i]
    result.head_frame[t, i] = head
    R = rotation_zyx(result.head_pose[t, :3])
    result.points[t, i] = np.einsum("mij,mj->mi", R, head) + result.head_pose[t, 3:]

    conjecture = np.where(gaps[..., None], result.points, np.nan)
    typical = np.nanmedian(sd[gaps]) if np.isfinite(sd[gaps]).any() else 0.2
    frames_off = np.minimum(np.where(last >= 0, np.arange(F)[:, None] - last, F),
                            np.where(nxt < F, nxt - np.arange(F)[:, None], F))
    expected = np.where(gaps, grown_sd(np.where(np.isnan(sd), typical, sd), frames_off), np.nan)
    if np.isfinite(max_sd_mm):
        withheld = _withheld_onwards(gaps & (expected > max_sd_mm), measured, last, nxt) & gaps
        result.points[withheld] = np.nan
        result.head_frame[withheld] = np.nan
        result.conjectured[withheld] = False
        result.stats["withheld"] = withheld.sum(axis=1)
    result.stats["conjectured"] = result.conjectured.sum(axis=1)
    return conjecture, expected


def _withheld_onwards(withheld, measured, last, nxt):
    """``withheld (F, N)`` spread through each gap away from the measurement each frame is
    nearest to (``last``/``nxt``: the frame of the previous/next measurement per cell, as
    :func:`core.track.motion.previous_and_next` gives them; ``nxt == F``: none)."""
    F = withheld.shape[0]
    forward, backward = withheld.copy(), withheld.copy()
    for t in range(1, F):
        forward[t] |= forward[t - 1] & ~measured[t]
    for t in range(F - 2, -1, -1):
        backward[t] |= backward[t + 1] & ~measured[t]
    frames = np.arange(F)[:, None]
    after_last = np.where(last >= 0, frames - last, F)
    before_next = np.where(nxt < F, nxt - frames, F)
    return np.where(after_last <= before_next, forward, backward) & ~measured
