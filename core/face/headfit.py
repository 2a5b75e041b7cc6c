"""Fitting the generic head to a scan of the performer (Lin 2003, section 7.3).

1. A similarity transform (Umeyama) puts the head's landmarks (``lm_<name>``) onto
   the scan's landmark points.
2. RBF scattering (eq. 7.1-7.2) of the remaining landmark displacements deforms the
   whole head, as in the paper.
3. Beyond the paper, ``rounds`` of projection onto the scan: control vertices spread
   over the head (farthest-point samples where the scan is within reach) move to the
   nearest point of the scan's surface (point-to-plane at the nearest scan vertex),
   and a regularised RBF (``smoothing``) carries those moves to every vertex, so the
   head hugs the scan without taking its noise or its topology. Landmarks stay pinned.

The residual reported is the distance from each fitted vertex within reach of the
scan to the scan's surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..common.errors import InputError
from ..geometry.rigid import similarity_fit
from .head import NOT_SKIN, HeadModel, farthest_points, vertex_normals
from .rbf import RBFScattering


@dataclass
class FitResult:
    vertices: np.ndarray       # (V, 3) fitted head, scan units (mm)
    scale: float               # similarity scale head -> scan
    landmark_rms_mm: float     # after the fit
    residual_rms_mm: float     # fitted vertices within reach -> scan surface
    residual_p95_mm: float
    residual_max_mm: float
    covered: int               # vertices within reach of the scan
    rounds: list               # per round: RMS residual of the controls before the move


def fit_head(head: HeadModel, scan_vertices, scan_faces=None, scan_landmarks: dict | None = None, rounds: int = 4,
             n_controls: int = 900, reach_mm: float = 12.0, k: float = 30.0, smoothing: float = 1e-3,
             exclude_groups=NOT_SKIN) -> FitResult:
    """Fit ``head`` to a scan ``(N, 3)`` (triangles ``(T, 3)`` optional) given ``{landmark: (3,) point}``."""
    from scipy.spatial import cKDTree

    S = np.asarray(scan_vertices, float)
    if S.ndim != 2 or S.shape[1] != 3 or len(S) == 0:
        raise InputError("the scan is empty (it needs vertices of shape (N, 3))")
    if not np.all(np.isfinite(S)):
        raise InputError("the scan has non-finite vertices")
    lms = head.landmarks()
    scan_landmarks = scan_landmarks or {}
    names = [n for n in sorted(scan_landmarks) if n in lms]
    if len(names) < 4:
        raise InputError(f"fitting needs at least 4 landmark pairs shared by the head and the scan; got {len(names)} "
                         f"(head landmarks: {', '.join(sorted(lms))})")
    src = head.vertices[[lms[n] for n in names]]
    dst = np.array([scan_landmarks[n] for n in names], float)
    s, R, t = similarity_fit(src, dst)
    V = s * head.vertices @ R.T + t
    lm_idx = np.array([lms[n] for n in names])
    rbf = RBFScattering(V[lm_idx], k=k * s)
    V = V + rbf(V, dst - V[lm_idx])
    tree = cKDTree(S)
    normals = None if scan_faces is None or len(scan_faces) == 0 else vertex_normals(S, scan_faces)

    # a scan is open (cut off behind the face, holes): a head vertex whose nearest scan point
    # lies on the scan's border is beyond the scan, not on it -- it must not be pulled onto the border
    border = np.zeros(len(S), bool)
    if normals is not None:
        F_ = np.asarray(scan_faces, np.int64)
        e = np.sort(np.concatenate([F_[:, [0, 1]], F_[:, [1, 2]], F_[:, [2, 0]]]), axis=1)
        uniq, count = np.unique(e, axis=0, return_counts=True)
        border[uniq[count == 1].ravel()] = True

    def closest(points):
        d, j = tree.query(points)
        if normals is None:
            return S[j], d, border[j]
        off = np.einsum("ij,ij->i", points - S[j], normals[j])
        proj = points - off[:, None] * normals[j]
        return proj, np.abs(off), border[j]

    allowed = head.skin_mask(exclude_groups)
    history = []
    for _ in range(rounds):
        target, dist, off_scan = closest(V)
        near = np.flatnonzero(allowed & (dist < reach_mm * s) & ~off_scan)
        near = np.setdiff1d(near, lm_idx)
        if near.size < 4:
            break
        ctrl = near[farthest_points(V[near], n_controls)]
        move = target[ctrl] - V[ctrl]
        history.append(float(np.sqrt(np.mean(np.sum(move ** 2, axis=1)))))
        cidx = np.r_[ctrl, lm_idx]
        u = np.r_[move, dst - V[lm_idx]]
        rbf = RBFScattering(V[cidx], k=k * s, smoothing=smoothing)
        V = V + rbf(V, u)
    _, dist, off_scan = closest(V)
    cov = allowed & (dist < reach_mm * s) & ~off_scan
    res = dist[cov]
    lm_rms = float(np.sqrt(np.mean(np.sum((V[lm_idx] - dst) ** 2, axis=1))))
    return FitResult(vertices=V, scale=float(s), landmark_rms_mm=lm_rms,
                     residual_rms_mm=float(np.sqrt(np.mean(res ** 2))) if res.size else float("nan"),
                     residual_p95_mm=float(np.percentile(res, 95)) if res.size else float("nan"),
                     residual_max_mm=float(res.max()) if res.size else float("nan"), covered=int(cov.sum()),
                     rounds=history)


def subdivide(vertices, triangles, levels: int = 1):
    """Midpoint subdivision of a triangle mesh (each level: 4 triangles per triangle)."""
    V = np.asarray(vertices, float)
    T = np.asarray(triangles, np.int64)
    for _ in range(levels):
        e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), 1)
        uniq, inv = np.unique(e, axis=0, return_inverse=True)
        mids = len(V) + inv.reshape(3, -1).T            # (T, 3): midpoints of edges 01, 12, 20
        V = np.r_[V, 0.5 * (V[uniq[:, 0]] + V[uniq[:, 1]])]
        a, b, c = T.T
        m01, m12, m20 = mids.T
        T = np.concatenate([np.c_[a, m01, m20], np.c_[m01, b, m12], np.c_[m20, m12, c], np.c_[m01, m12, m20]])
    return V, T
