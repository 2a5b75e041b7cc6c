"""Pairing direct and mirrored markers through 2D tracks (issue 4, step 3).

Single-frame pairing inside the mirrored epipolar band (eq. 5.1-5.3) is only
75-94 % correct on dense layouts: a marker seen only directly and a different
marker seen only in the mirror can sit on each other's band with the same colour
(``shared/notes/mirror-self-calibration.md``). Over several frames such chance
alignments do not persist, so pairs are decided between *tracks*:

1. :func:`track_2d` links each view's detections frame to frame (constant-velocity
   prediction, same colour, a gate in pixels, one-to-one by
   ``linear_sum_assignment``), tolerating short gaps;
2. :func:`pair_tracks` scores every same-colour (direct track, mirror track) pair by
   how often and how closely it sits in the band over the frames both tracks
   exist, and assigns pairs one-to-one; what cannot be decided is reported with
   its ambiguity rather than forced, and a mirror image that two dots contest is reported
   for the tracker to settle through the other mirror, or over the whole clip
   (:func:`clip_band_support`; ``core.track.initial``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.camera import Camera
from ..capture.views import ClipDetections, frame_spaced
from ..geometry.epipolar import line_distance, lines_of_normalised
from ..geometry.mirror import MirrorPlane
from .candidates import spans

#: a mirror track that is the only partner of two direct tracks of comparable support is contested (TrackPairs)
#: when they sit in its band within this ratio of each other's RMS residual: blur540n's nose-tip dot and the like
#: dot beside it at one height, 0.25 and 0.32 px (the wrong one nearer); where the nearer is right, 1.5-5x apart
CONTEST_RMS_RATIO = 1.3


def track_2d(positions, colors, gate_px: float = 8.0, max_gap: int = 2):
    """Link detections of one view over frames.

    ``positions``: list over frames of ``(n_f, 2)`` pixel arrays; ``colors``: list of
    ``(n_f,)`` class indices. Returns a list of ``(n_f,)`` track ids (``-1`` never
    happens: every detection starts or continues a track) and the number of tracks."""
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    last = np.zeros((0, 2))
    vel = np.zeros((0, 2))
    col = np.zeros(0, int)
    seen = np.zeros(0, int)  # frame a track was last matched
    ids_per_frame = []
    for f, (xy, c) in enumerate(zip(positions, colors)):
        xy = np.asarray(xy, float).reshape(-1, 2)
        c = np.asarray(c, int)
        ids = np.full(len(xy), -1)
        active = np.flatnonzero(f - seen <= max_gap + 1) if len(seen) else np.zeros(0, int)
        if active.size and len(xy):
            pred = last[active] + vel[active] * (f - seen[active])[:, None]
            near = cKDTree(pred).sparse_distance_matrix(cKDTree(xy), gate_px, output_type="ndarray")
            rows, cols, dist = near["i"].astype(int), near["j"].astype(int), near["v"]
            same = col[active[rows]] == c[cols]
            rows, cols, dist = rows[same], cols[same], dist[same]
            if rows.size:
                # a prediction with one detection in its gate that no other prediction reaches takes
                # it (the assignment would); the rest are assigned one-to-one by distance
                alone = (np.bincount(rows)[rows] == 1) & (np.bincount(cols)[cols] == 1)
                r_pick, d_pick = rows[alone], cols[alone]
                rows, cols, dist = rows[~alone], cols[~alone], dist[~alone]
                if rows.size:
                    ur, rinv = np.unique(rows, return_inverse=True)
                    uc, cinv = np.unique(cols, return_inverse=True)
                    cost = np.full((ur.size, uc.size), 1e9)
                    cost[rinv, cinv] = dist
                    r, k = linear_sum_assignment(cost)
                    ok = cost[r, k] < 1e9
                    r_pick, d_pick = np.r_[r_pick, ur[r[ok]]], np.r_[d_pick, uc[k[ok]]]
                t = active[r_pick]
                d = d_pick
                dt = (f - seen[t])[:, None]
                vel[t] = (xy[d] - last[t]) / dt
                last[t] = xy[d]
                seen[t] = f
                ids[d] = t
        new = np.flatnonzero(ids < 0)
        if new.size:
            start = len(last)
            last = np.vstack([last, xy[new]])
            vel = np.vstack([vel, np.zeros((new.size, 2))])
            col = np.concatenate([col, c[new]])
            seen = np.concatenate([seen, np.full(new.size, f)])
            ids[new] = start + np.arange(new.size)
        ids_per_frame.append(ids)
    return ids_per_frame, len(last)


@dataclass
class TrackPairs:
    direct_track: np.ndarray  # (P,) paired direct-view track ids
    mirror_track: np.ndarray  # (P,) their mirror track ids
    rms_px: np.ndarray  # (P,) band residual over the frames they were paired
    support: np.ndarray  # (P,) frames in which the pair sat in the band
    ambiguous: np.ndarray  # direct tracks with more than one plausible partner, left unpaired
    qualifying: np.ndarray  # (Q, 2) every (direct track, mirror track) pair that qualified (before the
    # ambiguity test and the assignment)
    contested: np.ndarray  # (R, 2) the qualifying pairs of mirror tracks that are the only partner of two
    # direct tracks or more, of comparable support and residual (CONTEST_RMS_RATIO): which dot the image shows, the
    # band cannot tell (the assignment gives it to the one a shade nearer its line)


def pair_tracks(det: ClipDetections, direct_ids, mirror: int, mirror_ids, camera: Camera, plane: MirrorPlane,
                band_px: float = 1.0, min_frames: int = 5, min_agreement: float = 0.8,
                ambiguity_ratio: float = 0.5, max_rms_factor: float = 2.0) -> TrackPairs:
    """Pair direct-view tracks with tracks of mirror ``mirror`` (module docstring):
    ``det`` holds the detections (:class:`..capture.views.ClipDetections`, read in
    normalised coordinates), ``direct_ids`` and ``mirror_ids`` the 2D track of each
    detection per frame (:func:`track_2d`).

    Per frame, same-colour detections within ``band_px`` of each other's mirrored
    epipolar line vote for their tracks' pair (perpendicular distance, eq. 5.2). A
    track pair qualifies when it sat in the band in at least ``min_frames`` frames
    and in ``min_agreement`` of the frames both tracks exist. Assignment is one-to-one
    by RMS residual. A direct track whose second-best qualifying partner has more than
    ``ambiguity_ratio`` of the best one's support is ambiguous and left unpaired.
    Finally a pair whose RMS residual exceeds ``max_rms_factor`` times the median
    RMS of all pairs is rejected: for a true pair the RMS over n >= 5 frames, in
    units of the detection noise, follows sqrt(chi2_n / n), whose 99.9 % quantile is
    about 2.0 -- chance alignments of two different markers sit further out."""
    from scipy.optimize import linear_sum_assignment

    keys, sq = [], []
    n_mt = 1 + max((int(m.max()) for m in mirror_ids if len(m)), default=0)
    v = mirror + 1
    for dn, did, dcol, mn, mid, mcol in zip(det.per_frame(0, "norm"), direct_ids, det.per_frame(0, "colour"),
                                            det.per_frame(v, "norm"), mirror_ids, det.per_frame(v, "colour")):
        if len(dn) == 0 or len(mn) == 0:
            continue
        lines = lines_of_normalised(dn, camera, plane)  # (n_d, 3), undistorted px
        q = camera.ideal_pixels(mn)  # (n_m, 2)
        dist = line_distance(lines[:, None], q[None])
        i, j = np.nonzero((dist <= band_px) & (dcol[:, None] == mcol[None, :]))
        keys.append(np.asarray(did)[i] * n_mt + np.asarray(mid)[j])
        sq.append(dist[i, j] ** 2)
    if not keys:
        empty = np.zeros(0, int)
        return TrackPairs(empty, empty, np.zeros(0), empty, empty, np.zeros((0, 2), int), np.zeros((0, 2), int))
    keys = np.concatenate(keys)
    sq = np.concatenate(sq)
    uk, inv = np.unique(keys, return_inverse=True)
    support = np.bincount(inv)
    rms = np.sqrt(np.bincount(inv, sq) / support)
    dt, mt = uk // n_mt, uk % n_mt
    # frames in which both tracks exist: a product of (frame x track) presence matrices
    both = np.asarray(_presence(direct_ids).T.dot(_presence(mirror_ids)).tocsr()[dt, mt]).ravel()
    ok = (support >= min_frames) & (support >= min_agreement * both)
    dt, mt, rms, support = dt[ok], mt[ok], rms[ok], support[ok]
    if rms.size:
        close = rms <= max_rms_factor * np.median(rms)
        dt, mt, rms, support = dt[close], mt[close], rms[close], support[close]
    # ambiguity: a rival partner with comparable support (best and second best per direct track)
    ambiguous = _rivalled(dt, support, ambiguity_ratio)
    # a contested image (TrackPairs.contested): the only partner of two direct tracks that it rivals as closely
    sole = np.bincount(dt, minlength=int(dt.max(initial=-1)) + 1)[dt] == 1
    contested_tracks = _rivalled(mt[sole], support[sole], ambiguity_ratio, rms[sole], CONTEST_RMS_RATIO)
    on = sole & np.isin(mt, contested_tracks)
    qualifying, contested = np.c_[dt, mt], np.c_[dt[on], mt[on]]
    keep = ~np.isin(dt, ambiguous)
    dt, mt, rms, support = dt[keep], mt[keep], rms[keep], support[keep]
    if dt.size == 0:
        empty = np.zeros(0, int)
        return TrackPairs(empty, empty, np.zeros(0), empty, ambiguous, qualifying, contested)
    ud, dinv = np.unique(dt, return_inverse=True)
    um, minv = np.unique(mt, return_inverse=True)
    cost = np.full((ud.size, um.size), 1e9)
    cost[dinv, minv] = rms - 1e-3 * support  # prefer closer, then longer-supported pairs
    r, c = linear_sum_assignment(cost)
    good = cost[r, c] < 1e9
    index = np.full(cost.shape, -1)
    index[dinv, minv] = np.arange(dt.size)
    pick = index[r[good], c[good]]  # rows come sorted, so pairs stay in direct-track order
    return TrackPairs(dt[pick], mt[pick], rms[pick], support[pick], ambiguous, qualifying, contested)


def _rivalled(tracks, support, ratio: float, rms=None, rms_ratio: float = np.inf) -> np.ndarray:
    """Of the qualifying pairs' ``tracks`` (one view's), those whose second-best partner has more than ``ratio``
    of the best one's ``support`` -- and, with ``rms``, whose partners of such support sit in the band nearly as
    closely as each other: the second-closest within ``rms_ratio`` times the closest's RMS residual."""
    order = np.lexsort((-support, tracks))
    by_track, sup_sorted = tracks[order], support[order]
    if by_track.size == 0:
        return np.zeros(0, int)
    starts = np.flatnonzero(np.r_[True, by_track[1:] != by_track[:-1]])
    sizes = np.diff(np.r_[starts, by_track.size])
    second = sup_sorted[np.minimum(starts + 1, by_track.size - 1)]
    rival = (sizes > 1) & (second > ratio * sup_sorted[starts])
    if rms is not None:
        group = np.repeat(np.arange(starts.size), sizes)
        r = np.where(sup_sorted > ratio * sup_sorted[starts][group], rms[order], np.inf)  # comparable support
        by_rms = np.lexsort((r, group))
        lowest, next_lowest = r[by_rms[starts]], r[by_rms[np.minimum(starts + 1, by_track.size - 1)]]
        rival &= next_lowest < rms_ratio * lowest
    return by_track[starts][rival]


