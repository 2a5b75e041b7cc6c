"""The mirror geometry core against the equations of Lin (2003), ch. 3 and 5."""

from __future__ import annotations

import numpy as np
import pytest

from mirrorcap.core.geometry import epipolar, refine
from mirrorcap.core.geometry import mirror as mr
from mirrorcap.synthetic import simulate as sim
from mirrorcap.core.geometry.camera import Camera, angle_deg
from mirrorcap.core.common.errors import DegenerateError, InputError


def _views(camera, pts, planes, noise=0.0, seed=0, quantize=False):
    rng = np.random.default_rng(seed)
    direct, mirrored = sim.observe(pts, planes, camera, noise_px=noise, rng=rng, quantize=quantize)
    return direct, mirrored


# ------------------------------------------------------------------ eq. 3.5-3.8
def test_correspondence_matrix_annihilates_true_normal(paper_camera, cube_scene):
    pts, normal, d = cube_scene
    direct, mirrored = _views(paper_camera, pts, [(normal, d)])
    p, pm = paper_camera.normalize(direct), paper_camera.normalize(mirrored[0])
    M = mr.correspondence_matrix(p, pm)
    assert M.shape == (60, 3)
    assert np.max(np.abs(M @ normal)) < 1e-14
    # eq. 3.5: p'^T U p = 0 with U the cross-product matrix of u
    a, b, c = normal
    U = np.array([[0, -c, b], [c, 0, -a], [-b, a, 0]])
    ph = np.c_[p, np.ones(60)]
    pmh = np.c_[pm, np.ones(60)]
    assert np.allclose(np.einsum("ni,ij,nj->n", pmh, U, ph), M @ normal, atol=1e-15)


def test_noise_free_normal_and_points_to_1e9(paper_camera, cube_scene):
    pts, normal, d = cube_scene
    direct, mirrored = _views(paper_camera, pts, [(normal, d)])
    plane = mr.estimate_mirror_plane(direct, mirrored[0], paper_camera, robust=False)
    assert plane.normal[2] < 0
    assert np.linalg.norm(plane.normal - normal) < 1e-9
    # with the true d the points are absolute
    rec = mr.reconstruct_points(direct, mirrored, paper_camera, [mr.MirrorPlane(plane.normal, d)])
    rel = np.linalg.norm(rec.points - pts, axis=1) / np.linalg.norm(pts, axis=1)
    assert rel.max() < 1e-9
    # in relative units (|d| = 1), then scaled by a known length (step 3)
    rec = mr.reconstruct_points(direct, mirrored, paper_camera, [plane])
    s = mr.scale_to_length(rec.points, 0, 1, np.linalg.norm(pts[0] - pts[1]))
    assert np.max(np.linalg.norm(rec.points * s - pts, axis=1) / np.linalg.norm(pts, axis=1)) < 1e-9
    assert abs(plane.d * s - d) / abs(d) < 1e-9
    assert plane.d < 0  # camera on the reflecting side


def test_robust_estimate_is_exact_without_noise(paper_camera, cube_scene):
    pts, normal, d = cube_scene
    direct, mirrored = _views(paper_camera, pts, [(normal, d)])
    plane = mr.estimate_mirror_plane(direct, mirrored[0], paper_camera)
    assert plane.n_inliers == 60
    assert np.linalg.norm(plane.normal - normal) < 1e-9


def test_batched_normals_match_single(paper_camera):
    rng = np.random.default_rng(2)
    normal, d = sim.mirror_plane_from_angles(30.0, 15.0, [0, 0, 40000.0], 12000.0)
    ps, pms = [], []
    for _ in range(4):
        direct, mirrored = _views(paper_camera, sim.random_cube_points(40, rng), [(normal, d)], noise=1.0,
                                  seed=int(rng.integers(1 << 30)))
        ps.append(paper_camera.normalize(direct))
        pms.append(paper_camera.normalize(mirrored[0]))
    batched = mr.normal_from_correspondences(np.stack(ps), np.stack(pms))
    single = np.stack([mr.normal_from_correspondences(a, b) for a, b in zip(ps, pms)])
    assert batched.shape == (4, 3)
    assert np.allclose(batched, single, atol=1e-10)
    # noisy estimates are close but not equal to the truth (the check can fail)
    assert np.all(angle_deg(batched, normal) < 0.5) and np.all(angle_deg(batched, normal) > 0)


