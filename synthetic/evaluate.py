"""Scoring a tracked take against ground truth (the sample clip's, or a synthetic one's).

The tracker's labels (``m000``..) are its own, and a self-calibrated take is in relative
units: a global scale about the camera centre. Projections into the image do not see that
scale, so identities are first found in the image:

1. each tracked marker's true identity is the majority, over the frames where it was
   measured, of the true marker whose projection is nearest to its own (within
   ``match_px``);
2. one similarity transform (Umeyama), fitted over every measured marker-frame of the
   clip, brings the take onto the truth. Each identity is then checked in 3D: it becomes
   the majority of the true marker nearest in 3D over the same frames when that marker
   projects within ``match_px`` of the tracked one too (median; the image cannot tell the
   two apart), and the similarity is fitted again (``ids_image`` keeps step 1's,
   ``ids_reassigned_in_3d`` counts the changes). Near the silhouette a dot hidden in the
   direct view -- on the cheek, 13 mm behind a dot on the nose's far side -- can project
   nearer a tracked point than the dot it measures. A point measured too deep, nearer
   another dot in 3D that projects elsewhere, keeps its identity: a switch in step 3.
   The 3D error is what remains, in truth units (mm). Conjectured points are scored
   separately under the same transform.
3. an identity switch is a measured marker-frame that lies nearer another true marker than
   its own, in 3D after the alignment (the 3D test: in one camera's image, two markers seen
   only in a mirror near the face's silhouette can project within 2 px of each other while
   22 mm apart). ``identity_switches_image`` counts the same in the direct camera's image, and
   ``off_marker`` those nearest their own true marker in the image but more than ``match_px``
   from it: the right marker, measured badly -- an error, not a switch.
4. completeness: ``split_markers`` counts true markers that carry two or more of the take's
   labels. With ``seen (F, N)`` (the true marker is seen in the direct view and at least one
   mirror, e.g. ``truth.npz``'s ``visible``), ``seen_reported_fraction`` is the share of those
   marker-frames the take reports (measured or conjectured, under the marker's label), and
   ``never_tracked`` lists the true markers seen in 10 frames or more that no label carries.
"""

from __future__ import annotations

import numpy as np

from ..core.common.errors import InputError
from ..core.geometry.camera import Camera
from ..core.geometry.rigid import similarity_fit


def _align(P, T, ids, ok):
    """Step 2 and the 3D test of step 3: the similarity over the marker-frames ``ok`` of ``P``
    onto ``T`` under ``ids``; returns the aligned take, each point's 3D error against its own
    true marker and the true marker nearest it in 3D (-1 where not in ``ok``)."""
    from scipy.spatial import cKDTree

    f_idx, m_idx = np.nonzero(ok)
    s, R, t = similarity_fit(P[f_idx, m_idx], T[f_idx, ids[m_idx]])
    aligned = s * P @ R.T + t
    err = np.linalg.norm(aligned - T[:, np.maximum(ids, 0)], axis=2)
    nearest_3d = np.full(ok.shape, -1)
    for f in range(P.shape[0]):
        idx = np.flatnonzero(ok[f])
        present = np.flatnonzero(np.all(np.isfinite(T[f]), axis=1))
        if idx.size and present.size:
            nearest_3d[f, idx] = present[cKDTree(T[f, present]).query(aligned[f, idx])[1]]
    return aligned, err, nearest_3d, s


