"""Detections over time -> labelled 3D marker trajectories with head motion separated
(Lin 2003, section 5.3 and "the motion tracking procedure" at the end of chapter 5).

Steps, per the procedure:

1. (given) camera and mirror planes -- from ``core.selfcal`` or ``mirrorcap mirrors``;
2. the neutral structure at the first frame: markers are direct-view 2D tracks paired
   with mirror tracks over the first ``init_frames`` frames (``core.pairing``);
3-4. per frame, 3D candidates from the band (``core.candidates``);
5. head motion: a robust rigid fit of the neutral structure to the tracked markers
   (iteratively reweighted, so expression motion counts little -- the idea of
   weight-compensated motion estimation, seed 003 section 3.3), filtered by the
   adaptive Kalman filter on the six pose parameters of eq. 5.4-5.5;
6. markers predicted by their own Kalman filters (eq. 4.1-4.2) in the head frame,
   assigned one-to-one to candidates within a gate; false tracking by the neighbour
   test (eq. 5.6-5.7); conflicts (one 2D blob claimed twice) keep the marker closest
   to its prediction;
7. missing markers conjectured from their neighbours (eq. 5.8);
8. the Kalman filters give the reported positions.

Everything is vectorised over markers; the loop is over frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .candidates import assign_nearest, frame_candidates
from .errors import DegenerateError
from .mirror import MirrorPlane, points_from_planes
from .motion import (
    ConstantVelocityKalman,
    angles_zyx,
    conjecture_motion,
    conjecture_since_last_seen,
    false_tracking,
    neighbours,
    rigid_fit,
    rotation_zyx,
)
from .pairing import pair_tracks, track_2d


@dataclass
class TrackSettings:
    band_px: float = 1.0  # mirrored epipolar band half-width (about 3 sigma of the detections)
    gate_mm: float = 3.0  # largest distance between a marker's prediction and its candidate
    min_gate_mm: float = 0.5  # each marker's gate: 4x its recent innovation + 0.3 mm, within these
    init_frames: int = 15  # frames used to pair direct and mirror tracks
    neighbour_radius_mm: float = 25.0  # neighbours in the neutral face (eq. 5.6-5.8)
    false_threshold: float = 3.0  # JF above this is false tracking (eq. 5.6)
    measure_sigma_mm: float = 0.1  # measurement noise for the marker filters
    conjecture_sigma_mm: float = 1.0  # conjectured positions are trusted less
    accel_sigma_mm: float = 1.0  # velocity change per frame, marker filters
    pose_accel_sigma: tuple = (0.01, 1.0)  # rotation (rad) and translation (mm) per frame
    pose_measure_sigma: tuple = (0.0005, 0.05)
    depth_margin_mm: float = 200.0  # candidates deeper/shallower than the neutral face +- this are dropped
    rigid_fraction: float = 0.2  # share of the markers that carry the head pose when none are named
    min_measured_frames: int = 5  # a marker measured in fewer frames is not reported
    min_measured_fraction: float = 0.25  # ... nor one this rarely measured that is lost for good (see _keep_measured)


@dataclass
class TrackResult:
    labels: list
    points: np.ndarray  # (F, N, 3) camera frame; NaN where not reported
    conjectured: np.ndarray  # (F, N)
    camera_mask: np.ndarray  # (F, N) bit 0 direct, bit 1 mirror 0, bit 2 mirror 1; 0 when conjectured
    head_pose: np.ndarray  # (F, 6): rx, ry, rz (rad, eq. 5.4) and tx, ty, tz
    neutral: np.ndarray  # (N, 3) the first frame, camera frame
    first_blob: np.ndarray  # (N,) the direct blob index of each marker in the first frame (-1: absent there)
    assigned_blob: np.ndarray  # (F, N) direct blob index each frame, -1 when not measured
    colour: np.ndarray  # (N,) colour class of each marker
    head_frame: np.ndarray = None  # (F, N, 3) positions with head motion removed (NaN where not reported)
    rigid: np.ndarray = None  # markers that carried the head pose
    stats: dict = field(default_factory=dict)


def robust_rigid_fit(A, B, iterations: int = 5):
    """Rigid fit with iteratively reweighted least squares: markers moving with the
    expression (large residuals) get small weights, so the pose follows the rigid part
    of the face."""
    w = np.ones(len(A))
    for _ in range(iterations):
        R, t = rigid_fit(A, B, w)
        r = np.linalg.norm(A @ R.T + t - B, axis=1)
        s = 1.4826 * np.median(r) + 1e-6
        w = 1.0 / (1.0 + (r / (2.0 * s)) ** 2)
    return rigid_fit(A, B, w)


def _paired_tracks(frames, camera, normals, ds, band_px: float, min_frames: int):
    """2D tracks of the direct view and of each mirror over ``frames``, and each direct
    track's partner track per mirror (``core.pairing``; -1: none). Returns
    ``(direct ids per frame, number of direct tracks, partner (K, n), mirror ids per
    frame per mirror)``."""
    dids, n_dt = track_2d([f.direct for f in frames], [f.direct_color for f in frames])
    K = len(normals)
    partner = np.full((K, n_dt), -1)
    mids_all = []
    for k in range(K):
        mids, _ = track_2d([f.mirror[k] for f in frames], [f.mirror_color[k] for f in frames])
        pairs = pair_tracks([f.direct for f in frames], dids, [f.mirror[k] for f in frames], mids,
                            [f.direct_color for f in frames], [f.mirror_color[k] for f in frames], camera,
                            MirrorPlane(normal=normals[k], d=float(ds[k])), band_px=band_px, min_frames=min_frames)
        partner[k, pairs.direct_track] = pairs.mirror_track
        mids_all.append(mids)
    return dids, n_dt, partner, mids_all


def _track_positions(frames, camera, normals, ds, dids, n_dt, partner, mids_all, tracks):
    """3D position of chosen direct tracks in every frame where the track and one of
    its partner mirror tracks both have a blob (fused over mirrors): ``pos (F, M, 3)``
    (NaN elsewhere, each frame's own camera coordinates), the direct blob per frame
    ``(F, M)`` (-1: absent) and each track's colour ``(M,)``. Vectorised per frame
    through lookup arrays."""
    F, M, K = len(frames), len(tracks), len(normals)
    col_of = np.full(n_dt, -1)
    col_of[tracks] = np.arange(M)
    n_mt = [1 + max((int(m.max()) for m in mids_all[k] if len(m)), default=0) for k in range(K)]
    pos = np.full((F, M, 3), np.nan)
    blob = np.full((F, M), -1)
    colour = np.full(M, -1)
    for f in range(F):
        here = col_of[dids[f]] if len(dids[f]) else np.zeros(0, int)
        sel = np.flatnonzero(here >= 0)
        if sel.size == 0:
            continue
        marker = here[sel]
        blob[f, marker] = sel
        unset = colour[marker] < 0
        colour[marker[unset]] = np.asarray(frames[f].direct_color)[sel[unset]]
        vis = np.zeros((K, sel.size), bool)
        pm = np.zeros((K, sel.size, 2))
        for k in range(K):
            blob_of = np.full(n_mt[k], -1)
            blob_of[mids_all[k][f]] = np.arange(len(mids_all[k][f]))
            mate = partner[k, tracks[marker]]
            j = np.where(mate >= 0, blob_of[np.maximum(mate, 0)], -1)
            vis[k] = j >= 0
            if vis[k].any():
                pm[k, vis[k]] = camera.normalize(frames[f].mirror[k][j[vis[k]]])
        ok = vis.any(axis=0)
        if ok.any():
            pos[f, marker[ok]] = points_from_planes(camera.normalize(frames[f].direct[sel[ok]]), pm[:, ok],
                                                    normals, ds, visible=vis[:, ok])
    return pos, blob, colour


def _initial_markers(frames, camera, normals, ds, settings):
    """Step 2: markers are direct-view tracks paired with a mirror track over the first
    ``init_frames`` frames. Each marker's neutral position is its 3D position at the
    first frame where it is paired, mapped into frame 0 by a robust rigid fit of the
    markers both frames share (so markers hidden at frame 0 are tracked too).
    Returns each marker's frame-0 direct blob (-1 if absent), the neutral structure
    (N, 3) and the markers' colour classes (N,)."""
    W = min(settings.init_frames, len(frames))
    init = frames[:W]
    dids, n_dt, partner, mids_all = _paired_tracks(init, camera, normals, ds, settings.band_px, min(5, W))
    tracks = np.flatnonzero(np.any(partner >= 0, axis=0))
    if tracks.size < 10:
        raise DegenerateError(f"only {tracks.size} markers could be paired between the direct view and a mirror "
                              "in the first frames; are both mirrors visible and calibrated?")
    pos, blob, colour = _track_positions(init, camera, normals, ds, dids, n_dt, partner, mids_all, tracks)
    neutral = pos[0].copy()
    known = np.all(np.isfinite(neutral), axis=1)
    for f in range(1, W):
        new = ~known & np.all(np.isfinite(pos[f]), axis=1)
        common = known & np.all(np.isfinite(pos[f]), axis=1)
        if new.any() and common.sum() >= 6:
            R, T = robust_rigid_fit(pos[f, common], neutral[common])  # frame f -> frame 0
            neutral[new] = pos[f, new] @ R.T + T
            known |= new
    keep = np.flatnonzero(known)
    return blob[0, keep], neutral[keep], colour[keep]


def track(frames, camera: Camera, planes, settings: TrackSettings | None = None, progress=None,
          rigid=None) -> TrackResult:
    """Track the markers of ``frames`` (objects with ``direct``, ``direct_color``,
    ``mirror[k]``, ``mirror_color[k]`` in pixels, e.g. :class:`core.simulate.FrameDetections`)
    given the ``camera`` and mirror ``planes`` (``MirrorPlane`` or ``(normal, d)``).

    Head motion comes from ``rigid`` markers (indices into the result's markers). When
    not given they are found automatically: a first pass estimates the pose from all
    markers (robustly), then the ``rigid_fraction`` of markers that moved least
    relative to the head -- forehead, nose bridge, temples on a real face -- carry the
    pose in a second pass."""
    s = settings or TrackSettings()
    normals = np.stack([np.asarray(getattr(pl, "normal", pl[0] if isinstance(pl, tuple) else None), float)
                        for pl in planes])
    ds = np.array([float(getattr(pl, "d", pl[1] if isinstance(pl, tuple) else np.nan)) for pl in planes])
    if len(frames) < 2:
        raise DegenerateError("tracking needs at least 2 frames")
    markers = _initial_markers(frames, camera, normals, ds, s)
    n_initial = len(markers[1])
    given = None if rigid is None else np.asarray(rigid, int)
    first = _track_pass(frames, camera, normals, ds, s, markers, given, None)
    if given is None:
        motion = np.nanmean(np.linalg.norm(first.head_frame - first.neutral[None], axis=2) ** 2, axis=0)
        motion = np.where(np.isfinite(motion), motion, np.inf)
        n_rigid = max(8, int(round(s.rigid_fraction * len(motion))))
        given = np.argsort(motion)[:n_rigid]
    markers = _add_late_markers(frames, camera, normals, ds, s, markers, first)
    result = _track_pass(frames, camera, normals, ds, s, markers, given, progress)
    result.rigid = given
    result.stats["markers_added_later"] = np.array([len(markers[1]) - n_initial])
    return _keep_measured(result, s.min_measured_frames, s.min_measured_fraction)


def _keep_measured(result: TrackResult, min_frames: int, min_fraction: float = 0.0) -> TrackResult:
    """A marker must earn its place. Dropped: one measured in fewer than ``min_frames``
    frames; and one measured in fewer than ``min_fraction`` of its frames (from its first
    measurement on) that is also never measured again in the last three quarters of them -- a wrong
    direct/mirror pairing whose 3D point stops matching real candidates, and would be
    conjectured, wrongly, for the rest of the take. (A marker that is merely often hidden
    keeps coming back, and stays.) Nothing is reported for a marker before its first
    measurement."""
    measured = result.assigned_blob >= 0
    F = measured.shape[0]
    first = np.argmax(measured, axis=0)
    last = F - 1 - np.argmax(measured[::-1], axis=0)
    span = F - first
    count = measured.sum(axis=0)
    lost = (count < min_fraction * span) & (F - 1 - last > 0.75 * span)
    keep = np.flatnonzero((count >= min_frames) & ~lost)
    before = np.arange(measured.shape[0])[:, None] < first[None, :]
    result.points[before] = np.nan
    result.head_frame[before] = np.nan
    result.conjectured[before] = False
    result.camera_mask[before] = 0
    old_to_new = np.full(measured.shape[1], -1)
    old_to_new[keep] = np.arange(keep.size)
    rigid = old_to_new[result.rigid]
    result.rigid = rigid[rigid >= 0]
    for name in ("points", "conjectured", "camera_mask", "assigned_blob", "head_frame"):
        setattr(result, name, getattr(result, name)[:, keep])
    for name in ("neutral", "first_blob", "colour"):
        setattr(result, name, getattr(result, name)[keep])
    result.labels = [f"m{i:03d}" for i in range(keep.size)]
    result.stats["markers_dropped_unmeasured"] = np.array([measured.shape[1] - keep.size])
    return result


def _add_late_markers(frames, camera, normals, ds, s, markers, first_pass):
    """Markers the initial window missed (hidden at the start, turned into view later):
    direct-view tracks over the whole clip that pair with a mirror track but were never
    claimed by a tracked marker. Each enters at its head-frame position when first
    paired (the first pass's head pose); one within 4 mm of an existing (or an earlier
    added) marker is the same marker found again and is not added."""
    from scipy.spatial import cKDTree

    first_blob, neutral, colour = markers
    F = len(frames)
    dids, n_dt, partner, mids_all = _paired_tracks(frames, camera, normals, ds, s.band_px, 5)
    claimed = np.zeros(n_dt, bool)
    for t in range(F):
        ab = first_pass.assigned_blob[t]
        claimed[dids[t][ab[ab >= 0]]] = True
    new_tracks = np.flatnonzero((partner >= 0).any(axis=0) & ~claimed)
    if new_tracks.size == 0:
        return markers
    pos, _, new_colour = _track_positions(frames, camera, normals, ds, dids, n_dt, partner, mids_all, new_tracks)
    seen = np.all(np.isfinite(pos), axis=2)  # (F, M)
    has = seen.any(axis=0)
    first = np.argmax(seen, axis=0)
    X = pos[first, np.arange(new_tracks.size)]
    pose = first_pass.head_pose[first]
    R = rotation_zyx(pose[:, :3])  # (M, 3, 3)
    head = np.einsum("mji,mj->mi", R, X - pose[:, 3:])  # R^T (X - T): into the head frame of frame 0
    head, new_colour = head[has], new_colour[has]
    far = cKDTree(neutral).query(head)[0] > 4.0 if len(head) else np.zeros(0, bool)
    keep = []
    for q in np.flatnonzero(far):  # the few candidates left, against each other
        if not keep or np.min(np.linalg.norm(head[keep] - head[q], axis=1)) > 4.0:
            keep.append(q)
    if not keep:
        return markers
    return (np.r_[first_blob, np.full(len(keep), -1)], np.vstack([neutral, head[keep]]),
            np.r_[colour, new_colour[keep]])


def _track_pass(frames, camera: Camera, normals, ds, s: TrackSettings, markers, rigid, progress) -> TrackResult:
    F = len(frames)
    first_blob, neutral, colour = markers
    N = len(neutral)
    nidx, ndist = neighbours(neutral, s.neighbour_radius_mm)
    z_mid = float(np.median(neutral[:, 2]))
    depth_range = (z_mid - s.depth_margin_mm, z_mid + s.depth_margin_mm)
    kf = ConstantVelocityKalman.start(neutral, accel_sigma=s.accel_sigma_mm, initial_sigma=s.measure_sigma_mm)
    kf_rot = ConstantVelocityKalman.start(np.zeros((1, 3)), accel_sigma=s.pose_accel_sigma[0],
                                          initial_sigma=s.pose_measure_sigma[0])
    kf_tr = ConstantVelocityKalman.start(np.zeros((1, 3)), accel_sigma=s.pose_accel_sigma[1],
                                         initial_sigma=s.pose_measure_sigma[1])
    points = np.full((F, N, 3), np.nan)
    head_frame = np.full((F, N, 3), np.nan)
    last_motion = np.zeros((N, 3))  # each marker's motion at its last measurement
    last_frame = np.full(N, -1)
    innovation = np.full(N, s.gate_mm / 4.0)  # per marker, moving average; starts at the widest gate
    conjectured = np.zeros((F, N), bool)
    camera_mask = np.zeros((F, N), int)
    head_pose = np.zeros((F, 6))
    assigned_blob = np.full((F, N), -1)
    counts = {k: np.zeros(F, int) for k in ("candidates", "measured", "false_tracking", "conflicts", "conjectured")}
    for t in range(F):
        fr = frames[t]
        R_p = rotation_zyx(kf_rot.predict()[0])
        T_p = kf_tr.predict()[0]
        pred_h = kf.predict()
        pred_cam = pred_h @ R_p.T + T_p
        cand = frame_candidates(camera.normalize(fr.direct), fr.direct_color,
                                [camera.normalize(m) for m in fr.mirror], fr.mirror_color, normals, ds,
                                camera.focal_px, band_px=s.band_px, depth_range=depth_range)
        counts["candidates"][t] = len(cand.direct)
        # each marker's gate follows how well it has been predicted lately: tight where
        # predictions are good (fewer chance candidates), wide where the face moves fast
        gate_i = np.clip(4.0 * innovation + 0.3, s.min_gate_mm, s.gate_mm)
        # one-to-one within each colour class: a marker only takes candidates of its colour
        a = np.full(N, -1)
        cand_colour = np.asarray(fr.direct_color)[cand.direct] if len(cand.direct) else np.zeros(0, int)
        for c in np.unique(colour):
            mk = np.flatnonzero(colour == c)
            cc = np.flatnonzero(cand_colour == c)
            if cc.size:
                got = assign_nearest(pred_cam[mk], cand.points[cc], s.gate_mm)
                a[mk] = np.where(got >= 0, cc[np.maximum(got, 0)], -1)
        # (a blank frame has no candidate: pad so that indexing stays valid; nothing is assigned)
        cpts = cand.points if len(cand.points) else np.zeros((1, 3))
        near = np.linalg.norm(cpts[np.maximum(a, 0)] - pred_cam, axis=1)
        a = np.where((a >= 0) & (near <= gate_i), a, -1)
        valid = a >= 0
        # conflicts: one 2D blob claimed by two markers -> keep the one closest to its prediction
        err = np.where(valid, near, np.inf)
        keys = [cand.direct] + [cand.mirror_blob[:, k] for k in range(cand.mirror_blob.shape[1])]
        for key in keys if len(cand.points) else []:
            blob = np.where(valid, key[np.maximum(a, 0)], -1)
            order = np.lexsort((err, blob))
            dup = np.r_[False, (blob[order][1:] == blob[order][:-1]) & (blob[order][1:] >= 0)]
            loser = order[dup]
            counts["conflicts"][t] += loser.size
            valid[loser] = False
        meas_cam = cpts[np.maximum(a, 0)]
        use = valid if rigid is None else valid & np.isin(np.arange(N), rigid)
        if use.sum() >= 4:
            R_m, T_m = robust_rigid_fit(neutral[use], meas_cam[use])
            kf_rot.update(angles_zyx(R_m)[None], s.pose_measure_sigma[0])
            kf_tr.update(T_m[None], s.pose_measure_sigma[1])
        R = rotation_zyx(kf_rot.position[0])
        T = kf_tr.position[0]
        head_pose[t] = np.r_[kf_rot.position[0], T]
        meas_h = (meas_cam - T) @ R  # R^T (x - T): head motion removed
        motion = np.where(valid[:, None], meas_h - neutral, np.nan)
        false, _ = false_tracking(np.nan_to_num(motion), valid, nidx, threshold=s.false_threshold)
        counts["false_tracking"][t] = false.sum()
        valid &= ~false
        motion[false] = np.nan
        innovation[valid] = 0.8 * innovation[valid] + 0.2 * near[valid]
        # markers seen before: their own last motion plus the neighbours' motion since;
        # never seen (or no such neighbour): eq. 5.8 from the neighbours' motion now
        since, filled_since = conjecture_since_last_seen(motion, valid, nidx, ndist, last_motion, last_frame,
                                                         head_frame - neutral[None])
        filled_motion, filled = conjecture_motion(motion, valid, nidx, ndist)
        filled_motion = np.where(filled_since[:, None], since, filled_motion)
        filled |= filled_since
        z = np.where(valid[:, None], meas_h, neutral + np.nan_to_num(filled_motion))
        sigma = np.where(valid, s.measure_sigma_mm, s.conjecture_sigma_mm)
        out_h = kf.update(z, sigma, valid | filled)
        reported = valid | filled
        last_motion[valid] = motion[valid]
        last_frame[valid] = t
        kf.velocity[~reported] = 0.0  # lost and not conjecturable: hold still rather than drift away
        points[t] = np.where(reported[:, None], out_h @ R.T + T, np.nan)
        head_frame[t] = np.where(reported[:, None], out_h, np.nan)
        conjectured[t] = filled
        counts["conjectured"][t] = filled.sum()
        counts["measured"][t] = valid.sum()
        if len(cand.points):
            blobs = cand.mirror_blob[np.maximum(a, 0)]
            mask = 1 | ((blobs[:, 0] >= 0) << 1) | (((blobs[:, 1] >= 0) << 2) if blobs.shape[1] > 1 else 0)
            camera_mask[t] = np.where(valid, mask, 0)
            assigned_blob[t] = np.where(valid, cand.direct[np.maximum(a, 0)], -1)
        if progress:
            progress(t + 1, F)
    labels = [f"m{i:03d}" for i in range(N)]
    return TrackResult(labels=labels, points=points, conjectured=conjectured, camera_mask=camera_mask,
                       head_pose=head_pose, neutral=neutral, first_blob=first_blob, assigned_blob=assigned_blob,
                       colour=colour, head_frame=head_frame, stats=counts)