def _presence(ids_per_frame):
    """Sparse (frames x tracks) matrix: 1 where a track has a detection in a frame."""
    from scipy.sparse import csr_matrix

    frames = np.concatenate([np.full(len(ids), f) for f, ids in enumerate(ids_per_frame)])
    tracks = np.concatenate([np.asarray(ids, int) for ids in ids_per_frame])
    n_tracks = int(tracks.max()) + 1 if tracks.size else 1
    m = csr_matrix((np.ones(tracks.size), (frames, tracks)), shape=(len(ids_per_frame), n_tracks))
    m.sum_duplicates()
    m.data[:] = 1.0
    return m


def paired_tracks(det: ClipDetections, camera: Camera, normals, band_px: float = 1.0, min_frames: int = 5,
                  max_rms_factor: float = 2.0, tracks=None, detail: dict | None = None):
    """2D tracks of the direct view and of each mirror over the frames of ``det``, and each
    direct track's partner track per mirror (:func:`pair_tracks`; the band depends only on
    the mirrors' ``normals`` ``(K, 3)``, eq. 5.2). Returns ``(direct ids per frame, number of
    direct tracks, partner (K, n): -1 none, mirror ids per frame per mirror, ambiguous (K, n):
    tracks with rival partners in that mirror, rms_px (K, n): each pair's band residual)``.
    ``max_rms_factor``: :func:`pair_tracks`'s RMS test (``inf``: none). ``tracks``: the
    ``(direct ids, number of direct tracks, mirror ids)`` of an earlier call on the same ``det``,
    to pair them again (another band) without linking them again. ``detail``: a dict that gets, per mirror,
    :class:`TrackPairs`' ``qualifying`` and ``contested`` pairs (lists under those keys)."""
    if tracks is None:
        dids, n_dt = track_2d(det.per_frame(0), det.per_frame(0, "colour"))
        given = None
    else:
        dids, n_dt, given = tracks
    K = len(normals)
    partner = np.full((K, n_dt), -1)
    ambiguous = np.zeros((K, n_dt), bool)
    rms_px = np.full((K, n_dt), np.nan)
    mids_all = []
    for k in range(K):
        mids = track_2d(det.per_frame(k + 1), det.per_frame(k + 1, "colour"))[0] if given is None else given[k]
        pairs = pair_tracks(det, dids, k, mids, camera, MirrorPlane(normal=np.asarray(normals[k], float), d=-1.0),
                            band_px=band_px, min_frames=min_frames, max_rms_factor=max_rms_factor)
        partner[k, pairs.direct_track] = pairs.mirror_track
        rms_px[k, pairs.direct_track] = pairs.rms_px
        ambiguous[k, pairs.ambiguous] = True
        mids_all.append(mids)
        if detail is not None:
            detail.setdefault("qualifying", []).append(pairs.qualifying)
            detail.setdefault("contested", []).append(pairs.contested)
    return dids, n_dt, partner, mids_all, ambiguous, rms_px


