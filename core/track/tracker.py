"""Detections over time -> labelled 3D marker trajectories with head motion separated
(Lin 2003, section 5.3 and "the motion tracking procedure" at the end of chapter 5).

Steps, per the procedure:

1. (given) camera and mirror planes -- from ``core.track.selfcal`` or ``mirrorcap mirrors``;
2. the neutral structure at the first frame: markers are direct-view 2D tracks paired
   with mirror tracks over the first ``init_frames`` frames (``core.track.pairing``); a
   direct track left unpaired is paired in a band ``wide_band_factor`` times wider when both
   mirrors then put it at the same 3D point (:func:`.initial.initial_markers`: the face's
   midline, seen at a grazing angle in both mirrors);
3-4. per frame, 3D candidates from the band (``core.track.candidates``);
5. head motion: a robust rigid fit of the neutral structure to the tracked markers
   (iteratively reweighted, so expression motion counts little -- the idea of
   weight-compensated motion estimation, seed 003 section 3.3), filtered by the
   adaptive Kalman filter on the six pose parameters of eq. 5.4-5.5;
6. markers predicted by their own Kalman filters (eq. 4.1-4.2) in the head frame,
   assigned one-to-one to candidates within a gate; false tracking by the neighbour
   test (eq. 5.6-5.7), except, in the final pass, for a candidate on the 2D tracks of the
   marker's last measurement in the direct view and a mirror (:func:`.pairing.continuing_candidate`: the same
   dot, though it moves unlike its neighbours -- a lip against the chin), preferred to a nearer
   pairing of the same direct blob once the marker has held its mirror track ``HELD_FRAMES``
   measurements; a marker whose direct dot was hidden comes back on the mirror track it held
   (:func:`.pairing.back_on_mirror_track`); conflicts (one 2D blob claimed twice) keep the marker closest to its
   prediction;
7. missing markers conjectured from their neighbours (eq. 5.8); after the pass, with the
   whole take known, a gap that the marker's 2D tracks bracket is measured from its candidates, and a marker
   lost for good is followed on along all its 2D tracks (:func:`.bridge.bridge_gaps_along_2d_tracks`), dots are
   followed into the other gaps
   (``core.track.singleview``), and the rest conjectured from relations to their neighbours learned over the take
   (``core.track.motion.learned_conjectures``), meeting the measurements at both ends of a gap;
8. the Kalman filters give the reported positions.

Everything is vectorised over markers; the loop is over frames.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..common.errors import DegenerateError
from ..common.threads import with_limited_threads
from ..geometry.camera import Camera
from ..geometry.rigid import angles_zyx, robust_rigid_fit, rotation_zyx
from ..capture.views import ClipDetections
from .bridge import bridge_gaps_along_2d_tracks
from .initial import initial_markers
from .candidates import ClipCandidates, clip_candidates
from .gapfill import doubt_outlying_measurements, fill_gaps
from .late import add_late_markers, lost_markers, release_other_markers_blobs, settle_lost_markers
from .splits import merge_along_2d_tracks, merge_split_labels
from .singleview import follow_dots_through_gaps, measure_in_single_views, meeting_limit
from .motion import (ConstantVelocityKalman, conjecture_motion, conjecture_since_last_seen, false_tracking,
                     neighbours)
from .pairing import (back_on_mirror_track, candidate_tracks, continuing_candidate, continuing_owner,
                      direct_track_frames, direct_track_spans)
from .relocate import (RELOCATE_CONFLICT_SHARE, RELOCATE_CONFLICTS, RELOCATE_DROP, RELOCATE_MIN_MARKERS, on_candidates,
                       relocate_head)
from .result import COLOUR_SPACING_MM, TrackResult, TrackSettings, camera_mask_of, keep_measured

#: measurements a marker must have run on a mirror track before that track's pairing is preferred
#: to a nearer candidate of the same direct blob (fewer: mirror45's dot 53 took a neighbour's pairing
#: in its first frames, 2.8 mm off; the sample rig's dot 40 needs the preference after ~40 frames)
HELD_FRAMES = 5
#: a marker lost for LOST_GATE_AFTER frames or more has its gate widened by LOST_GATE_GROWTH_MM per frame lost
#: (up to TrackSettings.gate_mm). Measured on 16 clips: the normal-light clip's nose-tip dot, hidden for 9
#: frames, came back 0.05 mm outside its gate and was never tracked (97.9 % -> 98.5 % of the seen marker-frames
#: reported); webcam 97.9 -> 98.4 %, fast540 95.8 -> 96.1 %; but the held-out lip648 98.0 -> 97.5 % (two markers
#: re-acquired 20 frames later) and wide576 6 -> 14 points over 2 mm
LOST_GATE_AFTER = 5
LOST_GATE_GROWTH_MM = 0.02
#: a marker back from behind an object in the direct view, on the mirror track it held, may be this many widest
#: gates from its prediction (.pairing.back_on_mirror_track). Measured with a sphere swept before the face
#: (make occluded-clips): fast720_hand 31 -> 0 switches, tempo720_hand 3 -> 0, lip648 1 -> 0; the 66 other clips
#: as before (the gate alone: no change; no distance limit: tempo720_hand 3 -> 80 switches)
REACQUIRE_GATE_FACTOR = 3.0


@with_limited_threads
def track(frames, camera: Camera, planes, settings: TrackSettings | None = None, progress=None,
          rigid=None, seeds=None) -> TrackResult:
    """Track the markers of ``frames`` (objects with ``direct``, ``direct_color``,
    ``mirror[k]``, ``mirror_color[k]`` in pixels, e.g. :class:`synthetic.simulate.FrameDetections`)
    given the ``camera`` and mirror ``planes`` (``MirrorPlane`` or ``(normal, d)``).

    Head motion comes from ``rigid`` markers: indices into the result's markers, or a
    ``(region, colour classes)`` pair (:func:`rigid_by_image`) naming them by where they
    are in the first frame's image and/or their colour (at least 4 must match). When
    not given they are found automatically: a first pass estimates the pose from all
    markers (robustly), then the ``rigid_fraction`` of markers that moved least
    relative to the head -- forehead, nose bridge, temples on a real face -- carry the
    pose in a second pass.

    ``seeds`` (:class:`.seeds.Seeds`, SEEDS.csv): markers the user designated in the first
    frame; their pairs override the automatic pairing and their names become their labels.

    ``frames`` may be a :class:`..capture.views.ClipDetections` (as ``mirrorcap track``
    passes them, normalised once on ingest); per-frame detections are flattened and
    undistorted here, once. The 3D candidates of every
    frame are found in one vectorised pass (``core.track.candidates.clip_candidates``) before
    the frame loop."""
    s = settings or TrackSettings()
    normals = np.stack([np.asarray(getattr(pl, "normal", pl[0] if isinstance(pl, tuple) else None), float)
                        for pl in planes])
    ds = np.array([float(getattr(pl, "d", pl[1] if isinstance(pl, tuple) else np.nan)) for pl in planes])
    if len(frames) < 2:
        raise DegenerateError("tracking needs at least 2 frames")
    clock = [time.perf_counter()]
    timings = {}

    def lap(name):
        clock.append(time.perf_counter())
        timings[name] = clock[-1] - clock[-2]

    det = ClipDetections.of(frames, camera)
    markers, undecided, names = initial_markers(det, camera, normals, ds, s, seeds)
    n_initial = len(markers[1])
    lap("initial_markers")
    z_mid = float(np.median(markers[1][:, 2]))
    cands = clip_candidates(det, normals, ds, camera.focal_px, s.band_px,
                            (z_mid - s.depth_margin_mm, z_mid + s.depth_margin_mm))
    lap("candidates")
    by_image = isinstance(rigid, tuple)
    given = (rigid_by_image(camera, markers[1], markers[2], *rigid) if by_image
             else None if rigid is None else np.asarray(rigid, int))
    # the first pass leaves the blobs of markers it loses unclaimed: late markers come from them
    first = _track_pass(det, cands, replace(s, follow_2d_tracks=False), markers, given, None)
    lap("first_pass")
    if given is None:
        moved = np.linalg.norm(first.head_frame - first.neutral[None], axis=2) ** 2
        seen = np.isfinite(moved).sum(axis=0)          # markers never reported: no motion to rank (NaN)
        motion = np.where(seen > 0, np.nansum(moved, axis=0) / np.maximum(seen, 1), np.nan)
        if np.isfinite(motion).sum() < 4:
            raise DegenerateError("no rigid markers found: fewer than 4 markers were followed through the take; "
                                  "name them in RIG.json (\"rigid\") or check the detections")
        motion = np.where(np.isfinite(motion), motion, np.inf)
        n_rigid = max(8, int(round(s.rigid_fraction * len(motion))))
        given = np.argsort(motion)[:n_rigid]
    markers = add_late_markers(det, cands, s, markers, first, camera.focal_px, planes=(normals, ds))
    del first                                          # its (frames, markers) arrays: a long take's memory
    if by_image:  # markers found later may be rigid too
        given = rigid_by_image(camera, markers[1], markers[2], *rigid)
    lap("late_markers")
    result = _track_pass(det, cands, s, markers, given, progress)
    result.rigid = given
    result.stats["markers_added_later"] = np.array([len(markers[1]) - n_initial])
    result.labels = [names[i] if i < len(names) and names[i] else label for i, label in enumerate(result.labels)]
    result = keep_measured(result, s.min_measured_frames)
    # a marker lost for good (keep_measured) goes, unless its dot is followed on (paired in the first
    # frames) or into a later label of it, its points on that label's path (settle_lost_markers)
    passive, lost_initial, lost = lost_markers(result, s)
    tracks = candidate_tracks(det, cands) if s.follow_2d_tracks else None
    direct_track = tracks[0] if tracks is not None else None
    result = merge_split_labels(result, s, direct_track)
    result = merge_along_2d_tracks(result, tracks, direct_track_frames(det, cands) if tracks is not None else None)
    result = bridge_gaps_along_2d_tracks(result, det, cands, tracks, (normals, ds))
    lap("final_pass")
    if s.single_views:
        limit = meeting_limit(result, det, cands, normals, ds, camera.focal_px, s.band_px)
        result = follow_dots_through_gaps(result, det, cands, normals, ds, camera.focal_px, s, limit,
                                          passive=passive, lost_initial=lost_initial)
        # the followed dots steady the earlier marker's conjecture
        result = merge_split_labels(result, s, direct_track)
    result = release_other_markers_blobs(result, det, cands, normals, ds, camera.focal_px, tracks)
    result = settle_lost_markers(result, lost, s.gate_mm)
    result = doubt_outlying_measurements(result, s.neighbour_radius_mm, cands, det=det)
    conjecture, expected = fill_gaps(result, s.neighbour_radius_mm, max_sd_mm=s.conjecture_max_sd_mm)
    if s.single_views:
        measure_in_single_views(result, det, cands, normals, ds, camera.focal_px, conjecture, expected, s, limit)
    lap("gap_fill")
    result.undecided = _still_undecided(undecided, result)
    result.timings = timings
    return result


def _still_undecided(undecided: dict, result: TrackResult) -> list:
    """The undecided direct-view tracks of the first frames that the tracker did not
    take up later (no blob of theirs became a marker's measurement), as report rows."""
    blobs = undecided.pop("blobs")
    taken = np.zeros(len(undecided["track"]), bool)
    for f, ids in enumerate(blobs):
        used = result.assigned_blob[f][result.assigned_blob[f] >= 0]
        taken |= np.isin(undecided["track"], ids[used[used < len(ids)]])
    rows = []
    for i in np.flatnonzero(~taken):
        mirrors = np.flatnonzero(undecided["ambiguous_in"][i]).tolist()
        rows.append({"frame": int(undecided["frame"][i]), "x": round(float(undecided["xy"][i, 0]), 2),
                     "y": round(float(undecided["xy"][i, 1]), 2), "colour": int(undecided["colour"][i]),
                     "frames_seen": int(undecided["frames_seen"][i]),
                     "reason": f"ambiguous in mirror {', '.join(map(str, mirrors))}" if mirrors
                     else "no mirror partner"})
    return rows


def rigid_by_image(camera: Camera, neutral, colour, region=None, colours=None) -> np.ndarray:
    """Indices of the markers whose neutral position projects into ``region`` ``(x0, y0,
    x1, y1)`` (pixels, the first frame's image) and whose colour class is in ``colours``
    (either None: no condition). Fewer than 4 is an error: the head pose needs them."""
    ok = np.ones(len(neutral), bool)
    if region is not None:
        px = camera.project(np.asarray(neutral, float))
        x0, y0, x1, y1 = region
        ok &= (px[:, 0] >= x0) & (px[:, 0] < x1) & (px[:, 1] >= y0) & (px[:, 1] < y1)
    if colours is not None:
        ok &= np.isin(colour, list(colours))
    if ok.sum() < 4:
        raise DegenerateError(f"only {int(ok.sum())} markers match the rigid markers named (RIG.json \"rigid\": "
                              f"region {region}, colour classes {colours}); at least 4 are needed to follow the head")
    return np.flatnonzero(ok)


def _resolve_conflicts(a, near, keys):
    """Conflicts (procedure step 6): a 2D blob -- direct, or in a mirror -- claimed by
    two markers in one frame stays with the marker closest to its prediction.
    ``a`` ``(N,)`` candidate per marker (-1: none), ``near`` its distance, ``keys`` the
    candidates' blob per view (``(C,)`` each, -1: none). Returns the markers that lost."""
    valid = a >= 0
    lost = np.zeros(len(a), bool)
    if not valid.any():
        return lost
    chosen = a[valid]
    shared = [np.unique(b).size < b.size for b in (key[chosen][key[chosen] >= 0] for key in keys)]
    if not any(shared):
        return lost
    for key, clash in zip(keys, shared):
        if not clash:
            continue
        blob = np.where(valid, key[np.maximum(a, 0)], -1)
        order = np.lexsort((near, blob))
        dup = np.r_[False, (blob[order][1:] == blob[order][:-1]) & (blob[order][1:] >= 0)]
        lost[order[dup]] = True
        valid &= ~lost
    return lost


def _track_pass(det: ClipDetections, cands: ClipCandidates, s: TrackSettings, markers, rigid, progress) -> TrackResult:
    """One pass of the procedure over the clip (module docstring, steps 4-8)."""
    from scipy.spatial import cKDTree

    F = det.n_frames
    first_blob, neutral, colour, entry = markers
    N = len(neutral)
    nidx, ndist = neighbours(neutral, s.neighbour_radius_mm)
    kf = ConstantVelocityKalman.start(neutral, accel_sigma=s.accel_sigma_mm, initial_sigma=s.measure_sigma_mm)
    pose_kf = ConstantVelocityKalman.start(np.zeros((2, 3)), accel_sigma=s.pose_accel_sigma,
                                           initial_sigma=0.0)  # rotation (rad), translation (mm): exact at frame 0
    pose_sigma = np.asarray(s.pose_measure_sigma, float)
    points = np.full((F, N, 3), np.nan)
    head_frame = np.full((F, N, 3), np.nan)
    history = np.full((F, N, 3), np.nan)  # head-frame motion per frame, for conjectures since a last sighting
    last_motion = np.zeros((N, 3))  # each marker's motion at its last measurement
    last_frame = np.full(N, -1)
    innovation = np.full(N, s.gate_mm / 4.0)  # per marker, moving average; starts at the widest gate
    conjectured = np.zeros((F, N), bool)
    camera_mask = np.zeros((F, N), np.int8)
    head_pose = np.zeros((F, 6))
    assigned_blob = np.full((F, N), -1)
    candidate = np.full((F, N), -1)
    counts = {k: np.zeros(F, int) for k in ("candidates", "measured", "false_tracking", "conflicts", "conjectured",
                                             "relocated", "out_of_place")}
    is_rigid = np.ones(N, bool) if rigid is None else np.isin(np.arange(N), rigid)
    pose_weights = np.ones(N)  # robust weights, carried from frame to frame
    cand_key = np.c_[cands.points, det.colour[0][cands.direct] * COLOUR_SPACING_MM]
    query = np.c_[neutral, colour * COLOUR_SPACING_MM]
    K = cands.mirror_blob.shape[1]
    keys = [cands.direct] + [cands.mirror_blob[:, k] for k in range(K)]
    trees = {}
    # 2D continuity: each candidate's direct and mirror blobs' 2D tracks (.pairing.track_2d)
    cand_dtrack, cand_mtrack = candidate_tracks(det, cands) if s.follow_2d_tracks else (None, None)
    spans = direct_track_spans(det, cands) if s.follow_2d_tracks else None
    last_dtrack = np.full(N, -1)
    last_mtrack = np.full((N, K), -1)
    held = np.zeros((N, K), int)   # measurements running on each last mirror track

    def tree(u):
        """Frame ``u``'s candidates as a KD-tree (None: none), built once and kept while in use."""
        if u not in trees:
            su = cands.at(u)
            trees[u] = cKDTree(cand_key[su]) if su.stop > su.start else None
            trees.pop(u - 5, None)
        return trees[u]

    def associate():
        """Steps 4-6 for frame ``t``: each marker's candidate in its gate around ``query`` (its prediction), the
        2D tracks' continuity, markers coming back, conflicts. Returns ``(valid, candidate, distance, confirmed,
        conflicts)``."""
        if sl.stop > sl.start:
            near, j = tree(t).query(query, distance_upper_bound=s.gate_mm)
            valid = (near <= gate_i) & (entry <= t)  # a late marker is measured from its first sighting on
            a = np.where(valid, j + sl.start, -1)
            confirmed = np.zeros(N, bool)
            if cand_dtrack is not None:
                cont, cont_held = continuing_candidate(cand_dtrack[sl], cand_mtrack[sl], last_dtrack, last_mtrack,
                                                       held)
                cont = np.where(cont >= 0, cont + sl.start, -1)
                # two pairings of the direct blob taken, both in the gate: the one on the mirror track
                # the marker has held for HELD_FRAMES measurements, not the nearer (a dot grazing in a
                # mirror next to the marker's hidden image pairs within the fused candidates' 2 mm and
                # pulls the prediction its way; or the held pairing with one mirror fewer, whose point
                # the prediction would then follow off the two mirrors' average); a pairing younger
                # than that earns no such trust
                other = np.flatnonzero(valid & (cont >= 0) & (cont != a))
                other = other[cands.direct[cont[other]] == cands.direct[a[other]]]
                other = other[cont_held[other] >= HELD_FRAMES]
                if other.size:
                    gap = np.linalg.norm(cand_key[cont[other]] - query[other], axis=1)
                    inside = gap <= gate_i[other]
                    a[other[inside]], near[other[inside]] = cont[other[inside]], gap[inside]
                confirmed = valid & (a == cont)
                # a candidate on another marker's own 2D tracks, held HELD_FRAMES measurements, is that marker's
                # dot: a marker coasting through a gap of its own does not take it, its owner does (side600: a dot
                # moving 5 px in 3 frames at the silhouette coasted 10 px onto its neighbour's dot, 11 mm away,
                # while the neighbour, its step along the line of sight, was lost)
                owner = continuing_owner(cont, cont_held, sl, HELD_FRAMES)
                taken = np.flatnonzero(valid & ~confirmed & (last_frame >= 0) & (last_frame < t - 1))
                # a marker whose direct dot was hidden (a hand before the mouth) and whose mirror image was followed
                # all along comes back to a candidate on that mirror track, its direct dot new since, within
                # REACQUIRE_GATE_FACTOR gates of its prediction: a fast mouth outruns the conjecture while hidden
                o, c = back_on_mirror_track(cand_mtrack[sl], cand_dtrack[sl], last_mtrack, last_dtrack, held,
                                            last_frame, spans, t, HELD_FRAMES, LOST_GATE_AFTER)
                reach = np.linalg.norm(cand_key[c + sl.start] - query[o], axis=1)
                back_on = ~valid[o] & (entry[o] <= t) & (reach <= REACQUIRE_GATE_FACTOR * s.gate_mm)
                order = np.argsort(-reach[back_on])          # a marker's nearest such candidate is assigned last
                o, c = o[back_on][order], c[back_on][order] + sl.start
                a[o], near[o], valid[o] = c, reach[back_on][order], True
                claim = owner[a[taken] - sl.start]
                other_s = (claim >= 0) & (claim != taken)
                stolen, owners = taken[other_s], claim[other_s]
                back_to = ~valid[owners]
                o, c = owners[back_to], a[stolen[back_to]]
                a[o], near[o], valid[o], confirmed[o] = c, np.linalg.norm(cand_key[c] - query[o], axis=1), True, True
                valid[stolen], a[stolen] = False, -1
                # no candidate in the gate, but one on the marker's own 2D tracks: the same dot, moved
                # faster than the gate allows (a jaw opening in a frame or two). The direct view's track
                # vouches for the motion across the line of sight; along it, where only the mirror's
                # pairing speaks (a mirror's 2D track can slip onto a like dot on the same epipolar
                # line), the widest gate holds, and the step must lie mostly across it
                beyond = np.flatnonzero(~valid & (cont >= 0) & (entry <= t))
                if beyond.size:
                    step = cands.points[cont[beyond]] - query[beyond, :3]
                    sight = query[beyond, :3] / np.linalg.norm(query[beyond, :3], axis=1, keepdims=True)
                    along = np.abs(np.einsum("ij,ij->i", step, sight))
                    off = np.linalg.norm(step, axis=1)
                    ok = (off <= s.follow_2d_max_mm) & (along <= np.minimum(s.gate_mm, 0.5 * off))
                    take = beyond[ok]
                    a[take], near[take] = cont[take], off[ok]
                    valid[take] = True    # and, unlike a confirmed candidate in the gate, judged by eq. 5.6
            back = np.flatnonzero(valid & ~confirmed & (last_frame < t - 1)) if t > 0 else np.zeros(0, int)
            if back.size:  # coming back after a gap: only to a candidate that lasts
                lasts = np.zeros(back.size, bool)
                for u in (t - 1, t + 1, t - 2, t + 2):
                    if 0 <= u < F and tree(u) is not None and not lasts.all():
                        r = s.reacquire_mm * abs(u - t)
                        lasts |= tree(u).query(cand_key[a[back]], distance_upper_bound=r)[0] <= r
                valid[back[~lasts]] = False
                a = np.where(valid, a, -1)
            lost = _resolve_conflicts(a, near, keys)
            return valid & ~lost, a, near, confirmed, int(lost.sum())
        return unmeasured()

    def unmeasured():
        """:func:`associate`'s answer for a frame in which nothing is measured."""
        return np.zeros(N, bool), np.full(N, -1), np.full(N, np.inf), np.zeros(N, bool), 0

    for t in range(F):
        sl = cands.at(t)
        counts["candidates"][t] = sl.stop - sl.start
        pose_pred = pose_kf.predict()
        R_p, T_p = rotation_zyx(pose_pred[0]), pose_pred[1]
        predicted = kf.predict()                    # each marker's predicted position, head frame
        query[:, :3] = predicted @ R_p.T + T_p
        # each marker's gate follows how well it has been predicted lately: tight where
        # predictions are good (fewer chance candidates), wide where the face moves fast
        gate_i = np.clip(4.0 * innovation + 0.3, s.min_gate_mm, s.gate_mm)
        # ... and widens while the marker is lost: its prediction is a conjecture, further off with each
        # frame (LOST_GATE_GROWTH_MM a frame from the LOST_GATE_AFTER-th frame lost)
        lost_for = t - 1 - last_frame
        gate_i = np.where((last_frame >= 0) & (lost_for >= LOST_GATE_AFTER),
                          np.minimum(gate_i + LOST_GATE_GROWTH_MM * lost_for, s.gate_mm), gate_i)
        valid, a, near, confirmed, conflicts = associate()
        known = (last_frame >= 0) & (entry <= t)
        if t > 0 and known.sum() >= RELOCATE_MIN_MARKERS and sl.stop > sl.start and (
                conflicts >= max(RELOCATE_CONFLICTS, RELOCATE_CONFLICT_SHARE * valid.sum())
                or valid.sum() < RELOCATE_DROP * counts["measured"][t - 1]):
            # the face may not be where the head pose says (a jump in the video): the markers that carry the head
            # pose look for it (the expression may have changed across the jump). The frame keeps its markers'
            # candidates (taken again from the pose found: at a 60-frame cut of a synthetic take 200 switches
            # against 100); the head's filter restarts from that pose, and the frames after it are predicted from it
            pick = known & is_rigid
            pick = pick if pick.sum() >= RELOCATE_MIN_MARKERS else known
            model = predicted[pick]
            pose = relocate_head(model, colour[pick], tree(t), R_p, T_p)
            following = tree(t + 1) if t + 1 < F else None
            if pose is not None and following is not None and (
                    on_candidates(model, colour[pick], following, *pose)
                    <= on_candidates(model, colour[pick], following, R_p, T_p)):
                # the face is back where it was in the next frame: this one frame is out of place (a frame of
                # another moment, a glitch), and nothing is measured in it
                valid, a, near, confirmed, _ = unmeasured()
                counts["out_of_place"][t] = 1
            elif pose is not None:
                R_p, T_p = pose
                pose_kf.position[:] = np.stack([angles_zyx(R_p), T_p])
                pose_kf.velocity[:] = 0.0
                kf.velocity[:] = 0.0
                counts["relocated"][t] = 1
        counts["conflicts"][t] = conflicts
        meas_cam = cands.points[np.maximum(a, 0)] if len(cands.points) else np.zeros((N, 3))
        use = valid & is_rigid
        if use.sum() >= 4:
            R_m, T_m, w = robust_rigid_fit(neutral[use], meas_cam[use], iterations=1, weights=pose_weights[use])
            pose_weights[use] = w
            pose_kf.update(np.stack([angles_zyx(R_m), T_m]), pose_sigma)
        R, T = rotation_zyx(pose_kf.position[0]), pose_kf.position[1]
        head_pose[t] = pose_kf.position.ravel()
        meas_h = (meas_cam - T) @ R  # R^T (x - T): head motion removed
        motion = np.where(valid[:, None], meas_h - neutral, 0.0)
        false, _ = false_tracking(motion, valid, nidx, threshold=s.false_threshold)
        # a candidate on the 2D tracks (direct view and a mirror) the marker was last measured on is
        # the same dot: its own, however its motion differs from its neighbours' (a lip against the chin)
        false &= ~confirmed
        counts["false_tracking"][t] = false.sum()
        valid &= ~false
        motion[~valid] = np.nan
        innovation[valid] = 0.8 * innovation[valid] + 0.2 * near[valid]
        # markers seen before: their own last motion plus the neighbours' motion since;
        # never seen (or no such neighbour): eq. 5.8 from the neighbours' motion now
        filled_motion, filled = conjecture_since_last_seen(motion, valid, nidx, ndist, last_motion, last_frame,
                                                           history)
        if (~valid & ~filled).any():
            now, filled_now = conjecture_motion(motion, valid, nidx, ndist, only=~filled)
            filled_motion = np.where(filled_now[:, None], now, filled_motion)
            filled |= filled_now
        reported = valid | filled
        z = np.where(valid[:, None], meas_h, neutral + filled_motion)
        out_h = kf.update(z, np.where(valid, s.measure_sigma_mm, s.conjecture_sigma_mm), reported)
        last_motion[valid] = motion[valid]
        last_frame[valid] = t
        if cand_dtrack is not None and valid.any():
            last_dtrack[valid] = cand_dtrack[a[valid]]
            seen_m = cand_mtrack[a[valid]]
            held[valid] = np.where(seen_m < 0, held[valid], np.where(seen_m == last_mtrack[valid], held[valid] + 1, 1))
            last_mtrack[valid] = np.where(seen_m >= 0, seen_m, last_mtrack[valid])
        kf.velocity[~reported] = 0.0  # lost and not conjecturable: hold still rather than drift away
        out_h = np.where(reported[:, None], out_h, np.nan)
        head_frame[t] = out_h
        history[t] = out_h - neutral
        points[t] = out_h @ R.T + T
        conjectured[t] = filled
        counts["conjectured"][t] = filled.sum()
        counts["measured"][t] = valid.sum()
        if valid.any():
            camera_mask[t, valid] = camera_mask_of(cands.mirror_blob[a[valid]])
            assigned_blob[t, valid] = cands.direct[a[valid]] - det.start[0][t]
            candidate[t, valid] = a[valid]
        if progress:
            progress(t + 1, F)
    labels = [f"m{i:03d}" for i in range(N)]
    return TrackResult(labels=labels, points=points, conjectured=conjectured, camera_mask=camera_mask.astype(int),
                       head_pose=head_pose, neutral=neutral, first_blob=first_blob, assigned_blob=assigned_blob,
                       colour=colour, head_frame=head_frame, candidate=candidate, stats=counts)