def test_weights_exclude_rows(paper_camera, cube_scene):
    pts, normal, d = cube_scene
    direct, mirrored = _views(paper_camera, pts, [(normal, d)])
    p, pm = paper_camera.normalize(direct), paper_camera.normalize(mirrored[0])
    pm_bad = pm.copy()
    pm_bad[:5] += 0.01  # five wrong rows
    w = np.ones(60)
    w[:5] = 0
    assert np.linalg.norm(mr.normal_from_correspondences(p, pm_bad, weights=w) - normal) < 1e-9
    assert np.linalg.norm(mr.normal_from_correspondences(p, pm_bad) - normal) > 1e-4


# ---------------------------------------------------------------- eq. 3.9-3.12
def _paper_G(u, x, y, xm, ym):
    """The matrix G of eq. 3.10, written out term by term (f = 1)."""
    a, b, c = u
    return np.array([
        [(2 * a * a - 1) / 2 * x + a * b * y + a * c, xm / 2],
        [a * b * x + (2 * b * b - 1) / 2 * y + b * c, ym / 2],
        [a * c * x + b * c * y + (2 * c * c - 1) / 2, 0.5],
    ])


def test_depths_match_literal_eq_3_10_3_11(paper_camera, cube_scene):
    pts, normal, d = cube_scene
    direct, mirrored = _views(paper_camera, pts, [(normal, d)], noise=1.5, seed=4)
    p, pm = paper_camera.normalize(direct), paper_camera.normalize(mirrored[0])
    z, zm = mr.depths_from_planes(p, pm, normal[None], np.array([d]))
    for i in range(60):
        G = _paper_G(normal, p[i, 0], p[i, 1], pm[i, 0], pm[i, 1])
        sol = np.linalg.lstsq(G, d * normal, rcond=None)[0]
        assert sol == pytest.approx([z[i], zm[0, i]], rel=1e-9)


def test_points_match_literal_eq_3_12(paper_camera, cube_scene):
    pts, normal, d = cube_scene
    direct, mirrored = _views(paper_camera, pts, [(normal, d)], noise=1.5, seed=5)
    p, pm = paper_camera.normalize(direct), paper_camera.normalize(mirrored[0])
    fused, m, back = mr.points_from_planes(p, pm, normal[None], np.array([d]), return_views=True)
    z, zm = mr.depths_from_planes(p, pm, normal[None], np.array([d]))
    H = np.eye(3) - 2 * np.outer(normal, normal)
    theta = np.array([0.0, 0.0, d / normal[2]])
    m_lit = z[:, None] * np.c_[p, np.ones(60)]
    virt = zm[0][:, None] * np.c_[pm, np.ones(60)]
    m2_lit = (np.linalg.inv(H) @ (virt - theta).T).T + theta
    assert np.allclose(m, m_lit, rtol=1e-12, atol=1e-8)
    assert np.allclose(back[0], m2_lit, rtol=1e-12, atol=1e-8)
    assert np.allclose(fused, (m_lit + m2_lit) / 2, rtol=1e-12, atol=1e-8)


def test_averaged_estimate_beats_either_view_on_average(paper_camera):
    """Why eq. 3.12 averages: over many noisy trials the average is more accurate
    than the direct estimate or the reflected-back estimate alone."""
    normal, d = sim.mirror_plane_from_angles(45.0, 0.0, [0, 0, 40000.0], 12000.0)
    sq = np.zeros(3)
    for seed in range(100):
        rng = np.random.default_rng(seed)
        pts = sim.random_cube_points(60, rng)
        direct, mirrored = sim.observe(pts, [(normal, d)], paper_camera, noise_px=1.5, rng=rng)
        p, pm = paper_camera.normalize(direct), paper_camera.normalize(mirrored[0])
        fused, m, back = mr.points_from_planes(p, pm, normal[None], np.array([d]), return_views=True)
        sq += [np.mean(np.sum((v - pts) ** 2, axis=1)) for v in (fused, m, back[0])]
    rms_avg, rms_direct, rms_back = np.sqrt(sq / 100)
    assert rms_avg < 0.99 * rms_direct
    assert rms_avg < 0.95 * rms_back