def partner_blobs(det: ClipDetections, direct_ids, partner, mirror_ids):
    """For every direct blob of ``det`` (global index): its direct track ``(D,)`` and, per
    mirror, the blob of its partner track in the same frame ``(K, D)`` (global index in that
    mirror's view; -1 where the blob's track has no partner or the partner is not seen then).
    ``direct_ids``, ``partner`` and ``mirror_ids`` as :func:`paired_tracks` returns them."""
    track = np.concatenate([np.asarray(d, int) for d in direct_ids]) if len(direct_ids) else np.zeros(0, int)
    K = partner.shape[0]
    blob = np.full((K, track.size), -1)
    for k in range(K):
        m_track = (np.concatenate([np.asarray(m, int) for m in mirror_ids[k]]) if len(mirror_ids[k])
                   else np.zeros(0, int))
        if m_track.size and track.size:
            blob[k] = blobs_at(det, k + 1, m_track, det.frame[0], partner[k, track])
    return track, blob


def blobs_at(det: ClipDetections, view: int, blob_track, frames, tracks) -> np.ndarray:
    """The blob of ``view`` (global index) that 2D track ``tracks[i]`` holds in frame ``frames[i]``, -1 where it
    holds none (or ``tracks[i]`` is -1); ``blob_track`` ``(n_v,)``: each blob's track. A 2D track holds at most one
    blob per frame, so (frame, track) finds one blob, by a sorted search."""
    frames, tracks = np.asarray(frames, int), np.asarray(tracks, int)
    out = np.full(tracks.size, -1)
    if len(blob_track) == 0:
        return out
    n = int(blob_track.max()) + 1
    key = det.frame[view] * n + blob_track
    order = np.argsort(key, kind="stable")
    want = frames * n + np.maximum(tracks, 0)
    at = np.minimum(np.searchsorted(key[order], want), key.size - 1)
    hit = (tracks >= 0) & (key[order][at] == want)
    out[hit] = order[at[hit]]
    return out


