"""General two-view baselines the mirror method is compared with (benchmark code,
not the product path).

The mirrored view is treated as a second, *virtual* camera. A mirror maps a
marker ``m`` to ``H_u m + 2 d u``; ``H_u`` is a reflection (det -1), so the image
is flipped: flipping the mirrored image's x axis (``F = diag(-1, 1, 1)``) turns
the virtual camera into an ordinary one with rotation ``R = F H_u`` and
translation ``T = 2 d F u`` (Lin 2003, section 6.2, methods (b) and (c)).

* :func:`two_view_linear` -- the linear algorithm of Weng et al. in Lin's
  Appendix A (8-point essential matrix -> T -> R -> depths).
* :func:`opencv_two_view` -- ``cv2.findEssentialMat`` / ``recoverPose`` /
  ``triangulatePoints`` on the same data.
* :func:`two_view_ml` -- maximum-likelihood refinement of a two-view result
  (reprojection error over R, T and the points; Appendix A, last paragraph).

All functions take normalised coordinates ``(N, 2)`` of the direct view ``p1`` and
of the flipped mirror view ``p2`` and return points ``(N, 3)`` in the real
camera's frame, up to scale (``|T| = 1``).
"""

from __future__ import annotations

import numpy as np


def flip_mirror_view(pm: np.ndarray) -> np.ndarray:
    """Normalised mirrored points -> the virtual camera's un-flipped image."""
    out = np.array(pm, dtype=float, copy=True)
    out[..., 0] *= -1.0
    return out


def _h(p):
    return np.concatenate([p, np.ones((p.shape[0], 1))], axis=1)


def _nearest_rotation(W):
    U, _, Vt = np.linalg.svd(W)
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, -1] *= -1
        R = U @ Vt
    return R


def _depths(X1, X2, R, T):
    """Step 5: least squares ``z2 X2 - z1 R X1 = T`` per point -> (z1, z2)."""
    a = -(X1 @ R.T)  # coefficient of z1
    b = X2  # coefficient of z2
    aa, bb, ab = (a * a).sum(1), (b * b).sum(1), (a * b).sum(1)
    at, bt = a @ T, b @ T
    det = aa * bb - ab * ab
    return (bb * at - ab * bt) / det, (aa * bt - ab * at) / det


def two_view_linear(p1: np.ndarray, p2: np.ndarray):
    """Weng's two-view linear algorithm (Lin 2003, Appendix A). Returns ``(R, T, X)``.

    Step 1: ``E`` from the smallest right singular vector of ``A`` (scaled to
    ``||E|| = sqrt 2``). Step 2: ``T_s`` = the unit vector minimising ``||E^T T_s||``.
    Step 3: ``R`` = the rotation nearest to ``W``. Step 4: the sign of ``T`` --
    where the appendix's text is ambiguous the sign (and, for robustness, the
    sign of ``E``) is chosen so that most depths are positive. Step 5: depths by
    least squares."""
    X1, X2 = _h(p1), _h(p2)
    u, v = X1[:, 0], X1[:, 1]
    u2, v2 = X2[:, 0], X2[:, 1]
    one = np.ones_like(u)
    A = np.stack([u * u2, u * v2, u, v * u2, v * v2, v, u2, v2, one], axis=1)
    h = np.linalg.svd(A)[2][-1]
    E0 = np.sqrt(2.0) * h.reshape(3, 3).T  # columns E1, E2, E3 = (h1 h2 h3), (h4 h5 h6), (h7 h8 h9)
    best = None
    for E in (E0, -E0):
        Ts = np.linalg.svd(E.T)[2][-1]  # min ||E^T Ts||: E^T = R^T [T]x^T annihilates T
        if np.sum(np.cross(Ts, X1) * (X1 @ E.T)) < 0:
            Ts = -Ts
        E1, E2, E3 = E[:, 0], E[:, 1], E[:, 2]
        W = np.stack([np.cross(E1, Ts) + np.cross(E2, E3), np.cross(E2, Ts) + np.cross(E3, E1),
                      np.cross(E3, Ts) + np.cross(E1, E2)], axis=1)
        R = _nearest_rotation(W)
        for T in (Ts, -Ts):
            z1, z2 = _depths(X1, X2, R, T)
            score = np.count_nonzero((z1 > 0) & (z2 > 0))
            if best is None or score > best[0]:
                best = (score, R, T, z1)
    _, R, T, z1 = best
    return R, T, z1[:, None] * X1