def test_reflect_points_is_an_involution_and_matches_householder(cube_scene):
    pts, normal, d = cube_scene
    H = np.eye(3) - 2 * np.outer(normal, normal)
    refl = mr.reflect_points(pts, normal, d)
    theta = np.array([0.0, 0.0, d / normal[2]])
    assert np.allclose(refl, (H @ (pts - theta).T).T + theta, atol=1e-7)
    assert np.allclose(mr.reflect_points(refl, normal, d), pts, atol=1e-7)


def _face_setup(face, noise=0.0, seed=0):
    """Planes and normalised views of the face rig, every marker in both mirrors."""
    cam = face.camera
    normals = np.stack([n for n, _ in face.planes])
    ds = np.array([d for _, d in face.planes])
    direct, mirrored = _views(cam, face.points, face.planes, noise=noise, seed=seed)
    vis = np.ones((2, len(face.points)), dtype=bool)
    return normals, ds, cam.normalize(direct), cam.normalize(mirrored), vis


def test_two_mirror_fusion_exact_and_more_accurate(face):
    cam = face.camera
    normals, ds, p, pm, vis = _face_setup(face)
    vis[0, ::4] = False  # some points only in mirror 1
    fused = mr.points_from_planes(p, pm, normals, ds, vis)
    assert np.max(np.linalg.norm(fused - face.points, axis=1)) < 1e-9
    # a point in no mirror is NaN, not a guess
    none = vis.copy()
    none[:, 0] = False
    assert np.all(np.isnan(mr.points_from_planes(p, pm, normals, ds, none)[0]))
    # with noise, fusing both mirrors beats either mirror alone
    errs = {"both": [], "m0": [], "m1": []}
    for seed in range(20):
        direct, mirrored = _views(cam, face.points, face.planes, noise=0.5, seed=seed)
        p, pm = cam.normalize(direct), cam.normalize(mirrored)
        errs["both"].append(mr.points_from_planes(p, pm, normals, ds) - face.points)
        errs["m0"].append(mr.points_from_planes(p, pm[:1], normals[:1], ds[:1]) - face.points)
        errs["m1"].append(mr.points_from_planes(p, pm[1:], normals[1:], ds[1:]) - face.points)
    rms = {k: np.sqrt(np.mean(np.sum(np.square(v), axis=-1))) for k, v in errs.items()}
    assert rms["both"] < 0.85 * min(rms["m0"], rms["m1"])


def test_points_vectorised_over_frames(face):
    cam = face.camera
    normals = np.stack([n for n, _ in face.planes])
    ds = np.array([d for _, d in face.planes])
    frames = []
    for f in range(5):
        direct, mirrored = _views(cam, face.points, face.planes, noise=0.3, seed=f)
        frames.append((cam.normalize(direct), cam.normalize(mirrored)))
    p = np.stack([a for a, _ in frames])  # (F, N, 2)
    pm = np.stack([b for _, b in frames], axis=1)  # (K, F, N, 2)
    out = mr.points_from_planes(p, pm, normals, ds)
    assert out.shape == (5, len(face.points), 3)
    for f, (a, b) in enumerate(frames):
        assert np.allclose(out[f], mr.points_from_planes(a, b, normals, ds), atol=1e-12)


def test_link_mirror_scales(face):
    normals, true_ds, p, pm, vis = _face_setup(face)
    ds, shared = mr.link_mirror_scales(p, pm, vis, normals, np.array([-1.0, -1.0]))
    assert shared == len(face.points)
    assert ds[1] / ds[0] == pytest.approx(true_ds[1] / true_ds[0], rel=1e-9)
    vis[1, :] = False
    _, shared = mr.link_mirror_scales(p, pm, vis, normals, np.array([-1.0, -1.0]))
    assert shared == 0


def test_scale_to_length_errors():
    pts = np.array([[0.0, 0, 1], [0.0, 0, 1], [3.0, 4, 1]])
    assert mr.scale_to_length(pts, 0, 2, 10.0) == pytest.approx(2.0)
    with pytest.raises(DegenerateError):
        mr.scale_to_length(pts, 0, 1, 10.0)
    with pytest.raises(InputError):
        mr.scale_to_length(pts, 0, 2, -1.0)