#: the whole clip's 2D tracks (:func:`blob_tracks`) link a blob this far (a share of the view's typical spacing
#: between neighbouring blobs), at least :func:`track_2d`'s 8 px: a chin or lip dot moving 10-20 px a frame at
#: 2-3x tempo broke its tracks at 8 px (jaw, fast720, lip648: 97.0-98.2 % -> 99.0-99.6 % of the seen marker-frames,
#: no identity switch); the first frames' pairing keeps 8 px (at 12 px yaw540 got 4 points over 2 mm, wide576 16)
CLIP_LINK_SPACING_SHARE = 0.8


def clip_link_gate_px(det: ClipDetections, view: int) -> float:
    """How far :func:`blob_tracks` links a blob of ``view`` from its prediction: the larger of 8 px
    and :data:`CLIP_LINK_SPACING_SHARE` of the view's typical blob spacing
    (:meth:`.ClipDetections.typical_spacing`)."""
    return max(8.0, CLIP_LINK_SPACING_SHARE * det.typical_spacing(view))


#: a new 2D track born this near (a share of the view's typical blob spacing) a track of the same colour is where
#: two dots imaged as one blob came apart (:func:`cut_at_splits`; pitch800's two jaw-side dots: 3.1 px)
SPLIT_SPACING_SHARE = 0.5


