"""The neutral structure (Lin 2003, the motion tracking procedure, step 2): markers are direct-view 2D tracks paired
with mirror tracks over the first frames (:mod:`.pairing`); a mirror image that two like dots on its line contest
goes to the one the other mirror confirms, else to the one whose pairing with it holds over the whole clip
(:func:`_settle_contests`); an image whose pairing holds over the clip less than a like dot's paired nowhere in that
mirror goes to neither (:func:`_doubt_near_rivals`); two dots paired crosswise in one mirror each, against the
face's convexity, are settled by the 3D or swapped (:func:`_settle_crossed_pairs`); a direct track left unpaired is
paired in a wider band when both mirrors put it at the same 3D point (:func:`_confirm_by_both_mirrors`); the tracks
paired in no mirror are reported (:func:`undecided_tracks`)."""

from __future__ import annotations

import functools
import warnings

import numpy as np

from ..common.errors import DegenerateError
from ..geometry.mirror import points_from_planes
from ..geometry.rigid import robust_rigid_fit
from ..capture.views import ClipDetections
from .candidates import spans
from .pairing import SPLIT_SPACING_SHARE, blob_tracks, clip_band_support, paired_tracks, partner_blobs
from .seeds import seeded_tracks

#: a contested image the other mirror cannot settle goes to the dot whose pairing with it holds in the band over
#: the whole clip in this many times as many frames as its rival's (:func:`_settle_by_clip_support`)
CLIP_SUPPORT_RATIO = 1.5
#: ... and holds in the band in at least this share of the frames both are seen (a dot and its own image do,
#: unless the video is too noisy for the band to tell)
CLIP_SUPPORT_SHARE = 0.9


def undecided_tracks(det: ClipDetections, dids, n_dt, partner, ambiguous, min_frames: int) -> dict:
    """Direct-view tracks of the first frames, seen in at least ``min_frames`` of them,
    that no mirror track was paired with: markers whose 3D position cannot be decided
    (procedure step 2). Per track: where it was first seen (frame, x, y px), its colour
    class, the frames it was seen in, and why -- ``ambiguous`` (rival partners in a
    mirror: the mirrors listed) or ``no mirror partner``."""
    seen = np.zeros(n_dt, int)
    first = np.full(n_dt, -1)
    xy = np.zeros((n_dt, 2))
    colour = np.zeros(n_dt, int)
    for f in range(det.n_frames - 1, -1, -1):  # backwards: the earliest sighting is written last
        ids = np.asarray(dids[f], int)
        if ids.size == 0:
            continue
        seen[ids] += 1
        first[ids] = f
        xy[ids] = det.xy[0][det.frame_view(f, 0)]
        colour[ids] = det.colour[0][det.frame_view(f, 0)]
    tracks = np.flatnonzero((seen >= min_frames) & np.all(partner < 0, axis=0))
    return {"track": tracks, "frame": first[tracks], "xy": xy[tracks], "colour": colour[tracks],
            "frames_seen": seen[tracks], "ambiguous_in": ambiguous[:, tracks].T}


def track_positions(det: ClipDetections, normals, ds, dids, n_dt, partner, mids_all, tracks):
    """3D position of chosen direct tracks in every frame where the track and one of
    its partner mirror tracks both have a blob (fused over mirrors): ``pos (F, M, 3)``
    (NaN elsewhere, each frame's own camera coordinates), the direct blob per frame
    ``(F, M)`` (-1: absent) and each track's colour ``(M,)``. Vectorised over the whole
    window (:func:`.pairing.partner_blobs`)."""
    F, M, K = det.n_frames, len(tracks), len(normals)
    col_of = np.full(n_dt, -1)
    col_of[tracks] = np.arange(M)
    pos = np.full((F, M, 3), np.nan)
    blob = np.full((F, M), -1)
    colour = np.full(M, -1)
    track, mirror_blob = partner_blobs(det, dids, partner, mids_all)
    sel = np.flatnonzero(col_of[track] >= 0)  # the chosen tracks' blobs, in frame order
    f, marker = det.frame[0][sel], col_of[track[sel]]
    blob[f, marker] = sel - det.start[0][f]  # the blob's index in its frame
    _, first = np.unique(marker, return_index=True)
    colour[marker[first]] = det.colour[0][sel[first]]
    vis = mirror_blob[:, sel] >= 0
    ok = vis.any(axis=0)
    pm = np.stack([det.norm[k + 1][np.maximum(mirror_blob[k, sel[ok]], 0)] if len(det.norm[k + 1])
                   else np.zeros((int(ok.sum()), 2)) for k in range(K)])
    if ok.any():
        pos[f[ok], marker[ok]] = points_from_planes(det.norm[0][sel[ok]], pm, normals, ds, visible=vis[:, ok])
    return pos, blob, colour


