"""Markers the tracker conjectured, measured where their dot is seen after all.

The passes of :mod:`.tracker` measure a marker from a 3D candidate: a direct blob paired with
a mirror blob in the mirrored epipolar band (eq. 5.2-5.3). Where a marker's dot is detected
in one view only -- its mirror image hidden by the cheek, merged with a neighbour's, or too
small to detect -- or where the pass lost a pair it did not trust (fast motion outruns the
gate), the take holds a conjecture from the neighbours (eq. 5.8, learned relations;
``tracker._fill_gaps``), or a gap where that conjecture was expected too far off. Once the
whole take is known, the conjecture predicts where the dot must appear in each view; an
unclaimed blob of the marker's colour there, unambiguously nearer this marker than any
other, measures it:

* in two views (direct and a mirror): the point nearest both rays (the reconstruction of
  eq. 3.10-3.12 by least squares), kept when the rays meet as closely as the take's own
  measured pairs do and the point lies within the conjecture's expected error. The cell is
  measured: it is reported even where its conjecture had been withheld.
* in one view: the point on that view's ray nearest the conjecture -- the ray fixes the two
  directions across it, the neighbours only the depth along it. The cell stays a conjecture
  (flagged so in the take) and only a reported one is refined: one view does not bring back
  a withheld conjecture, whose depth would still be expected too far off.

The gate in each view is the conjecture's expected error projected into the image (three
sigma, plus the detections' own noise), at most :data:`MAX_GATE_PX` and at most
:data:`SPACING_SHARE` of the distance to the nearest other marker's image, and the blob must be
:data:`AMBIGUITY_RATIO` times nearer this marker's image than any other's, so a blob that could
belong to a neighbour is never taken. A blob two cells would take goes to neither. Only markers
measured in enough frames take part: a marker measured a few times may be a chain of chance
pairings, and its conjecture would lead it onto another marker's dot.

Measured (``make bench``, README): on the project's rendered clips this reports 0.5-2.4 % more
of the marker-frames seen in the direct view and a mirror, with no identity switch.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..capture.views import ClipDetections
from ..geometry.mirror import reflect_points
from ..geometry.rigid import rotation_zyx
from .result import COLOUR_SPACING_MM, TrackResult

MAX_GATE_PX = 2.5        # the largest distance (pixels) from the predicted image to the blob taken
DETECTION_PX = 0.75      # the detections' own noise, added to the projected conjecture error (pixels)
SPACING_SHARE = 0.4      # the gate is at most this share of the distance to another marker's image
AMBIGUITY_RATIO = 2.0    # the blob must be this much nearer this marker's image than any other's
TWO_VIEW_SIGMAS = 3.0    # a two-view point must lie within this many expected errors of the conjecture (+ 0.5 mm)
CONTINUITY_PX = 1.0      # the dot in the frame before or after lies this near where it should (pixels)
MEETING_PERCENTILE = 90  # two rays must meet as closely as this share of the take's measured pairs do
MEETING_SAMPLE = 20000   # measured pairs that set that limit, at most


def _image(points, view: int, normals, ds):
    """Normalised image coordinates ``(..., 2)`` and depth ``(...)`` of camera-frame ``points``
    in ``view`` (0: direct; k > 0: through mirror k - 1, the virtual point's image, eq. 3.9)."""
    p = points if view == 0 else reflect_points(points, normals[view - 1], ds[view - 1])
    z = p[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        return p[..., :2] / z[..., None], z


def _ray(xy_norm):
    """Unit ray directions ``(..., 3)`` through normalised image points."""
    r = np.concatenate([xy_norm, np.ones(xy_norm.shape[:-1] + (1,))], axis=-1)
    return r / np.linalg.norm(r, axis=-1, keepdims=True)


def _on_ray(point, ray):
    """The point on the ray from the origin along ``ray`` nearest ``point`` (row-wise)."""
    return ray * np.sum(point * ray, axis=-1, keepdims=True)


def _two_rays(a, b_virtual, normals, ds, focal_px: float):
    """The point nearest the direct ray ``a (n, 3)`` and the ray of a mirror image ``b_virtual
    (n, 3)`` (camera rays, unit) of mirrors ``normals (n, 3)``, ``ds (n,)``: in real space the
    mirror's ray starts at the mirrored camera centre ``2 d u`` along ``H_u b`` (eq. 3.9, 3.12).
    Returns the midpoint of the two rays' closest points ``(n, 3)`` and how far apart they pass,
    in pixels at that depth ``(n,)``."""
    o = 2.0 * ds[:, None] * normals
    b = b_virtual - 2.0 * np.sum(b_virtual * normals, axis=1, keepdims=True) * normals
    ab, ao, bo = np.sum(a * b, axis=1), np.sum(a * o, axis=1), np.sum(b * o, axis=1)
    den = 1.0 - ab ** 2
    den = np.where(den > 1e-9, den, np.nan)
    s, u = (ao - ab * bo) / den, (ab * ao - bo) / den          # minimise |s a - (o + u b)|^2
    on_a, on_b = s[:, None] * a, o + u[:, None] * b
    pt = 0.5 * (on_a + on_b)
    return pt, np.linalg.norm(on_a - on_b, axis=1) * focal_px / np.abs(pt[:, 2])


def _meeting_limit(result: TrackResult, det: ClipDetections, cands, normals, ds, focal_px: float) -> float:
    """How closely the direct and mirror rays of the take's measured markers meet (pixels): the
    :data:`MEETING_PERCENTILE` th percentile over up to :data:`MEETING_SAMPLE` measured cells
    with a mirror image -- the clip's own detection noise."""
    c = result.candidate[result.candidate >= 0]
    if c.size == 0:
        return np.inf
    c = c[:: max(1, c.size // MEETING_SAMPLE)]
    direct = cands.direct[c]
    k = np.argmax(cands.mirror_blob[c] >= 0, axis=1)
    mb = cands.mirror_blob[c, k]
    ok = (mb >= 0) & (direct >= 0)
    if not ok.any():
        return np.inf
    _, gap = _two_rays(_ray(det.norm[0][direct[ok]]), _ray(np.stack([det.norm[v + 1][b] for v, b in zip(k[ok], mb[ok])])),
                       normals[k[ok]], ds[k[ok]], focal_px)
    return float(np.nanpercentile(gap, MEETING_PERCENTILE))


def _lasts(det: ClipDetections, view: int, blob, pred, frame, marker, colour, result: TrackResult, conjecture,
           normals, ds, focal_px: float) -> np.ndarray:
    """Whether each blob taken for a cell is a lasting dot: in the frame before or after, a blob of
    the same colour in the same view lies within :data:`CONTINUITY_PX` of where the marker is
    then (its reported point, else its conjecture) plus the same offset from its prediction."""
    F = det.n_frames
    all_blobs = cKDTree(_tree_points(det.norm[view], det.frame[view], det.colour[view], focal_px))
    offset = det.norm[view][blob] - pred
    lasts = np.zeros(blob.size, bool)
    for step in (-1, 1):
        g = frame + step
        inside = (g >= 0) & (g < F)
        g = np.clip(g, 0, F - 1)
        there = np.where(np.isfinite(result.points[g, marker]), result.points[g, marker], conjecture[g, marker])
        img, z = _image(there, view, normals, ds)
        ok = inside & np.all(np.isfinite(img), axis=1) & (z > 0)
        q = _tree_points(np.where(ok[:, None], img + offset, 0.0), g, colour, focal_px)
        d, _ = all_blobs.query(q, k=1, distance_upper_bound=CONTINUITY_PX)
        lasts |= ok & (d <= CONTINUITY_PX)
    return lasts


def _claimed(result: TrackResult, det: ClipDetections, cands, view: int) -> np.ndarray:
    """Blobs of ``view`` (global indices) that a measured marker holds, as a boolean mask."""
    taken = np.zeros(len(det.frame[view]), bool)
    if view == 0:   # assigned_blob counts within each frame
        f, i = np.nonzero(result.assigned_blob >= 0)
        b = result.assigned_blob[f, i] + det.start[0][f]
    else:
        c = result.candidate[result.candidate >= 0]
        b = cands.mirror_blob[c, view - 1]
        b = b[b >= 0]
    taken[b] = True
    return taken


def _tree_points(xy, frame, colour, focal_px: float) -> np.ndarray:
    """Pixel-scaled image points with the frame and colour class as far-apart extra
    coordinates: one KD-tree then serves every frame and class."""
    return np.column_stack([np.asarray(xy, float) * focal_px, np.asarray(frame, float) * COLOUR_SPACING_MM,
                            np.asarray(colour, float) * COLOUR_SPACING_MM])


def measure_in_single_views(result: TrackResult, det: ClipDetections, cands, normals, ds, focal_px: float,
                            conjecture, expected_sd, band_px: float, min_frames: int = 30) -> dict:
    """Measure the gap cells of ``result`` from unclaimed blobs (module text).
    ``conjecture (F, N, 3)``: every gap cell's conjectured camera-frame point, withheld or not
    (NaN elsewhere); ``expected_sd (F, N)``: its expected 3D error (mm); ``band_px``: the
    tracker's epipolar band (the rays of a two-view cell meet closer than this); markers
    measured in fewer than ``min_frames`` frames are left alone. Updates ``points``,
    ``head_frame``, ``conjectured``, ``camera_mask`` and ``assigned_blob`` in place; returns the
    cells measured per frame, ``{"two_views": (F,), "one_view": (F,)}``."""
    normals = np.asarray(normals, float)
    ds = np.asarray(ds, float)
    K = len(normals)
    measured = result.assigned_blob >= 0
    # a marker measured in few frames may be a chain of chance pairings, its conjecture built on them
    settled = measured.sum(axis=0) >= min_frames
    f_c, i_c = np.nonzero(~measured & settled[None] & np.all(np.isfinite(conjecture), axis=2)
                          & np.isfinite(expected_sd))
    F = measured.shape[0]
    counts = {"two_views": np.zeros(F, int), "one_view": np.zeros(F, int)}
    if f_c.size == 0:
        return counts
    # a withheld conjecture (expected off by more than the take allows) is reported again only where two
    # views measure the marker; one view refines a reported conjecture but does not bring back a withheld one
    reported_before = result.conjectured[f_c, i_c]
    p_conj = conjecture[f_c, i_c]
    sd = expected_sd[f_c, i_c]
    colour = result.colour[i_c]
    # where every marker is in every frame, for the spacing and ambiguity tests: its reported point,
    # else its withheld conjecture, else (before its first measurement) its neutral position posed
    R = rotation_zyx(result.head_pose[:, :3])
    posed = np.einsum("fij,nj->fni", R, result.neutral) + result.head_pose[:, None, 3:]
    everywhere = np.where(np.isfinite(result.points), result.points,
                          np.where(np.isfinite(conjecture), conjecture, posed))
    f_r, i_r = np.nonzero(np.all(np.isfinite(everywhere), axis=2))
    blob = np.full((f_c.size, K + 1), -1)
    for v in range(K + 1):
        pred, z = _image(p_conj, v, normals, ds)
        ok = np.all(np.isfinite(pred), axis=1) & (z > 0)
        # the gate: the conjecture's error across the ray, projected (3 sigma), plus the detection noise
        gate = np.minimum(DETECTION_PX + 3.0 * sd * np.sqrt(2.0 / 3.0) * focal_px / np.where(ok, z, 1.0), MAX_GATE_PX)
        # ... and a share of the distance to the nearest other marker's image in that frame
        # (of any colour: a neighbour's blob of another class can still sit over this one's)
        others, oz = _image(everywhere[f_r, i_r], v, normals, ds)
        seen = np.all(np.isfinite(others), axis=1) & (oz > 0)
        other_tree = cKDTree(_tree_points(others[seen], f_r[seen], result.colour[i_r[seen]] * 0, focal_px))
        d_other, j_other = other_tree.query(_tree_points(pred, f_c, colour * 0, focal_px), k=2)
        own = (f_r[seen][j_other[:, 0]] == f_c) & (i_r[seen][j_other[:, 0]] == i_c)
        nearest_other = np.where(own, d_other[:, 1], d_other[:, 0])
        gate = np.minimum(gate, SPACING_SHARE * nearest_other)
        free = ~_claimed(result, det, cands, v)
        if not free.any():
            continue
        idx = np.flatnonzero(free)
        tree = cKDTree(_tree_points(det.norm[v][idx], det.frame[v][idx], det.colour[v][idx], focal_px))
        q = _tree_points(np.where(ok[:, None], pred, 0.0), f_c, colour, focal_px)
        d, j = tree.query(q, k=1, distance_upper_bound=MAX_GATE_PX)
        hit = ok & (d <= gate)
        # the blob must be clearly this marker's: much nearer its image than any other marker's
        b = idx[np.minimum(j, idx.size - 1)]
        blob_xy = _tree_points(det.norm[v][b], det.frame[v][b], np.zeros(b.size), focal_px)
        d_b, j_b = other_tree.query(blob_xy, k=2)
        own_b = (f_r[seen][j_b[:, 0]] == f_c) & (i_r[seen][j_b[:, 0]] == i_c)
        hit &= np.where(own_b, d_b[:, 1], d_b[:, 0]) >= AMBIGUITY_RATIO * d
        # ... and a dot that lasts: a stray blob (a glint, a tooth) seldom sits where the marker is two frames running
        rows = np.flatnonzero(hit)
        hit[rows] = _lasts(det, v, b[rows], pred[rows], f_c[rows], i_c[rows], colour[rows], result, conjecture,
                           normals, ds, focal_px)
        blob[:, v] = np.where(hit, b, -1)
    # a blob two cells would take goes to neither
    for v in range(K + 1):
        taken = blob[:, v] >= 0
        _, inverse, n = np.unique(blob[taken, v], return_inverse=True, return_counts=True)
        clash = np.zeros(f_c.size, bool)
        clash[np.flatnonzero(taken)] = n[inverse] > 1
        blob[clash, v] = -1

    rays = np.full((f_c.size, K + 1, 3), np.nan)   # each view's camera ray (a mirror's: to the virtual point)
    for v in range(K + 1):
        has = blob[:, v] >= 0
        rays[has, v] = _ray(det.norm[v][blob[has, v]])
    direct = blob[:, 0] >= 0
    mirror = np.argmax(blob[:, 1:] >= 0, axis=1) + 1 if K else np.zeros(f_c.size, int)
    has_mirror = (blob[:, 1:] >= 0).any(axis=1) if K else np.zeros(f_c.size, bool)
    new = np.full((f_c.size, 3), np.nan)
    mask = np.zeros(f_c.size, int)
    two_view = np.zeros(f_c.size, bool)
    # two views: the direct ray and the mirror's, the point nearest both (least squares on the depths)
    two = direct & has_mirror
    if two.any():
        k = mirror[two] - 1
        pt, gap_px = _two_rays(rays[two, 0], rays[two][np.arange(two.sum()), mirror[two]], normals[k], ds[k],
                               focal_px)
        # the two rays must meet as closely as the take's own measured pairs do (a merged or partly
        # hidden blob still falls in the epipolar band, off the dot's centre) ...
        limit = min(band_px, _meeting_limit(result, det, cands, normals, ds, focal_px))
        # ... at a point within the conjecture's expected error
        near = (gap_px <= limit) & (np.linalg.norm(pt - p_conj[two], axis=1) <= TWO_VIEW_SIGMAS * sd[two] + 0.5)
        # both views found a blob and they do not meet: one of them is not this marker's dot
        blob[np.flatnonzero(two)[~near]] = -1
        rows = np.flatnonzero(two)[near]
        new[rows] = pt[near]
        mask[rows] = 1 | (1 << mirror[rows])
        two_view[rows] = True
        counts["two_views"] = np.bincount(f_c[rows], minlength=F)
    # one view: the point on its ray nearest the conjecture (its depth from the conjecture)
    direct = blob[:, 0] >= 0
    has_mirror = (blob[:, 1:] >= 0).any(axis=1)
    one = np.isnan(new[:, 0]) & (direct | has_mirror) & reported_before
    view = np.where(direct, 0, mirror)
    for v in range(K + 1):
        rows = np.flatnonzero(one & (view == v))
        if rows.size == 0:
            continue
        r = rays[rows, v]
        if v == 0:
            new[rows] = _on_ray(p_conj[rows], r)
        else:   # in the mirror's virtual space, then reflected back (eq. 3.12)
            virtual = _on_ray(reflect_points(p_conj[rows], normals[v - 1], ds[v - 1]), r)
            new[rows] = reflect_points(virtual, normals[v - 1], ds[v - 1])
        counts["one_view"] += np.bincount(f_c[rows], minlength=F)
    done = np.isfinite(new[:, 0])
    f, i = f_c[done], i_c[done]
    result.points[f, i] = new[done]
    result.head_frame[f, i] = np.einsum("mji,mj->mi", R[f], new[done] - result.head_pose[f, 3:])
    # two views measure the marker; one view only refines its conjecture (the depth is still the neighbours')
    both = two_view[done]
    result.conjectured[f, i] = ~both
    result.camera_mask[f, i] = np.where(both, mask[done], 0)
    result.assigned_blob[f[both], i[both]] = blob[done][both, 0] - det.start[0][f[both]]
    return counts