def cut_at_splits(det: ClipDetections, view: int, ids: np.ndarray, radius_px: float) -> np.ndarray:
    """2D track ids ``ids`` ``(n_v,)`` of ``view``'s blobs, each track cut where a new track of its colour is
    born within ``radius_px`` of its blob. Two like dots imaged as one blob for a while (a dot turning
    behind another at the face's silhouette) come apart as the old track and a new one, and which of the two
    dots the old track goes on with is the linker's guess: from that frame on it is a new track, and what
    follows the tracks (:func:`continuing_candidate`, the late merges, the gap bridge) decides afresh.
    (Blobs of two colours cannot swap: :func:`track_2d` links one colour.)"""
    from scipy.spatial import cKDTree

    ids = np.asarray(ids, int).copy()
    if ids.size == 0:
        return ids
    frame = det.frame[view]
    n = int(ids.max()) + 1
    born = np.full(n, det.n_frames)
    np.minimum.at(born, ids, frame)
    newborn = np.flatnonzero((frame == born[ids]) & (frame > 0))      # each track's first blob, after frame 0
    if newborn.size == 0:
        return ids
    pts = frame_spaced(det.xy[view], frame, radius_px)                   # one tree for every frame
    near = cKDTree(pts[newborn]).sparse_distance_matrix(cKDTree(pts), radius_px, output_type="ndarray")
    b, o = newborn[near["i"]], near["j"].astype(int)
    split = (o != b) & (born[ids[o]] < frame[b]) & (det.colour[view][o] == det.colour[view][b])
    if not split.any():
        return ids
    cut_from = np.full(n, det.n_frames)
    np.minimum.at(cut_from, ids[o[split]], frame[b[split]])
    cut = np.flatnonzero(cut_from < det.n_frames)
    renamed = np.full(n, -1)
    renamed[cut] = n + np.arange(cut.size)
    after = frame >= cut_from[ids]
    ids[after] = renamed[ids[after]]
    return ids


