"""Speed of the mirror core on one frame (300 markers).

Each operation is timed over repeated runs (``time.perf_counter``) after a warm-up,
on one process; ``<name>_us`` is the fastest run (the ``timeit`` convention: on a
shared VM noise only ever adds time) and ``<name>_median_us`` the median. "kernel" timings take normalised coordinates (what the
tracker calls per frame once detections are undistorted); "pixels" timings
include the conversion from pixels through the camera.
"""

from __future__ import annotations

import time

import numpy as np

from mirrorcap.core.geometry import epipolar
from mirrorcap.core.geometry import mirror as mr
from mirrorcap.synthetic import simulate as sim
from mirrorcap.core.geometry.camera import Camera


def _times(fn, repeat: int, inner: int = 1) -> tuple[float, float]:
    """(fastest, median) seconds per call over ``repeat`` runs of ``inner`` calls."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        times.append((time.perf_counter() - t0) / inner)
    return float(np.min(times)), float(np.median(times))


def run_speed(n_points: int = 300, repeat: int = 200) -> dict:
    rig = sim.face_rig(n_markers=n_points, seed=1)
    rng = np.random.default_rng(5)
    camera = Camera.ideal(1400.0, (1280, 720))
    dist_camera = Camera(K=camera.K, dist=np.array([-0.08, 0.03, 0.0005, -0.0003, 0.0]), image_size=(1280, 720))
    pts = rig.points
    normal, d = rig.planes[0]
    direct, mirrored = sim.observe(pts, [(normal, d)], camera, noise_px=0.2, rng=rng)
    direct_dist, mirrored_dist = sim.observe(pts, [(normal, d)], dist_camera, noise_px=0.2, rng=rng)
    p, pm = camera.normalize(direct), camera.normalize(mirrored[0])
    plane = mr.MirrorPlane(normal=normal, d=d)
    normals, ds = normal[None], np.array([d])
    pm_k = pm[None]
    # 30 % wrong correspondences for the robust estimate
    bad = rng.random(n_points) < 0.3
    mirrored_bad = mirrored[0].copy()
    mirrored_bad[bad] = mirrored_bad[rng.permutation(np.flatnonzero(bad))]
    # two mirrors, every marker in both (the heaviest fusion case)
    normal1, d1 = rig.planes[1]
    _, mirrored2 = sim.observe(pts, [(normal, d), (normal1, d1)], camera, noise_px=0.2, rng=rng)
    pm2 = camera.normalize(mirrored2)
    normals2, ds2 = np.stack([normal, normal1]), np.array([d, d1])

    cases = {
        "reconstruct_kernel_1_mirror": lambda: mr.points_from_planes(p, pm_k, normals, ds),
        "reconstruct_kernel_2_mirrors_fused": lambda: mr.points_from_planes(p, pm2, normals2, ds2),
        "reconstruct_pixels_no_distortion": lambda: mr.reconstruct_points(direct, mirrored, camera, plane),
        "reconstruct_pixels_with_distortion": lambda: mr.reconstruct_points(direct_dist, mirrored_dist,
                                                                            dist_camera, plane),
        "plane_kernel_closed_form": lambda: mr.normal_from_correspondences(p, pm),
        "plane_pixels_closed_form": lambda: mr.estimate_mirror_plane(direct, mirrored[0], camera, robust=False),
        "plane_pixels_ransac_clean": lambda: mr.estimate_mirror_plane(direct, mirrored[0], camera),
        "plane_pixels_ransac_30pct_wrong": lambda: mr.estimate_mirror_plane(direct, mirrored_bad, camera),
        "expected_normal_error": lambda: mr.expected_normal_error(p, pm, normal, 0.2 / 1400),
        "mirrored_epipolar_band_300x300": lambda: epipolar.in_mirrored_epipolar_band(direct, mirrored[0], camera, plane),
    }
    slow = {"plane_pixels_ransac_clean", "plane_pixels_ransac_30pct_wrong", "plane_pixels_closed_form",
            "expected_normal_error", "mirrored_epipolar_band_300x300", "reconstruct_pixels_with_distortion"}
    out = {}
    for name, fn in cases.items():
        r = max(20, repeat // 5) if name in slow else repeat
        inner = 1 if name in slow else 20
        best, median = _times(fn, r, inner)
        out[name + "_us"] = best * 1e6
        out[name + "_median_us"] = median * 1e6
    out["n_points"] = n_points
    return out
