"""The four computer simulations of Lin (2003), section 6.2 (figures 6.1-6.4), and a
Monte-Carlo check of the expected normal error (eq. 3.25-3.26).

Protocol (section 6.2): a 720 x 720 px CCD with a 1500 px focal length; 3D points
uniform in a 9000 x 18000 x 9000 px cube centred 40000 px in front of the camera;
Gaussian noise added to the projections, which are then rounded to the pixel
grid. One mirror, tangent to a 12000 px sphere around the cube centre (it
circumscribes the cube) at longitude/latitude (45 deg, 0 deg) -- a 90 deg angle
between the real and virtual view directions -- except in the orientation sweep.
Mirrored points are not clipped to the sensor (the orientation sweep would push
many off it; the paper's simulation does not clip either). Each method's points
get the least-squares scale against the truth (a perfect ruler) before the RMS
3D error is taken, in the cube's units (1 unit = 0.05 mm for a face 2 m away).

Methods: (a) the mirror method, closed form (eq. 3.8, 3.10-3.12); (a+ML) the same
refined by reprojection error; (b) the two-view linear algorithm of Appendix A;
(b-cv) OpenCV's findEssentialMat/recoverPose/triangulatePoints; (c) the
maximum-likelihood refinement of (b).
"""

from __future__ import annotations

import numpy as np

from mirrorcap.core.geometry import refine
from mirrorcap.core.geometry import mirror as mr
from mirrorcap.synthetic import simulate as sim
from mirrorcap.core.geometry.camera import Camera

from .baselines import flip_mirror_view, opencv_two_view, rms_3d_error, two_view_linear, two_view_ml

FOCAL = 1500.0
SENSOR = 720
CENTRE = np.array([0.0, 0.0, 40000.0])
RADIUS = 12000.0
METHODS = ("mirror", "mirror_ml", "two_view_linear", "opencv", "two_view_ml")
METHOD_LABELS = {
    "mirror": "(a) mirror, linear",
    "mirror_ml": "(a) mirror + ML",
    "two_view_linear": "(b) two-view linear",
    "opencv": "(b) OpenCV essential",
    "two_view_ml": "(c) two-view ML",
}

EXPERIMENTS = {
    # name: (x label, settings)
    "fig6_1_points": ("number of correspondences", [8, 10, 15, 20, 30, 45, 60, 80, 100]),
    "fig6_2_noise": ("noise standard deviation (px)", [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]),
    "fig6_3_resolution": ("pixel width (1.0 = 720 x 720 px)", [1 / 3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]),
    "fig6_4_orientation": ("mirror orientation (longitude, latitude)",
                           [(lon, lat) for lon in (15, 30, 45, 60) for lat in (-45, -30, -15, 0, 15, 30, 45)]),
}


def scene_for(experiment: str, setting):
    """(n_points, noise_px, pixel_pitch, longitude, latitude) of one setting."""
    n, noise, pitch, lon, lat = 60, 1.0, 1.0, 45.0, 0.0
    if experiment == "fig6_1_points":
        n = int(setting)
    elif experiment == "fig6_2_noise":
        noise = float(setting)
    elif experiment == "fig6_3_resolution":
        noise, pitch = 0.0, float(setting)
    elif experiment == "fig6_4_orientation":
        lon, lat = setting
    return n, noise, pitch, lon, lat


def run_trial(experiment: str, setting_index: int, trial: int, methods=METHODS) -> dict:
    """One random point set through every method; returns ``{method: rms_3d_error}``."""
    setting = EXPERIMENTS[experiment][1][setting_index]
    n, noise, pitch, lon, lat = scene_for(experiment, setting)
    exp_index = list(EXPERIMENTS).index(experiment)
    rng = np.random.default_rng([2003, exp_index, setting_index, trial])
    camera = Camera.ideal(FOCAL, (SENSOR, SENSOR))
    pts = sim.random_cube_points(n, rng)
    normal, d = sim.mirror_plane_from_angles(lon, lat, CENTRE, RADIUS)
    direct, mirrored = sim.observe(pts, [(normal, d)], camera, noise_px=noise, rng=rng, quantize=True,
                                   pixel_pitch=pitch)
    p = camera.normalize(direct)
    pm = camera.normalize(mirrored[0])
    out = {}
    u = mr.normal_from_correspondences(p, pm)
    X = mr.points_from_planes(p, pm[None], u[None], np.array([-1.0]))
    out["mirror"] = rms_3d_error(X, pts)
    if "mirror_ml" in methods:
        ref = refine.refine_reconstruction(p, pm[None], np.ones((1, n), bool), u[None], np.array([-1.0]), X,
                                       focal_px=FOCAL / pitch)
        out["mirror_ml"] = rms_3d_error(ref.points, pts)
    p2 = flip_mirror_view(pm)
    R, T, X2 = two_view_linear(p, p2)
    out["two_view_linear"] = rms_3d_error(X2, pts)
    if "opencv" in methods:
        res = opencv_two_view(p, p2, threshold=max(3.0 * noise, pitch) / FOCAL)
        out["opencv"] = rms_3d_error(res[2] if res is not None else None, pts)
    if "two_view_ml" in methods:
        R3, T3, X3 = two_view_ml(p, p2, R, T, X2, focal_px=FOCAL / pitch)
        out["two_view_ml"] = rms_3d_error(X3, pts)
    return out