def blob_tracks(det: ClipDetections) -> list:
    """The 2D track (:func:`track_2d`, over the whole clip) of every blob of each view, ``(n_v,)``
    per view, the direct view's cut where two like dots merged in one blob come apart
    (:func:`cut_at_splits`); computed once per clip (kept with the clip's detections ``det``: the
    first frames' pairing reads them too, before the clip's candidates exist)."""
    if "_blob_tracks" not in det.__dict__:
        out = []
        for v in range(len(det.xy)):
            if not len(det.xy[v]):
                out.append(np.zeros(0, int))
                continue
            ids = np.concatenate([np.asarray(i, int) for i in
                                  track_2d(det.per_frame(v), det.per_frame(v, "colour"), clip_link_gate_px(det, v))[0]])
            if v == 0:   # the mirrors' cut too: mirror35 19 -> 30 points over 2 mm, dots720 35 -> 38
                ids = cut_at_splits(det, v, ids, SPLIT_SPACING_SHARE * det.typical_spacing(v))
            out.append(ids)
        det.__dict__["_blob_tracks"] = out
    return det.__dict__["_blob_tracks"]


def clip_band_support(det: ClipDetections, camera: Camera, normal, mirror: int, direct_track, mirror_track,
                      band_px: float) -> tuple:
    """For each pair of whole-clip 2D tracks (:func:`blob_tracks`) -- ``direct_track`` ``(P,)`` of the direct
    view, ``mirror_track`` ``(P,)`` of mirror ``mirror`` (plane ``normal``) -- the frames of the whole clip in
    which the mirror track's blob lies within ``band_px`` of the direct track's blob's mirrored epipolar line
    (eq. 5.2), and the frames in which both tracks have a blob: ``(in_band (P,), shared (P,))``. A dot and its own
    mirror image stay in the band as the head turns and the face moves; two dots' chance alignment on one line
    slides out of it."""
    ids = blob_tracks(det)
    direct_track, mirror_track = np.asarray(direct_track, int), np.asarray(mirror_track, int)
    d_ids, m_ids = ids[0], ids[mirror + 1]
    if direct_track.size == 0 or d_ids.size == 0 or m_ids.size == 0:
        return np.zeros(direct_track.size, int), np.zeros(direct_track.size, int)
    by_track = np.argsort(d_ids, kind="stable")
    lo = np.searchsorted(d_ids[by_track], direct_track)
    count = np.searchsorted(d_ids[by_track], direct_track, "right") - lo
    pair, blob = np.repeat(np.arange(direct_track.size), count), by_track[spans(lo, count)]
    image = blobs_at(det, mirror + 1, m_ids, det.frame[0][blob], mirror_track[pair])
    hit = image >= 0
    pair, blob, image = pair[hit], blob[hit], image[hit]
    lines = lines_of_normalised(det.norm[0][blob], camera, MirrorPlane(normal=np.asarray(normal, float), d=-1.0))
    near = line_distance(lines, camera.ideal_pixels(det.norm[mirror + 1][image])) <= band_px
    return np.bincount(pair[near], minlength=direct_track.size), np.bincount(pair, minlength=direct_track.size)


def candidate_tracks(det: ClipDetections, cands):
    """The 2D track (:func:`blob_tracks`) of every clip candidate's direct blob ``(C,)`` and
    mirror blobs ``(C, K)`` (-1: no blob in that mirror)."""
    if "_tracks" in cands.__dict__:
        return cands.__dict__["_tracks"]
    ids = blob_tracks(det)
    dtrack = ids[0][cands.direct] if len(cands.direct) else np.zeros(0, int)
    mtrack = np.full(cands.mirror_blob.shape, -1)
    for k in range(cands.mirror_blob.shape[1]):
        has = cands.mirror_blob[:, k] >= 0
        mtrack[has, k] = ids[k + 1][cands.mirror_blob[has, k]]
    cands.__dict__["_tracks"] = (dtrack, mtrack)      # the final pass and the merge read them
    return dtrack, mtrack


