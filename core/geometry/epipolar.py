"""The mirrored epipolar band (Lin 2003, eq. 5.1-5.3): where a direct-view marker's image
can lie in a mirror, for pairing markers across views."""

from __future__ import annotations

import numpy as np

from .camera import Camera
from .mirror import MirrorPlane, _homogeneous


def mirrored_epipolar_lines(direct_px, camera: Camera, plane: MirrorPlane) -> np.ndarray:
    """Mirrored epipolar lines (eq. 5.1-5.2) of direct-view pixels ``(..., 2)``.

    Returned as ``(..., 3)`` coefficients ``(l1, l2, l3)`` of
    ``l1 x + l2 y + l3 = 0`` in *undistorted* pixel coordinates
    (:meth:`Camera.ideal_pixels`), scaled so that ``l1^2 + l2^2 = 1``: evaluating a
    line at an undistorted pixel gives the signed distance in pixels."""
    return lines_of_normalised(camera.normalize(direct_px), camera, plane)


def lines_of_normalised(direct_n, camera: Camera, plane: MirrorPlane) -> np.ndarray:
    """:func:`mirrored_epipolar_lines` of direct points already in normalised
    coordinates ``(..., 2)`` (:class:`core.capture.views.ClipDetections` ``norm``)."""
    p_h = _homogeneous(np.asarray(direct_n, dtype=float))
    line_n = np.cross(np.asarray(plane.normal, dtype=float), p_h)  # u x p: (b - c y, c x - a, a y - b x)
    line_px = line_n @ np.linalg.inv(camera.K)  # l_px = K^-T l_n, as row vectors
    return line_px / np.linalg.norm(line_px[..., :2], axis=-1, keepdims=True)


def epipolar_distance(lines, mirror_px, camera: Camera, vertical: bool = False) -> np.ndarray:
    """Distance in pixels of mirrored-view pixels ``(..., 2)`` from lines ``(..., 3)``
    (both broadcast). ``vertical=True`` measures along the image's y axis as the band
    of eq. 5.3 does ("k pixels up and down"); the default measures perpendicular to
    the line, which stays meaningful for steep lines."""
    lines = np.asarray(lines, dtype=float)
    dist = line_distance(lines, camera.ideal_pixels(camera.normalize(mirror_px)))
    if vertical:
        return dist / np.maximum(np.abs(lines[..., 1]), 1e-300)
    return dist


def line_distance(lines, ideal_px) -> np.ndarray:
    """Distance in pixels of undistorted pixels ``(..., 2)`` from lines ``(..., 3)`` whose ``(a, b)`` is a unit
    vector (:func:`lines_of_normalised`), both broadcast: the band test of eq. 5.3."""
    lines = np.asarray(lines, dtype=float)
    return np.abs(lines[..., 0] * ideal_px[..., 0] + lines[..., 1] * ideal_px[..., 1] + lines[..., 2])


def in_mirrored_epipolar_band(
    direct_px, mirror_px, camera: Camera, plane: MirrorPlane, half_width_px: float = 1.5,
    vertical: bool = False,
) -> np.ndarray:
    """Candidate matrix ``(N, M)``: mirrored detection ``j`` lies inside the mirrored
    epipolar band (eq. 5.3, half-width ``k`` = ``half_width_px``) of direct detection
    ``i``."""
    lines = mirrored_epipolar_lines(direct_px, camera, plane)  # (N, 3)
    mirror_px = np.asarray(mirror_px, dtype=float)
    dist = epipolar_distance(lines[:, None, :], mirror_px[None, :, :], camera, vertical=vertical)
    return dist <= half_width_px
