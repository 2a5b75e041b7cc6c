"""Marker motion over time (Lin 2003, sections 4.2 and 5.3): the building blocks of
the tracker, vectorised over markers.

* :class:`ConstantVelocityKalman` -- the adaptive position-velocity Kalman filter
  (eq. 4.1-4.2), for many markers (or the six head-pose parameters) at once, with
  a measurement variance per marker and frame and missing measurements;
* :func:`neighbours` -- markers within a distance in the neutral face, as a padded
  index array;
* :func:`false_tracking` -- the neighbour test (eq. 5.6-5.7): a marker's motion since
  the first frame is judged against the closest ``alpha`` of its neighbours' motions;
* :func:`conjecture_motion` -- the motion of missing markers as the weighted
  combination of their neighbours' (eq. 5.8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# ----------------------------------------------------------------------- Kalman
@dataclass
class ConstantVelocityKalman:
    """Position-velocity Kalman filters for ``n`` items of ``dim`` coordinates
    (eq. 4.1-4.2). The 6-state model of eq. 4.1 decouples into independent
    (position, velocity) pairs per axis; as every axis of an item shares its
    measurement variance, the axes also share one 2x2 covariance ``[[p00, p01],
    [p01, p11]]`` per item (each ``(n, 1)``), so a step is a handful of array
    operations for all items.

    ``accel_sigma`` (a scalar, or one per item) is the standard deviation of the
    velocity change per frame (process noise, ``w_v``); the measurement variance is
    given per update and item ("adjusted according to the confidence of
    measurement")."""

    position: np.ndarray  # (n, dim)
    velocity: np.ndarray  # (n, dim)
    p00: np.ndarray  # (n, 1) position variance
    p01: np.ndarray  # (n, 1) position-velocity covariance
    p11: np.ndarray  # (n, 1) velocity variance
    accel_sigma: float | np.ndarray = 1.0
    dt: float = 1.0

    @classmethod
    def start(cls, position, accel_sigma=1.0, initial_sigma: float = 1.0, dt: float = 1.0):
        pos = np.array(position, dtype=float)
        n = pos.shape[0]
        acc = np.broadcast_to(np.asarray(accel_sigma, float).reshape(-1, 1), (n, 1)).copy()
        return cls(position=pos, velocity=np.zeros_like(pos), p00=np.full((n, 1), float(initial_sigma) ** 2),
                   p01=np.zeros((n, 1)), p11=(10.0 * acc) ** 2, accel_sigma=acc, dt=dt)

    @property
    def P(self) -> np.ndarray:
        """The covariance per item and axis, ``(n, dim, 2, 2)``."""
        n, dim = self.position.shape
        P = np.empty((n, dim, 2, 2))
        P[..., 0, 0], P[..., 0, 1], P[..., 1, 0], P[..., 1, 1] = self.p00, self.p01, self.p01, self.p11
        return P

    def predict(self) -> np.ndarray:
        """Advance one frame: ``s(t|t-1) = A s(t-1)``; returns the predicted positions."""
        dt = self.dt
        self.position = self.position + dt * self.velocity
        self.p00 = self.p00 + dt * (2.0 * self.p01 + dt * self.p11)
        self.p01 = self.p01 + dt * self.p11
        self.p11 = self.p11 + self.accel_sigma ** 2
        return self.position

    def update(self, measured, measured_sigma, valid=None) -> np.ndarray:
        """Correct with measurements ``(n, dim)`` of standard deviation ``measured_sigma``
        (scalar or ``(n,)``); items with ``valid`` False keep their prediction (their
        measurement may be NaN). Returns the filtered positions."""
        z = np.asarray(measured, float)
        r = np.asarray(measured_sigma, float).reshape(-1, 1) ** 2
        s = self.p00 + r  # innovation variance
        k0, k1 = self.p00 / s, self.p01 / s  # Kalman gain
        innov = z - self.position
        if valid is not None:
            ok = np.asarray(valid, bool)[:, None]
            k0 = np.where(ok, k0, 0.0)
            k1 = np.where(ok, k1, 0.0)
            innov = np.where(ok, innov, 0.0)
        self.position = self.position + k0 * innov
        self.velocity = self.velocity + k1 * innov
        self.p11 = self.p11 - k1 * self.p01
        self.p01 = (1.0 - k0) * self.p01
        self.p00 = (1.0 - k0) * self.p00
        return self.position


def previous_and_next(valid):
    """For ``valid`` ``(F, N)``: the frame of each item's last valid frame at or before
    each frame (-1: none yet) and of its next one at or after it (``F``: none left),
    both ``(F, N)`` -- the two ends of every gap, vectorised."""
    valid = np.asarray(valid, bool)
    F = valid.shape[0]
    t = np.arange(F)[:, None]
    prev = np.maximum.accumulate(np.where(valid, t, -1), axis=0)
    nxt = np.minimum.accumulate(np.where(valid, t, F)[::-1], axis=0)[::-1]
    return prev, nxt


def interpolate_in_time(values, valid) -> np.ndarray:
    """``values`` ``(F, M, D)`` with each item's entries outside ``valid`` ``(F, M)``
    replaced by linear interpolation in time between the valid frames around them; before
    an item's first and after its last valid frame its nearest valid value is held. Items
    never valid are returned as they are."""
    values = np.asarray(values, float)
    F, M = np.shape(valid)
    prev, nxt = previous_and_next(valid)
    prev_c = np.where(prev < 0, nxt, prev)
    nxt_c = np.where(nxt >= F, prev_c, nxt)
    ever = prev_c < F  # items valid somewhere
    prev_c, nxt_c = np.minimum(prev_c, F - 1), np.minimum(nxt_c, F - 1)
    cols = np.arange(M)[None, :]
    v0, v1 = values[prev_c, cols], values[nxt_c, cols]
    w = np.clip((np.arange(F)[:, None] - prev_c) / np.maximum(nxt_c - prev_c, 1), 0, 1)[..., None]
    return np.where((np.asarray(valid, bool) | ~ever)[..., None], values, v0 + w * (v1 - v0))


# -------------------------------------------------------- neighbour statistics
def neighbours(neutral, radius: float, max_neighbours: int = 24):
    """Markers within ``radius`` of each marker in the neutral face (itself excluded):
    ``(index (N, K), distance (N, K))`` padded with -1 / inf, nearest first."""
    from scipy.spatial import cKDTree

    pts = np.asarray(neutral, float)
    dist, idx = cKDTree(pts).query(pts, k=max_neighbours + 1, distance_upper_bound=radius)
    dist, idx = dist[:, 1:], idx[:, 1:]
    missing = ~np.isfinite(dist)
    idx = np.where(missing, -1, idx)
    return idx, np.where(missing, np.inf, dist)


def _gather(values, idx, valid):
    """values[idx] with padding and invalid neighbours masked: ``(N, K, ...), mask (N, K)``."""
    safe = np.maximum(idx, 0)
    mask = (idx >= 0) & np.asarray(valid, bool)[safe]
    return np.take(values, safe, axis=0), mask  # (np.take: several times faster than values[safe])


_ONES3 = np.ones(3)
_EYE3 = np.eye(3)


def false_tracking(motion, valid, neighbour_idx, alpha: float = 0.6667, threshold: float = 3.0,
                   k: float = 0.1, min_neighbours: int = 3):
    """The neighbour test of eq. 5.6-5.7 for every marker at once.

    ``motion`` ``(N, 3)``: each marker's displacement since the first frame,
    ``v_i(t) = m_i(t) - m_i(1)``; ``valid`` ``(N,)``: markers with a measurement. For
    marker i, the neighbours' motions closest to ``v_i`` -- the first ``alpha`` of
    them -- give a per-axis mean and standard deviation; ``JF`` is the norm of
    ``(v_i - mean) / (std + k)`` (eq. 5.7) and the tracking is false when
    ``JF > threshold`` (eq. 5.6). Markers with fewer than ``min_neighbours`` valid
    neighbours are not judged. Returns ``(false (N,), JF (N,))``.

    (Sums over the 3 coordinates and over neighbours are matrix products: numpy's
    reductions over short axes cost several times more.)"""
    v = np.asarray(motion, float)
    valid = np.asarray(valid, bool)
    nv, mask = _gather(v, neighbour_idx, valid)  # (N, K, 3)
    d = np.square(nv - v[:, None, :]) @ _ONES3
    d[~mask] = np.inf
    count = mask.sum(axis=1)
    take = np.ceil(alpha * count).astype(int)
    # the alpha closest: at most the take-th smallest distance (ties are measure-zero)
    limit = np.sort(d, axis=1)[np.arange(len(v)), np.maximum(take - 1, 0)]
    w = (mask & (d <= limit[:, None])).astype(float)[:, None, :]  # (N, 1, K)
    n = np.maximum(w.sum(axis=2), 1.0)
    mean = (w @ nv)[:, 0] / n
    var = np.maximum((w @ (nv * nv))[:, 0] / n - mean * mean, 0.0)
    jf = np.sqrt(np.square((v - mean) / (np.sqrt(var) + k)) @ _ONES3)
    judged = valid & (count >= min_neighbours)
    return judged & (jf > threshold), np.where(judged, jf, np.nan)


def conjecture_motion(motion, valid, neighbour_idx, neighbour_dist, kc: float = 1.0, only=None):
    """Motions of the markers not ``valid`` from their valid neighbours (eq. 5.8):
    ``v_i = sum_j w_ij v_j / sum_j w_ij`` with ``w_ij = 1 / (d_ij + kc)`` and ``d_ij`` the
    neutral-face distance. (The printed equation omits the normalisation by the sum
    of the weights, without which the result would scale with the neighbour count.)
    Returns ``(motion (N, 3), filled (N,))``; markers with no valid neighbour stay
    unfilled (their rows are NaN). ``only`` (``(N,)`` bool) limits the estimate to
    those missing markers."""
    v = np.asarray(motion, float)
    valid = np.asarray(valid, bool)
    out = v.copy()
    rows = np.flatnonzero(~valid if only is None else ~valid & np.asarray(only, bool))  # missing markers only
    filled = np.zeros(len(v), bool)
    if rows.size == 0:
        return out, filled
    idx = neighbour_idx[rows]
    safe = np.maximum(idx, 0)
    w = np.where((idx >= 0) & valid[safe], 1.0 / (np.asarray(neighbour_dist)[rows] + kc), 0.0)
    total = w.sum(axis=1)
    est = (w[:, None, :] @ np.nan_to_num(np.take(v, safe, axis=0)))[:, 0] / np.where(total > 0, total, 1.0)[:, None]
    good = total > 0
    filled[rows[good]] = True
    out[rows] = np.where(good[:, None], est, np.nan)
    return out, filled


RELATION_CORRELATION = 0.5  # correlation of the errors of one marker's learned relations (see learned_conjectures)
#: the prior variance of a learned relation's B about eq. 5.8's identity (learned_conjectures): a relation fitted
#: over frames where the pair barely moved claimed 0.15 mm where the dense clip's dot 277, in an 18-frame gap of
#: its first 60 frames, moved 2.2 mm unlike its neighbours (with it: withheld). Over 16 clips, points over 2 mm
#: 157 -> 143 (dense 11 -> 8, fast540 11 -> 7, mirror45 7 -> 3) for 0-0.1 points of completeness each
RELATION_PRIOR_VAR = 0.1


def learned_conjectures(motion, measured, neighbour_idx, rows, ridge: float = 1.0, min_frames: int = 10,
                        block_values: int = 2_000_000, correlation: float = 0.0, prior_var: float = 0.0,
                        anchored: bool = False):
    """Eq. 5.8 with the neighbour relations learned from the take (offline, whole take known).

    Eq. 5.8 assumes a hidden marker moves as its neighbours do (``v_i = v_j``, weighted by
    distance). Here each pair -- a marker ``i`` of ``rows`` and each of its neighbours ``j``
    (``neighbour_idx``, nearest first) -- gets its own linear relation, fitted over the
    frames where both are measured by regularised least squares:
    ``v_i ~= (v_j - mean_j) B_ij + mean_i``, ``B_ij`` 3x3, shrunk towards eq. 5.8's
    ``B = I`` with strength ``ridge`` (mm^2: as if ``ridge`` mm^2 of motion had been seen
    moving one-to-one). So a pair with little shared motion falls back on eq. 5.8, and a
    pair seen over a whole range of expressions follows its data. A pair needs
    ``min_frames`` shared frames. Where ``i`` is not measured, its motion is the
    mean of the relations of the neighbours measured there, each weighted by the inverse of
    its fit's residual variance -- so a lip marker follows the lip markers that moved like
    it, not the cheek beside it.

    ``motion`` ``(F, N, 3)`` (anything where not ``measured`` ``(F, N)``); returns
    ``(estimate (F, P, 3), variance (F, P))`` for the ``P`` markers of ``rows``: the
    estimate at every frame (measured or not, so that callers can compare it with the
    measurements) and the variance of the weighted mean (mm^2) -- the relations' errors taken
    as correlated by ``correlation`` (0: independent; the tracker's gap filling uses
    :data:`RELATION_CORRELATION`: the expression that hides a marker throws its neighbours'
    relations off together, and taken as independent, 12 relations claimed a 0.5 mm error where
    the sample clip's lower lip was 2-6 mm off); NaN and inf where no related neighbour is
    measured. ``prior_var``: the prior variance of B about the identity, added to a relation's
    prediction variance where the data do not pin B down (0: none; the tracker's gap filling uses
    :data:`RELATION_PRIOR_VAR`). ``anchored``: each relation's prediction corrected by its own error where
    the marker and that neighbour were both measured, blended linearly in time between those frames
    (:func:`interpolate_in_time`; where the marker is measured the estimate is then its measurement).
    Markers are done in blocks of about ``block_values`` numbers, so memory stays bounded on long takes."""
    measured = np.asarray(measured, bool)
    F, N = measured.shape
    rows = np.asarray(rows, int)
    vz = np.where(measured[..., None], np.nan_to_num(np.asarray(motion, float)), 0.0)
    K = neighbour_idx.shape[1]
    est = np.full((F, rows.size, 3), np.nan)
    var = np.full((F, rows.size), np.inf)
    step = max(1, int(block_values // max(K * F * 3, 1)))
    for lo in range(0, rows.size, step):
        r = rows[lo:lo + step]
        P = r.size
        idx = neighbour_idx[r]                                       # (P, K)
        js = np.maximum(idx, 0)
        mi = measured[:, r].T                                        # (P, F)
        mj = np.take(measured, js, axis=1).transpose(1, 2, 0) & (idx >= 0)[..., None]  # (P, K, F)
        vi = vz[:, r].transpose(1, 0, 2)                             # (P, F, 3)
        vj = np.take(vz, js, axis=1).transpose(1, 2, 0, 3)           # (P, K, F, 3), zero where unmeasured
        both = (mi[:, None] & mj).astype(float)                      # (P, K, F)
        n = both.sum(axis=2)                                         # (P, K)
        nn = np.maximum(n, 1.0)[..., None]
        mean_i = (both @ vi) / nn                                    # (P, K, 3)
        vjb = vj * both[..., None]
        mean_j = vjb.sum(axis=2) / nn                                # (P, K, 3)
        # centred second moments over the shared frames, from raw sums (no (P, K, F, 3) residuals)
        vjbt = vjb.swapaxes(-1, -2)                                  # (P, K, 3, F)
        s_jj = vjbt @ vj - n[..., None, None] * mean_j[..., :, None] * mean_j[..., None, :]
        s_ji = vjbt @ vi[:, None] - n[..., None, None] * mean_j[..., :, None] * mean_i[..., None, :]
        s_ii = (both @ np.einsum("pfc,pfc->pf", vi, vi)[..., None])[..., 0] - n * np.sum(mean_i ** 2, axis=-1)
        B = np.linalg.solve(s_jj + ridge * _EYE3, s_ji + ridge * _EYE3)  # (P, K, 3, 3), shrunk towards I
        rss = s_ii - 2.0 * np.einsum("pkab,pkab->pk", B, s_ji) + np.einsum("pkab,pkac,pkcb->pk", B, s_jj, B)
        pair_var = np.maximum(rss, 0.0) / np.maximum(n - 3.0, 1.0) + 1e-4  # (P, K) mm^2
        # a relation's prediction variance grows where the neighbour moves outside what the fit
        # saw (the leverage of regression: d' S^-1 d, d the neighbour's motion off its mean)
        dj = vj - mean_j[:, :, None]                                 # (P, K, F, 3)
        lev = (dj @ np.linalg.inv(s_jj + ridge * _EYE3) * dj) @ _ONES3  # (P, K, F)
        # ... and where the data do not pin B down (little shared motion), by how far B may lie from
        # eq. 5.8's identity: the prior's variance per unit of the neighbour's motion off what was
        # fitted, weighted by the prior's share of the fit (ridge over ridge + S)
        pred_var = pair_var[..., None] * (1.0 + 1.0 / nn + lev) + prior_var * ridge * lev  # (P, K, F)
        w = np.where(mj & (n >= min_frames)[..., None], 1.0 / pred_var, 0.0)  # (P, K, F)
        total = w.sum(axis=1)                                        # (P, F)
        # sum_k w_k ((v_j - mean_j) B_k + mean_i) = sum_k w_k (dj B_k) + sum_k w_k mean_i
        if anchored:
            # each relation's prediction corrected by its own error, blended in time between the frames
            # around where the marker and that neighbour were both measured
            pred = dj @ B + mean_i[:, :, None]                          # (P, K, F, 3)
            off = (vi[:, None] - pred).reshape(P * K, F, 3).transpose(1, 0, 2)
            corr = interpolate_in_time(off, both.reshape(P * K, F).T > 0).transpose(1, 0, 2).reshape(P, K, F, 3)
            mean = np.einsum("pkf,pkfb->pfb", w, pred + corr) / np.where(total > 0, total, 1.0)[..., None]
        else:
            wdB = np.einsum("pkf,pkfb->pfb", w, dj @ B)
            mean = (wdB + w.transpose(0, 2, 1) @ mean_i) / np.where(total > 0, total, 1.0)[..., None]
        have = total > 0
        est[:, lo:lo + P] = np.where(have[..., None], mean, np.nan).transpose(1, 0, 2)
        # the variance of the relations' weighted mean, their errors correlated by ``correlation``
        used = (w > 0).sum(axis=1)                                   # (P, F) relations used
        inflate = 1.0 + correlation * (used - 1)
        var[:, lo:lo + P] = np.where(have, inflate / np.where(have, total, 1.0), np.inf).T
    return est, var


def conjecture_gaps(motion, measured, gaps, neighbour_idx, ridge: float = 1.0, min_frames: int = 10,
                    correlation: float = 0.0, prior_var: float = 0.0):
    """Motions of the ``gaps`` cells ``(F, N)`` from the learned neighbour relations
    (:func:`learned_conjectures`), each relation corrected to meet the marker's measurements: its
    error where the marker and that neighbour were both ``measured`` is blended linearly in time
    across the frames between (held beyond the first and the last; ``anchored``). So the
    conjecture meets the measurements at the ends of each gap, whichever neighbours are measured
    in the gap: a neighbour lost there takes its own correction with it. (Stop 37: one correction
    of the relations' mean, taken from the neighbours measured at the gap's ends, put a marker's
    conjecture 2 mm off where a neighbour measured at the end was not measured in the gap; over the 24
    bench clips the conjectures' RMS error falls 0.01-0.02 mm on 15, rises 0.01 mm on one.) Returns
    ``(motion (F, N, 3), sd (F, N))`` -- NaN where the cell is no gap or no related neighbour is
    measured; ``sd`` is the standard deviation of the relations' estimate (mm); ``correlation``,
    ``prior_var``: as :func:`learned_conjectures` takes them."""
    measured = np.asarray(measured, bool)
    gaps = np.asarray(gaps, bool)
    F, N = gaps.shape
    out = np.full((F, N, 3), np.nan)
    sd = np.full((F, N), np.nan)
    rows = np.flatnonzero(gaps.any(axis=0))
    if rows.size == 0:
        return out, sd
    est, var = learned_conjectures(np.asarray(motion, float), measured, neighbour_idx, rows, ridge, min_frames,
                                   correlation=correlation, prior_var=prior_var, anchored=True)
    learned = gaps[:, rows] & np.isfinite(est[..., 0])
    out[:, rows] = np.where(learned[..., None], est, np.nan)
    sd[:, rows] = np.where(learned, np.sqrt(var), np.nan)
    return out, sd


def grown_sd(sd, frames_away):
    """A conjecture's expected error ``frames_away`` frames from the marker's nearest
    measurement: the relations' standard deviation ``sd`` grown as a random walk,
    ``sd * sqrt(frames)`` (at least one frame)."""
    return np.asarray(sd, float) * np.sqrt(np.maximum(frames_away, 1))


def conjecture_since_last_seen(motion, valid, neighbour_idx, neighbour_dist, last_motion, last_frame, history,
                               kc: float = 1.0):
    """A temporal refinement of eq. 5.8 for markers missing now but measured before:
    ``v_i(t) = v_i(t_i) + sum_j w_ij (v_j(t) - v_j(t_i)) / sum_j w_ij`` -- the marker
    keeps its own motion at its last measurement ``t_i`` and borrows only its
    neighbours' motion since then (same weights as eq. 5.8). ``history`` ``(T, N, 3)``
    holds every marker's motion per past frame (NaN where not reported);
    ``last_motion`` ``(N, 3)`` and ``last_frame`` ``(N,)`` (-1: never measured) the
    last measurement. Returns ``(motion (N, 3), filled (N,))`` for the markers it could
    fill."""
    v = np.asarray(motion, float)
    missing = ~np.asarray(valid, bool) & (np.asarray(last_frame) >= 0)
    out = np.full_like(v, np.nan)
    filled = np.zeros(len(v), bool)
    rows = np.flatnonzero(missing)
    if rows.size == 0:
        return out, filled
    idx = neighbour_idx[rows]  # (M, K)
    safe = np.maximum(idx, 0)
    now = np.take(v, safe, axis=0)  # (M, K, 3) neighbours' motion now
    then = history[np.asarray(last_frame)[rows][:, None], safe]  # (M, K, 3) at the marker's last sighting
    ok = (idx >= 0) & np.asarray(valid, bool)[safe] & ~np.isnan(then[..., 0])  # (valid motions are finite)
    w = np.where(ok, 1.0 / (np.asarray(neighbour_dist)[rows] + kc), 0.0)
    total = w.sum(axis=1)
    delta = (w[:, None, :] @ np.where(ok[..., None], now - then, 0.0))[:, 0]
    good = total > 0
    out[rows[good]] = np.asarray(last_motion)[rows[good]] + delta[good] / total[good, None]
    filled[rows[good]] = True
    return out, filled