def direct_track_frames(det: ClipDetections, cands) -> np.ndarray:
    """Sorted codes ``track * F + frame`` of the frames each direct-view 2D track (the ids of
    :func:`blob_tracks`) has a blob in."""
    return np.unique(blob_tracks(det)[0].astype(np.int64) * det.n_frames + det.frame[0])


def continuing_candidate(dtrack, mtrack, last_dtrack, last_mtrack, held=None) -> tuple:
    """Per marker, the frame's candidate (index into the frame's candidates; -1: none) whose
    direct blob continues the 2D track of the marker's last measurement *and* whose blob in some
    mirror continues that mirror's track: the same physical dot seen the same way, so the same
    marker whatever its 3D motion. Several such candidates: the one sharing the most tracks, then
    (``held`` ``(N, K)``: for how many measurements running the marker has been on its mirror
    tracks) the one on the mirror track held longest -- the marker's own pairing, where a
    newcomer is another dot imaged next to the marker's hidden image. Returns the candidates and,
    per marker, how long it has held the longest-held mirror track its candidate continues (0: none,
    or no ``held``)."""
    out, out_held = np.full(len(last_dtrack), -1), np.zeros(len(last_dtrack), int)
    if dtrack.size == 0 or not (last_dtrack >= 0).any():
        return out, out_held
    # the (marker, candidate) pairs on one direct track, markers ascending and candidates ascending within
    # each (as a marker x candidate comparison would list them), by a join on the sorted tracks
    by_track = np.argsort(dtrack, kind="stable")
    sorted_tracks = dtrack[by_track]
    markers = np.flatnonzero(last_dtrack >= 0)
    lo = np.searchsorted(sorted_tracks, last_dtrack[markers], "left")
    count = np.searchsorted(sorted_tracks, last_dtrack[markers], "right") - lo
    i = np.repeat(markers, count)
    c = by_track[spans(lo, count)]
    on = (mtrack[c] == last_mtrack[i]) & (last_mtrack[i] >= 0)
    shared = on.sum(axis=1)
    on_held = on * held[i] if held is not None else np.zeros(on.shape, int)
    age, longest = on_held.sum(axis=1), on_held.max(axis=1, initial=0)
    ok = shared > 0
    i, c, shared, age, longest = i[ok], c[ok], shared[ok], age[ok], longest[ok]
    if i.size == 0:                                   # no candidate continues a marker's tracks
        return out, out_held
    order = np.lexsort((-age, -shared, i))            # per marker, most shared tracks, then the oldest
    first = order[np.r_[True, i[order][1:] != i[order][:-1]]]
    out[i[first]], out_held[i[first]] = c[first], longest[first]
    return out, out_held


def continuing_owner(cont, cont_held, sl, min_held: int) -> np.ndarray:
    """Per candidate of the frame's slice ``sl``, the marker whose own 2D tracks it continues
    (:func:`continuing_candidate`: ``cont`` (N,), index of the clip's candidates, -1 none), where that
    marker has held its mirror track ``min_held`` measurements (``cont_held``) and no other marker's tracks
    lead there too; -1 elsewhere."""
    owner = np.full(sl.stop - sl.start, -1)
    mine = np.flatnonzero((cont >= 0) & (cont_held >= min_held))
    if mine.size:
        at = cont[mine] - sl.start
        claims = np.bincount(at, minlength=owner.size)
        owner[at] = mine
        owner[claims > 1] = -1
    return owner