def opencv_two_view(p1: np.ndarray, p2: np.ndarray, threshold: float):
    """OpenCV's essential-matrix pipeline on normalised coordinates (identity
    camera matrix): 5-point RANSAC ``findEssentialMat`` with ``threshold`` (normalised
    units), ``recoverPose`` (cheirality), ``triangulatePoints``. Returns ``(R, T, X)``
    or ``None`` when OpenCV finds no essential matrix."""
    import cv2

    a = np.ascontiguousarray(p1, dtype=np.float64)
    b = np.ascontiguousarray(p2, dtype=np.float64)
    E, _ = cv2.findEssentialMat(a, b, np.eye(3), method=cv2.RANSAC, prob=0.999, threshold=threshold)
    if E is None or E.shape[0] < 3:
        return None
    E = E[:3]
    _, R, t, _ = cv2.recoverPose(E, a, b, np.eye(3))
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([R, t])
    Xh = cv2.triangulatePoints(P1, P2, a.T, b.T)
    X = (Xh[:3] / Xh[3]).T
    return R, t.ravel(), X


def _rotvec_to_matrix(r):
    theta = np.linalg.norm(r)
    if theta < 1e-15:
        return np.eye(3)
    k = r / theta
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * Kx + (1 - np.cos(theta)) * Kx @ Kx


def two_view_ml(p1, p2, R0, T0, X0, focal_px: float = 1.0, max_evaluations: int = 200):
    """Maximum-likelihood two-view refinement: minimise the reprojection error in
    both views over ``R`` (rotation vector update), the direction of ``T`` (2 DOF
    on the unit sphere) and the points, from a linear result. Returns ``(R, T, X)``."""
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    n = p1.shape[0]
    T0 = T0 / np.linalg.norm(T0)
    helper = np.array([1.0, 0, 0]) if abs(T0[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(T0, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(T0, e1)

    def unpack(x):
        R = _rotvec_to_matrix(x[:3]) @ R0
        T = T0 + x[3] * e1 + x[4] * e2
        return R, T / np.linalg.norm(T), x[5:].reshape(n, 3)

    def residuals(x):
        R, T, X = unpack(x)
        Y = X @ R.T + T
        return np.concatenate([(X[:, :2] / X[:, 2:3] - p1).ravel(), (Y[:, :2] / Y[:, 2:3] - p2).ravel()]) * focal_px

    S = lil_matrix((4 * n, 5 + 3 * n), dtype=int)
    rows = np.arange(n)
    for c in range(3):
        for off in (0, 1):
            S[2 * rows + off, 5 + 3 * rows + c] = 1
            S[2 * n + 2 * rows + off, 5 + 3 * rows + c] = 1
    S[2 * n:, :5] = 1
    x0 = np.concatenate([np.zeros(5), np.asarray(X0, dtype=float).ravel()])
    sol = least_squares(residuals, x0, jac_sparsity=S.tocsr(), method="trf", x_scale="jac",
                        max_nfev=max_evaluations, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    return unpack(sol.x)


def best_scale(X, X_true) -> float:
    """The scale ``s`` minimising ``||s X - X_true||`` -- every method is given the same
    perfect ruler before its 3D error is measured."""
    return float(np.sum(X * X_true) / np.sum(X * X))


def rms_3d_error(X, X_true) -> float:
    if X is None or not np.all(np.isfinite(X)):
        return float("nan")
    s = best_scale(X, X_true)
    return float(np.sqrt(np.mean(np.sum((s * X - X_true) ** 2, axis=1))))