def _run_chunk(args):
    experiment, setting_index, trials, methods = args
    return experiment, setting_index, [run_trial(experiment, setting_index, t, methods) for t in trials]


def run_simulations(trials: int = 100, workers: int = 2, experiments=None, methods=METHODS, progress=None):
    """All settings of the chosen experiments; returns rows
    ``{experiment, setting, method, rms, median, failures, trials}`` where ``rms`` is
    the root mean square over trials of the per-trial RMS 3D error."""
    from concurrent.futures import ProcessPoolExecutor

    experiments = list(experiments or EXPERIMENTS)
    jobs = [(e, i, range(trials), methods) for e in experiments for i in range(len(EXPERIMENTS[e][1]))]
    results = {}
    if workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            for k, (e, i, errs) in enumerate(pool.map(_run_chunk, jobs)):
                results[(e, i)] = errs
                if progress:
                    progress(k + 1, len(jobs))
    else:
        for k, job in enumerate(jobs):
            e, i, errs = _run_chunk(job)
            results[(e, i)] = errs
            if progress:
                progress(k + 1, len(jobs))
    rows = []
    for e in experiments:
        for i, setting in enumerate(EXPERIMENTS[e][1]):
            errs = results[(e, i)]
            for m in methods:
                v = np.array([t[m] for t in errs], dtype=float)
                ok = np.isfinite(v)
                rows.append({
                    "experiment": e,
                    "setting": setting if not isinstance(setting, tuple) else f"{setting[0]}/{setting[1]}",
                    "method": m,
                    "rms": float(np.sqrt(np.mean(v[ok] ** 2))) if ok.any() else float("nan"),
                    "median": float(np.median(v[ok])) if ok.any() else float("nan"),
                    "failures": int((~ok).sum()),
                    "trials": int(v.size),
                })
    return rows


def expected_error_check(sigmas=(0.25, 0.5, 1.0, 2.0, 3.0), configurations: int = 20, draws: int = 200,
                         n_points: int = 60):
    """Monte-Carlo RMS of the normal's error vs the eq. 3.26 prediction.

    For each noise level: ``configurations`` random point sets (section 6.2
    protocol, Gaussian noise only, no rounding); for each, ``draws`` noisy
    estimates of ``u`` by eq. 3.8. Returns rows ``{sigma_px, predicted_deg,
    monte_carlo_deg, ratio}`` with the ratio of the pooled MC RMS to the pooled
    prediction, plus the worst per-configuration ratio."""
    camera = Camera.ideal(FOCAL, (SENSOR, SENSOR))
    normal, d = sim.mirror_plane_from_angles(45, 0, CENTRE, RADIUS)
    rows = []
    for s_index, sigma in enumerate(sigmas):
        pred_sq, mc_sq, ratios = [], [], []
        for c in range(configurations):
            rng = np.random.default_rng([326, s_index, c])
            pts = sim.random_cube_points(n_points, rng)
            direct, mirrored = sim.observe(pts, [(normal, d)], camera)
            p, pm = camera.normalize(direct), camera.normalize(mirrored[0])
            predicted = mr.expected_normal_error(p, pm, normal, sigma / FOCAL)
            noise = rng.normal(0.0, sigma / FOCAL, (draws, 2, n_points, 2))
            u = mr.normal_from_correspondences(p[None] + noise[:, 0], pm[None] + noise[:, 1])
            err2 = np.sum((u - normal) ** 2, axis=1)
            pred_sq.append(predicted**2)
            mc_sq.append(err2.mean())
            ratios.append(np.sqrt(err2.mean()) / predicted)
        rows.append({
            "sigma_px": sigma,
            "predicted_deg": float(np.degrees(np.sqrt(np.mean(pred_sq)))),
            "monte_carlo_deg": float(np.degrees(np.sqrt(np.mean(mc_sq)))),
            "ratio": float(np.sqrt(np.mean(mc_sq) / np.mean(pred_sq))),
            "worst_configuration_ratio": float(max(ratios, key=lambda r: abs(r - 1.0))),
        })
    return rows