def score_take(points, truth, camera: Camera, conjectured=None, match_px: float = 2.0, seen=None) -> dict:
    """``points (F, M, 3)`` tracked (NaN gaps), ``truth (F, N, 3)`` mm, ``seen (F, N)`` optional;
    returns a dict of figures (see the module text) plus ``ids (M,)`` (-1: no true marker),
    ``aligned (F, M, 3)`` and ``error_mm (F, M)``."""
    from scipy.spatial import cKDTree

    P = np.asarray(points, float)
    T = np.asarray(truth, float)
    if P.ndim != 3 or T.ndim != 3 or P.shape[0] != T.shape[0]:
        raise InputError(f"take {P.shape} and truth {T.shape} must both be (frames, markers, 3) over the same frames")
    F, M, _ = P.shape
    conj = np.zeros((F, M), bool) if conjectured is None else np.asarray(conjectured, bool)
    reported = np.all(np.isfinite(P), axis=2)
    measured = reported & ~conj
    nearest = np.full((F, M), -1)  # nearest true marker, at any distance
    near_px = np.full((F, M), np.inf)
    for f in range(F):
        idx = np.flatnonzero(reported[f])
        present = np.flatnonzero(np.all(np.isfinite(T[f]), axis=1))
        if idx.size == 0 or present.size == 0:
            continue
        d, j = cKDTree(camera.project(T[f, present])).query(camera.project(P[f, idx]))
        nearest[f, idx], near_px[f, idx] = present[j], d
    ids = np.full(M, -1)
    for m in range(M):
        v = nearest[measured[:, m] & (near_px[:, m] <= match_px), m]
        if v.size:
            ids[m] = np.bincount(v).argmax()
    ok = measured & (ids[None, :] >= 0)
    if ok.sum() < 3:
        raise InputError("fewer than 3 tracked points match the truth: nothing to score")
    ids_image = ids.copy()
    aligned, err, nearest_3d, scale = _align(P, T, ids, ok)
    # step 2's check of each identity in 3D: the majority of the true markers nearest each label
    f_ok, m_ok = np.nonzero(ok & (nearest_3d >= 0))
    N = T.shape[1]
    votes = np.bincount(m_ok * N + nearest_3d[f_ok, m_ok], minlength=M * N).reshape(M, N)
    nearest_mostly = np.where(votes.any(axis=1), votes.argmax(axis=1), ids)
    for m in np.flatnonzero((ids >= 0) & (nearest_mostly != ids)):  # a few labels, if any
        f_m = f_ok[m_ok == m]
        k = nearest_mostly[m]
        px = np.linalg.norm(camera.project(T[f_m, k]) - camera.project(aligned[f_m, m]), axis=1)
        if np.median(px) <= match_px:  # the image cannot tell the two apart
            ids[m] = k
    if np.any(ids != ids_image):
        aligned, err, nearest_3d, scale = _align(P, T, ids, ok)
    switches_image = int(np.count_nonzero(ok & (nearest != ids[None, :])))
    off_marker = int(np.count_nonzero(ok & (nearest == ids[None, :]) & (near_px > match_px)))
    switches = int(np.count_nonzero(ok & (nearest_3d != ids[None, :])))
    e = err[ok]
    cj = conj & reported & (ids[None, :] >= 0)
    ce = err[cj]
    labels_per_marker = np.bincount(ids[ids >= 0], minlength=N)
    completeness = {"split_markers": int(np.count_nonzero(labels_per_marker > 1))}
    if seen is not None:
        seen = np.asarray(seen, bool)
        if seen.shape != (F, N):
            raise InputError(f"seen {seen.shape} must be (frames, true markers) = {(F, N)}")
        covered = np.zeros((F, N), bool)             # the true marker reported under one of its labels
        f_r, m_r = np.nonzero(reported & (ids[None, :] >= 0))
        covered[f_r, ids[m_r]] = True
        n_seen = int(seen.sum())
        completeness.update({
            "seen_marker_frames": n_seen,
            "seen_reported_fraction": float((covered & seen).sum() / max(n_seen, 1)),
            "never_tracked": np.flatnonzero((seen.sum(axis=0) >= 10) & (labels_per_marker == 0)).tolist(),
            "unreported_seen": seen & ~covered,
        })
    return {
        **completeness,
        "markers_tracked": M, "markers_true": N, "markers_matched": int(np.count_nonzero(ids >= 0)),
        "identity_switches": switches, "identity_switches_image": switches_image, "off_marker": off_marker, "measured_marker_frames": int(measured.sum()),
        "reported_fraction": float(reported.mean()),
        "rms_mm": float(np.sqrt(np.mean(e ** 2))), "p95_mm": float(np.percentile(e, 95)), "max_mm": float(e.max()),
        "conjectured": int(cj.sum()),
        "conjectured_rms_mm": float(np.sqrt(np.mean(ce ** 2))) if ce.size else 0.0,
        "conjectured_max_mm": float(ce.max()) if ce.size else 0.0,
        "ids_reassigned_in_3d": int(np.count_nonzero(ids != ids_image)),
        "scale_to_mm": scale, "ids": ids, "ids_image": ids_image, "aligned": aligned, "error_mm": err,
    }
