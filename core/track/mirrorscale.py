"""The two mirrors' scales, and whether a take's mirrors agree (issue #18, part 1).

Self-calibration (:mod:`.selfcal`) finds each mirror's normal and leaves its distance ``d``
in units of its own. A marker seen in the direct view and in *both* mirrors fixes the
ratio of the two distances: its depth along the direct ray (eq. 3.10-3.11) is the same
through either mirror, and each depth is proportional to its mirror's ``d``. Pairing single
frames one-to-one inside the band is only 75-94 % correct on dense layouts
(``shared/notes/mirror-self-calibration.md``), which moved the ratio by 2 % on a 290-marker
rig; pairs between *2D tracks* (:func:`.pairing.paired_tracks`) are >= 99.5 % precise.

:func:`both_mirror_samples` collects such markers from a few windows of frames spread over
the clip; :func:`link_mirror_scales` takes the ratio as their median (robust to the rare
wrong pair). A rig whose mirrors see only the sides of the face has no marker in both mirrors
(mirrors at 35 deg on a 960x540 clip: none in 90 frames); :func:`link_mirror_scales_by_motion`
then relates the scales through the head's motion, which moves both halves of the face rigidly
together; it also stands in for a shared markers' link whose ratios spread over
:data:`LINK_MAX_SPREAD` (a few markers in both mirrors, some wrongly paired: the pipeline's choice,
:func:`scale_link_warning` when nothing better is left). :func:`mirror_agreement` tests a take's planes --
self-calibrated or from MIRRORS.json -- on the same markers: through the two mirrors a marker must land at
the same depth within its expected error (the detection noise, from the pairs' band residuals,
propagated through eq. 3.10-3.11 for each mirror).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..capture.detect import VIDEO_QUALITY_HINT
from ..capture.views import ClipDetections
from ..common.errors import DegenerateError
from ..geometry.camera import Camera
from ..geometry.mirror import depths_from_planes
from ..geometry.rigid import rigid_fit
from .coverage import dot_sizes
from .pairing import paired_tracks, partner_blobs

WINDOW_FRAMES = 15       # frames per window of 2D tracks (as the tracker's initial pairing)
WINDOWS = 4              # windows spread over the clip
AGREEMENT_LIMIT = 2.0    # a take's mirrors disagree when the typical marker is off by more than 2 expected sd
SCATTER_LIMIT = 10.0     # ... or when the markers scatter between the mirrors by more than 10 expected sd: the
                         # 40 clips of stop 41 scatter 0.6-4.2, the 1080p normal-light clip re-encoded at H.264
                         # CRF 23-26 46-66 (its three markers in both mirrors mostly wrong pairs, 3 mm RMS)
LINK_MAX_SPREAD = 0.005  # the shared markers' link is doubted when their ratios spread by more than 0.5 %: 0.01-0.27 %
                         # on the 40 clips, 0.9-2.4 % on that clip re-encoded (its ratio 1.4-2.1 % off)
MIN_BOTH_MIRROR_SIGHTINGS = 10  # fewer sightings of markers in both mirrors: the scales are linked by head motion
MIN_BOTH_MIRROR_MARKERS = 3     # ... and fewer markers: one wrongly paired marker would set the ratio (mirror35,
                                # one marker's 15 sightings: 1.22 where the truth is 1.00), so head motion links them
MOTION_FRAMES = 300      # head-motion link: the first frames of the clip it reads
MOTION_MIN_PAIRS = 5     # ... and the frame pairs it needs, each with markers held in both (26 frames or more)
MOTION_MAX_ERROR = 0.005  # ... refused when its standard error exceeds 0.5 % (too little head motion)
MOTION_MIN_SHARE = 0.005  # ... or when the head's translation between frames is under 0.5 % of its distance
                          # (the clips move 2-17 %; a still head moves 0)
MOTION_MAX_SPREAD = 0.01  # ... or when the frame pairs' ratios spread by more than 1 % (0.1-0.4 % on the clips
                          # that link; 2.2 % on one with 20 markers per mirror, whose ratio came out 1.6 % off)
RIGID_SHARE = 0.5         # the link rests on each mirror's half of its markers that move most rigidly with the
                          # head: with the true normals, over the 59 rendered clips it links (stop 57), 0.11 % off
                          # the truth on average and 0.50 % at most with all markers, 0.04 % and 0.14 % with this
                          # half (0.04 / 0.05 / 0.06 % with 1/3, 2/3, 4/5; weighting by residual 0.08-0.14 %)
#: the motion link's opening words when it cannot link (it stands in for markers seen in both mirrors)
_NOT_SHARED = f"too few markers are seen in both mirrors (under {MIN_BOTH_MIRROR_SIGHTINGS} sightings)"


@dataclass
class BothMirrorSamples:
    """Markers seen in the direct view and both mirrors, one row per (marker, frame):
    normalised direct ``p`` ``(S, 2)`` and mirrored ``pm`` ``(2, S, 2)`` points, the
    ``marker`` ``(S,)`` (a direct 2D track, unique over the windows) and the detection
    noise ``noise_px`` (median band residual of the pairs, pixels)."""

    p: np.ndarray
    pm: np.ndarray
    marker: np.ndarray
    noise_px: float

    @property
    def n_markers(self) -> int:
        return int(np.unique(self.marker).size)

    @property
    def enough_to_link(self) -> bool:
        """Enough markers and sightings for :func:`link_mirror_scales` to be robust to a wrong pair."""
        return len(self.p) >= MIN_BOTH_MIRROR_SIGHTINGS and self.n_markers >= MIN_BOTH_MIRROR_MARKERS


def both_mirror_samples(det: ClipDetections, camera: Camera, normals, band_px: float = 1.0,
                        window: int = WINDOW_FRAMES, windows: int = WINDOWS) -> BothMirrorSamples:
    """Markers seen directly and in both mirrors in ``windows`` windows of ``window`` frames
    spread evenly over ``det``, paired through 2D tracks (:func:`.pairing.paired_tracks`;
    a direct track counts when it has an unambiguous partner track in each mirror)."""
    normals = np.asarray(normals, float)
    if len(normals) != 2:
        raise ValueError("two mirrors are needed to relate their scales")
    F = det.n_frames
    W = min(window, F)
    starts = np.unique(np.linspace(0, F - W, max(1, min(windows, F // max(W, 1)))).round().astype(int))
    p_all, pm_all, marker_all, rms_all = [], [[], []], [], []
    offset = 0
    for s in starts:
        sub = det.window(s, s + W)
        dids, n_dt, partner, mids, ambiguous, rms = paired_tracks(sub, camera, normals, band_px, min(5, W))
        both = np.all(partner >= 0, axis=0) & ~np.any(ambiguous, axis=0)
        rms_all.append(rms[:, both].ravel())
        track, blob = partner_blobs(sub, dids, partner, mids)
        sel = np.flatnonzero(both[track] & np.all(blob >= 0, axis=0))
        p_all.append(sub.norm[0][sel])
        for k in range(2):
            pm_all[k].append(sub.norm[k + 1][blob[k, sel]])
        marker_all.append(track[sel] + offset)
        offset += n_dt
    if not sum(len(p) for p in p_all):
        return BothMirrorSamples(np.zeros((0, 2)), np.zeros((2, 0, 2)), np.zeros(0, int), float("nan"))
    rms = np.concatenate(rms_all)
    rms = rms[np.isfinite(rms)]
    return BothMirrorSamples(np.concatenate(p_all), np.stack([np.concatenate(x) for x in pm_all]),
                             np.concatenate(marker_all), float(np.median(rms)) if rms.size else float("nan"))


def _along_ray(p, pm, normal, d) -> np.ndarray:
    """Distance from the camera along the direct ray through one mirror (eq. 3.10-3.11)."""
    z, _ = depths_from_planes(p, pm[None], np.asarray(normal, float)[None], np.array([float(d)]))
    return z * np.sqrt(1.0 + np.einsum("ij,ij->i", p, p))


def link_mirror_scales(samples: BothMirrorSamples, normals, ds) -> tuple[np.ndarray, dict]:
    """``ds`` with mirror 1's distance put in mirror 0's units: scaled by the median over
    ``samples`` of the ratio of a marker's depth through mirror 0 to its depth through
    mirror 1. Returns the new ``ds`` and the figures (ratio, its robust relative spread
    1.4826 MAD, standard error, samples, markers)."""
    if len(samples.p) < MIN_BOTH_MIRROR_SIGHTINGS:
        raise DegenerateError(f"only {len(samples.p)} sightings of markers in both mirrors: the two mirrors' scales "
                              "cannot be related (give MIRRORS.json from `mirrorcap mirrors`)")
    z0 = _along_ray(samples.p, samples.pm[0], normals[0], ds[0])
    z1 = _along_ray(samples.p, samples.pm[1], normals[1], ds[1])
    good = np.isfinite(z0) & np.isfinite(z1) & (np.abs(z1) > 0)
    ratio = z0[good] / z1[good]
    r = float(np.median(ratio))
    spread = float(1.4826 * np.median(np.abs(ratio - r)) / abs(r))
    out = np.array(ds, float)
    out[1] *= r
    figures = {"source": "markers tracked in both mirrors", "ratio": r, "relative_spread": spread,
               "standard_error": float(1.2533 * spread / np.sqrt(max(good.sum(), 1))),
               "samples": int(good.sum()), "markers": int(np.unique(samples.marker[good]).size)}
    return out, figures


def mirror_agreement(samples: BothMirrorSamples, normals, ds, focal_px: float) -> dict:
    """Do the planes ``(normals, ds)`` put each marker seen in both mirrors at one depth?
    Per sighting: the difference of its distances along the direct ray through mirror 0
    and mirror 1 (take units), and its expected sd -- the detection noise ``noise_px``
    moved along each mirror's epipolar line (the direction that changes the depth,
    eq. 5.2) through eq. 3.10-3.11. ``consistent`` is False when the median difference
    exceeds ``AGREEMENT_LIMIT`` times the median expected sd, or the differences' sd (1.4826 MAD)
    ``SCATTER_LIMIT`` times it (``scattered``: a self-calibrated take's median difference is zero by
    its scale link, so wrong pairs show as scatter); None (no verdict) with fewer than
    ``MIN_BOTH_MIRROR_MARKERS`` markers or ``MIN_BOTH_MIRROR_SIGHTINGS`` sightings."""
    n = len(samples.p)
    if not samples.enough_to_link or not np.isfinite(samples.noise_px):  # one marker may be a wrong pair
        return {"samples": int(n), "markers": samples.n_markers, "consistent": None,
                "reason": "too few markers seen in both mirrors to compare them"}
    p, pm = samples.p, samples.pm
    along = []
    slope = []
    for k in range(2):
        u = np.asarray(normals[k], float)
        z = _along_ray(p, pm[k], u, ds[k])
        # the mirrored point's epipolar line u x p (eq. 5.2) runs along (-l1, l0)
        l0 = u[1] - u[2] * p[:, 1]
        l1 = u[2] * p[:, 0] - u[0]
        step = np.c_[-l1, l0] / np.hypot(l0, l1)[:, None] / focal_px  # one pixel along the line
        z_step = _along_ray(p, pm[k] + step, u, ds[k])
        along.append(z)
        slope.append(np.abs(z_step - z))  # take units per pixel
    diff = along[0] - along[1]
    expected = samples.noise_px * np.hypot(slope[0], slope[1])
    good = np.isfinite(diff) & np.isfinite(expected)
    diff, expected = diff[good], expected[good]
    median = float(np.median(diff))
    expected_median = float(np.median(expected))
    observed_sd = float(1.4826 * np.median(np.abs(diff - median)))
    scattered = bool(observed_sd > SCATTER_LIMIT * expected_median)
    return {"samples": int(good.sum()), "markers": int(np.unique(samples.marker[good]).size),
            "median_difference": median, "median_abs_difference": float(np.median(np.abs(diff))),
            "p95_abs_difference": float(np.percentile(np.abs(diff), 95)),
            "expected_sd": expected_median, "observed_sd": observed_sd,
            "noise_px": samples.noise_px,
            "relative_difference": float(np.median(diff / ((along[0] + along[1])[good] / 2))),
            "scattered": scattered,
            "consistent": bool(abs(median) <= AGREEMENT_LIMIT * expected_median) and not scattered}


def link_self_calibrated_scales(both: BothMirrorSamples, det: ClipDetections, camera: Camera, normals,
                                ds) -> tuple[np.ndarray, dict]:
    """``ds`` (each mirror's self-calibrated distance, in its own units) with mirror 1's put in mirror 0's units,
    and the link's figures: through the markers seen in both mirrors (:func:`link_mirror_scales`) when they are
    enough and agree (ratios spread up to :data:`LINK_MAX_SPREAD`); else through the head's motion
    (:func:`link_mirror_scales_by_motion`; the doubted shared link kept as ``shared_markers_link``); with a head
    too still for that, through the few markers in both mirrors all the same (:func:`scale_link_warning` says
    so), and with under ``MIN_BOTH_MIRROR_SIGHTINGS`` of them not at all (the motion link's refusal)."""
    shared = link_mirror_scales(both, normals, ds) if len(both.p) >= MIN_BOTH_MIRROR_SIGHTINGS else None
    if shared is not None and both.enough_to_link and shared[1]["relative_spread"] <= LINK_MAX_SPREAD:
        return shared
    try:  # the mirrors see only the sides of the face, or the few markers in both disagree
        out, figures = link_mirror_scales_by_motion(det, camera, normals, ds)
    except DegenerateError:  # a still head: the few markers in both mirrors are all there is
        if shared is None:
            raise
        return shared
    if shared is not None and both.enough_to_link:
        figures["shared_markers_link"] = shared[1]    # the link it stood in for
    return out, figures


def scale_link_warning(link: dict | None) -> str | None:
    """A warning when the two mirrors' scales rest on the markers seen in both mirrors (``link`` from
    :func:`link_mirror_scales`) and those are too few (under ``MIN_BOTH_MIRROR_MARKERS``: one wrong pair
    sets the ratio) or disagree (their ratios spread over :data:`LINK_MAX_SPREAD`) -- what is left when
    the head's motion could not link them either; None otherwise."""
    if not link or link.get("source") != "markers tracked in both mirrors":
        return None
    few = link["markers"] < MIN_BOTH_MIRROR_MARKERS
    if not few and link["relative_spread"] <= LINK_MAX_SPREAD:
        return None
    why = (f"only {link['markers']} marker(s) seen in both mirrors" if few else
           f"the {link['markers']} markers seen in both mirrors, which disagree by "
           f"{100 * link['relative_spread']:.1f} % "
           f"(up to {100 * LINK_MAX_SPREAD:.1f} % holds)")
    return (f"the two mirrors' scales rest on {why}, and the head's motion could not relate them either: depths "
            "through one mirror may be off by a few per cent against the other's. Give MIRRORS.json from "
            f"`mirrorcap mirrors`, or a better video ({VIDEO_QUALITY_HINT})")


def _one_mirror_points(det: ClipDetections, camera: Camera, normals, ds, band_px: float = 1.0):
    """Per mirror, ``(F, T, 3)`` positions of the direct 2D tracks paired with a track of that
    mirror (:func:`.pairing.paired_tracks` over the frames of ``det``; NaN where not seen), each
    reconstructed through that mirror alone at its own ``ds`` (eq. 3.10-3.11)."""
    dids, n_dt, partner, mids, ambiguous, _ = paired_tracks(det, camera, normals, band_px, min(5, det.n_frames))
    track, blob = partner_blobs(det, dids, partner, mids)
    out = []
    for k in range(2):
        sel = (blob[k] >= 0) & ~ambiguous[k, track]
        p, pm = det.norm[0][sel], det.norm[k + 1][blob[k, sel]]
        z, _ = depths_from_planes(p, pm[None], np.asarray(normals[k], float)[None], np.array([float(ds[k])]))
        X = np.full((det.n_frames, n_dt, 3), np.nan)
        X[det.frame[0][sel], track[sel]] = np.c_[p, np.ones(len(p))] * z[:, None]
        out.append(X)
    return out


def _frame_pairs(n_frames: int) -> list:
    """The frame pairs :func:`link_mirror_scales_by_motion` fits among ``n_frames``: ``(a, b)``, anchors ``a`` every
    5 frames, ``b`` every 10 frames from ``a + 10``."""
    return [(a, b) for a in range(0, n_frames, 5) for b in range(a + 10, n_frames, 10)]


def link_mirror_scales_by_motion(det: ClipDetections, camera: Camera, normals, ds, frames: int = MOTION_FRAMES,
                                 min_markers: int = 6) -> tuple[np.ndarray, dict]:
    """``ds`` with mirror 1's distance put in mirror 0's units through the head's motion, for rigs
    where no marker is seen in both mirrors. Each mirror with the direct view reconstructs its own
    markers at a scale of its own (its ``d``), about the camera centre; the head moves them all
    with one rigid motion ``X(b) = R X(a) + t``. Between two frames ``a``, ``b`` the rotation is
    the same for both halves whatever their scales -- fitted to both, each half about its own
    centroid (:func:`_pair_motion`) -- while each half's centroid gives its own translation
    ``t_k = c_k(b) - R c_k(a) = s_k t``: the ratio of the scales is ``sum t_0 . t_1 / sum |t_0|^2`` over
    frame pairs 10 frames apart or more (anchors every 5 frames) among the first ``frames``. A marker that
    moves with the expressions moves its half's centroid too: the pairs are fitted twice, the second time with
    each mirror's :data:`RIGID_SHARE` of its markers that strayed least from the first fits (their mean
    residual over the pairs they are in; markers in fewer than 3 pairs left out). Figures: ratio,
    relative_spread (sd of the per-pair ratios), standard_error, samples (frame pairs), markers (tracked
    through either mirror), markers_per_mirror, rigid_markers_per_mirror and relative_spread_all_markers (the
    first fits' spread). Refused when the take is too short for :data:`MOTION_MIN_PAIRS` frame pairs (under 26
    frames), when the head moves too little (its median translation between the pairs under ``MOTION_MIN_SHARE``
    of its distance, or the standard error over ``MOTION_MAX_ERROR``), when the halves do not move
    together closely enough (the first fits' per-pair ratios, all markers', spread over ``MOTION_MAX_SPREAD``: few
    markers per mirror, most of them moving with the expressions), or a mirror shows too few tracked
    markers."""
    sub = det.window(0, min(frames, det.n_frames))
    F = sub.n_frames
    frame_pairs = _frame_pairs(F)
    if len(frame_pairs) < MOTION_MIN_PAIRS:
        shortest = next(n for n in itertools.count(F) if len(_frame_pairs(n)) >= MOTION_MIN_PAIRS)
        raise DegenerateError(f"{_NOT_SHARED}, and a take of {F} frames is too short to relate the two mirrors' "
                              f"scales through the head's motion (that takes frame pairs 10 frames apart or more: "
                              f"at least {shortest} frames); track a longer stretch, or give MIRRORS.json from "
                              "`mirrorcap mirrors`")
    pos = _one_mirror_points(sub, camera, normals, ds)
    seen = [np.isfinite(P[..., 0]) for P in pos]
    pairs, in_common = [], []
    for a, b in frame_pairs:
        common = [np.flatnonzero(s[a] & s[b]) for s in seen]
        in_common.append([len(c) for c in common])
        if min(len(c) for c in common) >= min_markers:
            pairs.append((a, b, common))
    markers = [int(s.any(0).sum()) for s in seen]
    if len(pairs) < MOTION_MIN_PAIRS:
        at_once = " and ".join(f"{v:.0f}" for v in np.median(np.reshape(in_common, (-1, 2)), axis=0)) \
            if in_common else "none"
        sizes = dot_sizes(det.typical_dot_px())
        raise DegenerateError(f"{_NOT_SHARED}, and too few markers are tracked in each mirror "
                              f"at once to relate the two mirrors' scales through the head's motion ({markers[0]} and "
                              f"{markers[1]} over the first {F} frames, but {at_once} held from a frame to the one 10 "
                              f"or more later, typically, where {min_markers} are needed"
                              + (f"; {sizes}" if sizes else "") + "): give MIRRORS.json from `mirrorcap mirrors`, or "
                              "make the dots easier to find in the mirrors (larger dots, a closer camera or a higher "
                              "resolution)")
    # each marker's mean residual over the frame pairs it is in: the more rigid share of each mirror's markers
    strayed = [np.zeros(len(s[0])) for s in seen]
    fitted = [np.zeros(len(s[0])) for s in seen]
    t_all = [[], []]
    for a, b, common in pairs:
        moves, residual = _pair_motion(pos, a, b, common)
        for k in range(2):
            strayed[k][common[k]] += residual[k]
            fitted[k][common[k]] += 1
            t_all[k].append(moves[k])
    depth = float(np.nanmedian(pos[0][..., 2]))
    moved = float(np.median(np.linalg.norm(np.array(t_all[0]), axis=1)) / depth)
    _, spread_all, error_all = _translation_ratio(*t_all)
    if moved >= MOTION_MIN_SHARE and np.isfinite(error_all) and spread_all > MOTION_MAX_SPREAD:
        raise DegenerateError(f"{_NOT_SHARED}, and the two halves of the face the mirrors see "
                              f"({markers[0]} and {markers[1]} markers) do not move together closely enough to relate "
                              f"the two mirrors' scales through the head's motion (the frame pairs disagree by "
                              f"{100 * spread_all:.1f} %); give MIRRORS.json from `mirrorcap mirrors`")
    rigid = []
    for k in range(2):
        mean = np.where(fitted[k] >= 3, strayed[k] / np.maximum(fitted[k], 1), np.inf)
        rigid.append(mean <= np.quantile(mean[np.isfinite(mean)], RIGID_SHARE) if np.isfinite(mean).any()
                     else np.zeros(len(mean), bool))
    t_pairs = [[], []]
    for a, b, common in pairs:
        common = [c[rigid[k][c]] for k, c in enumerate(common)]
        if min(len(c) for c in common) >= 3:
            for k, t in enumerate(_pair_motion(pos, a, b, common)[0]):
                t_pairs[k].append(t)
    if len(t_pairs[0]) < MOTION_MIN_PAIRS:
        raise DegenerateError(f"{_NOT_SHARED}, and too few of the markers tracked in each mirror "
                              f"({markers[0]} and {markers[1]}) move rigidly with the head to relate the two mirrors' "
                              "scales through its motion: give MIRRORS.json from `mirrorcap mirrors`")
    ratio, spread, error = _translation_ratio(*t_pairs)
    if not (moved >= MOTION_MIN_SHARE and np.isfinite(error) and error <= MOTION_MAX_ERROR):
        raise DegenerateError(f"{_NOT_SHARED}, and the head moves too little in the first "
                              f"{F} frames to relate the two mirrors' scales through its motion (it moves "
                              f"{100 * moved:.2f} % of its distance between frames, standard error "
                              f"{100 * error:.2f} %); turn the head during the take or give MIRRORS.json from "
                              "`mirrorcap mirrors`")
    out = np.array(ds, float)
    out[1] /= ratio
    figures = {"source": "head motion: markers tracked in each mirror", "ratio": 1.0 / ratio,
               "relative_spread": spread, "standard_error": float(error), "samples": len(t_pairs[0]),
               "relative_spread_all_markers": spread_all,
               "markers": int(sum(markers)), "markers_per_mirror": markers,
               "rigid_markers_per_mirror": [int(r.sum()) for r in rigid]}
    return out, figures


def _pair_motion(pos, a, b, common) -> tuple[list, list]:
    """Between frames ``a`` and ``b``, each half's translation ``t_k = c_k(b) - R c_k(a)`` (its centroid's, under the
    one rotation ``R`` fitted to both halves about their own centroids) and each marker's residual under that motion,
    per mirror ``k``; the markers of ``common[k]`` (into ``pos[k]``'s second axis) straying over 3x the median
    residual are left out of the fit, twice."""
    A = [pos[k][a, common[k]] for k in range(2)]
    B = [pos[k][b, common[k]] for k in range(2)]
    keep = [np.ones(len(x), bool) for x in A]
    for _ in range(3):
        ca = [A[k][keep[k]].mean(0) for k in range(2)]
        cb = [B[k][keep[k]].mean(0) for k in range(2)]
        R, _ = rigid_fit(np.r_[tuple(A[k][keep[k]] - ca[k] for k in range(2))],
                         np.r_[tuple(B[k][keep[k]] - cb[k] for k in range(2))])
        res = [np.linalg.norm((A[k] - ca[k]) @ R.T - (B[k] - cb[k]), axis=1) for k in range(2)]
        limit = 3.0 * np.median(np.r_[res[0][keep[0]], res[1][keep[1]]])
        keep = [r <= limit if (r <= limit).sum() >= 3 else keep[k] for k, r in enumerate(res)]
    return [B[k][keep[k]].mean(0) - R @ A[k][keep[k]].mean(0) for k in range(2)], res


def _translation_ratio(t0, t1) -> tuple[float, float, float]:
    """The ratio of two halves' translations ``t0``, ``t1`` (each ``(pairs, 3)``) over frame pairs,
    ``sum t_0 . t_1 / sum |t_0|^2``, the spread of the per-pair ratios about it (weighted by ``|t_0|^2``, relative)
    and its standard error."""
    t0, t1 = np.asarray(t0, float), np.asarray(t1, float)
    w = np.einsum("ij,ij->i", t0, t0)
    ratio = float(np.einsum("ij,ij->", t0, t1) / w.sum())
    per_pair = np.einsum("ij,ij->i", t0, t1) / np.maximum(w, 1e-300)
    spread = float(np.sqrt(np.sum(w * (per_pair - ratio) ** 2) / w.sum()) / abs(ratio))
    return ratio, spread, spread / np.sqrt(len(w))
