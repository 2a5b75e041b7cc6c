"""Mirror self-calibration from the markers themselves: no calibration object, no clicks.

Inputs are detections (pixels + colour class) of the direct view and of one mirror
over a few frames. Every same-colour (direct blob, mirror blob) pair of a frame is a
candidate correspondence; only 1-3 % of them are true, so the scoring decides
everything (see ``shared/notes/mirror-self-calibration.md``, which this follows):

* hypotheses from the 2-correspondence minimal solution ``u = M_i x M_j`` (eq. 3.7);
* sampling first from candidates whose vertical offset is small (mirrors beside
  the face are roughly upright), falling back to all candidates;
* a truncated-quadratic score with a ~1 px tolerance in which every blob counts at
  most once (its best candidate), direct and mirrored blobs alike;
* a depth check: both depths positive (in front of the camera, marker on the
  mirror's reflecting side);
* adaptive stopping at the requested confidence;
* then least squares (eq. 3.8) on one-to-one pairs (``linear_sum_assignment``)
  with the tolerance tightening to ~0.5 px, pooling every frame given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..capture.views import ClipDetections
from ..common.errors import DegenerateError
from ..geometry.camera import Camera
from ..geometry.mirror import (
    MirrorPlane,
    _plane_terms,
    _squared_residuals,
    correspondence_matrix,
    depths_from_planes,
    epipolar_residuals,
    estimate_image_noise,
    expected_normal_error,
    normal_from_correspondences,
    orient_normal,
)
from .candidates import _same_frame_pairs


REFINE_ROUNDS = 50      # least-squares rounds on one-to-one pairs (eq. 3.8), ...
CONVERGED_DEG = 1e-4    # ... until the normal moves less than this


@dataclass
class Candidates:
    """Same-colour direct/mirror pairs pooled over frames (normalised coordinates)."""

    p: np.ndarray  # (C, 2) direct
    pm: np.ndarray  # (C, 2) mirrored
    direct_blob: np.ndarray  # (C,) global index of the direct blob
    mirror_blob: np.ndarray  # (C,) global index of the mirror blob
    frame: np.ndarray  # (C,)
    dy_px: np.ndarray  # (C,) vertical offset in pixels


def build_candidates(det: ClipDetections, mirror: int) -> Candidates:
    """All same-colour (direct, mirror ``mirror``) pairs of each frame of ``det``
    (:class:`..capture.views.ClipDetections`; its normalised coordinates, no undistortion
    here). Blob indices are ``det``'s global ones."""
    v = mirror + 1
    i, j = _same_frame_pairs(det.frame[0], det.frame[v])
    same = det.colour[0][i] == det.colour[v][j]
    i, j = i[same], j[same]
    if i.size == 0:
        raise DegenerateError(f"no same-colour candidates between the direct view and mirror {mirror}")
    return Candidates(p=det.norm[0][i], pm=det.norm[v][j], direct_blob=i, mirror_blob=j, frame=det.frame[0][i],
                      dy_px=det.xy[v][j, 1] - det.xy[0][i, 1])


def _blob_min(values, groups_sorted_idx, starts):
    """Per-blob minimum of ``values`` (S, C) over candidate columns grouped by blob."""
    return np.minimum.reduceat(values[:, groups_sorted_idx], starts, axis=1)


