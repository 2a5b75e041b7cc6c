"""Is a point on the face? The tests by which late markers and wrong pairings are told apart
(:mod:`.late`): a point's distance along its line of sight from the face that the markers nearest that
line form, as the camera sees it and as a mirror sees it (eq. 3.9: the markers reflected in its plane)."""

from __future__ import annotations

import numpy as np

from ..geometry.mirror import reflect_points


def along_ray(gap, ray) -> float:
    """How far (mm) the vector ``gap`` (3,) lies from the line of the unit direction ``ray`` (3,)."""
    return float(np.linalg.norm(gap - (gap @ ray) * ray))


FACE_MARKERS = 6  # the markers nearest a point's ray that give the face there (off_the_face)


def face_offset(neutral, point, k: int = FACE_MARKERS) -> tuple:
    """``(distance, misfit)``: how far ``point`` lies along its ray from the face formed by the markers
    ``neutral`` ``(N, 3)`` (one frame, camera frame: the frame the point is seen in, so the face there faces
    the camera), and the RMS misfit of that face to its markers (mm). The face: the plane
    ``z = a x' + b y' + c`` (``x' = x/z``, ``y' = y/z``, the ray's direction) through the ``k`` markers
    nearest to its ray, least squares. ``(nan, nan)`` with fewer than ``k`` markers."""
    if len(neutral) < k or not np.all(np.isfinite(point)) or point[2] <= 0:
        return float("nan"), float("nan")
    rays = neutral[:, :2] / neutral[:, 2:3]
    ray = point[:2] / point[2]
    near = np.argsort(np.linalg.norm(rays - ray, axis=1))[:k]
    A = np.c_[rays[near], np.ones(k)]
    coef, *_ = np.linalg.lstsq(A, neutral[near, 2], rcond=None)
    z_face = float(np.r_[ray, 1.0] @ coef)
    misfit = float(np.sqrt(np.mean((A @ coef - neutral[near, 2]) ** 2)))
    return abs(point[2] - z_face) * float(np.sqrt(1.0 + ray @ ray)), misfit


def off_the_face(neutral, point, off_mm: float, k: int = FACE_MARKERS) -> bool:
    """Is ``point`` more than ``off_mm`` along its ray from the face formed by the markers ``neutral``
    (:func:`face_offset`, :func:`beyond`)? With fewer than ``k`` markers nothing is decided."""
    return beyond(face_offset(neutral, point, k), off_mm)


def beyond(offset, off_mm: float) -> bool:
    """Is a :func:`face_offset` ``(distance, misfit)`` more than ``off_mm``? Where the plane fits its markers
    loosely (the face curving away, at the silhouette) the limit grows to 4x that misfit. False where NaN."""
    distance, misfit = offset
    return bool(distance > max(off_mm, 4.0 * misfit))


def off_in_mirrors(markers, views, point, used, planes, off_mm: float) -> bool:
    """Is ``point`` off the face (:func:`off_the_face`) as every mirror it was paired through sees it
    (``used (K,)``; ``planes`` ``(normals (K, 3), ds (K,))``)? The face in mirror ``k``: the markers
    ``(N, 3)`` (camera frame, NaN where not measured) measured through it, bit ``2 << k`` of their
    camera mask ``views (N,)``. A mirror shows the scene as the camera reflected in its plane would
    (eq. 3.9): reflecting the markers and the point puts that view where :func:`off_the_face` looks
    from. A wrong pairing lies on another dot's mirror ray, off the face along it as well. A mirror
    through which fewer than :func:`off_the_face`'s ``k`` markers were measured clears nothing."""
    normals, ds = planes
    for k in np.flatnonzero(used):
        face = markers[((views & (2 << k)) > 0) & np.all(np.isfinite(markers), axis=1)]
        if len(face) >= FACE_MARKERS and not off_the_face(reflect_points(face, normals[k], ds[k]),
                                                          reflect_points(point, normals[k], ds[k]), off_mm,
                                                          FACE_MARKERS):
            return False
    return True
