"""A fast dot's gap measured where its 2D tracks bracket it, and its dot followed on along all its 2D tracks
after its last measurement (:func:`bridge_gaps_along_2d_tracks`), with
the face's surface normals at its markers (:func:`..geometry.surface.surface_normals`) to refuse a view that
sees the dot at a grazing angle."""

from __future__ import annotations

import numpy as np

from ..geometry.mirror import reflect_points
from ..geometry.rigid import rotation_zyx, to_head_frame
from ..geometry.surface import seen_face_on, surface_normals
from ..capture.views import ClipDetections
from .candidates import ClipCandidates
from .result import TrackResult, camera_mask_of
from .singleview import claimed_blobs, measured_blobs

#: a gap is bridged only where the dot moves at least this far in one frame of it (a slow dot's gap is the
#: passes' verdict on its blobs, not an expression outrunning them: the light clip got 3 points over 2 mm)
BRIDGE_STEP_MM = 1.0
#: ... and only where the camera and each mirror used see the dot within this angle of its surface normal: a
#: grazing image drifts off its dot along the 2D track (webcam: 12 of 26 bridged cells over 2 mm without this
#: test on the mirrors; vga480 a chin dot's bridge through a merged direct image without it on the camera)
BRIDGE_GRAZING_DEG = 80.0
#: ... and only a gap of this many frames or more: one missing frame is the passes' verdict with the dot's
#: position known on both sides (a false blob beside a missed detection continues its 2D track: the tracking
#: tests' harness of false blobs got an identity switch from a one-frame bridge)
BRIDGE_MIN_FRAMES = 2