# ------------------------------------------------------------------ RANSAC
def test_ransac_rejects_30_percent_wrong_correspondences(face):
    cam = face.camera
    rng = np.random.default_rng(8)
    normal, d = face.planes[0]
    direct, mirrored = _views(cam, face.points, [(normal, d)], noise=0.3, seed=8)
    clean = mr.estimate_mirror_plane(direct, mirrored[0], cam, robust=False)
    bad = rng.random(len(direct)) < 0.3
    corrupted = mirrored[0].copy()
    corrupted[bad] = corrupted[rng.permutation(np.flatnonzero(bad))]
    naive = mr.estimate_mirror_plane(direct, corrupted, cam, robust=False)
    robust = mr.estimate_mirror_plane(direct, corrupted, cam)
    assert angle_deg(robust.normal, clean.normal) < 0.1
    assert angle_deg(naive.normal, clean.normal) > 1.0  # the outliers do matter
    # nearly every wrong pair rejected, nearly every good pair kept
    assert np.count_nonzero(robust.inliers & bad) <= 0.05 * bad.sum()
    assert np.count_nonzero(robust.inliers & ~bad) >= 0.97 * np.count_nonzero(~bad)
    # deterministic for a seed
    again = mr.estimate_mirror_plane(direct, corrupted, cam)
    assert np.array_equal(again.normal, robust.normal)


def test_ransac_with_distortion(distorted_camera, face):
    normal, d = face.planes[1]
    direct, mirrored = _views(distorted_camera, face.points, [(normal, d)], noise=0.2, seed=9)
    rng = np.random.default_rng(3)
    bad = rng.random(len(direct)) < 0.3
    corrupted = mirrored[0].copy()
    corrupted[bad] = corrupted[rng.permutation(np.flatnonzero(bad))]
    plane = mr.estimate_mirror_plane(direct, corrupted, distorted_camera)
    assert angle_deg(plane.normal, normal) < 0.1
    # ignoring the distortion costs accuracy (so the undistortion is doing work)
    plain = Camera(K=distorted_camera.K, dist=np.zeros(0), image_size=distorted_camera.image_size)
    plane_plain = mr.estimate_mirror_plane(direct, corrupted, plain, threshold_px=20.0)
    assert angle_deg(plane_plain.normal, normal) > 3 * angle_deg(plane.normal, normal)


def test_degenerate_inputs_are_refused(paper_camera):
    rng = np.random.default_rng(0)
    normal, d = sim.mirror_plane_from_angles(45.0, 0.0, [0, 0, 40000.0], 12000.0)
    t = np.linspace(-1, 1, 20)[:, None]
    line = np.array([0.0, 0.0, 40000.0]) + t * np.array([3000.0, 6000.0, 1000.0])  # collinear 3D points
    direct, mirrored = _views(paper_camera, line, [(normal, d)])
    with pytest.raises(DegenerateError, match="one image line"):
        mr.estimate_mirror_plane(direct, mirrored[0], paper_camera)
    pts = sim.random_cube_points(2, rng)
    direct, mirrored = _views(paper_camera, pts, [(normal, d)])
    with pytest.raises(DegenerateError, match="at least 3"):
        mr.estimate_mirror_plane(direct, mirrored[0], paper_camera)
    with pytest.raises(InputError, match="finite"):
        mr.estimate_mirror_plane(np.full((5, 2), np.nan), np.ones((5, 2)), paper_camera)
    with pytest.raises(InputError, match="shape"):
        mr.estimate_mirror_plane(np.ones((5, 2)), np.ones((4, 2)), paper_camera)


# ------------------------------------------------------- expected error 3.13-3.26
def _literal_covariance(p, pm, u, sigma):
    """eq. 3.17-3.25 assembled exactly as printed: G_u (3x9), G_M'M (9x3n), the
    block-diagonal P_i, with dM^T perturbed entry by entry."""
    n = p.shape[0]
    M = mr.correspondence_matrix(p, pm)
    lam, H = np.linalg.eigh(M.T @ M)
    Lam = np.diag([0.0, 1 / (lam[0] - lam[1]), 1 / (lam[0] - lam[2])])
    a, b, c = u
    G_u = H @ Lam @ H.T @ np.hstack([a * np.eye(3), b * np.eye(3), c * np.eye(3)])  # eq. 3.19-3.20
    G_MM = np.zeros((9, 3 * n))  # eq. 3.22: psi_dM'M = G_M'M psi_dM'
    for i in range(n):
        for k in range(3):
            dM = np.zeros((n, 3))
            dM[i, k] = 1.0
            dMtM = M.T @ dM + dM.T @ M  # eq. 3.21
            G_MM[:, 3 * i + k] = dMtM.T.reshape(-1)  # columns of dM'M stacked (psi)
    P = np.zeros((3 * n, 3 * n))
    for i in range(n):
        x, y = p[i]
        xm, ym = pm[i]
        P[3 * i:3 * i + 3, 3 * i:3 * i + 3] = [  # eq. 3.16
            [2, 0, -x - xm], [0, 2, -y - ym], [-x - xm, -y - ym, x * x + ym * ym + y * y + xm * xm]]
    G = G_u @ G_MM
    return sigma**2 * G @ P @ G.T  # eq. 3.25


