"""Maximum-likelihood refinement of the mirror planes and the points by reprojection error
(scipy ``least_squares``), after the closed form of chapter 3."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mirror import reflect_points, tangent_basis


@dataclass
class RefinementResult:
    normals: np.ndarray  # (K, 3)
    ds: np.ndarray  # (K,)
    points: np.ndarray  # (N, 3)
    rms_px_before: float
    rms_px_after: float
    evaluations: int


def refine_reconstruction(p, pm, visible, normals, ds, points, focal_px: float = 1.0,
                          max_evaluations: int = 200) -> RefinementResult:
    """Maximum-likelihood refinement of the normals, the ``d`` of mirrors 1.., and the
    points, minimising reprojection error in all views (the nonlinear step the paper
    mentions after eq. 3.12), with ``scipy.optimize.least_squares``.

    ``p`` ``(N, 2)`` and ``pm`` ``(K, N, 2)`` normalised, ``visible`` ``(K, N)``; the
    first mirror's ``d`` is held fixed (it sets the scale). Each normal moves in
    its 2D tangent space; residuals are in pixels (normalised error x
    ``focal_px``), so the result is the Gaussian maximum-likelihood estimate."""
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    p = np.asarray(p, dtype=float)
    pm = np.asarray(pm, dtype=float)
    visible = np.asarray(visible, dtype=bool)
    normals0 = np.asarray(normals, dtype=float).reshape(-1, 3)
    ds0 = np.asarray(ds, dtype=float).reshape(-1)
    X0 = np.asarray(points, dtype=float)
    K, N = visible.shape
    bases = [tangent_basis(u) for u in normals0]
    idx = [np.flatnonzero(visible[k]) for k in range(K)]
    n_plane = 2 * K + (K - 1)  # tangent steps for every normal, d for mirrors 1..K-1
    n_res = 2 * N + 2 * sum(i.size for i in idx)

    def unpack(x):
        us, dd = [], ds0.copy()
        for k in range(K):
            e1, e2 = bases[k]
            u = normals0[k] + x[2 * k] * e1 + x[2 * k + 1] * e2
            us.append(u / np.linalg.norm(u))
        dd[1:] = x[2 * K:n_plane]
        return np.stack(us), dd, x[n_plane:].reshape(N, 3)

    def residuals(x):
        us, dd, X = unpack(x)
        out = [(X[:, :2] / X[:, 2:3] - p).ravel()]
        for k in range(K):
            V = reflect_points(X[idx[k]], us[k], dd[k])
            out.append((V[:, :2] / V[:, 2:3] - pm[k, idx[k]]).ravel())
        return np.concatenate(out) * focal_px

    sparsity = lil_matrix((n_res, n_plane + 3 * N), dtype=int)
    rows = np.arange(N)
    for c in range(3):
        sparsity[2 * rows, n_plane + 3 * rows + c] = 1
        sparsity[2 * rows + 1, n_plane + 3 * rows + c] = 1
    start = 2 * N
    for k in range(K):
        r = start + 2 * np.arange(idx[k].size)
        plane_cols = [2 * k, 2 * k + 1] + ([2 * K + k - 1] if k > 0 else [])
        for c in plane_cols:
            sparsity[r, c] = 1
            sparsity[r + 1, c] = 1
        for c in range(3):
            sparsity[r, n_plane + 3 * idx[k] + c] = 1
            sparsity[r + 1, n_plane + 3 * idx[k] + c] = 1
        start += 2 * idx[k].size
    x0 = np.concatenate([np.zeros(2 * K), ds0[1:], X0.ravel()])
    r0 = residuals(x0)
    sol = least_squares(residuals, x0, jac_sparsity=sparsity.tocsr(), method="trf", x_scale="jac",
                        max_nfev=max_evaluations, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    us, dd, X = unpack(sol.x)
    flip = us[:, 2] > 0  # keep c < 0; (u, d) and (-u, -d) are the same plane
    us[flip] *= -1.0
    dd[flip] *= -1.0
    return RefinementResult(
        normals=us, ds=dd, points=X,
        rms_px_before=float(np.sqrt(np.mean(r0**2))),
        rms_px_after=float(np.sqrt(np.mean(sol.fun**2))),
        evaluations=int(sol.nfev),
    )
