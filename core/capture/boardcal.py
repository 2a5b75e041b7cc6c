"""Mirror planes from a ChArUco board seen directly and in both mirrors
(``mirrorcap mirrors``), for rigs where the markers alone are too few.

Per frame the board is detected in the direct view's region and in each mirror's
region *flipped horizontally* (a mirror image is a flipped view, and ArUco markers
are not mirror-symmetric); mirror corners are un-flipped back to image pixels and
paired with the direct corners of the same ChArUco id. Pooled over frames, the
pairs give each mirror's normal by the robust closed form (eq. 3.8 with RANSAC).
The board's known size fixes the scale: its pose in the direct view
(``cv2.solvePnP``) gives the corners in millimetres, and each mirror's ``d`` is
scaled so that the corners reconstructed through that mirror (eq. 3.10-3.12)
match -- so the planes come out in millimetres, no known length needed.

MIRRORS.json::

    {"mirrors": [{"mirror": 0, "normal": [a, b, c], "d": -245.3, "pairs": 812, "inliers": 806,
                  "noise_px": 0.21, "expected_normal_error_deg": 0.01}, ...],
     "units": "mm", "board": "charuco:...", "frames_used": 24}
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..common.errors import DegenerateError, InputError
from ..geometry.camera import Camera
from ..geometry.mirror import MirrorPlane, estimate_mirror_plane, points_from_planes
from .calibrate import Board
from .rig import ViewLayout


def _regions(layout: ViewLayout | None, size):
    """(x0, y0, x1, y1) of direct, mirror0, mirror1; default: the image's thirds."""
    w, h = size
    if layout is not None and layout.regions:
        return [tuple(int(round(v)) for v in layout.regions[name]) if name in layout.regions else None
                for name in ("direct", "mirror0", "mirror1")]
    if layout is not None and layout.boundaries:
        b0, b1 = (int(round(b)) for b in layout.boundaries)
    else:
        b0, b1 = w // 3, 2 * w // 3
    return [(b0, 0, b1, h), (0, 0, b0, h), (b1, 0, w, h)]


def detect_board_views(gray: np.ndarray, board: Board, regions):
    """ChArUco corners per view: a list (direct, mirror0, mirror1) of ``{id: (x, y)}``
    in image pixels (mirror views detected flipped, then un-flipped)."""
    import cv2

    detector = cv2.aruco.CharucoDetector(board.charuco_board())
    out = []
    for k, reg in enumerate(regions):
        if reg is None:
            out.append({})
            continue
        x0, y0, x1, y1 = reg
        crop = np.ascontiguousarray(gray[y0:y1, x0:x1])
        flipped = k > 0
        if flipped:
            crop = cv2.flip(crop, 1)
        corners, ids, _, _ = detector.detectBoard(crop)
        found = {}
        if ids is not None:
            pts = corners.reshape(-1, 2).astype(float)
            if flipped:
                pts[:, 0] = (x1 - x0 - 1) - pts[:, 0]
            pts += (x0, y0)
            found = {int(i): p for i, p in zip(ids.ravel(), pts)}
        out.append(found)
    return out


@dataclass
class BoardMirrorCalibration:
    planes: list  # MirrorPlane per mirror, d in millimetres
    frames_used: int
    pairs: list  # correspondences per mirror

    def to_dict(self, board: Board) -> dict:
        return {"mirrors": [dict(mirror=k, **pl.to_dict()) for k, pl in enumerate(self.planes)], "units": "mm",
                "board": board.spec(), "frames_used": self.frames_used}


def calibrate_mirrors_from_board(frames, camera: Camera, board: Board, layout: ViewLayout | None = None,
                                 threshold_px: float = 2.0, min_pairs: int = 20) -> BoardMirrorCalibration:
    """``frames``: iterable of 8-bit BGR images of the board in the rig."""
    import cv2

    if board.kind != "charuco":
        raise InputError("mirror calibration needs a ChArUco board (its corners carry ids)")
    obj_all = board.charuco_board().getChessboardCorners()  # (n, 3) board mm
    pairs = [[], []]  # per mirror: (direct px, mirror px, frame, corner id)
    poses = {}
    used = 0
    regions = None
    for f, frame in enumerate(frames):
        gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        if regions is None:
            regions = _regions(layout, (gray.shape[1], gray.shape[0]))
        views = detect_board_views(gray, board, regions)
        direct = views[0]
        if len(direct) < 6:
            continue
        ids = np.array(sorted(direct))
        ok, rvec, tvec = cv2.solvePnP(obj_all[ids].astype(np.float64), np.array([direct[i] for i in ids]),
                                      camera.K, camera.dist)
        if not ok:
            continue
        poses[f] = (cv2.Rodrigues(rvec)[0], tvec.ravel())
        any_pair = False
        for k in (0, 1):
            common = sorted(set(direct) & set(views[k + 1]))
            for i in common:
                pairs[k].append((direct[i], views[k + 1][i], f, i))
            any_pair |= bool(common)
        used += any_pair
    planes, counts = [], []
    for k in (0, 1):
        if len(pairs[k]) < min_pairs:
            raise DegenerateError(f"the board was paired in mirror {k} at only {len(pairs[k])} corners "
                                  f"(need {min_pairs}); is the board visible in that mirror?")
        dp = np.array([p[0] for p in pairs[k]])
        mp = np.array([p[1] for p in pairs[k]])
        plane = estimate_mirror_plane(dp, mp, camera, threshold_px=threshold_px, label=f"mirror {k}")
        # metric scale: the corners reconstructed through this mirror vs the PnP corners
        inl = plane.inliers
        rel = points_from_planes(camera.normalize(dp[inl]), camera.normalize(mp[inl])[None], plane.normal[None],
                                 np.array([plane.d]))
        metric = np.array([poses[p[2]][0] @ obj_all[p[3]] + poses[p[2]][1] for p, keep in zip(pairs[k], inl)
                           if keep])
        scale = float(np.sum(rel * metric) / np.sum(rel * rel))
        plane.d *= scale
        planes.append(plane)
        counts.append(len(pairs[k]))
    return BoardMirrorCalibration(planes=planes, frames_used=used, pairs=counts)


def write_mirrors_json(result: BoardMirrorCalibration, board: Board) -> str:
    import json

    return json.dumps(result.to_dict(board), indent=2) + "\n"


def load_mirrors(path) -> list:
    """MIRRORS.json -> [MirrorPlane] (normal and d, mm)."""
    from ..common.files import read_json

    data = read_json(path, "mirrors file")
    shape = 'expected {"mirrors": [{"normal": [a, b, c], "d": ...}, ...]}'
    try:
        planes = []
        for m in data["mirrors"]:
            normal = np.asarray(m["normal"], float)
            d = float(m["d"])
            if normal.shape != (3,) or not np.all(np.isfinite(normal)) or not np.isfinite(d) or \
                    abs(np.linalg.norm(normal) - 1.0) > 1e-6:
                raise ValueError
            planes.append(MirrorPlane(normal=normal, d=d))
    except (KeyError, TypeError, ValueError):
        raise InputError(f"mirrors file {path}: {shape} with unit normals") from None
    if not planes:
        raise InputError(f"mirrors file {path}: no mirrors")
    return planes