def test_expected_error_matches_the_papers_block_formula(paper_camera, cube_scene):
    pts, normal, d = cube_scene
    direct, mirrored = _views(paper_camera, pts[:25], [(normal, d)])
    p, pm = paper_camera.normalize(direct), paper_camera.normalize(mirrored[0])
    sigma = 1.0 / 1500
    compact = mr.expected_normal_covariance(p, pm, normal, sigma)
    literal = _literal_covariance(p, pm, normal, sigma)
    assert np.allclose(compact, literal, rtol=1e-8, atol=1e-20)
    assert mr.expected_normal_error(p, pm, normal, sigma) == pytest.approx(np.sqrt(np.trace(literal)), rel=1e-8)


def test_expected_error_agrees_with_monte_carlo(paper_camera):
    """eq. 3.26 against the spread of 400 noisy estimates, 1 px noise, 60 points."""
    normal, d = sim.mirror_plane_from_angles(45.0, 0.0, [0, 0, 40000.0], 12000.0)
    rng = np.random.default_rng(326)
    for _ in range(3):
        pts = sim.random_cube_points(60, rng)
        direct, mirrored = _views(paper_camera, pts, [(normal, d)])
        p, pm = paper_camera.normalize(direct), paper_camera.normalize(mirrored[0])
        sigma = 1.0 / 1500
        predicted = mr.expected_normal_error(p, pm, normal, sigma)
        noise = rng.normal(0, sigma, (400, 2, 60, 2))
        u = mr.normal_from_correspondences(p[None] + noise[:, 0], pm[None] + noise[:, 1])
        mc = np.sqrt(np.mean(np.sum((u - normal) ** 2, axis=1)))
        assert mc == pytest.approx(predicted, rel=0.2)


def test_noise_estimate(paper_camera):
    normal, d = sim.mirror_plane_from_angles(45.0, 15.0, [0, 0, 40000.0], 12000.0)
    pts = sim.random_cube_points(400, np.random.default_rng(1))
    direct, mirrored = _views(paper_camera, pts, [(normal, d)], noise=0.7, seed=3)
    plane = mr.estimate_mirror_plane(direct, mirrored[0], paper_camera, robust=False)
    assert plane.noise_px == pytest.approx(0.7, rel=0.1)
    assert 0 < plane.expected_error_deg < 0.2


# -------------------------------------------------------- eq. 5.1-5.3 band
def test_mirrored_epipolar_line_eq_5_2(distorted_camera, face):
    normal, d = face.planes[0]
    direct, mirrored = _views(distorted_camera, face.points, [(normal, d)])
    plane = mr.MirrorPlane(normal=normal, d=d)
    lines = epipolar.mirrored_epipolar_lines(direct, distorted_camera, plane)
    assert np.allclose(np.linalg.norm(lines[:, :2], axis=1), 1.0)
    dist = epipolar.epipolar_distance(lines, mirrored[0], distorted_camera)
    assert dist.max() < 1e-6  # true correspondences lie on their lines, in pixels, despite distortion
    # eq. 5.2 in normalised coordinates: (-c y + b) x' + (c x - a) y' + (-b x + a y) = 0
    p, pm = distorted_camera.normalize(direct), distorted_camera.normalize(mirrored[0])
    a, b, c = normal
    lhs = (-c * p[:, 1] + b) * pm[:, 0] + (c * p[:, 0] - a) * pm[:, 1] + (-b * p[:, 0] + a * p[:, 1])
    assert np.abs(lhs).max() < 1e-12
    # a mirrored point moved 2 px (in undistorted pixels) perpendicular to its line
    # is measured 2 px away, after going through the distortion and back
    q = distorted_camera.ideal_pixels(pm) + 2.0 * lines[:, :2]
    q_distorted = distorted_camera.denormalize(np.c_[
        (q[:, 0] - distorted_camera.K[0, 2] - distorted_camera.K[0, 1] * (q[:, 1] - distorted_camera.K[1, 2])
         / distorted_camera.K[1, 1]) / distorted_camera.K[0, 0],
        (q[:, 1] - distorted_camera.K[1, 2]) / distorted_camera.K[1, 1]])
    assert np.allclose(epipolar.epipolar_distance(lines, q_distorted, distorted_camera), 2.0, atol=1e-6)


