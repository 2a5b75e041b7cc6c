"""Synthetic mirror rigs with exact ground truth -- a test tool.

Used by the tests, the benchmarks and the sample-scene scripts. Two kinds of
scene:

* :func:`random_cube_points` + :func:`mirror_plane_from_angles`: the simulation
  protocol of Lin (2003), section 6.2 -- random points in a 9000 x 18000 x 9000
  cube 40000 units in front of the camera, a mirror tangent to a sphere around
  the cube at a given longitude/latitude.
* :func:`face_rig`: a face-sized marker layout (millimetres) between two mirrors
  beside the cheeks, with per-view visibility from the surface normals.

:func:`observe` projects a scene into the direct and mirrored views with
Gaussian noise and optional rounding to the pixel grid.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.geometry.camera import Camera
from ..core.geometry.mirror import reflect_points


def mirror_plane_from_angles(longitude_deg: float, latitude_deg: float, centre, radius: float):
    """The mirror tangent to the sphere ``|x - centre| = radius`` at the point of
    the given longitude and latitude (section 6.2, figure 6.4).

    Longitude is measured from the optical axis (+z) towards +x, latitude towards
    +y. The normal faces the sphere centre, so ``c < 0``; at (45 deg, 0 deg) the
    virtual camera's view direction is 90 deg from the real one. Returns
    ``(normal (3,), d)`` with ``normal . x = d`` on the mirror."""
    lon, lat = np.radians(longitude_deg), np.radians(latitude_deg)
    t = np.array([np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)])
    centre = np.asarray(centre, dtype=float)
    normal = -t
    d = float(normal @ (centre + radius * t))
    return normal, d


def random_cube_points(n: int, rng: np.random.Generator, size=(9000.0, 18000.0, 9000.0),
                       distance: float = 40000.0) -> np.ndarray:
    """``n`` points uniform in an axis-aligned box of ``size`` (x, y, z) whose centre
    lies ``distance`` along the optical axis (section 6.2)."""
    size = np.asarray(size, dtype=float)
    pts = (rng.random((n, 3)) - 0.5) * size
    pts[:, 2] += distance
    return pts


def observe(points, planes, camera: Camera, noise_px: float = 0.0, rng=None, quantize: bool = False,
            pixel_pitch: float = 1.0):
    """Project ``points`` ``(N, 3)`` into the direct view and into each mirror of
    ``planes`` (a sequence of ``(normal, d)``).

    Gaussian noise of ``noise_px`` is added to every coordinate, then, with
    ``quantize``, positions are rounded to the pixel grid (the CCD digitisation of
    section 6.2; ``pixel_pitch`` rounds to multiples of a coarser pitch).
    Returns ``direct_px (N, 2)``, ``mirror_px (K, N, 2)``."""
    rng = np.random.default_rng(0) if rng is None else rng
    pts = np.asarray(points, dtype=float)
    views = [pts] + [reflect_points(pts, n, d) for n, d in planes]
    out = []
    for v in views:
        px = camera.project(v)
        if noise_px > 0:
            px = px + rng.normal(0.0, noise_px, px.shape)
        if quantize:
            px = np.round(px / pixel_pitch) * pixel_pitch
        out.append(px)
    return out[0], np.stack(out[1:]) if len(out) > 1 else np.zeros((0,) + out[0].shape)


def visibility(camera: Camera, planes, points, normals, grazing_deg: float = 80.0) -> np.ndarray:
    """``(1 + K, N)``: marker seen in the direct view and in each mirror -- its surface
    faces that (real or virtual) camera within ``grazing_deg`` and it projects inside
    the image."""
    cos_lim = np.cos(np.radians(grazing_deg))

    def facing(eye, pts):
        to_eye = eye - pts
        to_eye /= np.linalg.norm(to_eye, axis=1, keepdims=True)
        return np.sum(to_eye * normals, axis=1) > cos_lim

    out = [facing(np.zeros(3), points) & camera.contains(camera.project(points))]
    for n, d in planes:
        virt = reflect_points(points, n, d)
        eye = reflect_points(np.zeros(3), n, d)  # the virtual camera centre
        out.append(facing(eye, points) & (virt[:, 2] > 0) & camera.contains(camera.project(virt)))
    return np.stack(out)


@dataclass
class FaceRig:
    """A synthetic two-mirror face rig (millimetres, OpenCV camera frame)."""

    camera: Camera
    points: np.ndarray  # (N, 3) marker positions
    normals: np.ndarray  # (N, 3) outward surface normals
    planes: list  # [(normal (3,), d)] for mirror 0 (image left) and mirror 1 (image right)
    visible_direct: np.ndarray  # (N,)
    visible_mirror: np.ndarray  # (K, N)


def face_rig(n_markers: int = 150, seed: int = 0, image_size=(1280, 720), focal_px: float = 1400.0,
             distance_mm: float = 600.0, mirror_longitude_deg: float = 75.0, mirror_radius_mm: float = 90.0,
             grazing_deg: float = 80.0, dist=None, layout: str = "random") -> FaceRig:
    """Markers on the front of a face-sized ellipsoid (semi-axes 75 x 100 x 90 mm)
    ``distance_mm`` in front of the camera, with a mirror on each side tangent to a
    sphere of ``mirror_radius_mm`` around the face at +-``mirror_longitude_deg``.

    A marker is visible in a view when its surface faces that (real or virtual)
    camera within ``grazing_deg`` and it projects inside the image. Mirror 0 is
    the one that appears on the image's left (x < cx). ``dist`` adds OpenCV lens
    distortion coefficients to the camera. ``layout="even"`` spaces the markers
    evenly (a Fibonacci lattice on the front of the face, as markers are applied
    in practice); ``"random"`` places them uniformly at random."""
    rng = np.random.default_rng(seed)
    w, h = image_size
    camera = Camera.ideal(focal_px, (w, h))
    if dist is not None:
        camera = Camera(K=camera.K, dist=np.asarray(dist, dtype=float), image_size=(w, h))
    semi = np.array([75.0, 100.0, 90.0])
    centre = np.array([0.0, 0.0, distance_mm])
    # Uniform directions on the camera-facing half (z < 0 relative to the centre),
    # kept away from the back of the head.
    if layout == "even":
        # the kept cap z < -0.05 is 47.5 % of the sphere: grow the lattice until it holds n
        m = int(n_markers / 0.475) - 2
        while np.count_nonzero(1.0 - 2.0 * (np.arange(m) + 0.5) / m < -0.05) < n_markers:
            m += 1
        i = np.arange(m) + 0.5
        zz = 1.0 - 2.0 * i / m
        phi = i * np.pi * (3.0 - np.sqrt(5.0)) + rng.uniform(0, 2 * np.pi)
        rr = np.sqrt(1.0 - zz * zz)
        dirs = np.c_[rr * np.cos(phi), rr * np.sin(phi), zz]
        dirs = dirs[dirs[:, 2] < -0.05][:n_markers]
    elif layout == "random":
        dirs = rng.normal(size=(n_markers * 4, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        dirs = dirs[dirs[:, 2] < -0.05][:n_markers]
    else:
        raise ValueError(f"layout must be 'even' or 'random', got {layout!r}")
    pts = centre + dirs * semi
    nrm = dirs / semi**2
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    planes = [
        mirror_plane_from_angles(-mirror_longitude_deg, 0.0, centre, mirror_radius_mm),
        mirror_plane_from_angles(+mirror_longitude_deg, 0.0, centre, mirror_radius_mm),
    ]
    vis = visibility(camera, planes, pts, nrm, grazing_deg)
    vis_d, vis_m = vis[0], vis[1:]
    # Make mirror 0 the one imaged on the left.
    cx = camera.K[0, 2]
    left = [np.nanmedian(camera.project(reflect_points(pts, n, d))[:, 0]) < cx for n, d in planes]
    if not left[0] and left[1]:
        planes = planes[::-1]
        vis_m = vis_m[::-1]
    return FaceRig(camera=camera, points=pts, normals=nrm, planes=planes, visible_direct=vis_d,
                   visible_mirror=vis_m)


__all__ = ["mirror_plane_from_angles", "random_cube_points", "observe", "FaceRig", "face_rig"]


@dataclass
class FrameDetections:
    """One frame of marker detections per view, as the extractor reports them
    (pixels, colour-class index), with the true marker id of each (-1: false blob)."""

    direct: np.ndarray  # (n, 2)
    direct_color: np.ndarray  # (n,)
    direct_id: np.ndarray  # (n,)
    mirror: list  # K arrays (m_k, 2)
    mirror_color: list  # K arrays (m_k,)
    mirror_id: list  # K arrays (m_k,)


def rig_motion(rig: FaceRig, frame: int, n_frames: int, head_motion_deg: float = 3.0):
    """Marker positions and normals of ``rig`` at ``frame``: the head turns gently (a
    sinusoid of ``head_motion_deg``) about the face centre."""
    import cv2

    ang = head_motion_deg * np.sin(2 * np.pi * frame / max(n_frames, 2)) * np.array([0.3, 1.0, 0.2])
    R = cv2.Rodrigues(np.radians(ang))[0]
    centre = rig.points.mean(axis=0)
    return (rig.points - centre) @ R.T + centre, rig.normals @ R.T


def rig_performance(rig: FaceRig, n_frames: int, head_motion_deg: float = 10.0, expression_mm: float = 5.0,
                    seed: int = 0):
    """A synthetic performance: smooth expression fields (mm, in the head's frame)
    that rise and fall over the clip, on top of a head turning up to
    ``head_motion_deg``. Markers on the upper half of the face (forehead) stay
    rigid, as on a real face. Returns ``(points (F, N, 3), normals (F, N, 3),
    rotations (F, 3, 3), translations (F, 3), neutral_motion (F, N, 3))`` -- the last
    being the expression displacement of every marker in the head frame."""
    import cv2

    rng = np.random.default_rng(seed)
    centre = rig.points.mean(axis=0)
    rel = rig.points - centre
    lower = np.clip((rel[:, 1] + 20.0) / 60.0, 0.0, 1.0)  # 0 on the forehead, 1 around the mouth/jaw
    fields = []
    for _ in range(3):
        fx, fy = rng.uniform(20, 60, 2)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        fields.append(np.sin(rel[:, :1] / fx + rng.uniform(0, 6)) * np.cos(rel[:, 1:2] / fy) * direction)
    phases = rng.uniform(0, 2 * np.pi, 3)
    pts, nrm, Rs, Ts, expr = [], [], [], [], []
    for f in range(n_frames):
        s = np.sin(2 * np.pi * f / max(n_frames, 2) * np.array([1.0, 1.7, 2.3]) + phases)
        e = expression_mm * lower[:, None] * sum(si * fi for si, fi in zip(s, fields))
        ang = head_motion_deg * np.sin(2 * np.pi * f / max(n_frames, 2) * np.array([1.0, 0.6, 0.8]))
        R = cv2.Rodrigues(np.radians(ang * np.array([0.5, 1.0, 0.3])))[0]
        T = centre - R @ centre
        pts.append((rig.points + e) @ R.T + T)
        nrm.append(rig.normals @ R.T)
        Rs.append(R)
        Ts.append(T)
        expr.append(e)
    return np.array(pts), np.array(nrm), np.array(Rs), np.array(Ts), np.array(expr)


def synthetic_detections(rig: FaceRig, n_frames: int, noise_px: float = 0.1, n_colors: int = 4, seed: int = 0,
                         head_motion_deg: float = 3.0, missing: float = 0.0, false_blobs: float = 0.0,
                         performance=None, occlusions: int = 0, occlusion_frames: int = 10,
                         occlusion_radius_mm: float = 20.0):
    """Per-frame detections of ``rig`` under gentle head motion, without rendering:
    visible markers projected into each view with Gaussian noise, in shuffled order.
    ``missing`` drops that fraction of detections; ``false_blobs`` adds that many
    spurious blobs per true one, uniformly over the view's extent but at least 3 px from
    the image of every marker. Returns ``(colors (N,), [FrameDetections])``."""
    rng = np.random.default_rng(seed)
    n = len(rig.points)
    colors = np.arange(n) % n_colors
    rng.shuffle(colors)
    frames = []
    w, h = rig.camera.image_size

    def view(px, ids, every_px):
        keep = rng.random(len(ids)) >= missing
        px, ids = px[keep], ids[keep]
        n_false = int(round(false_blobs * len(ids)))
        if n_false and len(px):
            from scipy.spatial import cKDTree

            lo, hi = px.min(axis=0), px.max(axis=0)
            extra = rng.uniform(lo, hi, (4 * n_false, 2))
            # a spurious blob within 3 px of a marker's image is not a false candidate: it would
            # merge with the marker's own blob in extraction, and where that blob is missing
            # (dropped, occluded, turned away) it sits where the marker is and, paired with the
            # marker's image in another view, reconstructs the marker itself. So keep 3 px from
            # the image of every marker in the view, detected or not.
            extra = extra[cKDTree(every_px).query(extra)[0] > 3.0][:n_false]
            px = np.vstack([px, extra])
            ids = np.concatenate([ids, -np.ones(len(extra), int)])
        px = px + rng.normal(0.0, noise_px, px.shape)
        order = rng.permutation(len(ids))
        col = np.where(ids >= 0, colors[np.maximum(ids, 0)], rng.integers(0, n_colors, len(ids)))
        return px[order], col[order], ids[order]

    hidden = np.zeros((n_frames, n), bool)
    for _ in range(occlusions):
        centre = rng.integers(n)
        group = np.linalg.norm(rig.points - rig.points[centre], axis=1) <= occlusion_radius_mm
        start = rng.integers(0, max(1, n_frames - occlusion_frames))
        hidden[start:start + occlusion_frames, group] = True
    for f in range(n_frames):
        if performance is None:
            pts, nrm = rig_motion(rig, f, n_frames, head_motion_deg)
        else:
            pts, nrm = performance[0][f], performance[1][f]
        vis = visibility(rig.camera, rig.planes, pts, nrm) & ~hidden[f][None]
        ids = np.arange(n)
        direct_px = rig.camera.project(pts)
        d = view(direct_px[vis[0]], ids[vis[0]], direct_px)
        ms = []
        for k in range(len(rig.planes)):
            mirror_px = rig.camera.project(reflect_points(pts, *rig.planes[k]))
            ms.append(view(mirror_px[vis[1 + k]], ids[vis[1 + k]], mirror_px))
        frames.append(FrameDetections(d[0], d[1], d[2], [m[0] for m in ms], [m[1] for m in ms], [m[2] for m in ms]))
    return colors, frames
