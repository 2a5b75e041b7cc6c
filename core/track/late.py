"""Late markers (Lin 2003, section 5.8 "missing markers", the case of a marker first seen
after the neutral frame): chains of unclaimed candidates linked frame to frame become new
markers, entered at their neutral position so they pass the neighbour test and merge with
their own earlier chains; after the final pass, a later chain that the tracking kept apart from its
marker merges back into it (:mod:`.splits`), and markers lost for good or measured through another
marker's mirror image are settled."""

from __future__ import annotations

import numpy as np

from ..geometry.rigid import rotation_zyx, to_head_frame
from ..capture.views import ClipDetections, frame_spaced
from .candidates import ClipCandidates
from .onface import along_ray, beyond, face_offset, off_face_on_shared_tracks, off_in_mirrors, off_the_face
from .pairing import candidate_tracks, chain_pairing_support
from .result import COLOUR_SPACING_MM, TrackResult, TrackSettings, earns_place, keep_measured


#: a late chain is refused as off the face when it lies this far along its ray from the face formed by its
#: neighbours, both as the camera sees it and as each mirror it was paired through sees it
#: (:func:`add_late_markers`). A dot seen only directly, paired with the grazing image of a like dot on its epipolar
#: line, lands along its ray; between the eyes of the held-out tan720 (normal light), two such chains of magenta
#: dots in a row, 8-9 mm off, were kept at 10 mm (53 points over 2 mm, up to 9.4 mm; 14 with 7 mm). On the 28
#: other clips 7 mm drops four labels, none of them on a dot the truth counts as seen, and changes one point
#: over 2 mm (tilt630 53 -> 54)
LATE_OFF_FACE_MM = 7.0
#: ... the limit as the camera sees it, where the plane through the dot's neighbours fits them closely (it widens to
#: 4x its misfit, :func:`.onface.beyond`): a dot seen only directly, paired with like dots' grazing images, lay 5-7 mm
#: along its ray from planes 1.2 mm off their markers (cam450's dot 54, 38 points 5-7 mm off; hv2's and hx4's like
#: ones, tens of points). Over the 48 committed clips, points over 2 mm 612 -> 481 (cam450 42 -> 4, hv2 40 -> 1,
#: hx4 38 -> 4, mirror35 21 -> 3), no switch; ruddy540 loses a dot that lies 5-7 mm off such a plane (92.95 ->
#: 92.67 % reported) and tempo720 0.1 points. At 5.5 mm hv2 and hx4 keep theirs; the mirrors' limit stays 7 mm
LATE_OFF_FACE_CAMERA_MM = 5.0

#: one dot in the direct view, two late chains with two depths (add_late_markers): two chains on one direct 2D track
#: whose rest positions lie within RIVAL_ACROSS_MM of its line of sight and at least RIVAL_ALONG_MM apart along it
#: (beyond same_marker_mm, the limit of one marker's two stretches; a dot paired with a like dot's grazing image lands
#: 6-9 mm along its ray on tan720 and deep720) are rivals, and the one considered later replaces the kept one
#: (:func:`_replaces_rival`) when it lies RIVAL_NEARER_MM nearer the face along its ray (:func:`.onface.face_offset`),
#: or when neither lies that much nearer and its pairing of 2D tracks is the better supported. At 4 mm along the ray
#: wide576 lost 1 % of its seen marker-frames: two stretches of one dot at the silhouette, their rests 4.6 mm apart.
#: A marker kept from several stretches lies as far off the face as the nearest of them came: at the silhouette the
#: plane through a dot's neighbours misses the face curving away, and held-out hy2's cheek dot, 2.97 mm off it where
#: its kept chain began, 9.1 mm where an earlier stretch began, lost to a like dot's image 10.7 mm deeper (2.1 mm off)
#: when the earlier stretch's distance counted: 30 frames 10.7 mm off, 13 identity switches (hx4 and small540 changed
#: too, no other committed clip)
RIVAL_ACROSS_MM = 2.0
RIVAL_ALONG_MM = 5.0
RIVAL_NEARER_MM = 2.0
#: ... or this many times the misfit of the plane through the dot's neighbours to them, where that is more
#: (:func:`_replaces_rival`, as :func:`.onface.beyond` widens its limit)
RIVAL_MISFIT_FACTOR = 4.0


