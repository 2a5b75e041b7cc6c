"""Per-frame steps of the tracker (Lin 2003, the procedure at the end of chapter 5):
3D candidates through the mirrored epipolar band (step 4), for one frame or for
every frame of a take at once, vectorised over all detections.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..capture.views import ClipDetections
from ..geometry.mirror import depths_from_planes, points_from_planes


@dataclass
class Candidates3D:
    """3D candidates of one frame: each is a (direct blob, mirror blob) pair."""

    points: np.ndarray  # (C, 3) eq. 3.10-3.12, fused when the direct blob pairs in both mirrors
    direct: np.ndarray  # (C,) direct blob index
    mirror_blob: np.ndarray  # (C, K) blob index in each mirror, -1 where that mirror has none
    residual_px: np.ndarray  # (C,) largest band distance of its pairs


def spans(lo, count) -> np.ndarray:
    """The indices ``lo[i], ..., lo[i] + count[i] - 1`` of every ``i``, one run after another: the
    rows of sorted runs found by two binary searches, without a Python loop."""
    count = np.asarray(count, int)
    return np.repeat(np.asarray(lo, int) - np.cumsum(count) + count, count) + np.arange(count.sum())


def _pencil_key(pts, normal):
    """Which line of the pencil through the mirror's epipole ``u`` (the image of the
    mirror normal) each normalised point lies on: the line ``u x p`` (eq. 5.2) meets a
    fixed reference line at the coordinate ``s``; points on one mirrored epipolar line
    share ``s``. Returns ``s`` and ``|grad s|`` (how fast ``s`` changes across lines at
    each point). ``None`` when the epipole lies near the image centre (a mirror facing
    the camera), where the key degenerates."""
    a, b, c = (float(v) for v in normal)
    ab = np.hypot(a, b)
    if ab < 0.2 * abs(c):
        return None
    nx, ny = a / ab, b / ab
    x, y = pts[:, 0], pts[:, 1]
    l2 = a * y - b * x
    D = ab - c * (nx * x + ny * y)
    if np.any(D <= 0.05 * ab):
        return None  # a point beyond the epipole: not a mirror beside the face
    s = l2 / D
    grad = np.hypot(-b * D + c * nx * l2, a * D + c * ny * l2) / (D * D)
    return s, grad


def band_pairs(p, p_frame, q, q_frame, normal, focal_px: float, band_px: float):
    """All (direct ``i``, mirrored ``j``) pairs of the same frame with ``q[j]`` within
    ``band_px`` of the mirrored epipolar line of ``p[i]`` (eq. 5.2-5.3, perpendicular
    distance in pixels), for the detections of a whole clip at once. ``p`` ``(n, 2)``
    and ``q`` ``(m, 2)`` are normalised coordinates, ``p_frame``/``q_frame`` their
    frames. Each mirrored point is keyed by its epipolar line (:func:`_pencil_key`)
    and sorted; each direct point's band is a key interval found by binary search, and
    the pairs in it are checked exactly. Returns ``(i, j, distance_px)``."""
    p = np.asarray(p, float).reshape(-1, 2)
    q = np.asarray(q, float).reshape(-1, 2)
    empty = (np.zeros(0, int), np.zeros(0, int), np.zeros(0))
    if len(p) == 0 or len(q) == 0:
        return empty
    a, b, c = (float(v) for v in normal)
    kq = _pencil_key(q, normal)
    kp = _pencil_key(p, normal) if kq is not None else None
    if kq is None or kp is None:  # degenerate pencil: compare every pair, frame by frame
        i, j = _same_frame_pairs(np.asarray(p_frame), np.asarray(q_frame))
    else:
        (sq, grad), (sp, _) = kq, kp
        span = 2.0 * float(max(np.abs(sq).max(), np.abs(sp).max())) + 1.0
        key_q = np.asarray(q_frame) * span + sq
        order = np.argsort(key_q, kind="stable")
        sorted_q = key_q[order]
        half = 1.25 * band_px / focal_px * float(grad.max()) + 1e-12
        key_p = np.asarray(p_frame) * span + sp
        lo = np.searchsorted(sorted_q, key_p - half, "left")
        hi = np.searchsorted(sorted_q, key_p + half, "right")
        counts = hi - lo
        i = np.repeat(np.arange(len(p)), counts)
        j = order[spans(lo, counts)]
    x, y = p[i, 0], p[i, 1]
    l0, l1, l2 = b - c * y, c * x - a, a * y - b * x  # u x p (eq. 5.2)
    dist = np.abs(l0 * q[j, 0] + l1 * q[j, 1] + l2) * (focal_px / np.hypot(l0, l1))
    ok = dist <= band_px
    return i[ok], j[ok], dist[ok]


def _same_frame_pairs(p_frame, q_frame):
    """Every (i, j) with ``p_frame[i] == q_frame[j]`` (both sorted by frame)."""
    F = int(max(p_frame.max(initial=-1), q_frame.max(initial=-1))) + 1
    qs = np.searchsorted(q_frame, np.arange(F + 1))
    lo, hi = qs[p_frame], qs[p_frame + 1]
    counts = hi - lo
    i = np.repeat(np.arange(len(p_frame)), counts)
    return i, spans(lo, counts)


@dataclass
class ClipCandidates(Candidates3D):
    """:class:`Candidates3D` of a whole clip, sorted by frame: ``direct`` and
    ``mirror_blob`` hold global blob indices (:class:`ClipDetections`), ``frame`` each
    candidate's frame and ``start`` ``(F + 1,)`` the offsets of each frame's block."""

    frame: np.ndarray = None
    start: np.ndarray = None

    def at(self, f: int) -> slice:
        return slice(int(self.start[f]), int(self.start[f + 1]))


#: frames per block of :func:`clip_candidates`: its working arrays (every pair in every band) are ~4x its
#: result; in blocks a long take's stay bounded (a 3600-frame, 240-marker take: 413 MB at the peak in one block)
CANDIDATE_BLOCK_FRAMES = 600


def clip_candidates(det: ClipDetections, normals, ds, focal_px: float, band_px: float = 1.0,
                    depth_range=None, agree_mm: float | None = 2.0,
                    block_frames: int = CANDIDATE_BLOCK_FRAMES) -> ClipCandidates:
    """3D candidates (procedure step 4) of every frame of a clip, vectorised over blocks of
    ``block_frames`` frames (:func:`_block_candidates`): the same pairs and points as
    :func:`frame_candidates` frame by frame, in the same order whatever the block size."""
    F = det.n_frames
    if F <= block_frames:
        return _block_candidates(det, normals, ds, focal_px, band_px, depth_range, agree_mm)
    parts = []
    for a in range(0, F, block_frames):
        c = _block_candidates(det.window(a, a + block_frames), normals, ds, focal_px, band_px, depth_range, agree_mm)
        first_blob = np.array([s[a] for s in det.start])          # the window's blob 0 in each view
        parts.append((c, a, first_blob))
    points = np.concatenate([c.points for c, _, _ in parts])
    direct = np.concatenate([c.direct + first_blob[0] for c, _, first_blob in parts])
    blobs = np.concatenate([np.where(c.mirror_blob >= 0, c.mirror_blob + first_blob[1:], -1)
                            for c, _, first_blob in parts])
    residual = np.concatenate([c.residual_px for c, _, _ in parts])
    frame = np.concatenate([c.frame + a for c, a, _ in parts])
    return ClipCandidates(points, direct, blobs, residual, frame, np.searchsorted(frame, np.arange(F + 1)))


def _block_candidates(det: ClipDetections, normals, ds, focal_px: float, band_px: float = 1.0,
                      depth_range=None, agree_mm: float | None = 2.0) -> ClipCandidates:
    """:func:`clip_candidates` of the frames of ``det`` in one vectorised pass.

    A fused candidate (one direct blob with a partner in each mirror) is kept only when
    the two mirrors put the direct blob at the same point: the single-mirror depths
    (eq. 3.10-3.11) within ``agree_mm`` along the direct ray (``None``: no check). A
    true marker's two mirror images agree to the detection noise (measured: < 0.4 mm
    at 0.1 px noise, 600 mm away); a mirror blob that only happens to fall in the band
    -- half of all fused combinations on a 300-marker face -- puts it tens of
    millimetres off (median 45 mm)."""
    K = len(normals)
    pc = det.colour[0]
    per_mirror = []
    for k in range(K):
        i, j, r = band_pairs(det.norm[0], det.frame[0], det.norm[k + 1], det.frame[k + 1], normals[k], focal_px,
                             band_px)
        same = pc[i] == det.colour[k + 1][j]
        i, j, r = i[same], j[same], r[same]
        if agree_mm is not None and i.size:
            p = det.norm[0][i]
            z, _ = depths_from_planes(p, det.norm[k + 1][j][None], normals[k][None], np.asarray(ds)[k:k + 1])
            along = z * np.sqrt(1.0 + np.einsum("ij,ij->i", p, p))  # distance from the camera along the ray
        else:
            along = np.zeros(i.size)
        per_mirror.append((i, j, r, along))
    direct, blobs, res = _combine(per_mirror, K, agree_mm)
    empty = ClipCandidates(np.zeros((0, 3)), np.zeros(0, int), np.zeros((0, K), int), np.zeros(0),
                           np.zeros(0, int), np.zeros(det.n_frames + 1, int))
    if direct.size == 0:
        return empty
    pm = np.stack([det.norm[k + 1][np.maximum(blobs[:, k], 0)] if len(det.norm[k + 1]) else
                   np.zeros((direct.size, 2)) for k in range(K)])
    pts = points_from_planes(det.norm[0][direct], pm, normals, ds, visible=(blobs >= 0).T)
    keep = np.all(np.isfinite(pts), axis=1) & (pts[:, 2] > 0)
    if depth_range is not None:
        keep &= (pts[:, 2] >= depth_range[0]) & (pts[:, 2] <= depth_range[1])
    order = np.flatnonzero(keep)
    order = order[np.argsort(direct[order], kind="stable")]  # global direct index order = frame order
    frame = det.frame[0][direct[order]]
    return ClipCandidates(pts[order], direct[order], blobs[order], res[order], frame,
                          np.searchsorted(frame, np.arange(det.n_frames + 1)))


def _combine(per_mirror, K, agree_mm=None):
    """Candidate rows from each mirror's (direct, mirror, residual, distance along the
    direct ray) pairs, plus the fused rows: every combination of a mirror-0 and a
    mirror-1 partner of one direct blob whose distances differ by at most ``agree_mm``
    (``None``: every combination). Returns ``(direct (C,), mirror blobs (C, K),
    residual (C,))``."""
    rows_direct, rows_blob, rows_res = [], [], []
    for k, (i, j, r, _) in enumerate(per_mirror):
        blob = np.full((i.size, K), -1)
        blob[:, k] = j
        rows_direct.append(i)
        rows_blob.append(blob)
        rows_res.append(r)
    if K == 2 and per_mirror[0][0].size and per_mirror[1][0].size:
        i0, j0, r0, z0 = per_mirror[0]
        i1, j1, r1, z1 = per_mirror[1]
        order = np.argsort(i1, kind="stable")
        i1s, j1s, r1s, z1s = i1[order], j1[order], r1[order], z1[order]
        lo = np.searchsorted(i1s, i0, "left")
        hi = np.searchsorted(i1s, i0, "right")
        counts = hi - lo
        rep = np.repeat(np.arange(i0.size), counts)
        idx1 = np.repeat(lo, counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        if agree_mm is not None:
            agree = np.abs(z0[rep] - z1s[idx1]) <= agree_mm
            rep, idx1 = rep[agree], idx1[agree]
        rows_direct.append(i0[rep])
        rows_blob.append(np.c_[j0[rep], j1s[idx1]])
        rows_res.append(np.maximum(r0[rep], r1s[idx1]))
    direct = np.concatenate(rows_direct) if rows_direct else np.zeros(0, int)
    blobs = np.concatenate(rows_blob) if rows_blob else np.zeros((0, K), int)
    res = np.concatenate(rows_res) if rows_res else np.zeros(0)
    return direct, blobs, res


def frame_candidates(direct_n, direct_color, mirror_n, mirror_color, normals, ds, focal_px: float,
                     band_px: float = 1.0, depth_range=None, agree_mm: float | None = 2.0) -> Candidates3D:
    """3D candidates of one frame (procedure step 4).

    ``direct_n`` ``(n, 2)`` and ``mirror_n`` (a list, one ``(m_k, 2)`` per mirror) are
    *normalised* coordinates (undistort once per frame with ``Camera.normalize``);
    colours are class indices. A (direct, mirror) pair is a candidate when the
    colours agree and the mirrored blob lies within ``band_px`` of the direct blob's
    mirrored epipolar line (eq. 5.2-5.3, perpendicular distance in pixels). A direct
    blob with candidates in both mirrors yields the fused combinations as well, where
    the two mirrors agree on its depth within ``agree_mm``.
    ``depth_range`` ``(z_min, z_max)`` drops candidates outside a face-sized box.
    (A one-frame :func:`clip_candidates`.)"""
    norm = [np.asarray(direct_n, float).reshape(-1, 2)] + [np.asarray(m, float).reshape(-1, 2) for m in mirror_n]
    colour = [np.asarray(direct_color, int).reshape(-1)] + [np.asarray(c, int).reshape(-1) for c in mirror_color]
    det = ClipDetections(1, xy=norm, norm=norm, colour=colour, frame=[np.zeros(len(n), int) for n in norm],
                         start=[np.array([0, len(n)]) for n in norm])
    c = clip_candidates(det, normals, ds, focal_px, band_px, depth_range, agree_mm)
    return Candidates3D(c.points, c.direct, c.mirror_blob, c.residual_px)