def direct_track_spans(det: ClipDetections, cands) -> tuple:
    """The first and the last frame of each direct-view 2D track (the ids of :func:`blob_tracks`),
    ``(start (T,), end (T,))``; computed once per clip."""
    if "_spans" not in cands.__dict__:
        ids = blob_tracks(det)[0]
        start = np.full(int(ids.max(initial=-1)) + 1, det.n_frames)
        end = np.full(start.size, -1)
        np.minimum.at(start, ids, det.frame[0])
        np.maximum.at(end, ids, det.frame[0])
        cands.__dict__["_spans"] = (start, end)
    return cands.__dict__["_spans"]


def back_on_mirror_track(mtrack, dtrack, last_mtrack, last_dtrack, held, last_frame, spans, t: int,
                         min_held: int, min_lost: int) -> tuple:
    """Markers whose direct dot was hidden while their mirror image was followed (a hand before the
    mouth), and the frame ``t``'s candidates that bring them back: ``(markers, candidates)`` (index into
    the frame's candidates), each candidate's blob in a mirror on the 2D track the marker held for
    ``min_held`` measurements running (``last_mtrack``, ``held`` ``(N, K)``; no other marker holds it,
    none claims the candidate through the other mirror), the marker lost for ``min_lost`` frames or more
    since ``last_frame``, the direct track of its last measurement (``last_dtrack``) ended with it -- its
    dot vanished -- and the candidate's direct blob on a track begun since (``spans``:
    :func:`direct_track_spans`): the dot come back. ``mtrack`` ``(C, K)``, ``dtrack`` ``(C,)``: the
    frame's candidates' 2D tracks (:func:`candidate_tracks`)."""
    owner = np.full(len(mtrack), -1)
    clash = np.zeros(len(mtrack), bool)
    for k in range(mtrack.shape[1]):
        holders = np.flatnonzero((last_mtrack[:, k] >= 0) & (held[:, k] >= min_held))
        if not holders.size:
            continue
        tracks, first, count = np.unique(last_mtrack[holders, k], return_index=True, return_counts=True)
        at = np.minimum(np.searchsorted(tracks, mtrack[:, k]), tracks.size - 1)
        c = np.flatnonzero((mtrack[:, k] >= 0) & (tracks[at] == mtrack[:, k]) & (count[at] == 1))
        who = holders[first[at[c]]]
        clash[c] |= (owner[c] >= 0) & (owner[c] != who)
        owner[c] = np.where(owner[c] >= 0, owner[c], who)
    owner[clash] = -1
    c = np.flatnonzero(owner >= 0)
    o = owner[c]
    start, end = spans
    vanished = (last_dtrack[o] >= 0) & (end[np.maximum(last_dtrack[o], 0)] <= last_frame[o] + 2)
    ok = (t - 1 - last_frame[o] >= min_lost) & vanished & (start[dtrack[c]] > last_frame[o])
    return o[ok], c[ok]


def chain_pairing_support(chains, support, rows, direct_track, mirror_track) -> dict:
    """Per late chain (:func:`.late.add_late_markers`) of ``chains``, the support of its pairing of 2D tracks: the
    frames (``support``) of all the chains that pair the same direct track with the same track in a mirror (each
    chain's tracks: the most frequent among its candidates ``rows``; the best of its mirrors). Two like dots on
    one mirrored epipolar line and their two images on another (one a grazing image): both ways of pairing them
    sit in the band, but where a chance pairing's rays meet slides as the head turns, so its chains break and
    stay short, while the true pairing chains on (ruddy540: the grazing image's chains with its own dot 72 frames,
    with the other dot 45, though that chance pairing's single chain was the longest)."""
    def most(values):
        values = values[values >= 0]
        return int(np.bincount(values).argmax()) if values.size else -1

    keys = {c: [(k, most(direct_track[r]), most(mirror_track[r, k])) for k in range(mirror_track.shape[1])]
            for c, r in zip(chains, rows)}
    total = {}
    for c, ks in keys.items():
        for key in ks:
            if key[2] >= 0:
                total[key] = total.get(key, 0) + int(support[c])
    return {c: max((total[k] for k in ks if k[2] >= 0), default=0) for c, ks in keys.items()}