def add_late_markers(det: ClipDetections, cands: ClipCandidates, s: TrackSettings, markers, first_pass,
                      focal_px: float, link_mm: float = 1.0, link_frames: int = 3, min_frames: int = 5,
                      same_marker_mm: float = 4.0, same_ray_px: float = 2.0, min_support: float = 0.6,
                      max_rms_factor: float = 2.0, off_face_mm: float = LATE_OFF_FACE_MM, planes=None,
                      off_camera_mm: float = LATE_OFF_FACE_CAMERA_MM):
    """Markers the initial window missed (hidden at the start, turned into view later).

    Candidates the first pass left alone -- their direct blob and their mirror blobs
    unclaimed by any tracked marker -- are taken into the head frame (the first pass's
    head pose) and linked: two of the same colour within ``link_mm`` of each other and
    at most ``link_frames`` frames apart belong together. A chain seen in at least
    ``min_frames`` frames, and in ``min_support`` of the frames it spans, with an RMS
    band residual within ``max_rms_factor`` of the tracked markers', is a marker (a
    chance alignment of two markers' blobs drifts in and out of the band, anywhere
    in it: ``core.track.pairing`` has the same test). A chain that mostly runs within ``same_marker_mm`` of an existing marker, or
    within ``same_ray_px`` of its image (its direct blob, paired with a wrong mirror
    blob), is that marker found again and is not added; nor is one whose neutral
    position lies within ``same_marker_mm`` of an existing (or an earlier added) marker's, nor one sharing a
    blob with a chain on a better supported pairing of 2D tracks (:func:`.pairing.chain_pairing_support`; a chain
    that shares blobs with chains kept on worse supported pairings replaces them), nor one off the face: more
    than ``off_camera_mm`` along its ray, where it is first seen, from the surface through the markers measured then
    (:func:`.onface.off_the_face`; :data:`LATE_OFF_FACE_CAMERA_MM`; a direct blob paired with another marker's mirror
    image lands along its ray, typically ~45 mm away) *and*, with the mirrors' ``planes`` ``(normals (K, 3),
    ds (K,))`` given, more than ``off_face_mm`` off it as each mirror it was paired through sees it
    (:func:`.onface.off_in_mirrors`; :data:`LATE_OFF_FACE_MM`):
    a dot at the face's silhouette lies beyond all its neighbours' rays, where the plane through
    them misses the face curving away (10-30 mm), but the mirror sees it face on. Chance pairings
    with false blobs are scattered in space and time and do not chain. A marker added gets as its
    neutral position where it was first seen, less its neighbours' motion then
    (:func:`_motion_near`; from its earliest stretch that agrees within :data:`REST_AGREE_MM`), and is
    measured from the first frame of its chains on
    (before, its position is only a conjecture, and a false blob near that would be
    taken for it)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    first_blob, neutral, colour, entry = markers
    F = det.n_frames
    K = cands.mirror_blob.shape[1]
    taken = [np.zeros(len(det.frame[v]), bool) for v in range(K + 1)]
    claimed = first_pass.candidate[first_pass.candidate >= 0]
    taken[0][cands.direct[claimed]] = True
    for k in range(K):
        mb = cands.mirror_blob[claimed, k]
        taken[k + 1][mb[mb >= 0]] = True
    free = ~taken[0][cands.direct]
    for k in range(K):
        mb = cands.mirror_blob[:, k]
        free &= (mb < 0) | ~taken[k + 1][np.maximum(mb, 0)]
    idx = np.flatnonzero(free)
    if idx.size < min_frames:
        return markers
    f = cands.frame[idx]
    pose = first_pass.head_pose[f]
    R = rotation_zyx(pose[:, :3])  # (M, 3, 3)
    head = to_head_frame(R, pose[:, 3:], cands.points[idx])
    col = det.colour[0][cands.direct[idx]]
    pairs = _pairs_frames_apart(np.c_[head, col * COLOUR_SPACING_MM], f, link_mm, link_frames)
    n_comp, comp = connected_components(coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                                   shape=(idx.size, idx.size)), directed=False)
    # frames per chain (a chain may hold two candidates of one frame: count frames once)
    key = np.unique(comp * (F + 1) + f)
    support = np.bincount(key // (F + 1), minlength=n_comp)
    # a true pair sits in the band every frame both blobs are seen, as close as the
    # detection noise allows; a chance alignment drifts in and out, anywhere in the band
    first_f = np.full(n_comp, F)
    last_f = np.full(n_comp, -1)
    np.minimum.at(first_f, comp, f)
    np.maximum.at(last_f, comp, f)
    rms = np.sqrt(np.bincount(comp, cands.residual_px[idx] ** 2, minlength=n_comp) / np.bincount(comp, minlength=n_comp))
    true_rms = np.sqrt(np.mean(cands.residual_px[claimed] ** 2)) if claimed.size else np.inf
    good = np.flatnonzero((support >= min_frames) & (support >= min_support * (last_f - first_f + 1))
                          & (rms <= max_rms_factor * true_rms))
    if good.size == 0:
        return markers
    # a chain that mostly runs along an existing marker is that marker: near it in 3D (frames
    # the first pass missed it in), or on its image (its direct blob with a wrong mirror blob).
    # Markers that will not earn their place (wrong pairings, lost for good) do not count.
    member = np.flatnonzero(np.isin(comp, good))
    real = earns_place(first_pass.assigned_blob >= 0, s.min_measured_frames, s.min_measured_fraction)
    d = _nearest_same_frame(first_pass.head_frame[:, real], f[member], head[member], same_marker_mm)
    seen = first_pass.points[:, real]
    rays = seen[..., :2] / np.where(seen[..., 2:] > 1e-9, seen[..., 2:], np.nan)
    d_px = _nearest_same_frame(rays, f[member], det.norm[0][cands.direct[idx[member]]],
                               same_ray_px / focal_px) * focal_px
    near_existing = np.bincount(comp[member], (d <= same_marker_mm) | (d_px <= same_ray_px), minlength=n_comp)
    good = good[near_existing[good] < 0.5 * np.bincount(comp[member], minlength=n_comp)[good]]
    if good.size == 0:
        return markers
    # one blob is one marker: chains sharing a blob (a marker's chain and its chance pairings with another
    # unclaimed blob) compete, and the one on the best supported pairing of 2D tracks wins
    cand_of = idx[member]
    blob_keys = [cands.direct[cand_of]] + [cands.mirror_blob[cand_of, k] for k in range(K)]
    used = [np.full(len(det.frame[v]), -1) for v in range(K + 1)]     # the kept chain that holds each blob
    by_chain = np.argsort(comp[member], kind="stable")
    bounds = np.searchsorted(comp[member][by_chain], np.arange(n_comp + 1))
    order = np.lexsort((np.arange(idx.size), f, comp))
    first_of = order[np.r_[True, comp[order][1:] != comp[order][:-1]]]  # each chain's first candidate
    entry_of = np.full(n_comp, -1)
    entry_of[comp[first_of]] = first_of
    # where each chain's marker sits in the neutral face: where it first shows, less its
    # neighbours' motion then -- two chains of one marker (split by a long gap) land together
    q_of = entry_of[good]
    at_rest = np.full((n_comp, 3), np.nan)
    at_rest[good] = head[q_of] - _motion_near(first_pass, real, head[q_of], f[q_of], s.neighbour_radius_mm)
    keep, seen_from = [], {}
    # one dot in the direct view is one marker: a chain on the direct 2D tracks of a chain kept, resting
    # elsewhere (further than same_marker_mm), paired its dot with another mirror blob -- of the two, the one
    # nearer the face is kept (a dot paired with a like dot's grazing image lands 5-9 mm along its ray), where
    # neither is clearly nearer the better supported pairing (:func:`_replaces_rival`)
    direct_track, mirror_track = candidate_tracks(det, cands)
    owner = np.full(int(direct_track.max(initial=-1)) + 1, -1)          # the kept chain on each direct track
    face_off, misfit, blobs_of = {}, {}, {}
    paired = chain_pairing_support(good, support, [by_chain[bounds[c]:bounds[c + 1]] for c in good],
                              direct_track[cand_of], mirror_track[cand_of])

    def drop(kept):
        keep.remove(kept)
        del seen_from[kept]
        for v, b in enumerate(blobs_of[kept]):
            used[v][b[b >= 0]] = -1
        owner[owner == kept] = -1

    for c in good[np.argsort(-support[good], kind="stable")]:  # the chains left (tens), best supported first
        rows = by_chain[bounds[c]:bounds[c + 1]]
        blobs = [key[rows] for key in blob_keys]
        # a blob is one marker's: of two chains that share blobs, the one on the better supported pairing of 2D
        # tracks stays (:func:`.pairing.chain_pairing_support`)
        holders = np.unique(np.concatenate([used[v][b[b >= 0]] for v, b in enumerate(blobs)]))
        holders = holders[holders >= 0].tolist()
        if holders and not all(paired[c] > paired[h] for h in holders):
            continue
        if real.any() and np.min(np.linalg.norm(neutral[real] - at_rest[c], axis=1)) <= same_marker_mm:
            continue
        q = entry_of[c]  # where the chain is first seen: off the face as the camera sees it then?
        seen_then = first_pass.points[f[q]][real]
        seen_then = seen_then[np.all(np.isfinite(seen_then), axis=1)]
        point, views_then = cands.points[idx[q]], np.where(real, first_pass.camera_mask[f[q]], 0)
        offset = face_offset(seen_then, point)
        if beyond(offset, off_camera_mm) and (
                planes is None or off_in_mirrors(first_pass.points[f[q]], views_then, point,
                                                  cands.mirror_blob[idx[q]] >= 0, planes, off_face_mm)):
            continue
        others = [k for k in keep if k not in holders]
        if others:
            gap = np.linalg.norm(at_rest[others] - at_rest[c], axis=1)
            if gap.min() <= same_marker_mm:  # another stretch of a marker kept: it is seen from then
                same = others[int(np.argmin(gap))]
                if first_f[c] < seen_from[same] and gap.min() <= REST_AGREE_MM:
                    at_rest[same] = at_rest[c]      # ... and where it rests is read nearer the neutral frame
                # how far off the face it lies (for its rivals): the nearest any of its stretches came
                face_off[same] = np.fmin(face_off[same], offset[0])
                misfit[same] = np.fmax(misfit[same], offset[1])     # ... and how loosely the face there fits
                seen_from[same] = min(seen_from[same], first_f[c])
                continue
        tracks_c = direct_track[cand_of[rows]]
        face_off[c], misfit[c] = offset
        rival = _rival(owner[tracks_c], at_rest, c, R[q].T @ (point / np.linalg.norm(point)))
        if rival >= 0:
            if not _replaces_rival(face_off[rival] - face_off[c], paired[c] > paired[rival], rms[c] < rms[rival],
                                   max(misfit[rival], misfit[c])):
                continue
            drop(rival)                                                # the rival was the wrong pairing
        for held in holders:
            if held in keep:
                drop(held)                                             # the weaker pairing of c's blobs
        for v, b in enumerate(blobs):
            used[v][b[b >= 0]] = c
        owner[tracks_c] = c
        blobs_of[c] = blobs
        keep.append(c)
        seen_from[c] = first_f[c]
    keep.sort(key=lambda c: (seen_from[c], entry_of[c]))  # markers in order of appearance
    if not keep:
        return markers
    return (np.r_[first_blob, np.full(len(keep), -1)], np.vstack([neutral, at_rest[keep]]),
            np.r_[colour, col[entry_of[keep]]], np.r_[entry, [seen_from[c] for c in keep]])


def _replaces_rival(nearer_mm: float, better_paired: bool, better_fit: bool | None = None,
                    misfit_mm: float = 0.0) -> bool:
    """Does a late chain replace its rival on one direct 2D track (:func:`_rival`)? ``nearer_mm``: the rival's
    :func:`.onface.face_offset` less the chain's (NaN: no); ``better_paired``: the chain's pairing of 2D tracks is the
    better supported (:func:`.pairing.chain_pairing_support`); ``better_fit``: its band residual is the lower (RMS
    over its candidates; None: not known); ``misfit_mm``: the looser of the two faces' misfits to their markers.

    1. Yes when it lies nearer the face by more than the margin: :data:`RIVAL_NEARER_MM`, or
       :data:`RIVAL_MISFIT_FACTOR` times ``misfit_mm`` where that is more, as :func:`.onface.beyond` widens its
       limit where the plane through the dot's neighbours misses the face curving away.
    2. Within that margin, where the band and the pairing agree on one of the two, that one stays.
    3. Else as before: yes when :data:`RIVAL_NEARER_MM` nearer, or within it and the better paired.

    At a grazing angle the face around a dot says little: hv2's chin dot, seen directly at a grazing angle and hidden
    from mirror 0, was paired there with the image of a like dot the direct view does not see, 3.1 mm from the face
    against its own pairing's 3.4 mm, and kept 6-11 mm off for 45 frames (24 identity switches); its own pairing with
    mirror 1 holds over 78 chained frames against 62. At the silhouette the plane misses the face: held-out hy6's
    cheek dot, its own pairing 6.2 mm off a plane 5.0 mm off its own markers and a like dot's image's 2.2 mm, lost to
    the latter (8 mm off, 12 identity switches); its own pairing sits nearer its band (0.27 px RMS against 0.35) and
    holds over more chained frames (46 against 32)."""
    margin = max(RIVAL_NEARER_MM, RIVAL_MISFIT_FACTOR * misfit_mm) if np.isfinite(misfit_mm) else RIVAL_NEARER_MM
    if nearer_mm > margin:
        return True
    if better_fit is not None and abs(nearer_mm) <= margin and better_fit == better_paired:
        return bool(better_fit)
    if nearer_mm > RIVAL_NEARER_MM:
        return True
    return bool(abs(nearer_mm) <= RIVAL_NEARER_MM and better_paired)


def _rival(held_by, at_rest, c, ray) -> int:
    """The kept chain that holds most of chain ``c``'s direct 2D tracks (``held_by``: the kept chain on each
    of its rows' tracks, -1 none), when it holds half of them or more and rests on ``c``'s line of sight
    (``ray``, unit, head frame) :data:`RIVAL_ALONG_MM` or more away along it, within :data:`RIVAL_ACROSS_MM`
    of it; else -1."""
    held = held_by[held_by >= 0]
    if held.size == 0 or held.size < 0.5 * held_by.size:
        return -1
    rival = int(np.bincount(held).argmax())
    apart = at_rest[rival] - at_rest[c]
    return rival if along_ray(apart, ray) <= RIVAL_ACROSS_MM and abs(apart @ ray) >= RIVAL_ALONG_MM else -1


#: an earlier stretch of a late marker gives it its rest position (add_late_markers) when the two stretches'
#: estimates agree this closely: each is its position less its neighbours' motion then, good to about 1 mm, and
#: the earlier one has less motion to take off (tilt630's dot 77, seen from frame 0, was refused by the neighbour
#: test until frame 25 with the later stretch's, 1.1 mm off); a wrong pairing's stretch lies 2.5-3.6 mm off
#: (wide576's dots 129 and 200 were lost for good when any stretch gave it). At 1.0 mm pitch800 keeps 8 more
#: points over 2 mm; at 2.0 mm tilt630 5
REST_AGREE_MM = 1.5

def _pairs_frames_apart(points, frame, within: float, max_gap: int) -> np.ndarray:
    """Pairs ``(P, 2)`` of ``points`` ``(M, D)`` within ``within`` of each other whose
    ``frame`` numbers are 1 to ``max_gap`` apart (earlier first). Per gap one KD-tree
    query against the points shifted by the gap (:func:`frame_spaced`): a blob that sits
    still over the take gives pairs with the few frames next to it, not with all of them."""
    from scipy.spatial import cKDTree

    if len(points) == 0:
        return np.zeros((0, 2), int)
    tree = cKDTree(frame_spaced(points, frame, within))
    out = []
    for gap in range(1, max_gap + 1):
        later = cKDTree(frame_spaced(points, frame - gap, within))
        pairs = tree.sparse_distance_matrix(later, within, output_type="ndarray")
        out.append(np.c_[pairs["i"], pairs["j"]])
    return np.concatenate(out).astype(int)


def _nearest_same_frame(tracked, frame, query, within: float) -> np.ndarray:
    """Distance from each ``query`` point ``(M, D)`` to the nearest of the ``tracked``
    points ``(F, N, D)`` (NaN: not tracked) of its own ``frame`` ``(M,)``; ``inf`` where
    none lies within ``within``. One KD-tree over every frame (:func:`frame_spaced`)."""
    from scipy.spatial import cKDTree

    F, N, D = tracked.shape
    ok = np.isfinite(tracked).all(axis=2)
    if not ok.any() or len(query) == 0:
        return np.full(len(query), np.inf)
    frames = np.broadcast_to(np.arange(F)[:, None], (F, N))
    tree = cKDTree(frame_spaced(tracked[ok], frames[ok], within, query))
    dist, _ = tree.query(frame_spaced(query, frame, within, tracked[ok]),
                         distance_upper_bound=within * (1 + 1e-9) + 1e-12)
    return dist


def _motion_near(first_pass, real, where, frame, radius_mm: float, kc: float = 1.0):
    """The expression motion at ``where`` ``(M, 3)`` (head frame) in ``frame`` ``(M,)``:
    eq. 5.8's weighted combination of the motions of the ``real`` markers of
    ``first_pass`` within ``radius_mm`` (zero where none was measured). A late marker's
    neutral position is where it first shows minus this motion, so that its own motion,
    like every other marker's, is measured from the neutral face (the neighbour test
    of eq. 5.6-5.7 and the conjectures compare motions)."""
    near = first_pass.neutral[real]  # (R, 3)
    d = np.linalg.norm(near[None] - where[:, None], axis=2)  # (M, R)
    motion = first_pass.head_frame[frame][:, real] - near[None]  # (M, R, 3)
    w = np.where((d <= radius_mm) & np.isfinite(motion[..., 0]), 1.0 / (d + kc), 0.0)
    total = w.sum(axis=1, keepdims=True)
    return np.einsum("mr,mrd->md", w, np.nan_to_num(motion)) / np.where(total > 0, total, 1.0)


def lost_markers(result: TrackResult, s: TrackSettings) -> tuple:
    """The markers lost for good (:func:`.result.earns_place`) -- a wrong direct/mirror pairing
    whose 3D point stops matching real candidates, or a real marker the final pass lost or whose
    dot a later label picked up: the labels of those added later (not followed through their gaps,
    :func:`.singleview.follow_dots_through_gaps` ``passive``), of those paired in the first frames
    (followed, strictly: ``lost_initial``), and their measurements as ``(frame, direct blob)`` codes
    (frame * :data:`BLOB_CODE` + blob) for :func:`settle_lost_markers`."""
    measured = result.assigned_blob >= 0
    lost = ~earns_place(measured, s.min_measured_frames, s.min_measured_fraction)
    f, m = np.nonzero(measured & lost[None])
    labels = np.asarray(result.labels, dtype=object)
    initial = result.first_blob >= 0
    codes = f * BLOB_CODE + result.assigned_blob[f, m]
    return frozenset(labels[lost & ~initial]), frozenset(labels[lost & initial]), codes


BLOB_CODE = 1 << 20  # frame * BLOB_CODE + blob: one code per (frame, direct blob)
INTERLEAVE_FRAMES = 2  # a lost marker's point bracketed by another's measurements this near


def settle_lost_markers(result: TrackResult, codes, gate_mm: float) -> TrackResult:
    """After the dots were followed through gaps and labels found to be one dot merged
    (:func:`.singleview.follow_dots_through_gaps`): the measurements of markers lost for good
    (``codes``, :func:`lost_markers`) go with their marker when nothing else joined it. Where they
    joined other measurements -- a later label of the dot, or the marker's own dot followed on --
    they stay only if they lie on that path: at the lost
    measurements bracketed by the other's within :data:`INTERLEAVE_FRAMES` frames on both sides, the
    median distance (head frame) from the line between those is at most ``gate_mm``. (On jaw a chin
    dot's first 18 frames come back this way; a wrong pairing interleaved with the true marker's
    measurements lies 7-8 mm off its path.)"""
    measured = result.assigned_blob >= 0
    f, m = np.nonzero(measured)
    suspect = np.zeros_like(measured)
    suspect[f, m] = np.isin(f * BLOB_CODE + result.assigned_blob[f, m], codes)
    other = measured & ~suspect
    drop = np.zeros_like(measured)
    H = result.head_frame
    for label in np.flatnonzero(suspect.any(axis=0)):
        own = np.flatnonzero(suspect[:, label])
        if not other[:, label].any():
            drop[own, label] = True
            continue
        theirs = np.flatnonzero(other[:, label])
        after = np.searchsorted(theirs, own)
        lo, hi = theirs[np.maximum(after - 1, 0)], theirs[np.minimum(after, theirs.size - 1)]
        inside = (after > 0) & (after < theirs.size) & (own - lo <= INTERLEAVE_FRAMES) & (hi - own <= INTERLEAVE_FRAMES)
        if inside.any():
            w = ((own - lo) / np.maximum(hi - lo, 1))[inside, None]
            path = (1 - w) * H[lo[inside], label] + w * H[hi[inside], label]
            if np.median(np.linalg.norm(H[own[inside], label] - path, axis=1)) > gate_mm:
                drop[own, label] = True
    return keep_measured(drop_measurements(result, drop), 1)


def drop_measurements(result: TrackResult, drop) -> TrackResult:
    """The measurements at ``drop`` ``(F, N)`` undone (in place): gaps for the gap fill."""
    if drop.any():
        result.assigned_blob[drop] = -1
        result.points[drop] = np.nan
        result.head_frame[drop] = np.nan
        result.conjectured[drop] = False
        result.camera_mask[drop] = 0
        if result.candidate is not None:
            result.candidate[drop] = -1
    return result


EXPLAINED_PX = 1.0  # a mirror blob this near another marker's predicted image in that mirror is that marker's
OFF_FACE_MM = 10.0  # ... when the point it gave lies this far along its ray off the face (add_late_markers' limit)


def release_other_markers_blobs(result: TrackResult, det: ClipDetections, cands: ClipCandidates, normals, ds,
                                focal_px: float, tracks) -> TrackResult:
    """A measurement from the direct view and one mirror only is undone when its mirror blob is
    another marker's: within :data:`EXPLAINED_PX` of that marker's image in the mirror -- its 3D
    point, measured in the frame from the direct view and the other mirror, reflected in the
    mirror's plane (eq. 3.9) -- and on a 2D track of that mirror (``tracks``:
    :func:`.pairing.candidate_tracks`) the other marker measures in other frames. Grazing in a
    mirror a dot is imaged there, intermittently claimed by its marker; a dot seen only directly,
    on the same epipolar line, pairs with the image into a point 15 mm off any dot, frame after
    frame wherever the dot's own marker is measured without that mirror (wide576, 17 frames). The
    track condition spares a marker whose image merely falls where another marker, hidden in the
    mirror, would be imaged (on a dense face one mirror blob in seven lies within a pixel of such a
    point). Also undone: of two labels on one mirror track, the one off the face while the other lies on it
    (:func:`.onface.off_face_on_shared_tracks`: the image's own dot, seen in no other mirror, took it too)."""
    from scipy.spatial import cKDTree

    from ..geometry.mirror import reflect_points

    if result.candidate is None or tracks is None:
        return result
    mirror_track = tracks[1]
    n_tracks = int(mirror_track.max(initial=-1)) + 1
    drop = np.zeros(result.assigned_blob.shape, bool)
    measured = (result.assigned_blob >= 0) & (result.candidate >= 0)
    cand = np.maximum(result.candidate, 0)
    for k in range(len(normals)):
        own, other = 1 | (2 << k), 1 | (2 << (1 - k))
        f, a = np.nonzero(measured & (result.camera_mask == own))
        g, b = np.nonzero(measured & (result.camera_mask == other) & np.isfinite(result.points[..., 0]))
        if f.size == 0 or g.size == 0:
            continue
        h, c = np.nonzero(measured & (mirror_track[cand, k] >= 0))          # who measures which track
        claimed = np.unique(c.astype(np.int64) * n_tracks + mirror_track[cand[h, c], k])
        virtual = reflect_points(result.points[g, b], normals[k], ds[k])
        predicted = virtual[:, :2] / virtual[:, 2:3]
        blob = cands.mirror_blob[cand[f, a], k]
        f, a, blob = f[blob >= 0], a[blob >= 0], blob[blob >= 0]
        seen = det.norm[k + 1][blob]
        within = EXPLAINED_PX / focal_px
        dist, hit = cKDTree(frame_spaced(predicted, g, within, seen)).query(
            frame_spaced(seen, f, within, predicted), distance_upper_bound=within)
        near = np.flatnonzero(np.isfinite(dist))
        track = mirror_track[cand[f, a], k]                                  # each measurement's mirror track
        near = near[np.isin(b[hit[near]].astype(np.int64) * n_tracks + track[near], claimed)]
        for frame, label in zip(f[near], a[near]):      # a few per take: is the point off the face as well?
            rest = np.flatnonzero(measured[frame] & (np.arange(measured.shape[1]) != label))
            drop[frame, label] = off_the_face(result.points[frame, rest], result.points[frame, label], OFF_FACE_MM)
        # and the label's other frames on that mirror track: the same wrong pairing
        pairing = a.astype(np.int64) * n_tracks + track
        wrong = np.isin(pairing, pairing[drop[f, a]])
        drop[f[wrong], a[wrong]] = True
    drop |= off_face_on_shared_tracks(result, mirror_track, OFF_FACE_MM)     # the image's own dot took it too
    result.stats["released_blobs"] = np.array([int(drop.sum())])
    return drop_measurements(result, drop)
