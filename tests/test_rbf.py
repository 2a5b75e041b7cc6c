"""RBF data scattering, eq. 7.1-7.2."""

from __future__ import annotations

import numpy as np
import pytest

from mirrorcap.core.common.errors import DegenerateError, InputError
from mirrorcap.core.face.rbf import RBFScattering
from mirrorcap.synthetic.simulate import face_rig


@pytest.fixture(scope="module")
def controls():
    rig = face_rig(n_markers=120, seed=3, layout="even")
    rng = np.random.default_rng(0)
    return rig.points, rng.normal(0, 2.0, (120, 3))


def test_interpolates_the_control_points(controls):
    centres, u = controls
    rbf = RBFScattering(centres)
    assert np.allclose(rbf(centres, u), u, atol=1e-9)
    coef = rbf.coefficients(u)
    # side conditions of eq. 7.2: sum c_i = 0 and sum c_i m_i^T = 0
    assert np.allclose(coef[:-4].sum(axis=0), 0, atol=1e-9)
    assert np.allclose(centres.T @ coef[:-4], 0, atol=1e-6)


def test_matches_the_literal_eq_7_2_system(controls):
    centres, u = controls
    rbf = RBFScattering(centres)
    A = rbf.system_matrix()
    n = len(centres)
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    assert np.allclose(A[:n, :n], np.exp(-d / 16.0))
    assert np.allclose(A[:n, n:n + 3], centres) and np.allclose(A[:n, -1], 1) and np.all(A[n:, n:] == 0)
    rhs = np.r_[u, np.zeros((4, 3))]
    assert np.allclose(rbf.coefficients(u), np.linalg.solve(A, rhs), atol=1e-8)


def test_reproduces_an_affine_field_exactly(controls):
    centres, _ = controls
    M = np.array([[0.01, 0.002, 0.0], [0.0, -0.02, 0.01], [0.003, 0.0, 0.015]])
    t = np.array([1.0, -2.0, 0.5])
    u = centres @ M.T + t
    rbf = RBFScattering(centres)
    coef = rbf.coefficients(u)
    assert np.allclose(coef[:-4], 0, atol=1e-9)  # no radial part needed
    far = np.random.default_rng(1).normal(0, 100, (50, 3)) + [0, 0, 600]
    assert np.allclose(rbf(far, u), far @ M.T + t, atol=1e-8)


def test_batches_of_frames_equal_single_solves(controls):
    centres, u = controls
    rbf = RBFScattering(centres)
    frames = np.stack([u * s for s in (0.5, 1.0, -2.0)])
    verts = np.random.default_rng(2).normal(0, 60, (3000, 3)) + [0, 0, 600]
    batched = rbf.evaluate(verts, rbf.coefficients(frames), chunk=700)
    assert batched.shape == (3, 3000, 3)
    for f in range(3):
        assert np.allclose(batched[f], rbf(verts, frames[f]), atol=1e-10)


def test_scipy_kernels_are_an_option(controls):
    from scipy.interpolate import RBFInterpolator

    centres, u = controls
    pts = centres[:10] + 1.0
    ours = RBFScattering(centres, kernel="thin_plate_spline")(pts, u)
    assert np.allclose(ours, RBFInterpolator(centres, u, kernel="thin_plate_spline", degree=1)(pts))
    assert np.allclose(RBFScattering(centres, kernel="thin_plate_spline")(centres, u), u, atol=1e-6)


def test_degenerate_control_points():
    flat = np.c_[np.random.default_rng(3).normal(size=(10, 2)), np.zeros(10)]
    with pytest.raises(DegenerateError, match="plane"):
        RBFScattering(flat)
    pts = np.random.default_rng(4).normal(size=(6, 3))
    with pytest.raises(DegenerateError, match="coincide"):
        RBFScattering(np.vstack([pts, pts[:1]]))
    with pytest.raises(InputError):
        RBFScattering(np.zeros((0, 3)))
    with pytest.raises(InputError, match="displacements"):
        RBFScattering(pts).coefficients(np.zeros((5, 3)))
