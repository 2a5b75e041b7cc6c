"""Per-frame steps of the tracker (Lin 2003, the procedure at the end of chapter 5):
3D candidates through the mirrored epipolar band (step 4) and the one-to-one
assignment of predicted markers to candidates (step 6). Both are vectorised over
all detections of a frame; they are the tracker's hot loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mirror import points_from_planes


@dataclass
class Candidates3D:
    """3D candidates of one frame: each is a (direct blob, mirror blob) pair."""

    points: np.ndarray  # (C, 3) eq. 3.10-3.12, fused when the direct blob pairs in both mirrors
    direct: np.ndarray  # (C,) direct blob index
    mirror_blob: np.ndarray  # (C, K) blob index in each mirror, -1 where that mirror has none
    residual_px: np.ndarray  # (C,) largest band distance of its pairs


def frame_candidates(direct_n, direct_color, mirror_n, mirror_color, normals, ds, focal_px: float,
                     band_px: float = 1.0, depth_range=None) -> Candidates3D:
    """3D candidates of one frame (procedure step 4).

    ``direct_n`` ``(n, 2)`` and ``mirror_n`` (a list, one ``(m_k, 2)`` per mirror) are
    *normalised* coordinates (undistort once per frame with ``Camera.normalize``);
    colours are class indices. A (direct, mirror) pair is a candidate when the
    colours agree and the mirrored blob lies within ``band_px`` of the direct blob's
    mirrored epipolar line (eq. 5.2-5.3, perpendicular distance in pixels). A direct
    blob with candidates in both mirrors yields the fused combinations as well.
    ``depth_range`` ``(z_min, z_max)`` drops candidates outside a face-sized box."""
    p = np.asarray(direct_n, float)
    pc = np.asarray(direct_color)
    K = len(mirror_n)
    per_mirror = []
    for k in range(K):
        q = np.asarray(mirror_n[k], float)
        if len(p) == 0 or len(q) == 0:
            per_mirror.append((np.zeros(0, int), np.zeros(0, int), np.zeros(0)))
            continue
        a, b, c = (float(v) for v in normals[k])
        # mirrored epipolar line of p: u x p = (b - c y, c x - a, a y - b x) (eq. 5.2)
        l0 = b - c * p[:, 1]
        l1 = c * p[:, 0] - a
        l2 = a * p[:, 1] - b * p[:, 0]
        dist = np.abs(l0[:, None] * q[None, :, 0] + l1[:, None] * q[None, :, 1] + l2[:, None])
        dist *= focal_px / np.hypot(l0, l1)[:, None]
        i, j = np.nonzero((dist <= band_px) & (pc[:, None] == np.asarray(mirror_color[k])[None, :]))
        per_mirror.append((i, j, dist[i, j]))
    rows_direct, rows_blob, rows_res = [], [], []
    for k, (i, j, r) in enumerate(per_mirror):
        blob = np.full((i.size, K), -1)
        blob[:, k] = j
        rows_direct.append(i)
        rows_blob.append(blob)
        rows_res.append(r)
    if K == 2 and per_mirror[0][0].size and per_mirror[1][0].size:
        # fused candidates: every combination of a mirror-0 and a mirror-1 partner of one direct blob
        i0, j0, r0 = per_mirror[0]
        i1, j1, r1 = per_mirror[1]
        order = np.argsort(i1, kind="stable")
        i1s, j1s, r1s = i1[order], j1[order], r1[order]
        lo = np.searchsorted(i1s, i0, "left")
        hi = np.searchsorted(i1s, i0, "right")
        counts = hi - lo
        rep = np.repeat(np.arange(i0.size), counts)
        idx1 = np.repeat(lo, counts) + (np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts))
        blob = np.c_[j0[rep], j1s[idx1]]
        rows_direct.append(i0[rep])
        rows_blob.append(blob)
        rows_res.append(np.maximum(r0[rep], r1s[idx1]))
    direct = np.concatenate(rows_direct) if rows_direct else np.zeros(0, int)
    blobs = np.concatenate(rows_blob) if rows_blob else np.zeros((0, K), int)
    res = np.concatenate(rows_res) if rows_res else np.zeros(0)
    if direct.size == 0:
        return Candidates3D(np.zeros((0, 3)), direct, blobs, res)
    pm = np.stack([np.asarray(mirror_n[k], float)[np.maximum(blobs[:, k], 0)] if len(mirror_n[k]) else
                   np.zeros((direct.size, 2)) for k in range(K)])
    pts = points_from_planes(p[direct], pm, normals, ds, visible=(blobs >= 0).T)
    keep = np.all(np.isfinite(pts), axis=1) & (pts[:, 2] > 0)
    if depth_range is not None:
        keep &= (pts[:, 2] >= depth_range[0]) & (pts[:, 2] <= depth_range[1])
    return Candidates3D(pts[keep], direct[keep], blobs[keep], res[keep])


def assign_nearest(predicted, candidates, gate: float):
    """One-to-one assignment of predicted marker positions ``(N, 3)`` to candidate
    positions ``(C, 3)`` within ``gate`` (procedure step 6). Mutual nearest
    neighbours (from KD-trees) are accepted directly; only the markers and
    candidates left in conflict go through ``linear_sum_assignment``. Returns
    ``(N,)`` candidate indices, -1 for no candidate within the gate."""
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    pred = np.asarray(predicted, float)
    cand = np.asarray(candidates, float)
    out = np.full(len(pred), -1)
    if len(pred) == 0 or len(cand) == 0:
        return out
    ok_pred = np.all(np.isfinite(pred), axis=1)
    tree_c = cKDTree(cand)
    d_pc, nn_pc = tree_c.query(np.where(ok_pred[:, None], pred, 0.0), distance_upper_bound=gate)
    d_pc[~ok_pred] = np.inf
    tree_p = cKDTree(pred[ok_pred])
    pred_index = np.flatnonzero(ok_pred)
    _, nn_cp = tree_p.query(cand, distance_upper_bound=gate)
    has = np.isfinite(d_pc)
    mutual = has.copy()
    back = nn_cp[np.minimum(nn_pc, len(cand) - 1)]
    mutual[has] = (back[has] < len(pred_index)) & (pred_index[np.minimum(back[has], len(pred_index) - 1)]
                                                    == np.flatnonzero(has))
    # a candidate claimed as nearest by several markers is a conflict, even if mutual for one
    claimed = np.bincount(nn_pc[has], minlength=len(cand) + 1)
    mutual &= has & (claimed[np.minimum(nn_pc, len(cand))] == 1)
    out[mutual] = nn_pc[mutual]
    rest = np.flatnonzero(has & ~mutual)
    if rest.size:
        taken = np.zeros(len(cand), bool)
        taken[out[mutual]] = True
        near = tree_c.query_ball_point(pred[rest], gate)
        rows = np.repeat(np.arange(rest.size), [len(n) for n in near])
        cols = np.concatenate([np.asarray(n, int) for n in near]) if rows.size else np.zeros(0, int)
        free = ~taken[cols]
        rows, cols = rows[free], cols[free]
        if rows.size:
            uc, cinv = np.unique(cols, return_inverse=True)
            cost = np.full((rest.size, uc.size), 1e9)
            cost[rows, cinv] = np.linalg.norm(pred[rest[rows]] - cand[cols], axis=1)
            r, c = linear_sum_assignment(cost)
            good = cost[r, c] < 1e9
            out[rest[r[good]]] = uc[c[good]]
    return out
