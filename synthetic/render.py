"""Synthetic rig frames with exact truth -- a test tool.

Given a camera, the two mirror planes and 3D marker positions, :func:`render_rig_frame`
draws what the camera sees under blacklight: a dark image with each marker as a
bright coloured dot in the direct view and in each mirror, and returns the exact
image position of every dot. Faults a real capture has are switchable:

* ``blur_sigma``   -- Gaussian optical blur (px);
* ``noise_sigma``  -- Gaussian sensor noise (grey levels, 0..255);
* ``color_jitter`` -- per-dot relative change of each colour channel (view-dependent
  fluorescence);
* ``comb_px``      -- interlace combing: odd rows shifted horizontally, as when the
  two fields of an interlaced frame see a moving face (the truth is then the mean
  of the two fields' positions);
* ``occlusion``    -- the fraction of dots hidden in each view.

Dots are discs of ``marker_radius_mm`` seen at their depth, rendered by 4 x 4
supersampling (area coverage), so the truth is the projected marker centre.
Everything is vectorised over dots.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.geometry.camera import Camera
from ..core.geometry.mirror import reflect_points


@dataclass
class RenderSettings:
    marker_radius_mm: float = 1.25
    brightness: float = 235.0
    background: float = 6.0
    blur_sigma: float = 0.6
    noise_sigma: float = 2.0
    color_jitter: float = 0.0
    comb_px: int = 0
    occlusion: float = 0.0


@dataclass
class FrameTruth:
    centres: np.ndarray  # (3, N, 2) pixel centre per view (direct, mirror0, mirror1)
    visible: np.ndarray  # (3, N) drawn and not occluded
    radius_px: np.ndarray  # (3, N)
    color: np.ndarray  # (N,) class index


def render_rig_frame(camera: Camera, planes, points, color_index, class_rgb, settings: RenderSettings | None = None,
                     rng=None, visible=None):
    """Render one frame. ``points`` ``(N, 3)`` mm; ``color_index`` ``(N,)`` into
    ``class_rgb`` ``(C, 3)`` (RGB 0..255); ``visible`` ``(3, N)`` optional per-view
    visibility (e.g. from surface normals). Returns ``(bgr uint8 image, FrameTruth)``."""
    settings = settings or RenderSettings()
    rng = np.random.default_rng(0) if rng is None else rng
    w, h = camera.image_size
    pts = np.asarray(points, dtype=float)
    views = [pts] + [reflect_points(pts, nrm, d) for nrm, d in planes]
    centres = np.stack([camera.project(v) for v in views])  # (V, N, 2)
    depth = np.stack([v[:, 2] for v in views])
    radius = camera.focal_px * settings.marker_radius_mm / depth
    vis = np.ones(centres.shape[:2], dtype=bool) if visible is None else np.asarray(visible, dtype=bool).copy()
    vis &= (depth > 0) & camera.contains(centres, margin=-2.0)
    if settings.occlusion > 0:
        vis &= rng.random(vis.shape) >= settings.occlusion
    image = np.full((h, w, 3), settings.background, dtype=np.float64)
    v_idx, m_idx = np.nonzero(vis)
    if v_idx.size:
        c = centres[v_idx, m_idx]  # (B, 2)
        r = radius[v_idx, m_idx]  # (B,)
        rgb = np.asarray(class_rgb, dtype=float)[np.asarray(color_index)[m_idx]]
        if settings.color_jitter > 0:
            rgb = rgb * (1.0 + settings.color_jitter * rng.standard_normal(rgb.shape))
        rgb = np.clip(rgb, 0, None)
        rgb = rgb / rgb.max(axis=1, keepdims=True) * settings.brightness
        half = int(np.ceil(r.max())) + 2
        off = np.arange(-half, half + 1)
        base = np.floor(c).astype(int)  # (B, 2)
        sub = (np.arange(4) + 0.5) / 4 - 0.5  # 4 x 4 samples inside a pixel
        px = base[:, 0, None] + off[None, :]  # (B, P) pixel x
        py = base[:, 1, None] + off[None, :]
        dx = px[:, :, None] + sub[None, None, :] - c[:, 0, None, None]  # (B, P, 4)
        dy = py[:, :, None] + sub[None, None, :] - c[:, 1, None, None]
        inside = (dx[:, None, :, None, :] ** 2 + dy[:, :, None, :, None] ** 2) <= r[:, None, None, None, None] ** 2
        cover = inside.mean(axis=(3, 4))  # (B, Py, Px) area coverage
        X = np.broadcast_to(px[:, None, :], cover.shape)
        Y = np.broadcast_to(py[:, :, None], cover.shape)
        ok = (X >= 0) & (X < w) & (Y >= 0) & (Y < h) & (cover > 0)
        flat = (Y[ok] * w + X[ok])
        weights = cover[ok]
        blob_of = np.broadcast_to(np.arange(cover.shape[0])[:, None, None], cover.shape)[ok]
        for ch, col in ((2, 0), (1, 1), (0, 2)):  # BGR image from RGB colours
            image[..., ch] += np.bincount(flat, weights * rgb[blob_of, col], w * h).reshape(h, w)
    if settings.blur_sigma > 0:
        import cv2

        image = cv2.GaussianBlur(image, (0, 0), settings.blur_sigma)
    if settings.comb_px:
        image[1::2] = np.roll(image[1::2], settings.comb_px, axis=1)
        centres = centres.copy()
        centres[..., 0] += settings.comb_px / 2.0  # a combed dot's true centre: the mean of its two fields
    if settings.noise_sigma > 0:
        image += rng.normal(0.0, settings.noise_sigma, image.shape)
    frame = np.clip(image + 0.5, 0, 255).astype(np.uint8)
    truth = FrameTruth(centres=centres, visible=vis, radius_px=radius,
                       color=np.asarray(color_index).astype(int).copy())
    return frame, truth


def match_detections(det_x, det_y, det_view, truth: FrameTruth, max_px: float = 2.0):
    """Pair detections with true dots of the same view (one-to-one, nearest within
    ``max_px``). Returns ``(pairs (k, 2) of (detection, flat truth index view*N+marker),
    missed mask (3, N), false detections mask (n_det,))``."""
    from scipy.optimize import linear_sum_assignment

    V, N = truth.visible.shape
    det = np.c_[det_x, det_y]
    t_idx = np.flatnonzero(truth.visible.ravel())
    t_xy = truth.centres.reshape(-1, 2)[t_idx]
    t_view = t_idx // N
    d = np.linalg.norm(det[:, None, :] - t_xy[None, :, :], axis=2)
    d[np.asarray(det_view)[:, None] != t_view[None, :]] = np.inf
    big = 1e6
    cost = np.where(d <= max_px, d, big)
    rows, cols = linear_sum_assignment(cost) if cost.size else (np.zeros(0, int), np.zeros(0, int))
    good = cost[rows, cols] < big
    pairs = np.c_[rows[good], t_idx[cols[good]]]
    missed = truth.visible.copy().ravel()
    missed[pairs[:, 1]] = False
    false = np.ones(len(det), dtype=bool)
    false[pairs[:, 0]] = False
    return pairs, missed.reshape(V, N), false


# ------------------------------------------------------------ calibration boards
def board_texture(board, px_per_mm: float = 4.0):
    """A printable image of ``board`` (a :class:`core.capture.calibrate.Board`) with a white
    margin of one square, and the 3x3 matrix mapping board millimetres (origin at
    the first inner corner for a chessboard, at the board corner for ChArUco) to
    texture pixels."""
    import cv2

    sq = board.square_mm * px_per_mm
    if board.kind == "chessboard":
        n_x, n_y = board.cols + 1, board.rows + 1  # squares
        w, h = int(round((n_x + 2) * sq)), int(round((n_y + 2) * sq))
        tex = np.full((h, w), 255, np.uint8)
        for j in range(n_y):
            for i in range((j % 2), n_x, 2):
                x0, y0 = int(round((i + 1) * sq)), int(round((j + 1) * sq))
                tex[y0:int(round((j + 2) * sq)), x0:int(round((i + 2) * sq))] = 0
        origin = 2 * sq  # first inner corner
    else:
        inner_w, inner_h = int(round(board.cols * sq)), int(round(board.rows * sq))
        img = board.charuco_board().generateImage((inner_w, inner_h), marginSize=0, borderBits=1)
        w, h = inner_w + int(2 * sq), inner_h + int(2 * sq)
        tex = np.full((h, w), 255, np.uint8)
        tex[int(sq):int(sq) + inner_h, int(sq):int(sq) + inner_w] = img
        origin = sq
    S = np.array([[px_per_mm, 0, origin], [0, px_per_mm, origin], [0, 0, 1.0]])
    return cv2.cvtColor(tex, cv2.COLOR_GRAY2BGR), S


def _rotation(rx, ry, rz):
    import cv2

    return cv2.Rodrigues(np.radians([rx, ry, rz]))[0]


def render_board_views(camera: Camera, board, n_views: int, rng=None, distance_mm: float = 600.0,
                       noise_sigma: float = 1.0, max_tilt_deg: float = 35.0):
    """``n_views`` images of ``board`` in random poses (tilts up to ``max_tilt_deg`` about each axis) seen by
    ``camera`` (lens distortion included, by remapping an ideal render). Returns a
    list of 8-bit BGR images."""
    import cv2

    rng = np.random.default_rng(0) if rng is None else rng
    tex, S = board_texture(board)
    w, h = camera.image_size
    # centre of the board in board mm
    if board.kind == "chessboard":
        centre = np.array([(board.cols - 1) * board.square_mm / 2, (board.rows - 1) * board.square_mm / 2, 0])
    else:
        centre = np.array([board.cols * board.square_mm / 2, board.rows * board.square_mm / 2, 0])
    remap = None
    if camera.has_distortion:
        grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)), axis=-1)
        ideal = camera.ideal_pixels(camera.normalize(grid.reshape(-1, 2))).reshape(h, w, 2).astype(np.float32)
        remap = (ideal[..., 0], ideal[..., 1])
    images = []
    for _ in range(n_views):
        R = _rotation(*rng.uniform(-max_tilt_deg, max_tilt_deg, 2), rng.uniform(-20, 20))
        t = np.array([rng.uniform(-60, 60), rng.uniform(-40, 40), distance_mm * rng.uniform(0.85, 1.2)])
        t = t - R @ centre  # board centre at t
        H_board_to_img = camera.K @ np.c_[R[:, :2], t]
        H = H_board_to_img @ np.linalg.inv(S)
        img = cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_LINEAR,
                                  borderValue=(90, 90, 90))
        if remap is not None:
            img = cv2.remap(img, remap[0], remap[1], cv2.INTER_LINEAR, borderValue=(90, 90, 90))
        img = cv2.GaussianBlur(img, (0, 0), 0.6)
        img = np.clip(img + rng.normal(0, noise_sigma, img.shape), 0, 255).astype(np.uint8)
        images.append(img)
    return images


def rig_clip_frames(rig, n_frames: int, settings: RenderSettings | None = None, seed: int = 0,
                    class_rgb=None, head_motion_deg: float = 3.0):
    """Yield ``(frame_number, bgr image, FrameTruth)`` for a synthetic clip of a
    :class:`synthetic.simulate.FaceRig`: the face turns gently (a sinusoid of
    ``head_motion_deg``) about its centre; visibility per view is recomputed from the
    surface normals each frame. Colours cycle through ``class_rgb`` (default: the
    four blacklight classes)."""
    from ..core.capture.markers import DEFAULT_CLASSES
    from .simulate import rig_motion, visibility

    class_rgb = np.array([s[0] for s in DEFAULT_CLASSES.values()]) if class_rgb is None else np.asarray(class_rgb)
    rng = np.random.default_rng(seed)
    n = len(rig.points)
    color = np.arange(n) % len(class_rgb)
    rng.shuffle(color)
    for f in range(n_frames):
        pts, nrm = rig_motion(rig, f, n_frames, head_motion_deg)
        vis = visibility(rig.camera, rig.planes, pts, nrm)
        img, truth = render_rig_frame(rig.camera, rig.planes, pts, color, class_rgb, settings, rng, visible=vis)
        yield f, img, truth


def render_board_in_rig(camera: Camera, planes, board, n_frames: int, rng=None, distance_mm: float = 600.0,
                        noise_sigma: float = 1.0):
    """A board held where the face would be, turning (yaw sweeps +-35 deg), seen
    directly and in each mirror. The mirror images are drawn from the reflected
    board pose (a reflected plane is still imaged by a homography). Returns a list
    of 8-bit BGR frames (a dark room, the board lit)."""
    import cv2

    rng = np.random.default_rng(0) if rng is None else rng
    tex, S = board_texture(board)
    w, h = camera.image_size
    centre = np.array([board.cols * board.square_mm / 2, board.rows * board.square_mm / 2, 0])
    frames = []
    for f in range(n_frames):
        yaw = 35.0 * np.sin(2 * np.pi * f / max(n_frames, 2))
        R = _rotation(rng.uniform(-10, 10), yaw, rng.uniform(-8, 8))
        t = np.array([rng.uniform(-15, 15), rng.uniform(-15, 15), distance_mm]) - R @ centre
        views = [(R, t)]
        for n, d in planes:
            H = np.eye(3) - 2.0 * np.outer(n, n)
            views.append((H @ R, H @ t + 2.0 * d * n))
        img = np.zeros((h, w, 3), np.float64)
        for Rv, tv in views:
            Hb = camera.K @ np.c_[Rv[:, :2], tv] @ np.linalg.inv(S)
            warped = cv2.warpPerspective(tex, Hb, (w, h), flags=cv2.INTER_LINEAR, borderValue=(0, 0, 0))
            img = np.maximum(img, warped)
        img = cv2.GaussianBlur(img, (0, 0), 0.6)
        frames.append(np.clip(img + rng.normal(0, noise_sigma, img.shape), 0, 255).astype(np.uint8))
    return frames
