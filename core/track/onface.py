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
    distance, misfit = face_offsets(np.asarray(neutral, float)[None], np.asarray(point, float)[None], k)
    return float(distance[0]), float(misfit[0])


def face_offsets(markers, points, k: int = FACE_MARKERS) -> tuple:
    """:func:`face_offset` of many points at once: ``points`` ``(Q, 3)``, each against its own markers ``markers``
    ``(Q, N, 3)`` (NaN rows: not there). Returns ``(distance (Q,), misfit (Q,))``, NaN where fewer than ``k``
    markers are there."""
    markers, points = np.asarray(markers, float), np.asarray(points, float)
    distance, misfit = np.full(len(points), np.nan), np.full(len(points), np.nan)
    there = np.all(np.isfinite(markers), axis=2) & (np.nan_to_num(markers[..., 2]) > 0)
    ok = np.all(np.isfinite(points), axis=1) & (np.nan_to_num(points[:, 2]) > 0) & (there.sum(axis=1) >= k)
    if not ok.any():
        return distance, misfit
    m, p, there = markers[ok], points[ok], there[ok]
    with np.errstate(invalid="ignore", divide="ignore"):
        rays = m[..., :2] / m[..., 2:3]
    ray = p[:, :2] / p[:, 2:3]
    near = np.argsort(np.where(there, np.linalg.norm(rays - ray[:, None], axis=2), np.inf), axis=1)[:, :k]
    A = np.concatenate([np.take_along_axis(rays, near[..., None], axis=1), np.ones(near.shape + (1,))], axis=2)
    z = np.take_along_axis(m[..., 2], near, axis=1)
    coef = (np.linalg.pinv(A) @ z[..., None])[..., 0]                  # least squares, (q, 3)
    z_face = np.einsum("qi,qi->q", np.c_[ray, np.ones(len(ray))], coef)
    misfit[ok] = np.sqrt(np.mean((np.einsum("qki,qi->qk", A, coef) - z) ** 2, axis=1))
    distance[ok] = np.abs(p[:, 2] - z_face) * np.sqrt(1.0 + np.einsum("qi,qi->q", ray, ray))
    return distance, misfit


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


SHARED_TRACK_FRAMES = 64  # frames of a label on a shared mirror track whose face offsets are read (evenly spread)


def off_face_on_shared_tracks(result, mirror_track, off_mm: float) -> np.ndarray:
    """Measurements ``(F, N)`` to undo: of two labels measured on one 2D track of a mirror (``mirror_track``
    ``(C, K)`` per candidate, :func:`.pairing.candidate_tracks`), in frames of their own, the one whose points lie
    off the face (:func:`face_offset` against the frame's other measured markers, median over up to
    :data:`SHARED_TRACK_FRAMES` of its frames on the track, :func:`beyond` ``off_mm``) while another's lie on it --
    its frames on that track. A dot seen only directly pairs with a like dot's grazing image on its line from the
    first frames, and the image's own dot takes its image where it can (hr2: two forehead dots 17-19 mm off along
    the ray for 63 and 36 frames, their points a median 5.3 and 22.2 mm off the face, the owners' 3.6 and 1.9 mm:
    the second goes). Two markers that merely share a track at different times both lie on the face and stay."""
    F, N = result.assigned_blob.shape
    drop = np.zeros((F, N), bool)
    measured = (result.assigned_blob >= 0) & (result.candidate >= 0) & np.isfinite(result.points[..., 0])
    cand = np.maximum(result.candidate, 0)
    for k in range(mirror_track.shape[1]):
        frame, label = np.nonzero(measured & (mirror_track[cand, k] >= 0))
        track = mirror_track[cand[frame, label], k]
        order = np.lexsort((frame, label, track))                        # by track, then label, then frame
        frame, label, track = frame[order], label[order], track[order]
        start = np.flatnonzero(np.r_[True, (track[1:] != track[:-1]) | (label[1:] != label[:-1])])
        end = np.r_[start[1:], track.size]                               # one (track, label) run each
        first = np.flatnonzero(np.r_[True, track[start[1:]] != track[start[:-1]]])    # each track's first run
        runs = np.diff(np.r_[first, start.size])
        for a, n in zip(first[runs > 1], runs[runs > 1]):                # tracks two labels or more measure on
            off = np.zeros(n, bool)
            for i, r in enumerate(range(a, a + n)):
                frames, lab = frame[start[r]:end[r]], label[start[r]]
                frames = frames[np.linspace(0, frames.size - 1, min(frames.size, SHARED_TRACK_FRAMES)).astype(int)]
                others = measured[frames] & (np.arange(N) != lab)
                offsets = np.vstack(face_offsets(np.where(others[..., None], result.points[frames], np.nan),
                                                 result.points[frames, lab]))            # (2, frames)
                offsets = offsets[:, np.isfinite(offsets[0])]
                off[i] = offsets.size > 0 and beyond(tuple(np.median(offsets, axis=1)), off_mm)
            if off.any() and not off.all():
                for r in np.arange(a, a + n)[off]:
                    drop[frame[start[r]:end[r]], label[start[r]]] = True
    return drop