class _Scorer:
    """Truncated-quadratic score of normal hypotheses, each blob counted once."""

    def __init__(self, cand: Candidates, threshold: float):
        self.c = cand
        self.t2 = threshold * threshold
        self.x, self.y = cand.p[:, 0], cand.p[:, 1]
        self.xm, self.ym = cand.pm[:, 0], cand.pm[:, 1]
        self.M = correspondence_matrix(cand.p, cand.pm)
        self.d_order = np.argsort(cand.direct_blob, kind="stable")
        self.d_starts = np.flatnonzero(np.r_[True, np.diff(cand.direct_blob[self.d_order]) != 0])
        self.m_order = np.argsort(cand.mirror_blob, kind="stable")
        self.m_starts = np.flatnonzero(np.r_[True, np.diff(cand.mirror_blob[self.m_order]) != 0])

    def residuals(self, u):
        """(S, C): squared epipolar residual where the depths are positive, else t^2."""
        a, b, c = u[:, 0:1], u[:, 1:2], u[:, 2:3]
        num = u @ self.M.T
        x, y, xm, ym = self.x, self.y, self.xm, self.ym
        r2 = _squared_residuals(num, (b - c * y) ** 2 + (c * x - a) ** 2, (b - c * ym) ** 2 + (c * xm - a) ** 2)
        AA, BB, AB, Ar, Br, _ = _plane_terms(x, y, xm, ym, a, b, c, -1.0)
        z, zm = BB * Ar - AB * Br, AA * Br - AB * Ar  # signs of the depths (eq. 3.11 numerators)
        pos, neg = (z > 0) & (zm > 0), (z < 0) & (zm < 0)
        close = r2 < self.t2
        front = np.where(((pos & close).sum(1) >= (neg & close).sum(1))[:, None], pos, neg)
        return np.where(front, np.minimum(r2, self.t2), self.t2)

    def cost(self, u):
        r = self.residuals(u)
        best_d = _blob_min(r, self.d_order, self.d_starts)
        best_m = _blob_min(r, self.m_order, self.m_starts)
        inliers = np.minimum((best_d < self.t2).sum(1), (best_m < self.t2).sum(1))
        return best_d.sum(1) + best_m.sum(1), inliers


@dataclass
class SelfCalibration:
    plane: MirrorPlane
    pairs: int  # one-to-one pairs used in the final least squares
    iterations: int
    candidates: int


def self_calibrate_mirror(det: ClipDetections, camera: Camera, mirror: int, *, threshold_px: float = 1.0,
                          final_threshold_px: float = 0.5, confidence: float = 0.99, max_iterations: int = 60000,
                          max_dy_px: float | None = None, score_frames: int = 3, seed: int = 0,
                          batch: int = 32, rescored: int = 4) -> SelfCalibration:
    """Estimate mirror ``mirror``'s plane from the detections ``det`` alone (module
    docstring; a :class:`..capture.views.ClipDetections` of the first frames, or
    per-frame detections, normalised here).

    ``max_dy_px`` bounds the vertical offset of the candidates sampled first
    (default 5 % of the image height); ``score_frames`` frames score hypotheses,
    all frames feed the refinement; of each ``batch`` of hypotheses the ``rescored``
    best on the first frame are scored on all of them."""
    f = camera.focal_px
    det = ClipDetections.of(det, camera)
    cand_all = build_candidates(det, mirror)
    scoring = cand_all if score_frames >= det.n_frames else _subset(cand_all, cand_all.frame < score_frames)
    scorer = _Scorer(scoring, threshold_px / f)
    # preemptive scoring: every hypothesis is scored on the first frame alone, and only
    # the best ``rescored`` of each batch on all ``score_frames`` frames
    first = _subset(scoring, scoring.frame == scoring.frame.min()) if len(scoring.frame) else scoring
    quick = _Scorer(first, threshold_px / f) if 0 < len(first.frame) < len(scoring.frame) else None
    h = camera.image_size[1] or 720
    max_dy = 0.05 * h if max_dy_px is None else max_dy_px
    pools = [np.flatnonzero(np.abs(scoring.dy_px) <= max_dy), np.arange(len(scoring.dy_px))]
    rng = np.random.default_rng(seed)
    best_cost, best_u, best_inliers, done = np.inf, None, 0, 0
    n_direct = len(scorer.d_starts)
    for pool in pools:
        if pool.size < 2:
            continue
        needed, tried = max_iterations, 0
        while tried < min(needed, max_iterations):
            i = pool[rng.integers(0, pool.size, batch)]
            j = pool[rng.integers(0, pool.size, batch)]
            ok = scoring.frame[i] == scoring.frame[j]  # two correspondences of one frame...
            ok &= scoring.direct_blob[i] != scoring.direct_blob[j]  # ...of two different markers
            ok &= scoring.mirror_blob[i] != scoring.mirror_blob[j]
            tried += batch
            done += batch
            cand = np.cross(scorer.M[i[ok]], scorer.M[j[ok]])
            norm = np.linalg.norm(cand, axis=1)
            keep = norm > 1e-12
            if not keep.any():
                continue
            u = orient_normal(cand[keep] / norm[keep, None])
            if quick is not None and len(u) > rescored:
                u = u[np.argsort(quick.cost(u)[0], kind="stable")[:rescored]]
            cost, inl = scorer.cost(u)
            k = int(np.argmin(cost))
            if cost[k] < best_cost:
                best_cost, best_u, best_inliers = cost[k], u[k], int(inl[k])
                w = min(inl[k] / max(pool.size, 1), 1.0)  # chance that a sampled candidate is a true pair
                if w > 0:
                    needed = int(np.ceil(np.log(1 - confidence) / np.log(max(1 - w * w, 1e-12))))
        if best_u is not None and best_inliers >= 0.3 * n_direct / max(min(det.n_frames, score_frames), 1):
            break  # the restricted pool found a plane explaining many blobs: no fallback needed
    if best_u is None:
        raise DegenerateError(f"mirror {mirror}: no mirror plane hypothesis could be formed")
    u, pairs, t_px = best_u, None, threshold_px
    for _ in range(REFINE_ROUNDS):
        previous = u
        pairs = _one_to_one(cand_all, u, t_px / f)
        if pairs.size < 6:
            raise DegenerateError(f"mirror {mirror}: fewer than 6 consistent marker pairs; the mirror is "
                                  "not visible or the markers are too few")
        u = normal_from_correspondences(cand_all.p[pairs], cand_all.pm[pairs])
        # tighten towards final_threshold_px, but never below 3 sigma of the pairs' own
        # residuals (robust: 1.4826 x median), so noisier detections keep their true pairs
        sigma_px = 1.4826 * np.median(epipolar_residuals(u, cand_all.p[pairs], cand_all.pm[pairs])) * f
        t_px = max(final_threshold_px, 3.0 * sigma_px, 0.5 * (t_px + final_threshold_px))
        if np.degrees(np.arccos(min(1.0, abs(float(u @ previous))))) < CONVERGED_DEG:
            break
    p, pm = cand_all.p[pairs], cand_all.pm[pairs]
    z, _ = depths_from_planes(p, pm[None], u[None], np.array([-1.0]))
    sign = -1.0 if np.median(z) > 0 else 1.0
    sigma = estimate_image_noise(p, pm, u)
    err = np.degrees(expected_normal_error(p, pm, u, sigma)) if np.isfinite(sigma) else float("nan")
    inliers = np.zeros(len(cand_all.p), dtype=bool)
    inliers[pairs] = True
    plane = MirrorPlane(normal=u, d=sign, inliers=inliers, noise_px=sigma * f, expected_error_deg=float(err),
                        iterations=done)
    return SelfCalibration(plane=plane, pairs=int(pairs.size), iterations=done, candidates=len(cand_all.p))