def _mirrors_spread(det: ClipDetections, normals, ds, dids, n_dt, mids_all, tracks, mates) -> np.ndarray:
    """Per direct track of ``tracks``, the median distance over the window between its reconstructions through
    each of the two mirrors, paired with its ``mates`` ``(2, n_dt)`` there (NaN: never through both)."""
    one = []
    for k in range(2):
        p_k = np.full_like(mates, -1)
        p_k[k, tracks] = mates[k, tracks]
        one.append(track_positions(det, normals, ds, dids, n_dt, p_k, mids_all, tracks)[0])
    with warnings.catch_warnings():   # a track never reconstructed through both mirrors: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(np.linalg.norm(one[0] - one[1], axis=2), axis=0)


def _agreement_limit(spread, partner, factor: float, floor_mm: float):
    """How far apart a direct track's two single-mirror reconstructions may lie and still agree: ``factor`` times
    the median :func:`_mirrors_spread` (``spread``) of the markers ``partner`` pairs in both mirrors, at least
    ``floor_mm``; None with fewer than 3 such markers."""
    both = np.flatnonzero(np.all(partner >= 0, axis=0))
    return max(factor * float(np.nanmedian(spread(both, partner))), floor_mm) if both.size >= 3 else None


def _settle_contests(det: ClipDetections, init: ClipDetections, camera, normals, ds, dids, n_dt, partner, detail,
                     mids_all, band_px: float, factor: float = 3.0, floor_mm: float = 0.5):
    """A contested mirror image (:class:`.pairing.TrackPairs`: the only partner of two like dots on its line,
    the band unable to tell which it shows over the first frames ``init``) goes to the one dot that the other
    mirror sees at the same 3D point through one of its partners there (:func:`_settle_by_other_mirror`); where
    no contender, or more than one, is confirmed so, to the dot whose pairing with it holds over the whole clip
    ``det`` (:func:`_settle_by_clip_support`)."""
    if not any(len(c) for c in detail["contested"]):
        return partner
    spread = functools.partial(_mirrors_spread, init, normals, ds, dids, n_dt, mids_all)
    limit = _agreement_limit(spread, partner, factor, floor_mm) if len(normals) == 2 else None
    direct_clip_track = None
    partner = partner.copy()
    for k in range(len(normals)):
        contested = detail["contested"][k]
        if limit is not None and len(contested):
            contested = _settle_by_other_mirror(contested, detail["qualifying"][1 - k], k, n_dt, partner, spread,
                                                limit)
        if len(contested):
            if direct_clip_track is None:
                direct_clip_track = _clip_track_of(det, 0, dids)
            support, shared = clip_band_support(det, camera, normals[k], k, direct_clip_track[contested[:, 0]],
                                                _clip_track_of(det, k + 1, mids_all[k])[contested[:, 1]], band_px)
            _settle_by_clip_support(contested, support, shared, k, partner)
    return partner


