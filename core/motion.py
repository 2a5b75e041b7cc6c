"""Marker motion over time (Lin 2003, sections 4.2 and 5.3): the building blocks of
the tracker, vectorised over markers.

* :func:`rigid_fit` -- the rotation and translation between two point sets by SVD
  (Arun et al.), for head motion from rigid markers;
* :func:`rotation_zyx` / :func:`angles_zyx` -- ``R = Rz Ry Rx`` and its angles (eq. 5.4);
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


# ------------------------------------------------------------------ rigid motion
def rigid_fit(A, B, weights=None):
    """``R, t`` minimising ``sum w |R a_i + t - b_i|^2`` for point sets ``(n, 3)``
    (Arun, Huang & Blostein 1987; the reflection case is corrected)."""
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    w = np.ones(len(A)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    ca, cb = w @ A, w @ B
    H = (A - ca).T @ ((B - cb) * w[:, None])
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cb - R @ ca


def rotation_zyx(angles) -> np.ndarray:
    """``R = Rz(rz) Ry(ry) Rx(rx)`` for angles ``(..., 3)`` = (rx, ry, rz) in radians (eq. 5.4)."""
    a = np.asarray(angles, float)
    cx, cy, cz = np.cos(a[..., 0]), np.cos(a[..., 1]), np.cos(a[..., 2])
    sx, sy, sz = np.sin(a[..., 0]), np.sin(a[..., 1]), np.sin(a[..., 2])
    R = np.empty(a.shape[:-1] + (3, 3))
    R[..., 0, 0] = cz * cy
    R[..., 0, 1] = cz * sy * sx - sz * cx
    R[..., 0, 2] = cz * sy * cx + sz * sx
    R[..., 1, 0] = sz * cy
    R[..., 1, 1] = sz * sy * sx + cz * cx
    R[..., 1, 2] = sz * sy * cx - cz * sx
    R[..., 2, 0] = -sy
    R[..., 2, 1] = cy * sx
    R[..., 2, 2] = cy * cx
    return R


def angles_zyx(R) -> np.ndarray:
    """(rx, ry, rz) of ``R = Rz Ry Rx`` (eq. 5.4), ``(..., 3)``; |ry| < 90 deg assumed,
    as for a head."""
    R = np.asarray(R, float)
    rx = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    ry = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    rz = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([rx, ry, rz], axis=-1)


# ----------------------------------------------------------------------- Kalman
@dataclass
class ConstantVelocityKalman:
    """Position-velocity Kalman filters for ``n`` items of ``dim`` coordinates
    (eq. 4.1-4.2). The 6-state model of eq. 4.1 decouples into independent
    (position, velocity) pairs per axis, so every axis of every item is filtered in
    one vectorised step.

    ``accel_sigma`` is the standard deviation of the velocity change per frame
    (process noise, ``w_v``); the measurement variance is given per update and item
    ("adjusted according to the confidence of measurement")."""

    position: np.ndarray  # (n, dim)
    velocity: np.ndarray  # (n, dim)
    P: np.ndarray  # (n, dim, 2, 2)
    accel_sigma: float = 1.0
    dt: float = 1.0

    @classmethod
    def start(cls, position, accel_sigma: float = 1.0, initial_sigma: float = 1.0, dt: float = 1.0):
        pos = np.array(position, dtype=float)
        P = np.zeros(pos.shape + (2, 2))
        P[..., 0, 0] = initial_sigma**2
        P[..., 1, 1] = (10.0 * accel_sigma) ** 2
        return cls(position=pos, velocity=np.zeros_like(pos), P=P, accel_sigma=accel_sigma, dt=dt)

    def predict(self) -> np.ndarray:
        """Advance one frame: ``s(t|t-1) = A s(t-1)``; returns the predicted positions."""
        dt = self.dt
        self.position = self.position + dt * self.velocity
        P = self.P
        p00, p01, p11 = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
        q = self.accel_sigma**2
        n00 = p00 + 2 * dt * p01 + dt * dt * p11
        n01 = p01 + dt * p11
        self.P = np.stack([np.stack([n00, n01], -1), np.stack([n01, p11 + q], -1)], -2)
        return self.position

    def update(self, measured, measured_sigma, valid=None) -> np.ndarray:
        """Correct with measurements ``(n, dim)`` of standard deviation ``measured_sigma``
        (scalar or ``(n,)``); items with ``valid`` False keep their prediction. Returns
        the filtered positions."""
        z = np.asarray(measured, float)
        r = np.broadcast_to(np.asarray(measured_sigma, float) ** 2, z.shape[:1])[:, None]
        ok = np.ones(z.shape[0], bool) if valid is None else np.asarray(valid, bool)
        P = self.P
        s = P[..., 0, 0] + r  # innovation variance
        k0, k1 = P[..., 0, 0] / s, P[..., 0, 1] / s  # Kalman gain
        innov = np.where(ok[:, None], z - self.position, 0.0)
        k0 = np.where(ok[:, None], k0, 0.0)
        k1 = np.where(ok[:, None], k1, 0.0)
        self.position = self.position + k0 * innov
        self.velocity = self.velocity + k1 * innov
        p00, p01, p11 = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
        n00 = (1 - k0) * p00
        n01 = (1 - k0) * p01
        n11 = p11 - k1 * p01
        self.P = np.stack([np.stack([n00, n01], -1), np.stack([n01, n11], -1)], -2)
        return self.position


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
    return values[safe], mask


def false_tracking(motion, valid, neighbour_idx, alpha: float = 0.6667, threshold: float = 3.0,
                   k: float = 0.1, min_neighbours: int = 3):
    """The neighbour test of eq. 5.6-5.7 for every marker at once.

    ``motion`` ``(N, 3)``: each marker's displacement since the first frame,
    ``v_i(t) = m_i(t) - m_i(1)``; ``valid`` ``(N,)``: markers with a measurement. For
    marker i, the neighbours' motions closest to ``v_i`` -- the first ``alpha`` of
    them -- give a per-axis mean and standard deviation; ``JF`` is the norm of
    ``(v_i - mean) / (std + k)`` (eq. 5.7) and the tracking is false when
    ``JF > threshold`` (eq. 5.6). Markers with fewer than ``min_neighbours`` valid
    neighbours are not judged. Returns ``(false (N,), JF (N,))``."""
    v = np.asarray(motion, float)
    nv, mask = _gather(v, neighbour_idx, valid)  # (N, K, 3)
    d = np.linalg.norm(nv - v[:, None, :], axis=2)
    d = np.where(mask, d, np.inf)
    order = np.argsort(d, axis=1)
    count = mask.sum(axis=1)
    take = np.ceil(alpha * count).astype(int)
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(order.shape[1])[None, :].repeat(len(v), 0), axis=1)
    sel = mask & (rank < take[:, None])
    w = sel.astype(float)
    n = np.maximum(w.sum(axis=1), 1.0)[:, None]
    mean = (nv * w[..., None]).sum(axis=1) / n
    var = ((nv - mean[:, None, :]) ** 2 * w[..., None]).sum(axis=1) / n
    jf = np.linalg.norm((v - mean) / (np.sqrt(var) + k), axis=1)
    judged = np.asarray(valid, bool) & (count >= min_neighbours)
    return judged & (jf > threshold), np.where(judged, jf, np.nan)


def conjecture_motion(motion, valid, neighbour_idx, neighbour_dist, kc: float = 1.0):
    """Motions of the markers not ``valid`` from their valid neighbours (eq. 5.8):
    ``v_i = sum_j w_ij v_j / sum_j w_ij`` with ``w_ij = 1 / (d_ij + kc)`` and ``d_ij`` the
    neutral-face distance. (The printed equation omits the normalisation by the sum
    of the weights, without which the result would scale with the neighbour count.)
    Returns ``(motion (N, 3), filled (N,))``; markers with no valid neighbour stay
    unfilled (their rows are NaN)."""
    v = np.asarray(motion, float)
    nv, mask = _gather(np.nan_to_num(v), neighbour_idx, valid)
    w = np.where(mask, 1.0 / (np.asarray(neighbour_dist) + kc), 0.0)
    total = w.sum(axis=1)
    est = (nv * w[..., None]).sum(axis=1) / np.where(total > 0, total, 1.0)[:, None]
    missing = ~np.asarray(valid, bool)
    filled = missing & (total > 0)
    out = v.copy()
    out[filled] = est[filled]
    out[missing & ~filled] = np.nan
    return out, filled


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
    now = v[safe]  # (M, K, 3) neighbours' motion now
    then = history[np.asarray(last_frame)[rows][:, None], safe]  # (M, K, 3) at the marker's last sighting
    ok = (idx >= 0) & np.asarray(valid, bool)[safe] & np.all(np.isfinite(then), axis=2) & np.all(np.isfinite(now), axis=2)
    w = np.where(ok, 1.0 / (np.asarray(neighbour_dist)[rows] + kc), 0.0)
    total = w.sum(axis=1)
    delta = (np.nan_to_num(now - then) * w[..., None]).sum(axis=1) / np.where(total > 0, total, 1.0)[:, None]
    good = total > 0
    out[rows[good]] = np.asarray(last_motion)[rows[good]] + delta[good]
    filled[rows[good]] = True
    return out, filled