def test_epipolar_band_selects_true_pairs(paper_camera, face):
    cam = face.camera
    normal, d = face.planes[1]
    direct, mirrored = _views(cam, face.points, [(normal, d)], noise=0.3, seed=12)
    plane = mr.MirrorPlane(normal=normal, d=d)
    band = epipolar.in_mirrored_epipolar_band(direct, mirrored[0], cam, plane, half_width_px=1.5)
    assert band.shape == (len(direct), len(direct))
    assert np.mean(np.diag(band)) > 0.99  # true pairs inside the band
    assert band.sum(axis=1).mean() < 0.1 * len(direct)  # the band is selective
    vertical = epipolar.in_mirrored_epipolar_band(direct, mirrored[0], cam, plane, half_width_px=1.5, vertical=True)
    assert np.mean(np.diag(vertical)) > 0.99
    # eq. 5.3: vertical half-width k on lines that are not vertical is >= the perpendicular one
    assert np.all(vertical >= band)


# ------------------------------------------------------ nonlinear refinement
def test_refinement_keeps_exact_solution_and_reduces_reprojection_error(face):
    cam = face.camera
    normals, ds, p, pm, vis = _face_setup(face)
    res = refine.refine_reconstruction(p, pm, vis, normals, ds, face.points, focal_px=cam.focal_px)
    assert res.rms_px_after < 1e-6
    assert np.max(np.abs(res.points - face.points)) < 1e-6
    # with noise: start from the linear solution with a perturbed second d
    _, _, p, pm, _ = _face_setup(face, noise=0.5, seed=2)
    u = np.stack([mr.normal_from_correspondences(p, pm[k]) for k in range(2)])
    start_ds = ds * np.array([1.0, 1.02])
    X = mr.points_from_planes(p, pm, u, start_ds)
    res = refine.refine_reconstruction(p, pm, vis, u, start_ds, X, focal_px=cam.focal_px)
    assert res.rms_px_after < res.rms_px_before
    assert res.ds[0] == ds[0]  # gauge: first mirror's d fixed
    # the second mirror's d started 2 % off; ML pulls it at least 5x closer
    assert abs(res.ds[1] / ds[1] - 1) < 0.2 * 0.02
    err_before = np.sqrt(np.mean(np.sum((X - face.points) ** 2, axis=1)))
    err_after = np.sqrt(np.mean(np.sum((res.points - face.points) ** 2, axis=1)))
    assert err_after < err_before
    assert np.all(res.normals[:, 2] < 0)


def test_single_mirror_fast_path_equals_general_solver(face):
    """points_from_planes has a written-out path for one mirror with every point
    visible; it must agree with the general K-mirror solver, for one frame and for a
    batch of frames."""
    normals, ds, _, _, _ = _face_setup(face)
    frames = [_face_setup(face, noise=0.4, seed=s)[2:4] for s in range(3)]
    p = np.stack([a for a, _ in frames])  # (F, N, 2)
    pm = np.stack([b[0] for _, b in frames])[None]  # (1, F, N, 2)
    fast = mr.points_from_planes(p, pm, normals[:1], ds[:1])
    general, _, _ = mr.points_from_planes(p, pm, normals[:1], ds[:1], return_views=True)
    masked = mr.points_from_planes(p, pm, normals[:1], ds[:1], visible=np.ones(pm.shape[:-1], bool))
    assert fast.shape == (3, len(face.points), 3)
    assert np.allclose(fast, general, rtol=1e-12, atol=1e-9) and np.allclose(fast, masked, rtol=1e-12, atol=1e-9)
    assert np.allclose(mr.points_from_planes(p[0], pm[0, 0], normals[0], ds[:1]), fast[0], atol=1e-9)