def _settle_by_other_mirror(contested, other, k: int, n_dt: int, partner, spread, limit: float):
    """The contested images of mirror ``k`` (``contested`` ``(R, 2)``: direct track, mirror track) that exactly one
    contender's reconstruction through one of its partners in the other mirror (``other``, that mirror's
    qualifying pairs) agrees with (``spread`` within ``limit``, :func:`_agreement_limit`): that contender takes
    the image and that partner, in ``partner`` (changed in place); the rest of ``contested`` is returned."""
    # each contender (a dot contests one image per mirror) with each of its partners in the other mirror
    other = other[np.argsort(other[:, 0], kind="stable")]
    lo = np.searchsorted(other[:, 0], contested[:, 0])
    count = np.searchsorted(other[:, 0], contested[:, 0], "right") - lo
    row, seen = np.repeat(np.arange(len(contested)), count), other[spans(lo, count), 1]
    option = np.arange(row.size) - np.repeat(np.cumsum(count) - count, count)
    agree = np.zeros(row.size, bool)
    for r in range(int(option.max(initial=-1)) + 1):          # each dot once per call: its r-th partner
        at = np.flatnonzero(option == r)
        dots = contested[row[at], 0]
        mates = np.full((2, n_dt), -1)
        mates[k, dots], mates[1 - k, dots] = contested[row[at], 1], seen[at]
        agree[at] = spread(dots, mates) <= limit
    image = contested[row[agree], 1]
    images, confirmations = np.unique(image, return_counts=True)
    settled = images[confirmations == 1]
    for img in settled:
        i = np.flatnonzero(image == img)[0]
        dot, mate = contested[row[agree][i], 0], seen[agree][i]
        partner[k][partner[k] == img] = -1
        partner[1 - k][partner[1 - k] == mate] = -1
        partner[k, dot], partner[1 - k, dot] = img, mate
    return contested[~np.isin(contested[:, 1], settled)]


def _clip_track_of(det: ClipDetections, view: int, ids_per_frame) -> np.ndarray:
    """Per 2D track of the first frames (``ids_per_frame``, :func:`.pairing.track_2d` over them), the whole clip's
    2D track (:func:`.pairing.blob_tracks`) of its first blob ``(n,)``."""
    first = np.concatenate([np.asarray(i, int) for i in ids_per_frame]) if len(ids_per_frame) else np.zeros(0, int)
    out = np.full(int(first.max(initial=-1)) + 1, -1)
    tracks, at = np.unique(first, return_index=True)        # blobs in frame order: each track's first blob
    out[tracks] = blob_tracks(det)[view][at]
    return out


def _settle_by_clip_support(contested, support, shared, mirror: int, partner) -> None:
    """The contested images of ``mirror`` (``contested`` ``(R, 2)``: direct track, mirror track of the first
    frames) that the other mirror did not settle: each goes to the contender whose whole-clip 2D track keeps its
    own in the band (``support``, of ``shared`` frames both are seen: :func:`.pairing.clip_band_support`) in at
    least :data:`CLIP_SUPPORT_SHARE` of those frames, and in at least :data:`CLIP_SUPPORT_RATIO` times as many
    frames as any rival's; the rivals lose it (``partner`` changed in place). The first frames may hold both dots
    in the band (touch576: a dot seen only directly and a like dot at its height, 0.19 and 0.29 px, the wrong one
    nearer); over the clip the chance alignment slides out (20 frames of 46 against 45 of 46). Where no contender
    stands out so, the assignment stands: in a noisy video a dot's own image leaves the band too (hd at CRF 26: 16
    of 34 frames, where a like dot at its height sat in it in 28)."""
    order = np.lexsort((-support, contested[:, 1]))
    image, support, shared, dot = contested[order, 1], support[order], shared[order], contested[order, 0]
    first = np.flatnonzero(np.r_[True, image[1:] != image[:-1]])      # each image's best supported contender
    contenders = np.diff(np.r_[first, image.size])
    runner_up = support[np.minimum(first + 1, image.size - 1)]
    clear = ((contenders > 1) & _holds_over_clip(support[first], shared[first])
             & (support[first] >= CLIP_SUPPORT_RATIO * runner_up))
    for i in first[clear]:
        partner[mirror][partner[mirror] == image[i]] = -1
        partner[mirror, dot[i]] = image[i]


def _holds_over_clip(support, shared) -> np.ndarray:
    """Does a pairing hold in the band over the clip: in at least :data:`CLIP_SUPPORT_SHARE` of the ``shared``
    frames both its tracks are seen (``support``: the frames in the band, :func:`.pairing.clip_band_support`)?"""
    return (support > 0) & (support >= CLIP_SUPPORT_SHARE * shared)


