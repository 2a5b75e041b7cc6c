"""Markers the tracker conjectured, measured where their dot is seen after all.

The passes of :mod:`.tracker` measure a marker from a 3D candidate: a direct blob paired with
a mirror blob in the mirrored epipolar band (eq. 5.2-5.3). Where a marker's dot is detected
in one view only -- its mirror image hidden by the cheek, merged with a neighbour's, or too
small to detect -- or where the pass lost a pair it did not trust (fast motion outruns the
gate), the take holds a conjecture from the neighbours (eq. 5.8, learned relations;
``gapfill.fill_gaps``), or a gap where that conjecture was expected too far off. Once the
whole take is known, the conjecture predicts where the dot must appear in each view; an
unclaimed blob of the marker's colour there, unambiguously nearer this marker than any
other and not a mirror blob of two dots' images (``capture.views.MERGED_SHARE``), measures it:

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
from ..geometry.mirror import points_from_planes, reflect_points
from ..geometry.rigid import rotation_zyx, to_head_frame
from .candidates import spans
from .splits import measured_together, merge_labels
from .result import COLOUR_SPACING_MM, TrackResult, TrackSettings

MAX_GATE_PX = 2.5        # the largest distance (pixels) from the predicted image to the blob taken
DETECTION_PX = 0.75      # the detections' own noise, added to the projected conjecture error (pixels)
SPACING_SHARE = 0.4      # the gate is at most this share of the distance to another marker's image
AMBIGUITY_RATIO = 2.0    # the blob must be this much nearer this marker's image than any other's
TWO_VIEW_SIGMAS = 3.0    # a two-view point must lie within this many expected errors of the conjecture (+ 0.5 mm)
CONTINUITY_PX = 1.0      # the dot in the frame before or after lies this near where it should (pixels)
MEETING_PERCENTILE = 90  # two rays must meet as closely as this share of the take's measured pairs do
MEETING_SAMPLE = 20000   # measured pairs that set that limit, at most
SETTLED_FACTOR = 3       # a marker takes part once measured in this many times TrackSettings.min_measured_frames
# following a dot (follow_dots_through_gaps):
LINK_PX = 10.0           # the next frame's blob within this of where its velocity puts it (pixels) and within
# SPACING_SHARE of the view's typical dot spacing,
LINK_RATIO = 2.0         # the next nearest blob this much further off,
RIVAL_MM = 1.0           # any other 3D candidate on the direct ray LINK_RATIO times further from the prediction + this,
DEPTH_RATIO = 2.0        # the step's surprise along each view's ray at most this times the one across it
DEPTH_SLACK_MM = 0.5     # plus this;
FOLLOW_ROUNDS = 2        # rounds of following: a second starts where the first stopped, after merges
MAX_COAST = 3            # a chain that finds no dot coasts on its velocity this many frames at most


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


def _mirror_norm(det: ClipDetections, mirror, blob) -> np.ndarray:
    """Normalised image points ``(n, 2)`` of ``blob`` (global indices) in each row's ``mirror``
    view (1..K), gathered view by view."""
    out = np.full((len(blob), 2), np.nan)
    for v in np.unique(mirror):
        rows = mirror == v
        out[rows] = det.norm[v][blob[rows]]
    return out


def _two_rays(direct, mirror_pts, mirror, normals, ds, focal_px: float):
    """Each row's point from its direct image ``direct (n, 2)`` and its image ``mirror_pts (n, 2)``
    in mirror ``mirror (n,)`` (0..K-1), normalised coordinates, by eq. 3.10-3.12
    (:func:`..geometry.mirror.points_from_planes`): the direct estimate and the reflected-back one
    are where the direct ray and the mirror's ray pass closest. Returns their average ``(n, 3)``
    and how far apart they are, in pixels at that depth ``(n,)``."""
    point = np.full((len(direct), 3), np.nan)
    gap_px = np.full(len(direct), np.nan)
    for k in np.unique(mirror):
        rows = mirror == k
        fused, on_direct, on_mirror = points_from_planes(direct[rows], mirror_pts[rows][None], normals[k][None],
                                                         ds[k:k + 1], return_views=True)
        point[rows] = fused
        gap_px[rows] = np.linalg.norm(on_direct - on_mirror[0], axis=1) * focal_px / np.abs(fused[:, 2])
    return point, gap_px


def meeting_limit(result: TrackResult, det: ClipDetections, cands, normals, ds, focal_px: float,
                  band_px: float) -> float:
    """How closely two rays must meet (pixels) for the steps here to take them as one dot: as
    closely as the direct and mirror rays of the passes' measured markers do -- the
    :data:`MEETING_PERCENTILE` th percentile over up to :data:`MEETING_SAMPLE` of them, the clip's
    own detection noise -- and within the tracker's band ``band_px``. Computed once after the
    passes (the cells these steps measure carry no clip candidate, so it does not change)."""
    c = result.candidate[result.candidate >= 0]
    if c.size == 0:
        return band_px
    c = c[:: max(1, c.size // MEETING_SAMPLE)]
    direct = cands.direct[c]
    k = np.argmax(cands.mirror_blob[c] >= 0, axis=1)
    mb = cands.mirror_blob[c, k]
    ok = (mb >= 0) & (direct >= 0)
    if not ok.any():
        return band_px
    _, gap = _two_rays(det.norm[0][direct[ok]], _mirror_norm(det, k[ok] + 1, mb[ok]), k[ok], normals, ds, focal_px)
    return min(band_px, float(np.nanpercentile(gap, MEETING_PERCENTILE)))


def _blob_tree(det: ClipDetections, view: int, focal_px: float) -> cKDTree:
    """The KD-tree of every blob of ``view`` (:func:`_tree_points`), built once per clip and view
    (kept with the clip's detections, which do not change once ingested)."""
    cache = det.__dict__.setdefault("_singleview_trees", {})
    key = (view, float(focal_px))
    if key not in cache:
        cache[key] = cKDTree(_tree_points(det.norm[view], det.frame[view], det.colour[view], focal_px))
    return cache[key]


def _lasts(det: ClipDetections, view: int, blob, pred, frame, marker, colour, result: TrackResult, conjecture,
           normals, ds, focal_px: float) -> np.ndarray:
    """Whether each blob taken for a cell is a lasting dot: in the frame before or after, a blob of
    the same colour in the same view lies within :data:`CONTINUITY_PX` of where the marker is
    then (its reported point, else its conjecture) plus the same offset from its prediction."""
    F = det.n_frames
    all_blobs = _blob_tree(det, view, focal_px)
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


def _alone_on_its_ray(cands, direct_blob, point, predicted) -> np.ndarray:
    """Whether each ``point`` (made from the direct blob ``direct_blob``, global index, and a mirror
    blob) is the only 3D candidate of that direct blob near the marker's ``predicted`` position:
    every other candidate on the direct ray (another mirror blob in its epipolar band, at another
    depth, :func:`.candidates.clip_candidates`) must be :data:`LINK_RATIO` times further from the
    prediction, plus :data:`RIVAL_MM`. On a dense face a mirror's epipolar band holds several
    markers' images, and the wrong one puts the right direct dot at the wrong depth."""
    lo = np.searchsorted(cands.direct, direct_blob, "left")
    hi = np.searchsorted(cands.direct, direct_blob, "right")
    n = hi - lo
    row = np.repeat(np.arange(direct_blob.size), n)
    idx = spans(lo, n)
    other = cands.points[idx]
    own = np.linalg.norm(point - predicted, axis=1)
    elsewhere = np.linalg.norm(other - point[row], axis=1) > RIVAL_MM
    rival = elsewhere & (np.linalg.norm(other - predicted[row], axis=1) < LINK_RATIO * own[row] + RIVAL_MM)
    return np.bincount(row[rival], minlength=direct_blob.size) == 0


def _surprise_matches(surprise, ray) -> np.ndarray:
    """Whether a chain's step is as surprising along ``ray`` (unit, ``(n, 3)``) as across it: the
    component of ``surprise`` (the point less its prediction, mm) along the ray is at most
    :data:`DEPTH_RATIO` times the component across it plus :data:`DEPTH_SLACK_MM`. Along a view's
    ray only the other view's blob moves the point; a blob there that is not the dot moves it in
    that direction alone, while a real change of motion shows across the ray too."""
    along = np.sum(surprise * ray, axis=1)
    across = np.linalg.norm(surprise - along[:, None] * ray, axis=1)
    return np.abs(along) <= DEPTH_RATIO * across + DEPTH_SLACK_MM


def measured_blobs(result: TrackResult, det: ClipDetections, cands) -> np.ndarray:
    """Each measured cell's blob per view ``(F, N, K + 1)``, global indices (-1: none): the direct
    blob from ``assigned_blob`` (which counts within each frame), the mirror blobs from the clip
    candidate the cell took."""
    F, N = result.assigned_blob.shape
    blobs = np.full((F, N, cands.mirror_blob.shape[1] + 1), -1)
    f, i = np.nonzero(result.assigned_blob >= 0)
    blobs[f, i, 0] = result.assigned_blob[f, i] + det.start[0][f]
    c = result.candidate[f, i]
    blobs[f[c >= 0], i[c >= 0], 1:] = cands.mirror_blob[c[c >= 0]]
    return blobs


def claimed_blobs(det: ClipDetections, blobs) -> list:
    """Per view, the blobs (global indices) a measured marker holds, as boolean masks, from
    :func:`measured_blobs`."""
    taken = []
    for v in range(blobs.shape[2]):
        mask = np.zeros(len(det.frame[v]), bool)
        b = blobs[..., v]
        mask[b[b >= 0]] = True
        taken.append(mask)
    return taken


def _tree_points(xy, frame, colour, focal_px: float) -> np.ndarray:
    """Pixel-scaled image points with the frame and colour class as far-apart extra
    coordinates: one KD-tree then serves every frame and class. (The idea of
    ``capture.views.frame_spaced``, with a fixed spacing: the trees here are cached and queried by many
    point sets, so the spacing cannot depend on the points of one query.)"""
    return np.column_stack([np.asarray(xy, float) * focal_px, np.asarray(frame, float) * COLOUR_SPACING_MM,
                            np.asarray(colour, float) * COLOUR_SPACING_MM])


def measure_in_single_views(result: TrackResult, det: ClipDetections, cands, normals, ds, focal_px: float,
                            conjecture, expected_sd, settings: TrackSettings, limit: float) -> dict:
    """Measure the gap cells of ``result`` from unclaimed blobs (module text).
    ``conjecture (F, N, 3)``: every gap cell's conjectured camera-frame point, withheld or not
    (NaN elsewhere); ``expected_sd (F, N)``: its expected 3D error (mm); ``limit``: how closely
    the rays of a two-view cell must meet (:func:`meeting_limit`). From ``settings``:
    ``min_measured_frames`` (markers measured in fewer than :data:`SETTLED_FACTOR` times as many
    frames are left alone). Updates ``points``,
    ``head_frame``, ``conjectured``, ``camera_mask`` and ``assigned_blob`` in place; returns the
    cells measured per frame, ``{"two_views": (F,), "one_view": (F,)}``."""
    min_frames = SETTLED_FACTOR * settings.min_measured_frames
    normals = np.asarray(normals, float)
    ds = np.asarray(ds, float)
    K = len(normals)
    measured = result.assigned_blob >= 0
    # a marker measured in few frames may be a chain of chance pairings, its conjecture built on them
    settled = measured.sum(axis=0) >= min_frames
    f_c, i_c = np.nonzero(~measured & settled[None] & np.all(np.isfinite(conjecture), axis=2)
                          & np.isfinite(expected_sd) & (K > 0))
    F = measured.shape[0]
    counts = {"two_views": np.zeros(F, int), "one_view": np.zeros(F, int)}
    claimed = claimed_blobs(det, measured_blobs(result, det, cands))
    if f_c.size == 0:
        result.stats["measured_in_one_view"] = counts["one_view"]
        result.stats["measured_in_two_views_after_gap_fill"] = counts["two_views"]
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
        d_other, j_other = other_tree.query(_tree_points(np.where(ok[:, None], pred, 0.0), f_c, colour * 0, focal_px),
                                            k=2, distance_upper_bound=MAX_GATE_PX / SPACING_SHARE + 1.0)
        j_other = np.minimum(j_other, max(int(seen.sum()) - 1, 0))
        own = (f_r[seen][j_other[:, 0]] == f_c) & (i_r[seen][j_other[:, 0]] == i_c)
        nearest_other = np.where(own, d_other[:, 1], d_other[:, 0])
        gate = np.minimum(gate, SPACING_SHARE * nearest_other)
        free = ~claimed[v]
        if not free.any():
            continue
        idx = np.flatnonzero(free)
        tree = cKDTree(_tree_points(det.norm[v][idx], det.frame[v][idx], det.colour[v][idx], focal_px))
        q = _tree_points(np.where(ok[:, None], pred, 0.0), f_c, colour, focal_px)
        d, j = tree.query(q, k=1, distance_upper_bound=MAX_GATE_PX)
        hit = ok & (d <= gate)
        # the blob must be clearly this marker's: much nearer its image than any other marker's
        b = idx[np.minimum(j, idx.size - 1)]
        if v > 0:    # a mirror blob of two dots' images measures neither (its centre lies between them)
            rows = np.flatnonzero(hit)
            hit[rows] = ~det.merged(v, b[rows])
        blob_xy = _tree_points(det.norm[v][b], det.frame[v][b], np.zeros(b.size), focal_px)
        d_b, j_b = other_tree.query(blob_xy, k=2, distance_upper_bound=AMBIGUITY_RATIO * MAX_GATE_PX + 1.0)
        j_b = np.minimum(j_b, max(int(seen.sum()) - 1, 0))
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

    direct = blob[:, 0] >= 0
    mirror = np.argmax(blob[:, 1:] >= 0, axis=1) + 1
    has_mirror = (blob[:, 1:] >= 0).any(axis=1)
    new = np.full((f_c.size, 3), np.nan)
    mask = np.zeros(f_c.size, int)
    two_view = np.zeros(f_c.size, bool)
    # two views: the direct ray and the mirror's, the point nearest both (least squares on the depths)
    two = direct & has_mirror
    if two.any():
        rows = np.flatnonzero(two)
        pt, gap_px = _two_rays(det.norm[0][blob[rows, 0]], _mirror_norm(det, mirror[rows], blob[rows, mirror[rows]]),
                               mirror[rows] - 1, normals, ds, focal_px)
        # the two rays must meet as closely as the take's own measured pairs do (a merged or partly
        # hidden blob still falls in the epipolar band, off the dot's centre) ...
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
        r = _ray(det.norm[v][blob[rows, v]])       # the view's camera ray (a mirror's: to the virtual point)
        if v == 0:
            new[rows] = _on_ray(p_conj[rows], r)
        else:   # in the mirror's virtual space, then reflected back (eq. 3.12)
            virtual = _on_ray(reflect_points(p_conj[rows], normals[v - 1], ds[v - 1]), r)
            new[rows] = reflect_points(virtual, normals[v - 1], ds[v - 1])
        counts["one_view"] += np.bincount(f_c[rows], minlength=F)
    done = np.isfinite(new[:, 0])
    f, i = f_c[done], i_c[done]
    result.points[f, i] = new[done]
    result.head_frame[f, i] = to_head_frame(R[f], result.head_pose[f, 3:], new[done])
    # two views measure the marker; one view only refines its conjecture (the depth is still the neighbours')
    both = two_view[done]
    result.conjectured[f, i] = ~both
    result.camera_mask[f, i] = np.where(both, mask[done], 0)
    result.assigned_blob[f[both], i[both]] = blob[done][both, 0] - det.start[0][f[both]]
    result.stats["measured_in_one_view"] = counts["one_view"]
    result.stats["measured_in_two_views_after_gap_fill"] = counts["two_views"]
    result.stats["conjectured"] = result.conjectured.sum(axis=1)
    result.stats["measured"] = (result.assigned_blob >= 0).sum(axis=1)   # the take's, these steps' included
    return counts


def _follow_once(result: TrackResult, det: ClipDetections, cands, normals, ds, focal_px: float,
                 settings: TrackSettings, limit: float, per_frame, tried=None, passive=(),
                 lost_initial=()) -> list:
    """Before the gaps are conjectured: follow each marker's dots in 2D into its gaps, from both
    ends. From the last frame a marker was measured in (and backwards from the next), its direct
    blob and mirror blob(s) are carried frame by frame at their image velocity (a mirror it has no
    dot in starts from the image of its 3D point moved by its 3D velocity). The marker is measured
    in the next frame where, in the direct view and a mirror,

    * an unclaimed blob of its colour lies within :data:`LINK_PX` of the predicted image, and
      within :data:`SPACING_SHARE` of the view's typical dot spacing, the next blob at least
      :data:`LINK_RATIO` times further;
    * the two rays meet within ``limit`` (:func:`meeting_limit`), within the tracker's
      gate (``gate_mm``) of the marker's last point;
    * no other 3D candidate of the direct blob (another mirror image in its epipolar band) lies
      about as near the predicted point (:func:`_alone_on_its_ray`);
    * the step is as surprising along each view's ray as across it (:func:`_surprise_matches`):
      a wrong blob in one view moves the point along the other view's ray only.

    A chain that finds nothing coasts on its velocity for up to :data:`MAX_COAST` frames; a blob
    two chains reach in one frame stops both. Identity comes from the dots' continuity, not from
    the neighbours: this reaches markers whose expression outran the passes' gate and the
    conjecture (fast lips).

    A chain whose next dot is another label's measurement there -- a label never measured in
    the same frame as this one, its point within the gate of this one's prediction -- has found the
    same dot under a second label (a split): it votes ``(this, other)``. Updates ``result`` in
    place, adds the cells measured to ``per_frame``; returns the votes. ``tried``: a set of the
    chain starts tried before (frame, marker, direction), skipped and added to. ``passive``: labels
    whose gaps are not followed (a chain of another label may still reach them and vote);
    ``lost_initial``: labels followed once measured in ``min_measured_frames`` (not
    :data:`SETTLED_FACTOR` times that), their chains never coasting (markers paired in the first
    frames and lost for good, :func:`.late.lost_markers`)."""
    normals = np.asarray(normals, float)
    ds = np.asarray(ds, float)
    K = len(normals)
    F, N = result.assigned_blob.shape
    measured = result.assigned_blob >= 0
    count, labels = measured.sum(axis=0), np.asarray(result.labels, dtype=object)
    settled = count >= SETTLED_FACTOR * settings.min_measured_frames
    may_coast = settled.copy()  # a lost marker's chain takes only unbroken dots
    settled |= np.isin(labels, list(lost_initial)) & (count >= settings.min_measured_frames)
    settled &= ~np.isin(labels, list(passive))
    votes = []
    if K == 0 or not settled.any():
        return votes
    trees = [_blob_tree(det, v, focal_px) for v in range(K + 1)]
    # the search radius in each view: at most SPACING_SHARE of the dots' typical spacing there
    radius = np.array([min(LINK_PX, SPACING_SHARE * det.typical_spacing(v, focal_px)) for v in range(K + 1)])
    blobs = measured_blobs(result, det, cands)
    claimed = claimed_blobs(det, blobs)
    owner = np.full(len(det.frame[0]), -1)             # the label measured from each direct blob
    f, i = np.nonzero(measured)
    owner[blobs[f, i, 0]] = i
    together = measured_together(measured)
    R = rotation_zyx(result.head_pose[:, :3])

    def pixels(v, b):
        return np.where((b >= 0)[:, None], det.norm[v][np.maximum(b, 0)] * focal_px, np.nan)

    for step in (1, -1):
        # the chains start where a measured frame of a settled marker borders an unmeasured one
        nxt = np.roll(measured, -step, axis=0)
        edge = np.zeros(F, bool)
        edge[-1 if step == 1 else 0] = True
        frame, marker = np.nonzero(measured & ~nxt & ~edge[:, None] & settled[None])
        if tried is not None:   # a start tried in an earlier round, whose gap nothing changed, fails again
            key = (frame * N + marker) * 2 + (step > 0)
            fresh = ~np.isin(key, tried)
            tried.update(key.tolist())
            frame, marker = frame[fresh], marker[fresh]
        before = frame - step
        prev_ok = (before >= 0) & (before < F)
        before = np.clip(before, 0, F - 1)
        pos = np.stack([pixels(v, blobs[frame, marker, v]) for v in range(K + 1)], axis=1)        # (n, K+1, 2)
        prev = np.stack([pixels(v, np.where(prev_ok, blobs[before, marker, v], -1)) for v in range(K + 1)], axis=1)
        vel = np.where(np.isfinite(prev), pos - prev, 0.0)
        alive = np.isfinite(pos[..., 0])
        last_point = result.points[frame, marker]
        before_point = result.points[before, marker]
        vel3 = np.where((prev_ok & measured[before, marker])[:, None], last_point - before_point, 0.0)
        colour = result.colour[marker]
        coast = np.zeros(frame.size, int)
        while frame.size:
            g = frame + step
            go = (g >= 0) & (g < F) & alive[:, 0]
            g = np.clip(g, 0, F - 1)
            go &= ~measured[g, marker]
            new_blob = np.full((frame.size, K + 1), -1)
            for v in range(K + 1):
                # a mirror the chain has no dot in yet: its image of the marker's last point
                if v > 0:
                    img, z = _image(last_point + vel3 * (1 + coast[:, None]), v, normals, ds)
                    fresh = ~alive[:, v] & np.all(np.isfinite(img), axis=1) & (z > 0)
                    pos[fresh, v], vel[fresh, v] = img[fresh] * focal_px, 0.0
                    alive[:, v] |= fresh
                want = go & alive[:, v]
                if not want.any():
                    continue
                pred = (pos[want, v] + vel[want, v]) / focal_px
                d, j = trees[v].query(_tree_points(pred, g[want], colour[want], focal_px), k=2,
                                      distance_upper_bound=LINK_RATIO * radius[v] + 1.0)
                j0 = np.minimum(j[:, 0], len(det.frame[v]) - 1)
                linked = (d[:, 0] <= radius[v]) & (d[:, 1] >= LINK_RATIO * d[:, 0])
                ok = linked & ~claimed[v][j0]
                if v > 0:    # a mirror blob of two dots' images measures neither
                    ok[ok] = ~det.merged(v, j0[ok])
                new_blob[np.flatnonzero(want)[ok], v] = j0[ok]
                if v == 0:   # the dot is another label's measurement: a split, if they never meet
                    a, b = marker[want], owner[j0]
                    split = linked & (b >= 0) & (b != a) & ~together[a, np.maximum(b, 0)]
                    ahead = last_point[want] + vel3[want] * (1 + coast[want, None])
                    split &= (np.linalg.norm(result.points[g[want], np.maximum(b, 0)] - ahead, axis=1)
                              <= settings.gate_mm * (1 + coast[want]))
                    votes.extend(zip(a[split].tolist(), b[split].tolist()))
            for v in range(K + 1):                    # a blob two chains reach goes to neither
                taken = new_blob[:, v] >= 0
                _, inverse, n = np.unique(new_blob[taken, v], return_inverse=True, return_counts=True)
                new_blob[np.flatnonzero(taken)[n[inverse] > 1], v] = -1
            mirror = np.argmax(new_blob[:, 1:] >= 0, axis=1) + 1
            ok = go & (new_blob[:, 0] >= 0) & (new_blob[:, 1:] >= 0).any(axis=1)
            rows = np.flatnonzero(ok)
            point = np.full((frame.size, 3), np.nan)
            if rows.size:
                m = mirror[rows]
                direct_pts, mirror_pts = det.norm[0][new_blob[rows, 0]], _mirror_norm(det, m, new_blob[rows, m])
                pt, gap_px = _two_rays(direct_pts, mirror_pts, m - 1, normals, ds, focal_px)
                # within the tracker's gate of where the marker's 3D velocity puts it
                predicted = last_point[rows] + vel3[rows] * (1 + coast[rows, None])
                meets = (gap_px <= limit) & (np.linalg.norm(pt - predicted, axis=1) <= settings.gate_mm * (1 + coast[rows]))
                meets &= _alone_on_its_ray(cands, new_blob[rows, 0], pt, predicted)
                # as surprising along each view's ray as across it (the mirror's ray in real space, eq. 3.9)
                n_m, mirror_ray = normals[m - 1], _ray(mirror_pts)
                mirror_ray = mirror_ray - 2.0 * np.sum(mirror_ray * n_m, axis=1, keepdims=True) * n_m
                for ray in (_ray(direct_pts), mirror_ray):
                    meets &= _surprise_matches(pt - predicted, ray)
                point[rows[meets]] = pt[meets]
                ok[rows[~meets]] = False
            rows = np.flatnonzero(ok)
            gf, mk = g[rows], marker[rows]
            result.points[gf, mk] = point[rows]
            result.head_frame[gf, mk] = to_head_frame(R[gf], result.head_pose[gf, 3:], point[rows])
            result.conjectured[gf, mk] = False
            result.camera_mask[gf, mk] = 1 | (1 << mirror[rows])
            result.assigned_blob[gf, mk] = new_blob[rows, 0] - det.start[0][gf]
            measured[gf, mk] = True
            owner[new_blob[rows, 0]] = mk
            np.add.at(per_frame, gf, 1)
            for v in range(K + 1):
                b = new_blob[rows, v]
                claimed[v][b[b >= 0]] = True
            # carry on: a chain measured here from the blobs found (views not found are dropped), one
            # that found nothing coasts on its velocity for up to MAX_COAST frames (a dot merged with a
            # neighbour's or missed for a frame or two), its gate growing with the frames coasted
            coasting = go & ~ok & (coast < MAX_COAST) & may_coast[marker]
            keep = ok | coasting
            if not keep.any():
                break
            found = np.stack([pixels(v, new_blob[:, v]) for v in range(K + 1)], axis=1)
            vel = np.where(ok[:, None, None], np.where(np.isfinite(found), found - pos, 0.0), vel)
            pos = np.where(ok[:, None, None], found, pos + vel)
            alive = np.where(ok[:, None], np.isfinite(found[..., 0]), alive)
            vel3 = np.where(ok[:, None], (point - last_point) / (1 + coast[:, None]), vel3)
            coast = np.where(ok, 0, coast + 1)
            last_point = np.where(ok[:, None], point, last_point)
            frame, marker, colour = g[keep], marker[keep], colour[keep]
            pos, vel, alive, coast, last_point = pos[keep], vel[keep], alive[keep], coast[keep], last_point[keep]
            vel3 = vel3[keep]
    return votes


def follow_dots_through_gaps(result: TrackResult, det: ClipDetections, cands, normals, ds, focal_px: float,
                             settings: TrackSettings, limit: float, passive=(), lost_initial=()) -> TrackResult:
    """Each marker's dots followed into its gaps (:func:`_follow_once`), in :data:`FOLLOW_ROUNDS`
    rounds (a second starts again where a chain stopped -- two chains that reached one blob, a
    chain that coasted out -- and follows the merged markers' new gaps); after each, labels found
    to be one dot (a chain that reaches the other's measurement, the two never measured in the
    same frame) are merged, the earlier-seen label keeping the other's measurements
    (:func:`.splits.merge_labels`). ``limit``: :func:`meeting_limit`. Returns the result (a new one when labels merged);
    ``stats["followed_through_gaps"]`` counts the cells measured per frame."""
    per_frame = np.zeros(result.assigned_blob.shape[0], int)
    result.stats["followed_through_gaps"] = per_frame
    tried = set()
    for _ in range(FOLLOW_ROUNDS):
        votes = _follow_once(result, det, cands, normals, ds, focal_px, settings, limit, per_frame, tried=tried,
                             passive=passive, lost_initial=lost_initial)
        measured = result.assigned_blob >= 0
        first = np.argmax(measured, axis=0)
        together = measured_together(measured)
        pairs = [(a, b) if first[a] <= first[b] else (b, a) for a, b in sorted(set(votes)) if not together[a, b]]
        if pairs:   # labels renumbered: every start is new again
            result = merge_labels(result, list(dict.fromkeys(pairs)))
            tried = set()
    return result
