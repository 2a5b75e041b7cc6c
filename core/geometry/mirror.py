"""Mirror geometry: the closed-form linear algorithm of Lin (2003), chapter 3.

A plane mirror ``a x + b y + c z = d`` (unit normal ``u = (a, b, c)``, ``c < 0``)
makes the camera see every marker ``m`` twice: directly, and as the virtual point
``m' = H_u m + 2 d u`` with the Householder matrix ``H_u = I - 2 u u^T`` (eq. 3.9).
From real-vs-mirrored correspondences alone this module recovers

* the mirror normal ``u`` (eq. 3.7-3.8), optionally robustly (RANSAC over the
  2-correspondence minimal solution, then least squares on the inliers);
* the depths and 3D points (eq. 3.10-3.12, the averaged ``m'''``), for one mirror
  or fused over several;
* the scale ``d`` from a known length (step 3 of the algorithm);
* the expected error of ``u`` (eq. 3.13-3.26);
* the mirrored epipolar line and band (eq. 5.1-5.3).

Two layers:

* kernels on *normalised* coordinates (``f = 1``; see :mod:`core.geometry.camera`):
  :func:`correspondence_matrix`, :func:`normal_from_correspondences`,
  :func:`depths_from_planes`, :func:`points_from_planes`, ...
  Everything is vectorised: points ``(..., N, 2)``, mirrors stacked on a leading
  axis ``(K, ..., N, 2)``.
* pixel front-ends taking an OpenCV :class:`~core.geometry.camera.Camera`:
  :func:`estimate_mirror_plane`, :func:`reconstruct_points`,
  :func:`.epipolar.mirrored_epipolar_lines`, :func:`.epipolar.in_mirrored_epipolar_band`.

Sign conventions: ``u`` is oriented with ``c < 0`` as in the paper, and ``d`` takes
the sign that puts the reconstructed markers in front of the camera (``z > 0``);
for a real rig (camera on the reflecting side) that is ``d < 0`` and ``|d|`` is the
distance from the camera centre to the mirror plane. Before a scale is known
``|d| = 1`` for the first mirror ("relative units").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..common.errors import DegenerateError, InputError
from .camera import Camera


# --------------------------------------------------------------------------- helpers
def _homogeneous(p: np.ndarray) -> np.ndarray:
    """(..., 2) -> (..., 3) with a trailing 1 (the projection ``p`` of eq. 3.2, f = 1)."""
    p = np.asarray(p, dtype=float)
    return np.concatenate([p, np.ones(p.shape[:-1] + (1,))], axis=-1)


def orient_normal(u: np.ndarray) -> np.ndarray:
    """Flip normals ``(..., 3)`` so that ``c < 0`` (the paper's choice, section 3.2)."""
    u = np.asarray(u, dtype=float)
    return np.where(u[..., 2:3] > 0, -u, u)


def reflect_points(points, normal, d) -> np.ndarray:
    """Mirror 3D points ``(..., 3)`` in the plane ``u.x = d``: ``H_u m + 2 d u`` (eq. 3.9).

    The reflection is an involution, so the same call maps virtual points back
    (eq. 3.12, ``H_u^{-1} = H_u``)."""
    m = np.asarray(points, dtype=float)
    u = np.asarray(normal, dtype=float)
    dist = np.sum(m * u, axis=-1, keepdims=True) - np.asarray(d, dtype=float)[..., None]
    return m - 2.0 * dist * u


def tangent_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane orthogonal to unit ``u`` (3,)."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(u, e1)


# ------------------------------------------------------------- normal (eq. 3.5-3.8)
def correspondence_matrix(p, pm) -> np.ndarray:
    """The rows of ``M`` (eq. 3.7) for normalised direct ``p`` and mirrored ``pm``
    points ``(..., N, 2)``: ``[y - y', x' - x, x y' - y x']``, so that ``M u = 0``
    is eq. 3.5, ``p'^T U p = 0``, stacked over correspondences."""
    p = np.asarray(p, dtype=float)
    pm = np.asarray(pm, dtype=float)
    x, y = p[..., 0], p[..., 1]
    xm, ym = pm[..., 0], pm[..., 1]
    return np.stack([y - ym, xm - x, x * ym - y * xm], axis=-1)


def normal_from_correspondences(p, pm, weights=None) -> np.ndarray:
    """Least-squares mirror normal (eq. 3.8): the unit ``u`` minimising ``||M u||``,
    i.e. the right singular vector of ``M`` for its smallest singular value,
    oriented ``c < 0``.

    ``p``, ``pm``: normalised ``(N, 2)``, or batched ``(B, N, 2)`` (then solved
    through the 3x3 eigenproblem of ``M^T M`` for every batch at once). Optional
    per-row ``weights`` ``(..., N)`` (0 excludes a row)."""
    M = correspondence_matrix(p, pm)
    if weights is not None:
        M = M * np.asarray(weights, dtype=float)[..., None]
    if M.ndim == 2:
        # SVD of M itself: better conditioned than the eigenproblem of M^T M.
        _, _, vt = np.linalg.svd(M, full_matrices=False)
        return orient_normal(vt[-1])
    MtM = np.einsum("...ni,...nj->...ij", M, M)
    _, vecs = np.linalg.eigh(MtM)
    return orient_normal(vecs[..., :, 0])


def epipolar_residuals(u, p, pm) -> np.ndarray:
    """Symmetric distance between a correspondence and the mirror geometry ``u``,
    in normalised units (multiply by the focal length for pixels).

    ``M_i . u`` is ``p'^T (u x p)``; dividing by the norms of the two image lines
    ``u x p`` (the mirrored epipolar line of ``p``, eq. 5.2) and ``u x p'`` gives the
    point-to-line distances in the mirrored and the direct view; the result is
    their root mean square. ``u`` ``(..., 3)`` broadcasts against points
    ``(..., N, 2)`` -- e.g. ``u[:, None, :]`` ``(S, 1, 3)`` scores ``S`` hypotheses."""
    u = np.asarray(u, dtype=float)
    p = np.asarray(p, dtype=float)
    pm = np.asarray(pm, dtype=float)
    a, b, c = u[..., 0], u[..., 1], u[..., 2]
    x, y = p[..., 0], p[..., 1]
    xm, ym = pm[..., 0], pm[..., 1]
    num = a * (y - ym) + b * (xm - x) + c * (x * ym - y * xm)  # M_i . u (eq. 3.6)
    den_m = (b - c * y) ** 2 + (c * x - a) ** 2
    den_d = (b - c * ym) ** 2 + (c * xm - a) ** 2
    return np.sqrt(_squared_residuals(num, den_m, den_d))


def _squared_residuals(num, den_m, den_d):
    tiny = 1e-300
    return num * num * (0.5 / np.maximum(den_m, tiny) + 0.5 / np.maximum(den_d, tiny))



# --------------------------------------------------------- depths (eq. 3.10-3.12)
def _plane_terms(x, y, xm, ym, a, b, c, d):
    """Per-point dot products of the normal equations of eq. 3.11, on components.

    With ``A = -H_u p`` and ``B = p'`` (``p = (x, y, 1)``) the system
    ``z A + z' B = 2 d u`` is eq. 3.10 times 2. Because ``H_u`` is orthogonal,
    ``A.A = |p|^2``; the others are ``A.B = 2 (u.p)(u.p') - p.p'``,
    ``A.r = 2 d (u.p)`` and ``B.r = 2 d (u.p')``. Returns those five and ``u.p'``."""
    s = a * x + b * y + c
    sm = a * xm + b * ym + c
    AA = x * x + y * y + 1.0
    BB = xm * xm + ym * ym + 1.0
    AB = 2.0 * s * sm - (x * xm + y * ym + 1.0)
    return AA, BB, AB, 2.0 * d * s, 2.0 * d * sm, sm


def _plane_components(normals, ds, lead_ndim: int):
    """``a, b, c, d`` of K planes, each shaped ``(K, 1, ..., 1)`` to broadcast
    against ``(K, ..., N)``."""
    normals = np.asarray(normals, dtype=float).reshape(-1, 3)
    ds = np.asarray(ds, dtype=float).reshape(-1)
    if normals.shape[0] != ds.shape[0]:
        raise InputError("need one d per mirror normal")
    shape = (normals.shape[0],) + (1,) * lead_ndim
    return (normals[:, 0].reshape(shape), normals[:, 1].reshape(shape), normals[:, 2].reshape(shape),
            ds.reshape(shape))


def _solve_depths(p, pm, normals, ds, visible):
    """Shared solver of :func:`depths_from_planes` and :func:`points_from_planes`."""
    p = np.asarray(p, dtype=float)
    pm = np.asarray(pm, dtype=float)
    if pm.ndim == p.ndim:  # a single mirror given without its K axis
        pm = pm[None]
    a, b, c, d = _plane_components(normals, ds, pm.ndim - 2)
    if a.shape[0] != pm.shape[0]:
        raise InputError(f"{pm.shape[0]} mirrored point sets but {a.shape[0]} mirror planes")
    x, y = p[..., 0], p[..., 1]
    xm, ym = pm[..., 0], pm[..., 1]
    AA, BB, AB, Ar, Br, sm = _plane_terms(x, y, xm, ym, a, b, c, d)
    # Eliminate z'_k = (B.r_k - A.B_k z) / B.B_k, then solve the scalar equation for z.
    num = Ar - AB * Br / BB
    den = AA - AB * AB / BB
    with np.errstate(invalid="ignore", divide="ignore"):
        if visible is None:
            z = num.sum(axis=0) / den.sum(axis=0)
        else:
            vis = np.asarray(visible, dtype=bool)
            z = np.where(vis, num, 0.0).sum(axis=0) / np.where(vis, den, 0.0).sum(axis=0)
        zm = (Br - AB * z) / BB
    return p, pm, (a, b, c, d), z, zm, sm


def depths_from_planes(p, pm, normals, ds, visible=None):
    """Depths of the real markers and of their mirror images (eq. 3.10-3.11).

    ``p``: normalised direct points ``(..., N, 2)``; ``pm``: normalised mirrored
    points ``(K, ..., N, 2)`` for ``K`` mirrors; ``normals`` ``(K, 3)``; ``ds``
    ``(K,)``; ``visible`` ``(K, ..., N)`` says in which mirrors each point is seen
    (default: all).

    For one mirror this is the paper's least-squares solution of
    ``min ||G z - d u||``. A point seen in several mirrors gets the joint least
    squares over all its equations (one shared direct depth ``z``, one virtual
    depth per mirror), solved in closed form by eliminating the virtual depths.

    Returns ``z`` ``(..., N)`` (NaN where the point is in no mirror) and ``zm``
    ``(K, ..., N)`` (NaN where not visible)."""
    *_, z, zm, _ = _solve_depths(p, pm, normals, ds, visible)
    if visible is not None:
        zm = np.where(np.asarray(visible, dtype=bool), zm, np.nan)
    return z, zm


def _points_one_mirror(p, pm, normal, d) -> np.ndarray:
    """:func:`points_from_planes` for one mirror and every point visible, written out:
    the 2x2 normal equations of eq. 3.11 by Cramer's rule, then eq. 3.12's average.
    The common per-frame case (a tracked frame with a known plane)."""
    a, b, c = (float(v) for v in np.asarray(normal, dtype=float).reshape(3))
    d = float(np.asarray(d).reshape(-1)[0])
    x, y = p[..., 0], p[..., 1]
    xm, ym = pm[..., 0], pm[..., 1]
    s = a * x + b * y + c  # u.p
    sm = a * xm + b * ym + c  # u.p'
    AA = x * x + y * y + 1.0
    BB = xm * xm + ym * ym + 1.0
    AB = 2.0 * s * sm - (x * xm + y * ym + 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = (2.0 * d) / (AA * BB - AB * AB)
    z = k * (BB * s - AB * sm)
    zm = k * (AA * sm - AB * s)
    g = 2.0 * (zm * sm - d)  # reflecting z' p' back: m'' = z' p' - g u
    out = np.empty(x.shape + (3,))
    out[..., 0] = 0.5 * (z * x + zm * xm - g * a)
    out[..., 1] = 0.5 * (z * y + zm * ym - g * b)
    out[..., 2] = 0.5 * (z + zm - g * c)
    return out


def points_from_planes(p, pm, normals, ds, visible=None, return_views: bool = False):
    """3D marker positions from correspondences and known planes (eq. 3.10-3.12).

    Each marker is estimated directly (``m = z p``) and, for each mirror it shows
    in, by reflecting its virtual point back: eq. 3.12,
    ``H_u (m' - Theta) + Theta``, which equals ``m' - 2 (u.m' - d) u`` for any
    ``Theta`` on the plane. The result is the average of these estimates; for one
    mirror that is the paper's averaged estimate ``(m + m'')/2``.

    Shapes as :func:`depths_from_planes`; returns ``(..., N, 3)`` (NaN for points in
    no mirror), and with ``return_views`` also the direct estimates ``(..., N, 3)``
    and the reflected-back estimates ``(K, ..., N, 3)`` (NaN where unseen)."""
    if visible is None and not return_views:
        p_arr = np.asarray(p, dtype=float)
        pm_arr = np.asarray(pm, dtype=float)
        one = pm_arr if pm_arr.ndim == p_arr.ndim else (pm_arr[0] if pm_arr.shape[0] == 1 else None)
        if one is not None and np.asarray(normals).size == 3:
            return _points_one_mirror(p_arr, one, normals, ds)
    p, pm, (a, b, c, d), z, zm, sm = _solve_depths(p, pm, normals, ds, visible)
    x, y = p[..., 0], p[..., 1]
    g = 2.0 * (zm * sm - d)  # reflect z' p' back, component by component
    bx = zm * pm[..., 0] - g * a
    by = zm * pm[..., 1] - g * b
    bz = zm - g * c
    if visible is None:
        count = pm.shape[0] + 1.0
        sx, sy, sz = bx.sum(axis=0), by.sum(axis=0), bz.sum(axis=0)
    else:
        vis = np.asarray(visible, dtype=bool)
        count = 1.0 + vis.sum(axis=0)
        sx = np.where(vis, bx, 0.0).sum(axis=0)
        sy = np.where(vis, by, 0.0).sum(axis=0)
        sz = np.where(vis, bz, 0.0).sum(axis=0)
        bx, by, bz = (np.where(vis, v, np.nan) for v in (bx, by, bz))
    fused = np.empty(z.shape + (3,))
    fused[..., 0] = (z * x + sx) / count
    fused[..., 1] = (z * y + sy) / count
    fused[..., 2] = (z + sz) / count
    if return_views:
        return fused, np.stack([z * x, z * y, z], axis=-1), np.stack([bx, by, bz], axis=-1)
    return fused


# ----------------------------------------------------------- expected error (3.13-26)
def expected_normal_covariance(p, pm, u, sigma: float) -> np.ndarray:
    """Covariance ``Gamma_du`` of the estimated normal (eq. 3.25) for isotropic image
    noise of standard deviation ``sigma`` (normalised units: pixels / focal).

    First-order perturbation of the smallest eigenvector of ``M^T M`` (eq. 3.18,
    after Weng et al.): ``du = H Lambda H^T d(M^T M) u`` with
    ``d(M^T M) u = M^T (dM u) + dM^T (M u)`` (eq. 3.21). Each row of ``dM`` is
    linear in the four coordinate errors of its correspondence,
    ``(dM)_i = D_i delta_i`` with ``D_i D_i^T = P_i`` (eq. 3.16), so the covariance
    is ``sigma^2 A (sum_i C_i C_i^T) A`` with ``A = H Lambda H^T`` and
    ``C_i = M_i^T (u^T D_i) + (M_i u) D_i`` -- eq. 3.22-3.25 assembled point by
    point instead of through the ``9 x 3n`` block matrices."""
    p = np.asarray(p, dtype=float)
    pm = np.asarray(pm, dtype=float)
    u = np.asarray(u, dtype=float)
    M = correspondence_matrix(p, pm)
    lam, H = np.linalg.eigh(M.T @ M)  # ascending: lambda_1 <= lambda_2 <= lambda_3
    Lam = np.diag([0.0, 1.0 / (lam[0] - lam[1]), 1.0 / (lam[0] - lam[2])])
    A = H @ Lam @ H.T
    x, y = p[:, 0], p[:, 1]
    xm, ym = pm[:, 0], pm[:, 1]
    n = p.shape[0]
    # D_i: derivative of row i of M w.r.t. (dx, dy, dx', dy').
    D = np.zeros((n, 3, 4))
    D[:, 0, 1], D[:, 0, 3] = 1.0, -1.0
    D[:, 1, 0], D[:, 1, 2] = -1.0, 1.0
    D[:, 2, 0], D[:, 2, 1], D[:, 2, 2], D[:, 2, 3] = ym, -xm, -y, x
    uD = np.einsum("k,nkj->nj", u, D)  # (n, 4) = u^T D_i
    r = M @ u  # (n,) algebraic residuals, zero for noise-free data
    C = M[:, :, None] * uD[:, None, :] + r[:, None, None] * D  # (n, 3, 4)
    S = np.einsum("nij,nkj->ik", C, C)
    return sigma**2 * A @ S @ A


def expected_normal_error(p, pm, u, sigma: float) -> float:
    """Expected Euclidean error of the unit normal, ``sqrt(trace Gamma_du)``
    (eq. 3.26); for small errors this is the expected angle in radians."""
    return float(np.sqrt(max(np.trace(expected_normal_covariance(p, pm, u, sigma)), 0.0)))


def estimate_image_noise(p, pm, u) -> float:
    """Noise standard deviation (normalised units) implied by the algebraic residuals:
    ``E[(M_i u)^2] = sigma^2 u^T P_i u`` (eq. 3.16), with 2 degrees of freedom
    taken by ``u``."""
    M = correspondence_matrix(p, pm)
    r = M @ u
    x, y = np.asarray(p)[:, 0], np.asarray(p)[:, 1]
    xm, ym = np.asarray(pm)[:, 0], np.asarray(pm)[:, 1]
    a, b, c = u
    w = (c * ym - b) ** 2 + (a - c * xm) ** 2 + (b - c * y) ** 2 + (c * x - a) ** 2  # u^T P_i u
    n = r.size
    if n <= 2:
        return float("nan")
    return float(np.sqrt(np.sum(r**2) / np.sum(w) * n / (n - 2)))


# ------------------------------------------------------------------ mirror planes
@dataclass
class MirrorPlane:
    """A mirror plane ``normal . x = d`` in the camera frame, with how it was found.

    ``inliers`` marks the correspondences used; ``noise_px`` is the image noise
    implied by their residuals and ``expected_error_deg`` the eq. 3.26 expected
    error of the normal for that noise."""

    normal: np.ndarray
    d: float = -1.0
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    noise_px: float = float("nan")
    expected_error_deg: float = float("nan")
    iterations: int = 0

    @property
    def n_inliers(self) -> int:
        return int(np.count_nonzero(self.inliers))

    def to_dict(self) -> dict:
        return {
            "normal": [float(v) for v in self.normal],
            "d": float(self.d),
            "pairs": int(self.inliers.size),
            "inliers": self.n_inliers,
            "noise_px": _finite_or_none(self.noise_px),
            "expected_normal_error_deg": _finite_or_none(self.expected_error_deg),
            "ransac_iterations": int(self.iterations),
        }


def _finite_or_none(v):
    v = float(v)
    return v if np.isfinite(v) else None


def _ransac_normal(p, pm, threshold, confidence, max_iterations, rng, batch=16):
    """2-correspondence RANSAC for the mirror normal on normalised points.

    Minimal solution: ``u`` is orthogonal to two rows of ``M``, so
    ``u = M_i x M_j``. Hypotheses are scored in batches with the truncated
    quadratic (MSAC) cost of the squared :func:`epipolar_residuals`, each pair counted once,
    and a pair only counts as an inlier when both its depths are positive (the
    marker and its mirror image lie in front of the camera). The number of
    iterations adapts to the inlier ratio for the requested ``confidence``."""
    n = p.shape[0]
    M = correspondence_matrix(p, pm)
    x, y, xm, ym = p[:, 0], p[:, 1], pm[:, 0], pm[:, 1]
    t2 = threshold * threshold
    best_cost, best_u, best_in = np.inf, None, None
    needed, done = max_iterations, 0
    while done < min(needed, max_iterations):
        i = rng.integers(0, n, size=batch)
        j = (i + rng.integers(1, n, size=batch)) % n  # j != i
        cand = np.cross(M[i], M[j])
        norm = np.linalg.norm(cand, axis=1)
        scale = np.linalg.norm(M[i], axis=1) * np.linalg.norm(M[j], axis=1)
        ok = norm > 1e-9 * np.maximum(scale, 1e-300)
        done += batch
        if not np.any(ok):
            continue
        cand = orient_normal(cand[ok] / norm[ok, None])  # (S, 3)
        a, b, c = cand[:, 0:1], cand[:, 1:2], cand[:, 2:3]
        num = cand @ M.T  # (S, N): M_i . u
        res2 = _squared_residuals(num, (b - c * y) ** 2 + (c * x - a) ** 2, (b - c * ym) ** 2 + (c * xm - a) ** 2)
        AA, BB, AB, Ar, Br, _ = _plane_terms(x, y, xm, ym, a, b, c, -1.0)
        # Only the signs of the depths matter here, and AA*BB - AB^2 >= 0
        # (Cauchy-Schwarz, |A| = |p|), so the numerators of eq. 3.11 suffice.
        z = BB * Ar - AB * Br
        zm = AA * Br - AB * Ar
        close = res2 < t2
        # The sign of d is free until depths are known: pick the sign per hypothesis
        # that puts most of its close pairs in front of the camera.
        pos = close & (z > 0) & (zm > 0)
        neg = close & (z < 0) & (zm < 0)
        front = np.where((pos.sum(1) >= neg.sum(1))[:, None], pos, neg)
        cost = np.where(front, res2, t2).sum(axis=1)
        k = int(np.argmin(cost))
        if cost[k] < best_cost:
            best_cost, best_u, best_in = cost[k], cand[k], front[k]
            w = best_in.mean()
            if w >= 1.0:
                needed = done
            elif w > 0:
                needed = int(np.ceil(np.log(1.0 - confidence) / np.log(1.0 - w * w)))
    return best_u, best_in, done


def _depth_sign(p, pm, u) -> float:
    """Sign of ``d`` that puts the median marker in front of the camera."""
    z, _ = depths_from_planes(p, pm[None], u[None], np.array([-1.0]))
    return -1.0 if np.nanmedian(z) > 0 else 1.0


def _check_not_degenerate(p, pm, focal_px: float = 1.0, label: str = "mirror", min_spread_px: float = 1.0):
    """Reject point sets that cannot determine a plane: too few, or all on one image
    line -- the RMS distance from the best-fitting line is under ``min_spread_px``
    in the direct or the mirrored view (then the normal is undetermined or at the
    mercy of noise)."""
    n = p.shape[0]
    if n < 3:
        raise DegenerateError(f"{label}: at least 3 correspondences are needed, got {n}")
    for pts, view in ((p, "direct"), (pm, "mirrored")):
        centred = pts - pts.mean(axis=0)
        cov = centred.T @ centred / n
        minor = np.sqrt(max(np.linalg.eigvalsh(cov)[0], 0.0)) * focal_px
        if minor < min_spread_px:
            raise DegenerateError(
                f"{label}: all {view} points lie on one image line (spread {minor:.2g} px); "
                "the mirror plane is undetermined"
            )
    sv = np.linalg.svd(correspondence_matrix(p, pm), compute_uv=False)
    if sv[1] <= 1e-9 * sv[0]:
        raise DegenerateError(f"{label}: the correspondences do not determine a mirror normal")


def estimate_mirror_plane(
    direct_px,
    mirror_px,
    camera: Camera,
    *,
    robust: bool = True,
    threshold_px: float = 2.0,
    confidence: float = 0.999,
    max_iterations: int = 20000,
    seed: int = 0,
    refine_rounds: int = 5,
    label: str = "mirror",
) -> MirrorPlane:
    """Estimate a mirror plane from pixel correspondences ``(N, 2)`` each.

    ``robust=False`` is the paper's closed form on all pairs (eq. 3.8). With
    ``robust=True`` (default) wrong correspondences are rejected first by
    :func:`_ransac_normal` (``threshold_px`` is the symmetric epipolar distance,
    in pixels, that still counts as an inlier), then the normal is re-estimated by
    eq. 3.8 on the inliers and the inlier set updated, ``refine_rounds`` times.

    ``d`` is returned with ``|d| = 1`` (relative units; see :func:`scale_to_length`).
    """
    direct_px = np.asarray(direct_px, dtype=float)
    mirror_px = np.asarray(mirror_px, dtype=float)
    if direct_px.shape != mirror_px.shape or direct_px.ndim != 2 or direct_px.shape[1] != 2:
        raise InputError(f"{label}: direct and mirrored points must both have shape (N, 2)")
    if not (np.all(np.isfinite(direct_px)) and np.all(np.isfinite(mirror_px))):
        raise InputError(f"{label}: point coordinates must be finite")
    p = camera.normalize(direct_px)
    pm = camera.normalize(mirror_px)
    _check_not_degenerate(p, pm, camera.focal_px, label)
    n = p.shape[0]
    f = camera.focal_px
    iterations = 0
    if robust:
        rng = np.random.default_rng(seed)
        u, inliers, iterations = _ransac_normal(p, pm, threshold_px / f, confidence, max_iterations, rng)
        if u is None or inliers.sum() < 3:
            raise DegenerateError(
                f"{label}: no mirror plane explains at least 3 correspondences within {threshold_px} px"
            )
        for _ in range(refine_rounds):
            u_new = normal_from_correspondences(p[inliers], pm[inliers])
            res = epipolar_residuals(u_new, p, pm)
            sign = _depth_sign(p[inliers], pm[inliers], u_new)
            z, zm = depths_from_planes(p, pm[None], u_new[None], np.array([sign]))
            new_in = (res < threshold_px / f) & (z > 0) & (zm[0] > 0)
            if new_in.sum() < 3:
                break
            converged = np.array_equal(new_in, inliers)
            u, inliers = u_new, new_in
            if converged:
                break
        u = normal_from_correspondences(p[inliers], pm[inliers])
    else:
        inliers = np.ones(n, dtype=bool)
        u = normal_from_correspondences(p, pm)
    sign = _depth_sign(p[inliers], pm[inliers], u)
    pin, pmin = p[inliers], pm[inliers]
    sigma = estimate_image_noise(pin, pmin, u) if pin.shape[0] > 2 else float("nan")
    err = float("nan")
    if np.isfinite(sigma) and pin.shape[0] >= 3:
        err = np.degrees(expected_normal_error(pin, pmin, u, sigma))
    return MirrorPlane(
        normal=u, d=float(sign), inliers=inliers, noise_px=sigma * f,
        expected_error_deg=float(err), iterations=iterations,
    )


def link_mirror_scales(p, pm, visible, normals, ds) -> tuple[np.ndarray, int]:
    """Put the ``d`` of every mirror in the units of mirror 0.

    Each mirror's plane is found only up to scale. For a marker seen in mirror 0
    and mirror ``k``, the depths computed with each mirror alone must agree; the
    median ratio over all such markers rescales ``d_k``. Returns the new ``ds``
    and the smallest number of shared markers behind any link (0 when some mirror
    shares none with mirror 0; that mirror's ``d`` is then left unchanged)."""
    normals = np.asarray(normals, dtype=float)
    ds = np.array(ds, dtype=float)
    shared_min = None
    for k in range(1, normals.shape[0]):
        both = visible[0] & visible[k]
        if not np.any(both):
            shared_min = 0
            continue
        z0, _ = depths_from_planes(p[both], pm[0][both][None], normals[:1], ds[:1])
        zk, _ = depths_from_planes(p[both], pm[k][both][None], normals[k:k + 1], ds[k:k + 1])
        ds[k] *= float(np.median(z0 / zk))
        cnt = int(both.sum())
        shared_min = cnt if shared_min is None else min(shared_min, cnt)
    return ds, (shared_min if shared_min is not None else 0)


# ------------------------------------------------------------------------- scale
def scale_to_length(points, index_a: int, index_b: int, length: float) -> float:
    """The scale ``s`` of step 3 of the algorithm: known length / estimated length.

    Multiply the points and every mirror's ``d`` by ``s``."""
    pts = np.asarray(points, dtype=float)
    est = float(np.linalg.norm(pts[index_a] - pts[index_b]))
    if not np.isfinite(est) or est <= 0:
        raise DegenerateError("the two points of the known length coincide; cannot fix the scale")
    if not (np.isfinite(length) and length > 0):
        raise InputError("the known length must be a positive number")
    return float(length) / est


# ---------------------------------------------------------------- pixel front-end
@dataclass
class Reconstruction:
    """3D markers from one frame of correspondences."""

    points: np.ndarray  # (N, 3) fused m''' per marker
    direct: np.ndarray  # (N, 3) m = z p
    mirrored_back: np.ndarray  # (K, N, 3) m'' per mirror (NaN where unseen)


def reconstruct_points(direct_px, mirror_px, camera: Camera, planes, visible=None) -> Reconstruction:
    """Reconstruct markers from pixels: ``direct_px`` ``(N, 2)``, ``mirror_px``
    ``(K, N, 2)`` (or ``(N, 2)`` for one mirror), planes a sequence of
    :class:`MirrorPlane`, ``visible`` ``(K, N)`` (eq. 3.10-3.12)."""
    direct_px = np.asarray(direct_px, dtype=float)
    mirror_px = np.asarray(mirror_px, dtype=float)
    if mirror_px.ndim == direct_px.ndim:
        mirror_px = mirror_px[None]
    if isinstance(planes, MirrorPlane):
        planes = [planes]
    normals = np.stack([pl.normal for pl in planes])
    ds = np.array([pl.d for pl in planes])
    p = camera.normalize(direct_px)
    if visible is None:
        pm = camera.normalize(mirror_px)
    else:
        visible = np.asarray(visible, dtype=bool)
        pm = camera.normalize(np.where(visible[..., None], mirror_px, 0.0))
    fused, m, back = points_from_planes(p, pm, normals, ds, visible, return_views=True)
    return Reconstruction(points=fused, direct=m, mirrored_back=back)


__all__ = [
    "MirrorPlane",
    "Reconstruction",
    "correspondence_matrix",
    "normal_from_correspondences",
    "epipolar_residuals",
    "depths_from_planes",
    "points_from_planes",
    "reflect_points",
    "expected_normal_covariance",
    "expected_normal_error",
    "estimate_image_noise",
    "estimate_mirror_plane",
    "link_mirror_scales",
    "scale_to_length",
    "reconstruct_points",
    "orient_normal",
    "tangent_basis",
]