def _doubt_near_rivals(det: ClipDetections, camera, normals, dids, partner, wide_qualifying, mids_all,
                       band_px: float):
    """A mirror image paired over the first frames with one dot (``partner``) that another dot of its colour, paired
    in that mirror with nothing, also keeps in a wider band there (``wide_qualifying``: per mirror, the pairs of
    :func:`.pairing.paired_tracks` in the wide band) is taken from its dot when, over the whole clip
    (:func:`.pairing.clip_band_support`), the rival's pairing holds in the band in :data:`CLIP_SUPPORT_SHARE` of the
    frames both are seen and its own does not: the image then goes to neither. A dot hidden from a mirror pairs
    with a like dot's grazing image on its line, whose centroid, biased by the face's edge, sits nearer the wrong
    dot's line than its own over the first frames (hr2: 0.2 px against 0.9, so its own dot's pairing failed the RMS
    test); over the clip its own dot's line keeps it (85 of 90 frames) and the wrong one's slides off (75 of 90).
    Neither is given the image: which dot it shows stays unsure (on dense rigs two dots' lines both keep one image
    over the whole clip, the first frames' choice right), and the image's dot comes back later where the late
    markers' tests allow."""
    partner = partner.copy()
    direct_clip_track = None
    for k in range(len(normals)):
        q = np.asarray(wide_qualifying[k], int).reshape(-1, 2)
        paired = np.flatnonzero(partner[k] >= 0)
        if q.size == 0 or paired.size == 0:
            continue
        owner = np.full(int(max(q[:, 1].max(), partner[k].max())) + 1, -1)
        owner[partner[k, paired]] = paired
        rival = q[(owner[q[:, 1]] >= 0) & (owner[q[:, 1]] != q[:, 0]) & (partner[k, q[:, 0]] < 0)]
        if rival.size == 0:
            continue
        if direct_clip_track is None:
            direct_clip_track = _clip_track_of(det, 0, dids)
        pairs = np.unique(np.r_[np.c_[owner[rival[:, 1]], rival[:, 1]], rival], axis=0)   # (dot, image): owners, rivals
        support, shared = clip_band_support(det, camera, normals[k], k, direct_clip_track[pairs[:, 0]],
                                            _clip_track_of(det, k + 1, mids_all[k])[pairs[:, 1]], band_px)
        holds = _holds_over_clip(support, shared)
        is_owner = owner[pairs[:, 1]] == pairs[:, 0]
        rival_holds = np.zeros(owner.size, bool)
        rival_holds[pairs[holds & ~is_owner, 1]] = True
        doubted = pairs[is_owner & ~holds & rival_holds[pairs[:, 1]], 1]
        partner[k, owner[doubted]] = -1
    return partner


