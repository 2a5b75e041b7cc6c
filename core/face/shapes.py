"""Turning per-frame vertex displacements into shape keys (bpy-free part of the bake).

``frames`` mode: one key per frame (the displacements themselves).
``pca`` mode: the eigen-deformations of Rurainsky & Eisert, section 4. The
displacements are stacked as columns of ``A (3V, F)``; the eigenvectors of
``A A^T`` come from the smaller ``A^T A (F, F)`` (``A A^T e = λ e`` with
``e = A w / sqrt(λ)``), and ``A ≈ Eig_K (Eig_K^T A)``. The decomposition is not
centred: the neutral face is the basis key, so a performance made of K shapes is
reproduced exactly by K modes. Each mode is scaled so its weights peak at ±1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..common.errors import InputError


@dataclass
class PCAShapes:
    modes: np.ndarray      # (K, V, 3) mm, each a shape-key offset
    weights: np.ndarray    # (F, K) the keys' values per frame
    max_error_mm: float    # largest vertex error of the reconstruction over all frames
    mean_error_mm: float   # mean vertex error
    energy: np.ndarray     # (K,) fraction of the squared deformation each mode explains


def _eigen_deformations(A, k: int):
    """Unit eigen-deformations ``(k, 3V)`` of ``A A^T`` from ``A^T A`` (rows of ``A`` = frames),
    and all eigenvalues, largest first; modes with a zero eigenvalue stay zero."""
    lam, W = np.linalg.eigh(A @ A.T)
    order = np.argsort(lam)[::-1]
    lam, W = np.maximum(lam[order], 0.0), W[:, order]
    E = np.zeros((k, A.shape[1]))
    keep = lam[:k] > lam[0] * 1e-18 if lam[0] > 0 else np.zeros(k, bool)
    E[keep] = (W[:, :k][:, keep].T @ A) / np.sqrt(lam[:k][keep])[:, None]
    return E, lam


def pca_shapes(displacements, n_modes: int) -> PCAShapes:
    D = np.asarray(displacements, float)
    if D.ndim != 3 or D.shape[2] != 3:
        raise InputError("displacements must have shape (frames, vertices, 3)")
    F, V, _ = D.shape
    if not 1 <= n_modes <= min(F, 3 * V):
        raise InputError(f"--modes must be between 1 and {min(F, 3 * V)} for this take")
    A = D.reshape(F, 3 * V)                       # rows = frames (A^T of the text)
    k = n_modes
    E, lam = _eigen_deformations(A, k)
    coeff = A @ E.T                               # (F, K)
    peak = np.abs(coeff).max(0)
    peak[peak == 0] = 1.0
    weights = coeff / peak
    modes = (E * peak[:, None]).reshape(k, V, 3)
    err = np.linalg.norm((A - coeff @ E).reshape(F, V, 3), axis=2)
    total = max(float(lam.sum()), 1e-300)
    return PCAShapes(modes=modes, weights=weights, max_error_mm=float(err.max()), mean_error_mm=float(err.mean()),
                     energy=lam[:k] / total)


def pca_error_table(displacements, ks=(1, 2, 3, 8, 23, 65)) -> list:
    """Max, mean and RMS reconstruction error (mm) for each K, as in Rurainsky & Eisert's Table 2.
    The RMS never grows with K (each K projects onto a larger subspace); a single vertex's
    error, and so the max, can."""
    D = np.asarray(displacements, float)
    F, V, _ = D.shape
    A = D.reshape(F, 3 * V)
    ks = [k for k in ks if k <= F]
    E_all, _ = _eigen_deformations(A, max(ks, default=0))   # one decomposition for every K
    rows = []
    for k in ks:
        E = E_all[:k]
        err = np.linalg.norm((A - (A @ E.T) @ E).reshape(F, V, 3), axis=2)
        rows.append({"modes": int(k), "max_mm": float(err.max()), "mean_mm": float(err.mean()),
                     "rms_mm": float(np.sqrt(np.mean(err ** 2)))})
    return rows
