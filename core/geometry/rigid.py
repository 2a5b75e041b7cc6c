"""Rigid and similarity fits between point sets, and the head-pose rotation of eq. 5.4: the
one place the core estimates a rotation from points (the tracker's head pose, the binder's
head motion, the head fit's first alignment, scoring a take against its truth).

* :func:`rigid_fit` -- ``R, t`` by SVD (Arun, Huang & Blostein 1987), weighted, for one
  point set ``(n, 3)`` or a batch ``(F, n, 3)`` at once;
* :func:`robust_rigid_fit` -- the same, iteratively reweighted (Cauchy weights
  ``1 / (1 + (r / c)^2)``, ``c`` a multiple of the median residual), so the pose
  follows the rigid part of a face whose markers also move with the expression (the
  weight-compensated estimate of Rurainsky & Eisert, section 3.3);
* :func:`similarity_fit` -- ``s, R, t`` (Umeyama 1991);
* :func:`rotation_zyx` / :func:`angles_zyx` -- ``R = Rz Ry Rx`` and its angles (eq. 5.4);
* :func:`to_head_frame` -- points with a head pose taken off, ``R^T (X - T)``.
"""

from __future__ import annotations

import numpy as np

# c of the Cauchy weights in multiples of the median residual: 2 x 1.4826 x median, i.e. the
# weight is 1/2 at two robust standard deviations (1.4826 x median estimates sigma).
CAUCHY_SCALE = 2.0 * 1.4826


def rigid_fit(A, B, weights=None):
    """``R, t`` minimising ``sum w |R a_i + t - b_i|^2`` (Arun et al. 1987; a reflection is
    corrected by flipping the weakest axis). ``A``, ``B``: ``(n, 3)``, or ``(F, n, 3)`` (``A``
    may stay ``(n, 3)``) with ``weights`` ``(n,)`` or ``(F, n)``: then ``R (F, 3, 3)``,
    ``t (F, 3)``, every frame at once (batched SVD)."""
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    if B.ndim == 3:
        return _rigid_fit_batch(A, B, weights)
    w = np.ones(len(A)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    ca, cb = w @ A, w @ B
    H = (A - ca).T @ ((B - cb) * w[:, None])
    U, _, Vt = np.linalg.svd(H)
    R = Vt.T @ U.T
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0:  # a reflection: flip the weakest axis
        Vt[2] *= -1.0
        R = Vt.T @ U.T
    return R, cb - R @ ca


def _rigid_fit_batch(A, B, weights):
    F, n = B.shape[:2]
    w = np.ones((F, n)) if weights is None else np.broadcast_to(np.asarray(weights, float), (F, n))
    w = w / w.sum(1, keepdims=True)
    A = np.broadcast_to(A, B.shape)
    ca = (w[:, None, :] @ A)[:, 0]                                   # (F, 3)
    cb = (w[:, None, :] @ B)[:, 0]
    H = np.swapaxes(A - ca[:, None], 1, 2) @ ((B - cb[:, None]) * w[:, :, None])
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, 1, 2)
    D = np.tile(np.eye(3), (F, 1, 1))
    D[:, 2, 2] = np.sign(np.linalg.det(V @ np.swapaxes(U, 1, 2)))
    R = V @ D @ np.swapaxes(U, 1, 2)
    return R, cb - (R @ ca[:, :, None])[:, :, 0]


def robust_rigid_fit(A, B, iterations: int = 5, weights=None, cauchy_scale: float = CAUCHY_SCALE, mask=None):
    """:func:`rigid_fit` iteratively reweighted: markers far from the fit (moving with the
    expression) get small weights ``1 / (1 + (r / c)^2)`` with ``c`` = ``cauchy_scale`` x
    the median residual (default :data:`CAUCHY_SCALE`). ``weights`` start the iteration (e.g. last frame's). For one point
    set returns ``R, t`` and the final weights ``(n,)``; for a batch ``(F, n, 3)`` every frame
    at once, ``R (F, 3, 3)``, ``t (F, 3)``, weights ``(F, n)``. ``mask`` (same shape as the
    weights, bool) leaves points out of every iteration (missing markers)."""
    A = np.asarray(A, float)
    B = np.asarray(B, float)
    batch = B.ndim == 3
    shape = B.shape[:-1]
    w = np.ones(shape) if weights is None else np.broadcast_to(np.asarray(weights, float), shape)
    if mask is not None:
        mask = np.broadcast_to(np.asarray(mask, bool), shape)
        w = w * mask
    half = shape[-1] // 2
    for _ in range(iterations):
        R, t = rigid_fit(A, B, w)
        if batch:
            d = A @ np.swapaxes(R, 1, 2) + t[:, None] - B
            r = np.sqrt(np.einsum("fij,fij->fi", d, d))
            s = (np.partition(r, half, axis=1)[:, half:half + 1] if mask is None
                 else np.nanmedian(np.where(mask, r, np.nan), axis=1, keepdims=True))
        else:
            d = A @ R.T + t - B
            r = np.sqrt(np.einsum("ij,ij->i", d, d))
            s = np.partition(r, half)[half] if mask is None else np.median(r[mask])
        c = cauchy_scale * s + 2e-6  # robust scale from the median residual (never 0)
        w = 1.0 / (1.0 + (r / c) ** 2)
        if mask is not None:
            w = w * mask
    R, t = rigid_fit(A, B, w)
    return R, t, w


def similarity_fit(A, B):
    """``s, R, t`` minimising ``sum |s R a_i + t - b_i|^2`` (Umeyama 1991)."""
    A, B = np.asarray(A, float), np.asarray(B, float)
    ca, cb = A.mean(0), B.mean(0)
    a, b = A - ca, B - cb
    U, S, Vt = np.linalg.svd(b.T @ a / len(A))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    var = (a ** 2).sum() / len(A)
    s = float(np.trace(np.diag(S) @ D) / var)
    return s, R, cb - s * R @ ca


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


def to_head_frame(R, T, X) -> np.ndarray:
    """Points ``X`` ``(..., 3)`` in the frame of a head at pose ``R`` ``(..., 3, 3)``, ``T`` ``(..., 3)``
    (eq. 5.4, ``X = R x + T`` inverted: ``x = R^T (X - T)``), row by row: one pose per point or one
    for all."""
    return np.einsum("...ji,...j->...i", R, X - T)


def angles_zyx(R) -> np.ndarray:
    """(rx, ry, rz) of ``R = Rz Ry Rx`` (eq. 5.4), ``(..., 3)``; |ry| < 90 deg assumed,
    as for a head."""
    R = np.asarray(R, float)
    rx = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    ry = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    rz = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([rx, ry, rz], axis=-1)