def _settle_crossed_pairs(init: ClipDetections, normals, ds, dids, n_dt, partner, wide_qualifying, mids_all,
                          factor: float = 3.0, floor_mm: float = 0.5):
    """Two dots each paired in one mirror only, crosswise (``a`` with image ``i`` in mirror 0, ``b`` with ``j`` in
    mirror 1), where the swap qualifies as well (``b`` keeps ``i`` and ``a`` keeps ``j`` in the wide band,
    ``wide_qualifying``): both lie on one line of each mirror, and the band cannot tell the two pairings apart. The
    face's convexity can: of two dots at one height, the one nearer a mirror's side of the direct view is the one
    that mirror still sees as the face turns from it. A crossing where ``a`` lies farther from mirror 0's side (the
    x of the plane's point nearest the camera, ``ds * normals``: planes ``normal . x = d``) than ``b``, by more than
    half the direct view's typical blob spacing, is wrong, and is settled so: when exactly one of the two dots is
    seen through ``i`` and ``j`` at one 3D point (:func:`_mirrors_spread` within :func:`_agreement_limit`), they are
    both its images and the other dot keeps none; when neither is, the pairs are swapped; when both are, or too few
    markers are paired in both mirrors to tell, neither dot keeps an image (a dot crossed with two is left as it
    is). Measured on the 48 committed clips' first frames (both pairings right in 25 crossings, all the convex way;
    the 3 the other way all wrong): hv2's two brow dots at one height, each hidden from the mirror across, had each
    the other's image (8-9 mm off; swapped, both right); umber600 at CRF 23, with fewer than 3 markers paired in
    both mirrors, gave a dot's mirror-0 image to a dot at its height and kept its mirror-1 one (neither keeps one
    now)."""
    side = np.sign(np.asarray(ds, float) * np.asarray(normals, float)[:, 0])   # x of the planes' nearest points
    ids = np.concatenate([np.asarray(d, int) for d in dids]) if len(dids) else np.zeros(0, int)
    single = [(partner[k] >= 0) & (partner[1 - k] < 0) for k in range(2)]
    a, b = np.flatnonzero(single[0]), np.flatnonzero(single[1])      # paired in mirror 0 only, in mirror 1 only
    if a.size == 0 or b.size == 0 or side[0] != -side[1]:            # no mirror on each side: no convexity
        return partner
    x = init.xy[0][int(init.start[0][0]):int(init.start[0][0]) + ids.size, 0]
    mean_x = np.bincount(ids, x, n_dt) / np.maximum(np.bincount(ids, minlength=n_dt), 1)
    a, b = np.repeat(a, b.size), np.tile(b, a.size)
    crossed = side[0] * (mean_x[a] - mean_x[b]) < -SPLIT_SPACING_SHARE * init.typical_spacing(0)
    for k, (dot, image) in enumerate(((b, partner[0, a]), (a, partner[1, b]))):   # the swap, per mirror
        q = np.asarray(wide_qualifying[k], int).reshape(-1, 2)
        base = int(max(q[:, 1].max(initial=0), image.max())) + 1
        crossed &= np.isin(dot * base + image, q[:, 0] * base + q[:, 1])
    a, b = a[crossed], b[crossed]
    once = (np.bincount(a, minlength=n_dt)[a] == 1) & (np.bincount(b, minlength=n_dt)[b] == 1)
    a, b = a[once], b[once]
    if a.size == 0:
        return partner
    i, j = partner[0, a], partner[1, b]
    spread = functools.partial(_mirrors_spread, init, normals, ds, dids, n_dt, mids_all)
    limit = _agreement_limit(spread, partner, factor, floor_mm)
    both = np.full((2, n_dt), -1)
    both[0, a], both[1, a], both[0, b], both[1, b] = i, j, i, j
    seen_as_one = spread(np.r_[a, b], both) <= limit if limit is not None else np.ones(2 * a.size, bool)
    a_one, b_one = seen_as_one[:a.size], seen_as_one[a.size:]
    partner = partner.copy()
    partner[:, a], partner[:, b] = -1, -1
    swap = ~a_one & ~b_one
    partner[0, b[swap]], partner[1, a[swap]] = i[swap], j[swap]
    for dot, keeps in ((a, a_one & ~b_one), (b, b_one & ~a_one)):       # both images to the one dot they show
        partner[0, dot[keeps]], partner[1, dot[keeps]] = i[keeps], j[keeps]
    return partner


def _confirm_by_both_mirrors(det: ClipDetections, normals, ds, dids, n_dt, partner, wide, mids_all,
                             factor: float = 3.0, floor_mm: float = 0.5):
    """Direct tracks with no partner in any mirror (a marker on the face's midline is seen at a
    grazing angle in both mirrors, its images noisier than most: it leaves the 1 px band too
    often), paired in *each* mirror when the band is wider and the RMS test is off (``wide``,
    :func:`.pairing.paired_tracks`): both partners are taken when the two mirrors put the marker
    at the same 3D point -- their median distance over the window within ``factor`` times the
    median of the markers both mirrors pair cleanly (at least ``floor_mm``), and neither mirror
    track is another marker's partner. Chance alignments in two mirrors at once do not agree in
    3D."""
    free = np.stack([(wide[k] >= 0) & ~np.isin(wide[k], partner[k][partner[k] >= 0]) for k in range(2)])
    noisy = np.where(free, wide, -1)
    cand = np.flatnonzero(np.all(partner < 0, axis=0) & np.all(noisy >= 0, axis=0))
    if cand.size == 0:
        return partner
    spread = functools.partial(_mirrors_spread, det, normals, ds, dids, n_dt, mids_all)
    limit = _agreement_limit(spread, partner, factor, floor_mm)
    if limit is None:
        return partner
    agree = spread(cand, noisy) <= limit
    partner = partner.copy()
    partner[:, cand[agree]] = noisy[:, cand[agree]]
    return partner


