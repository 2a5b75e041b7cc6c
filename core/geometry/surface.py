"""The face's surface at its markers, from the markers alone: unit normals by principal components
(:func:`surface_normals`), and whether a camera or a mirror's virtual camera sees a point within an angle of
its normal (:func:`seen_face_on`). A dot seen at a grazing angle -- its image foreshortened, partly hidden
by the face curving away, or merged with a neighbour's -- drifts off the dot; the offline steps that measure
a marker from 2D continuity alone take no view that sees its dot that way."""

from __future__ import annotations

import numpy as np


def surface_normals(points, neighbours_k: int = 9) -> np.ndarray:
    """Unit normals ``(N, 3)`` of the face at its markers ``points (N, 3)`` (camera frame): each the
    least-spread direction of the marker and its ``neighbours_k - 1`` nearest markers (the plane
    through them by principal components), turned towards the camera. NaN rows stay NaN."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, float)
    normals = np.full(pts.shape, np.nan)
    ok = np.flatnonzero(np.isfinite(pts).all(axis=1))
    if ok.size < neighbours_k:
        return normals
    _, idx = cKDTree(pts[ok]).query(pts[ok], k=neighbours_k)
    spread = pts[ok][idx] - pts[ok][idx].mean(axis=1, keepdims=True)              # (n, k, 3)
    _, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", spread, spread))
    n = vectors[:, :, 0]                                                           # smallest eigenvalue first
    normals[ok] = n * np.where(np.einsum("ni,ni->n", n, pts[ok]) > 0, -1.0, 1.0)[:, None]
    return normals


def seen_face_on(normals, points, centres, max_deg: float) -> np.ndarray:
    """Whether each of the cameras ``centres`` ``(..., C, 3)`` sees each point ``points`` ``(..., 3)``
    within ``max_deg`` of its surface normal ``normals`` ``(..., 3)``: ``(..., C)``. The camera's centre
    is the origin; a mirror's virtual camera is the origin reflected in its plane (eq. 3.9). NaN
    normals: False."""
    view = np.asarray(centres, float) - np.asarray(points, float)[..., None, :]
    cos = np.einsum("...i,...ci->...c", np.asarray(normals, float), view)
    with np.errstate(invalid="ignore"):
        return cos >= np.cos(np.radians(max_deg)) * np.linalg.norm(view, axis=-1)