def bridge_gaps_along_2d_tracks(result: TrackResult, det: ClipDetections, cands: ClipCandidates, tracks,
                                planes) -> TrackResult:
    """Offline, a marker's gap measured where the 2D tracks bracket it (:func:`.pairing.track_2d`;
    ``tracks``: :func:`.pairing.candidate_tracks`). A fast lip (fast540: 3-7 mm a frame, its velocity
    changing by 4 mm from frame to frame) outruns the passes' gate and the 2D following's prediction,
    and one view's 2D track breaks; the other view's track runs on through the gap, and the broken
    one's two pieces each continue one end. So, between two measurements ``a`` and ``b`` of a marker
    whose direct track, or whose track in one mirror, is the same at both ends, every frame of the gap
    takes the one candidate whose direct track is the marker's at ``a`` or at ``b``, whose mirror
    tracks are each the marker's at ``a`` or at ``b`` in that mirror, and whose blobs no other marker
    measures then -- when the gap spans :data:`BRIDGE_MIN_FRAMES` or more, every frame of it has one (a
    chain that connects both ends), the dot
    moves :data:`BRIDGE_STEP_MM` or more in a frame of it, and the camera and each mirror it is seen
    through see it within :data:`BRIDGE_GRAZING_DEG` of its surface normal
    (:func:`..geometry.surface.seen_face_on`: the normal of the neutral face turned with the head pose,
    against the direction to the camera or the mirror's virtual camera, the camera centre reflected in
    the plane, eq. 3.9; the camera's own grazing view let a chin dot's bridge take a merged image,
    vga480). ``det``: the clip's detections (:class:`.ClipDetections`); ``planes``: the mirrors'
    ``(normals (K, 3), ds (K,))``.

    After a marker's last measurement ``a`` before the take's end, where only that end vouches, the frames
    from ``a + 1`` take the candidates on the marker's direct track at ``a`` *and* on every mirror track it was
    measured on there (a mirror that loses the dot may drop out, none may join), unclaimed, while each frame
    has one such candidate -- :data:`BRIDGE_MIN_FRAMES` or more, under the same step and face-on tests.
    In place; ``stats["bridged"]`` counts the cells per frame."""
    cand = result.candidate
    F, N = result.assigned_blob.shape
    result.stats["bridged"] = np.zeros(F, int)
    if cand is None or tracks is None or len(tracks[0]) == 0:
        return result
    direct_track, mirror_track = tracks
    K = mirror_track.shape[1]
    measured = (result.assigned_blob >= 0) & (cand >= 0)
    held = claimed_blobs(det, measured_blobs(result, det, cands))          # per view: the blobs markers measure
    keys = [cands.direct] + [cands.mirror_blob[:, k] for k in range(K)]

    def holds(rows):                               # the candidates ``rows`` with a blob some marker measures
        out = np.zeros(len(rows), bool)
        for h, key in zip(held, keys):
            blob = key[rows]
            out[blob >= 0] |= h[blob[blob >= 0]]
        return out

    claimed = holds(np.arange(len(cands.direct)))
    R = rotation_zyx(result.head_pose[:, :3])
    surface = surface_normals(result.neutral)
    normals, ds = np.asarray(planes[0], float), np.asarray(planes[1], float)
    centres = np.vstack([np.zeros(3), reflect_points(np.zeros_like(normals), normals, ds)])   # camera, virtual ones

    def bridge(m, a, block, end):
        """Marker ``m``'s frames after its measurement ``a`` up to ``end`` (its next measurement; None: the chain's
        last frame) measured at the candidates ``block``, one a frame, if the tests pass."""
        if holds(block).any():
            return                                     # bridged into another marker's gap already
        f = cands.frame[block]
        heads = to_head_frame(R[f], result.head_pose[f, 3:], cands.points[block])
        path = np.vstack([result.head_frame[a, m], heads] + ([] if end is None else [result.head_frame[end, m]]))
        if np.linalg.norm(np.diff(path, axis=0), axis=1).max() < BRIDGE_STEP_MM:
            return
        normal = np.einsum("fij,j->fi", R[f], surface[m])
        seen = np.c_[np.ones(block.size, bool), cands.mirror_blob[block] >= 0]       # (n, 1 + K): the views used
        if not np.all(seen_face_on(normal, cands.points[block], centres, BRIDGE_GRAZING_DEG) | ~seen):
            return
        for h, key in zip(held, keys):
            h[key[block][key[block] >= 0]] = True                           # now this marker's
        result.candidate[f, m] = block
        result.points[f, m] = cands.points[block]
        result.head_frame[f, m] = heads
        result.conjectured[f, m] = False
        result.camera_mask[f, m] = camera_mask_of(cands.mirror_blob[block])
        result.assigned_blob[f, m] = cands.direct[block] - det.start[0][f]
        result.stats["bridged"][f] += 1

    # every gap of BRIDGE_MIN_FRAMES or more between two measurements, in one pass: (marker, a, b)
    m_all, f_all = np.nonzero(measured.T)                  # by marker, then frame
    after = np.flatnonzero((m_all[1:] == m_all[:-1]) & (np.diff(f_all) > BRIDGE_MIN_FRAMES))
    gm, ga, gb = m_all[after], f_all[after], f_all[after + 1]
    d_a, d_b = direct_track[cand[ga, gm]], direct_track[cand[gb, gm]]
    m_a, m_b = mirror_track[cand[ga, gm]], mirror_track[cand[gb, gm]]
    through = (d_a == d_b) | np.any((m_a == m_b) & (m_a >= 0), axis=1)   # a view's track runs through the gap
    for m, a, b, da, db, ma, mb in zip(gm[through], ga[through], gb[through], d_a[through], d_b[through],
                                       m_a[through], m_b[through]):
        block = np.arange(cands.start[a + 1], cands.start[b])
        mt = mirror_track[block]
        has = mt >= 0
        dt = direct_track[block]
        ok = ((dt == da) | (dt == db)) & ~claimed[block] & has.any(axis=1)
        block = block[ok & (~has | (mt == ma) | (mt == mb)).all(axis=1)]
        f = cands.frame[block]                          # sorted: one per frame when every step is one frame
        if block.size != b - a - 1 or (block.size > 1 and (np.diff(f) != 1).any()):
            continue                                   # a frame with none, or with two
        bridge(m, a, block, b)
    # a marker's last measurement before the take's end, its dot's direct track and the mirror tracks it was
    # measured on running on (only one end vouches, so all of them): followed on while every frame has one such
    # candidate. A fast expression's peak can outrun the pass's gate and leave the conjecture far off the dot for
    # good (hq1: a dot by the nose, 10 mm up and back in 5 frames, lost at its peak with 61 frames to go)
    last = F - 1 - np.argmax(measured[::-1], axis=0)
    open_m = np.flatnonzero(measured.any(axis=0) & (last < F - 1))
    by_track = np.argsort(direct_track, kind="stable")          # candidates by direct track, then index (frame)
    sorted_tracks = direct_track[by_track]
    for m in open_m:
        a = last[m]
        da, ma = direct_track[cand[a, m]], mirror_track[cand[a, m]]
        if da < 0 or not (ma >= 0).any():
            continue
        block = by_track[np.searchsorted(sorted_tracks, da, "left"):np.searchsorted(sorted_tracks, da, "right")]
        block = block[block >= cands.start[a + 1]]
        mt = mirror_track[block]
        shared = ((mt == ma) & (ma >= 0)).sum(axis=1)                # the marker's mirror tracks each continues
        ok = ~claimed[block] & ((mt == ma) | ((mt < 0) & (ma >= 0))).all(axis=1) & (shared > 0)
        block, shared = block[ok], shared[ok]
        if block.size < BRIDGE_MIN_FRAMES:
            continue
        # per frame the candidate sharing the most tracks (the fused one of a dot seen in both mirrors, not its
        # single-mirror pairings); a tie is two dots
        f = cands.frame[block]
        order = np.lexsort((-shared, f))
        block, f, shared = block[order], f[order], shared[order]
        lead = np.flatnonzero(np.r_[True, f[1:] != f[:-1]])
        nxt = np.minimum(lead + 1, f.size - 1)
        tied = (nxt > lead) & (f[nxt] == f[lead]) & (shared[nxt] == shared[lead])
        block, f = block[lead], f[lead]
        run = (f == a + 1 + np.arange(f.size)) & ~tied
        n = int(np.argmin(run)) if not run.all() else run.size      # the chain from a + 1, one candidate a frame
        if n >= BRIDGE_MIN_FRAMES:
            bridge(m, a, block[:n], None)
    return result