def initial_markers(det: ClipDetections, camera, normals, ds, settings, seeds=None):
    """Step 2: markers are direct-view tracks paired with a mirror track over the first
    ``init_frames`` frames. Each marker's neutral position is its 3D position at the
    first frame where it is paired, mapped into frame 0 by a robust rigid fit of the
    markers both frames share (so markers hidden at frame 0 are tracked too).
    Returns each marker's frame-0 direct blob (-1 if absent), the neutral structure
    (N, 3), the markers' colour classes (N,) and the frame each is measured from (N,),
    here 0; and the undecided direct-view tracks (:func:`undecided_tracks`)."""
    W = min(settings.init_frames, det.n_frames)
    init = det.head(W)
    detail = {}
    dids, n_dt, partner, mids_all, ambiguous, _ = paired_tracks(init, camera, normals, settings.band_px,
                                                               min(5, W), detail=detail)
    partner = _settle_contests(det, init, camera, normals, ds, dids, n_dt, partner, detail, mids_all,
                               settings.band_px)
    if settings.wide_band_factor > 1.0 and len(normals) == 2:
        wide_detail = {}
        wide = paired_tracks(init, camera, normals, settings.wide_band_factor * settings.band_px, min(5, W),
                             max_rms_factor=np.inf, tracks=(dids, n_dt, mids_all), detail=wide_detail)[2]
        partner = _doubt_near_rivals(det, camera, normals, dids, partner, wide_detail["qualifying"], mids_all,
                                     settings.band_px)
        partner = _settle_crossed_pairs(init, normals, ds, dids, n_dt, partner, wide_detail["qualifying"], mids_all)
        partner = _confirm_by_both_mirrors(init, normals, ds, dids, n_dt, partner, wide, mids_all)
    named = {}
    if seeds is not None:                  # the user's designations win over the automatic pairing
        seed_direct, seed_mirror = seeded_tracks(seeds, init, dids, mids_all)
        for k in range(len(normals)):
            for i in np.flatnonzero(seed_mirror[k] >= 0):
                partner[k, partner[k] == seed_mirror[k, i]] = -1
                partner[k, seed_direct[i]] = seed_mirror[k, i]
        named = {int(t): name for t, name in zip(seed_direct, seeds.names)}
    undecided = undecided_tracks(init, dids, n_dt, partner, ambiguous, min(5, W))
    undecided["blobs"] = [np.asarray(d, int) for d in dids]  # track id of each direct blob, per frame
    tracks = np.flatnonzero(np.any(partner >= 0, axis=0))
    if tracks.size < 10:
        raise DegenerateError(f"only {tracks.size} markers could be paired between the direct view and a mirror "
                              "in the first frames; are both mirrors visible and calibrated?")
    pos, blob, colour = track_positions(init, normals, ds, dids, n_dt, partner, mids_all, tracks)
    neutral = pos[0].copy()
    known = np.all(np.isfinite(neutral), axis=1)
    for f in range(1, W):
        new = ~known & np.all(np.isfinite(pos[f]), axis=1)
        common = known & np.all(np.isfinite(pos[f]), axis=1)
        if new.any() and common.sum() >= 6:
            R, T, _ = robust_rigid_fit(pos[f, common], neutral[common])  # frame f -> frame 0
            neutral[new] = pos[f, new] @ R.T + T
            known |= new
    keep = np.flatnonzero(known)
    missing = [name for t, name in named.items() if not known[np.searchsorted(tracks, t)]]
    if missing:
        raise DegenerateError(f"seed {missing[0]!r}: no 3D position in the first {W} frames (its direct and mirror "
                              "points do not meet on one ray: are they the same dot?)")
    names = [named.get(int(tracks[i])) for i in keep]
    return (blob[0, keep], neutral[keep], colour[keep], np.zeros(keep.size, int)), undecided, names