def _subset(c: Candidates, mask) -> Candidates:
    return Candidates(c.p[mask], c.pm[mask], c.direct_blob[mask], c.mirror_blob[mask], c.frame[mask], c.dy_px[mask])


def _one_to_one(c: Candidates, u, threshold: float) -> np.ndarray:
    """Candidate indices forming one-to-one pairs per frame: within ``threshold`` of
    the mirrored epipolar geometry, both depths positive, near the median depth,
    and assigned by minimum total residual (``linear_sum_assignment``)."""
    from scipy.optimize import linear_sum_assignment
    from scipy.sparse import coo_matrix

    res = epipolar_residuals(u, c.p, c.pm)
    z, zm = depths_from_planes(c.p, c.pm[None], u[None], np.array([-1.0]))
    zm = zm[0]
    sign = 1.0 if np.median(z[res < threshold]) > 0 else -1.0
    z, zm = sign * z, sign * zm
    ok = (res < threshold) & (z > 0) & (zm > 0)
    if ok.sum() >= 6:  # depth near the median: a face spans a few tens of percent in depth at most
        med = np.median(z[ok])
        ok &= np.abs(z / med - 1.0) < 0.35
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return idx
    chosen = []
    for f in np.unique(c.frame[idx]):
        sel = idx[c.frame[idx] == f]
        di, dinv = np.unique(c.direct_blob[sel], return_inverse=True)
        mi, minv = np.unique(c.mirror_blob[sel], return_inverse=True)
        cost = np.full((di.size, mi.size), 1e6)
        cost[dinv, minv] = res[sel]
        rows, cols = linear_sum_assignment(cost)
        good = cost[rows, cols] < 1e6
        lookup = coo_matrix((sel + 1, (dinv, minv)), shape=(di.size, mi.size)).tocsr()
        chosen.append(np.asarray(lookup[rows[good], cols[good]]).ravel() - 1)
    return np.concatenate(chosen).astype(int)
