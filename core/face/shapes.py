"""Turning per-frame vertex displacements into shape keys (bpy-free part of the bake).

``frames`` mode: one key per frame (the displacements themselves).
``pca`` mode: the eigen-deformations of Rurainsky & Eisert, section 4. The
displacements are stacked as columns of ``A (3V, F)``; the eigenvectors of
``A A^T`` come from the smaller ``A^T A (F, F)`` (``A A^T e = λ e`` with
``e = A w / sqrt(λ)``), and ``A ≈ Eig_K (Eig_K^T A)``. The decomposition is not
centred: the neutral face is the basis key, so a performance made of K shapes is
reproduced exactly by K modes. Each mode is scaled so its weights peak at ±1.

A long take is decomposed on :data:`PCA_BASIS_FRAMES` of its frames, evenly spread, and every frame is then
projected on those modes a block at a time: ``A^T A`` of a 10-minute take at 60 frames/s would be a
36,000-square matrix (10 GB), and the take's displacements 4 GB more. Measured on a 3,600-frame take at 60
frames/s: 8 modes from 2,000 of its frames reconstruct it to 3.480 mm max, 0.0289 mm mean, against 3.487 / 0.0288
from all of them (23 modes: 0.172 / 0.0003 against 0.171 / 0.0003), in a quarter of the time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..common.errors import InputError

PCA_BASIS_FRAMES = 2000   # frames of a take the eigen-deformations are computed from (all of a shorter take)
BLOCK_FRAMES = 256        # frames deformed, projected or written at a time (28 MB of displacements at 4,600 vertices)


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


class FrameSource:
    """Displacements ``(F, V, 3)`` served some frames at a time: ``n_frames`` and ``at(index)`` (a slice or
    indices), and from them :meth:`blocks` -- what :func:`pca_shapes` and the shape-key writer take
    (:class:`ArrayDisplacements`, :class:`..animate.Animation`)."""

    n_frames: int

    def at(self, index) -> np.ndarray:
        raise NotImplementedError

    def blocks(self, size: int = BLOCK_FRAMES):
        """``(offset, displacements (n, V, 3))`` for consecutive blocks of at most ``size`` frames."""
        for f0 in range(0, self.n_frames, size):
            yield f0, self.at(slice(f0, min(self.n_frames, f0 + size)))


class ArrayDisplacements(FrameSource):
    """Displacements ``(F, V, 3)`` held in memory."""

    def __init__(self, displacements):
        self.array = np.asarray(displacements, float)
        if self.array.ndim != 3 or self.array.shape[2] != 3:
            raise InputError("displacements must have shape (frames, vertices, 3)")
        self.n_frames = len(self.array)

    def at(self, index) -> np.ndarray:
        return self.array[index]


def displacement_source(displacements):
    """``displacements`` as a source of frames: a :class:`FrameSource` (an :class:`..animate.Animation`) as it
    is, an array wrapped in :class:`ArrayDisplacements`."""
    return displacements if isinstance(displacements, FrameSource) else ArrayDisplacements(displacements)


def pca_shapes(displacements, n_modes: int, basis_frames: int = PCA_BASIS_FRAMES) -> PCAShapes:
    """K eigen-deformations of ``displacements`` (an array ``(F, V, 3)`` or a source of frames,
    :func:`displacement_source`) and each frame's weights on them: the modes from ``basis_frames`` of the frames
    evenly spread (all of them in a take of at most that many), the weights and the errors from every frame,
    a block of frames at a time."""
    src = displacement_source(displacements)
    F = src.n_frames
    basis = np.unique(np.linspace(0, F - 1, min(F, basis_frames)).round().astype(int))
    S = src.at(basis)
    V = S.shape[1]
    if not 1 <= n_modes <= min(len(basis), 3 * V):
        raise InputError(f"--modes must be between 1 and {min(len(basis), 3 * V)} for this take")
    k = n_modes
    E, lam = _eigen_deformations(S.reshape(len(basis), 3 * V), k)   # rows = frames (A^T of the text)
    del S
    coeff = np.empty((F, k))
    err_max, err_sum = 0.0, 0.0
    for f0, block in src.blocks():
        A = block.reshape(len(block), 3 * V)
        c = coeff[f0:f0 + len(block)] = A @ E.T
        err = np.linalg.norm((A - c @ E).reshape(len(block), V, 3), axis=2)
        err_max, err_sum = max(err_max, float(err.max())), err_sum + float(err.sum())
    peak = np.abs(coeff).max(0)
    peak[peak == 0] = 1.0
    weights = coeff / peak
    modes = (E * peak[:, None]).reshape(k, V, 3)
    total = max(float(lam.sum()), 1e-300)
    return PCAShapes(modes=modes, weights=weights, max_error_mm=err_max, mean_error_mm=err_sum / (F * V),
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
