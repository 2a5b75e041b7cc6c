"""RBF data scattering (Lin 2003, section 7.3, eq. 7.1-7.2), applied to displacements.

Given control points ``m_i`` (n, 3) with displacements ``u_i`` (n, d), the scattering
function is

    f(m) = sum_i c_i phi(|m - m_i|) + M m + t,     phi(r) = exp(-r / k)      (eq. 7.1)

with the coefficients from the (n + 4)-square system of eq. 7.2: ``f(m_i) = u_i``,
``sum_i c_i = 0`` and ``sum_i c_i m_i^T = 0``. The paper's kernel is the point (k = 16,
in the model's units; millimetres here); scipy's kernels (``thin_plate_spline``,
``cubic``, ``gaussian``, ...) are available through :class:`scipy.interpolate.RBFInterpolator`
as an option.

The system depends only on the control points, so :class:`RBFScattering` factors it
once and then scatters any number of displacement sets -- e.g. every frame of a take
-- with one triangular solve each, and evaluates at many vertices in chunks.
"""

from __future__ import annotations

import numpy as np

from ..common.errors import DegenerateError, InputError

PAPER_K = 16.0


class RBFScattering:
    """Eq. 7.1-7.2 for fixed control points ``centres`` ``(n, 3)``."""

    def __init__(self, centres, k: float = PAPER_K, kernel: str = "exp", smoothing: float = 0.0):
        from scipy.linalg import lu_factor

        c = np.asarray(centres, dtype=float)
        if c.ndim != 2 or c.shape[1] != 3 or c.shape[0] == 0:
            raise InputError("RBF control points must have shape (n, 3) with n >= 1")
        if not np.all(np.isfinite(c)):
            raise InputError("RBF control points must be finite")
        if kernel != "exp":
            self._scipy_kernel = kernel
            self.centres = c
            return
        self._scipy_kernel = None
        if not (np.isfinite(k) and k > 0):
            raise InputError("the RBF constant k must be positive")
        n = c.shape[0]
        if n < 4 or np.linalg.matrix_rank(np.c_[c, np.ones(n)], tol=1e-9 * max(1.0, np.abs(c).max())) < 4:
            raise DegenerateError("RBF scattering needs at least 4 control points not all on one plane "
                                  "(the affine part of eq. 7.1 is otherwise undetermined)")
        from scipy.spatial.distance import cdist

        d = cdist(c, c)
        if np.any(d[np.triu_indices(n, 1)] < 1e-9 * max(1.0, np.abs(c).max())):
            raise DegenerateError("two RBF control points coincide")
        A = np.zeros((n + 4, n + 4))
        A[:n, :n] = np.exp(-d / k) + smoothing * np.eye(n)
        P = np.c_[c, np.ones(n)]
        A[:n, n:] = P
        A[n:, :n] = P.T
        self.centres, self.k, self.n = c, float(k), n
        self._lu = lu_factor(A)

    def system_matrix(self) -> np.ndarray:
        """The (n+4)-square matrix of eq. 7.2 (for inspection and tests)."""
        from scipy.spatial.distance import cdist

        n, c = self.n, self.centres
        A = np.zeros((n + 4, n + 4))
        A[:n, :n] = np.exp(-cdist(c, c) / self.k)
        A[:n, n:] = np.c_[c, np.ones(n)]
        A[n:, :n] = A[:n, n:].T
        return A

    def coefficients(self, displacements) -> np.ndarray:
        """Solve eq. 7.2 for displacements ``(n, d)`` or a batch ``(F, n, d)``:
        returns ``(..., n + 4, d)`` -- the ``c_i`` then the rows of ``M^T`` and ``t``."""
        from scipy.linalg import lu_solve

        u = np.asarray(displacements, dtype=float)
        if u.shape[-2] != self.n:
            raise InputError(f"{u.shape[-2]} displacements for {self.n} control points")
        batch = u.shape[:-2]
        d = u.shape[-1]
        rhs = np.zeros((self.n + 4,) + (int(np.prod(batch)) * d,))
        rhs[: self.n] = np.moveaxis(u.reshape(-1, self.n, d), 1, 0).reshape(self.n, -1)
        sol = lu_solve(self._lu, rhs)  # (n + 4, F * d)
        return np.moveaxis(sol.reshape(self.n + 4, -1, d), 1, 0).reshape(batch + (self.n + 4, d))

    def evaluate(self, points, coefficients, chunk: int = 20000) -> np.ndarray:
        """``f`` of eq. 7.1 at ``points`` ``(m, 3)`` for coefficients ``(..., n + 4, d)``;
        returns ``(..., m, d)``. Evaluated in chunks of points to bound memory."""
        from scipy.spatial.distance import cdist

        p = np.asarray(points, dtype=float)
        coef = np.asarray(coefficients, dtype=float)
        out = np.empty(coef.shape[:-2] + (p.shape[0], coef.shape[-1]))
        for s in range(0, p.shape[0], chunk):
            q = p[s:s + chunk]
            basis = np.c_[np.exp(-cdist(q, self.centres) / self.k), q, np.ones(len(q))]  # (m, n + 4)
            out[..., s:s + chunk, :] = np.einsum("mj,...jd->...md", basis, coef)
        return out

    def influence_matrix(self, points) -> np.ndarray:
        """The linear map of eq. 7.1-7.2 from control displacements to displacements at
        ``points``: ``(m, n)`` with ``f(points) = E @ u``. Its rows sum to 1 and it
        reproduces affine fields, since the system's affine part is exact."""
        from scipy.linalg import lu_solve
        from scipy.spatial.distance import cdist

        if self._scipy_kernel is not None:
            raise InputError("influence_matrix needs the paper's kernel (kernel='exp')")
        p = np.asarray(points, dtype=float)
        rhs = np.zeros((self.n + 4, self.n))
        rhs[: self.n] = np.eye(self.n)
        inv = lu_solve(self._lu, rhs)                                   # (n + 4, n)
        basis = np.c_[np.exp(-cdist(p, self.centres) / self.k), p, np.ones(len(p))]
        return basis @ inv

    def __call__(self, points, displacements) -> np.ndarray:
        """Scatter ``displacements`` (at the control points) to ``points``."""
        if self._scipy_kernel is not None:
            from scipy.interpolate import RBFInterpolator

            return RBFInterpolator(self.centres, np.asarray(displacements, float), kernel=self._scipy_kernel,
                                   degree=1)(np.asarray(points, float))
        return self.evaluate(points, self.coefficients(displacements))
