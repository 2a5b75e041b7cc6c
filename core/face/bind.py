"""Registering a take to a head (the step between the 3D take and the face rig).

1. Head motion is removed: each frame's markers are brought into the neutral
   frame's head pose, from the take's own head pose (REPORT.json, ``camera = R p + t``)
   or, without one, by a robust rigid fit of every frame to the neutral frame
   (iteratively reweighted Arun fit, the weight-compensated idea of Rurainsky &
   Eisert, section 3.3: markers that deform get down-weighted).
2. One similarity transform from the take's neutral frame to the head. Where at least
   three markers' labels name a landmark of the head (``nose_tip`` or ``lm_nose_tip``
   for the group ``lm_nose_tip``, in any case, after a subject's prefix such as Vicon's ``Actor1:``), they anchor it (Umeyama). Otherwise -- the labels
   ``m000``.. of a fully automatic take -- the markers register to the head's skin
   surface by similarity ICP (:func:`register_to_surface`), started from a frontal
   face (the head model is authored facing the camera, as the subject in the rig).
   Gaps (NaN: a marker the tracker did not measure, nor conjecture with confidence) are
   filled in time first (for the head motion), then in the head frame from the
   neighbours' motion through relations learned over the take
   (:func:`core.track.motion.conjecture_gaps`, eq. 5.8 per pair), where a related neighbour is
   measured: the face needs every marker every frame.
3. Every other marker binds to its nearest head vertex on the skin (not eyeballs,
   teeth or the inner lip), one marker per vertex (linear assignment).

The rig then receives each marker's displacement from the neutral frame, in
head millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..common.errors import InputError
from ..common.files import read_json
from ..geometry.rigid import rigid_fit, robust_rigid_fit, rotation_zyx, similarity_fit
from ..track.motion import conjecture_gaps, grown_sd, interpolate_in_time, neighbours
from .head import NOT_SKIN, HeadModel
from .headfit import subdivide

GAP_NEIGHBOUR_RADIUS = 25.0  # take units (mm): neighbours whose learned relations fill a gap
GAP_NEIGHBOURS = 12
UNSEEN_LIMIT_MM = 2.0  # a conjectured neutral position (unseen="conjecture") expected off by more (3 sigma): left out


# The whole-take head-pose fit looks for the markers that deform least over the take, so it
# down-weights harder than the tracker's per-frame fit (c = 1.5 x the median residual against the
# tracker's 2 x 1.4826): with the tracker's constant the head motion is removed 0.08-0.38 mm worse
# on the bind tests' synthetic takes (measured), with this one within their 0.05 mm.
HEAD_POSE_CAUCHY_SCALE = 1.5
SURFACE_RMS_LIMIT_MM = 2.5   # unlabelled markers further than this from the skin: not this head


def _skin_surface(head: HeadModel, exclude_groups, forward_min: float = -0.2):
    """Dense samples of the head's front skin: the triangles of allowed, roughly
    forward-facing vertices, subdivided once; points ``(N, 3)`` and normals ``(N, 3)``."""
    from .head import vertex_normals

    ok = head.skin_mask(exclude_groups)
    n = head.vertex_normals()
    ok &= n @ head.face_axes()["forward"] > forward_min
    T = head.triangles()
    T = T[np.all(ok[T], axis=1)]
    if len(T) < 10:
        raise InputError("the head has too little front skin to register a take to")
    V, T = subdivide(head.vertices, T, 1)
    used = np.unique(T)
    return V[used], vertex_normals(V, T)[used]


def register_to_surface(head: HeadModel, points, exclude_groups=(), iterations: int = 60, trim: float = 0.1):
    """Similarity ``s, R, t`` (head = s R p + t) placing unlabelled markers ``points (M, 3)``
    on the head's skin: ICP minimising each marker's distance to the tangent plane of its
    nearest skin point (a linearised scale-rotation-shift step per iteration), the worst
    ``trim`` of the matches left out, started from the frontal pose turned by 0 and +-15 degrees in
    yaw and pitch; the start with the smallest residual wins. A start whose scale leaves
    0.4-2.5 times the first guess (the markers' spread against the skin's) has collapsed
    onto a patch and counts as no fit (``rms_mm`` infinite). Returns ``s, R, t, rms_mm``."""
    from scipy.spatial import cKDTree
    from scipy.spatial.transform import Rotation


    P = np.asarray(points, float)
    if len(P) < 6:
        raise InputError(f"{len(P)} markers are too few to register to the head's surface (6 or more)")
    S, N = _skin_surface(head, exclude_groups)
    tree = cKDTree(S)
    sc = np.sqrt(np.mean(np.sum((S - S.mean(0)) ** 2, 1)))
    pc = np.sqrt(np.mean(np.sum((P - P.mean(0)) ** 2, 1)))
    s0 = 0.8 * sc / max(pc, 1e-12)          # markers cover a little less of the face than the skin samples
    keep = max(6, int(round((1.0 - trim) * len(P))))
    best = None
    for yaw in (0.0, -15.0, 15.0):
        for pitch in (0.0, -15.0, 15.0):
            R = rotation_zyx(np.radians([[pitch, yaw, 0.0]]))[0]
            s = s0
            t = S.mean(0) + np.array([0.0, 0.0, -0.3 * sc]) - s * R @ P.mean(0)
            for _ in range(iterations):
                X = s * P @ R.T + t
                _, j = tree.query(X)
                r = np.einsum("ij,ij->i", X - S[j], N[j])
                sel = np.argsort(np.abs(r))[:keep]
                # linearised point-to-plane step about the centroid: scale sigma, rotation omega, shift tau
                c = X[sel].mean(0)
                Xc, n = X[sel] - c, N[j[sel]]
                A = np.c_[np.einsum("ij,ij->i", n, Xc), np.cross(Xc, n), n]
                x = np.linalg.solve(A.T @ A + 1e-9 * np.eye(7), -A.T @ r[sel])
                sigma, omega, tau = x[0], x[1:4], x[4:]
                angle = np.linalg.norm(omega)
                dR = Rotation.from_rotvec(omega).as_matrix()
                ds = 1.0 + sigma
                # X' = c + ds dR (X - c) + tau
                s, R, t = ds * s, dR @ R, ds * dR @ (t - c) + c + tau
                if abs(sigma) < 1e-7 and angle < 1e-7 and np.linalg.norm(tau) < 1e-5 * sc:
                    break
            X = s * P @ R.T + t
            _, j = tree.query(X)
            dist = np.abs(np.einsum("ij,ij->i", X - S[j], N[j]))
            rms = float(np.sqrt(np.mean(np.sort(dist)[:keep] ** 2)))
            if not 0.4 * s0 < s < 2.5 * s0:
                rms = float("inf")            # collapsed or blown up: these markers do not cover a face
            if best is None or rms < best[3]:
                best = (float(s), R, t, rms)
    return best


def fill_gaps(points) -> np.ndarray:
    """Linear interpolation in time of NaN gaps ``(F, M, 3)``; ends hold the nearest value."""
    p = np.array(points, float)
    valid = np.all(np.isfinite(p), axis=2)
    if valid.all():
        return p
    if not valid.any(axis=0).all():
        bad = np.flatnonzero(~valid.any(axis=0))
        raise InputError(f"{bad.size} markers are never measured (first: index {bad[0]})")
    return interpolate_in_time(p, valid)


def estimate_head_pose(points, neutral_frame: int = 0, iterations: int = 6, rigid_fraction: float = 0.25):
    """Per-frame ``R (F, 3, 3), t (F, 3)`` with ``points[f] ≈ R[f] @ points[neutral] + t[f]``.

    Two passes in the spirit of weight-compensated motion estimation (Rurainsky & Eisert,
    section 3.3): an iteratively reweighted rigid fit of all markers
    (:func:`..geometry.rigid.robust_rigid_fit`) finds how much each marker
    deforms over the take; the ``rigid_fraction`` that deform least then carry the
    final per-frame fit. Every frame is fitted at once."""
    p = np.asarray(points, float)
    ref = p[neutral_frame]
    M = p.shape[1]
    R, t, _ = robust_rigid_fit(ref, p, iterations - 1, cauchy_scale=HEAD_POSE_CAUCHY_SCALE)
    resid = np.linalg.norm(ref @ np.swapaxes(R, 1, 2) + t[:, None] - p, axis=2)
    rigid = np.argsort(np.sqrt(np.mean(resid ** 2, axis=0)))[: max(4, int(rigid_fraction * M))]
    R, t, _ = robust_rigid_fit(ref[rigid], p[:, rigid], iterations - 1, cauchy_scale=HEAD_POSE_CAUCHY_SCALE)
    return R, t


@dataclass
class Binding:
    labels: list
    vertices: np.ndarray          # (M,) bound head vertex per marker
    distance_mm: np.ndarray       # (M,) marker-to-vertex distance in the neutral frame
    displacements: np.ndarray     # (F, M, 3) head mm, from the neutral frame
    markers_head: np.ndarray      # (F, M, 3) the markers in the head frame
    scale: float                  # head mm per take unit
    landmark_rms_mm: float        # residual of the similarity: over the landmark markers, or to the skin (ICP)
    landmarks_used: list
    registration: str             # "landmarks" or "surface"
    filled: np.ndarray            # (F, M) frames where a gap was filled
    head_motion: tuple = None     # (R (F, 3, 3), t (F, 3)): the head's rigid motion from the neutral frame, head mm
    dropped: list = field(default_factory=list)  # labels left out: not seen in the neutral frame
    conjectured_neutral: list = field(default_factory=list)  # labels bound from a conjectured neutral position


MAP_UNMAPPED, MAP_RIGID, MAP_IGNORE = -1, -2, -3   # marker roles besides a vertex index


def load_marker_map(path) -> dict:
    """A marker map ``{"LABEL": "lm_<name>" | vertex index | "rigid" | "ignore"}`` from JSON
    (README: marker maps), checked for form; :func:`resolve_marker_map` checks it against a
    take and a head."""
    data = read_json(path, "marker map")
    if not isinstance(data, dict) or not data:
        raise InputError(f"{path}: a marker map is a JSON object {{\"LABEL\": \"lm_<name>\" | vertex | \"rigid\" | "
                         "\"ignore\"}} with at least one entry")
    for label, role in data.items():
        ok = (isinstance(role, int) and not isinstance(role, bool) and role >= 0) or \
             (isinstance(role, str) and (role in ("rigid", "ignore") or role.startswith("lm_")))
        if not ok:
            raise InputError(f"{path}: marker {label!r} maps to {role!r}; use \"lm_<name>\", a vertex index (0 or "
                             "more), \"rigid\" or \"ignore\"")
    return data


def resolve_marker_map(marker_map: dict, labels, head: HeadModel) -> np.ndarray:
    """Each marker's role as ``(M,)`` ints: its head vertex (>= 0), :data:`MAP_RIGID` (a marker
    on a rigid part such as a headband: it carries the head motion and is not bound), or
    :data:`MAP_UNMAPPED`, or :data:`MAP_IGNORE` (left out). One message for labels the take
    does not have, landmarks the head does not have, vertices out of range, or two markers
    on one vertex."""
    labels = list(labels)
    unknown = [k for k in marker_map if k not in labels]
    if unknown:
        raise InputError(f"the marker map names {len(unknown)} label(s) the take does not have: "
                         f"{', '.join(unknown[:5])}{', ...' if len(unknown) > 5 else ''} (`mirrorcap info` lists the take's)")
    lms = head.landmarks()
    roles = np.full(len(labels), MAP_UNMAPPED, np.int64)
    for label, role in marker_map.items():
        i = labels.index(label)
        if role == "rigid":
            roles[i] = MAP_RIGID
        elif role == "ignore":
            roles[i] = MAP_IGNORE
        elif isinstance(role, str):
            if role[3:] not in lms:
                raise InputError(f"the marker map puts {label!r} on {role!r}, which the head does not have "
                                 f"(its landmarks: {', '.join('lm_' + n for n in sorted(lms))})")
            roles[i] = lms[role[3:]]
        else:
            if role >= len(head.vertices):
                raise InputError(f"the marker map puts {label!r} on vertex {role}; the head has "
                                 f"{len(head.vertices)} vertices (0..{len(head.vertices) - 1})")
            roles[i] = role
    vertices, counts = np.unique(roles[roles >= 0], return_counts=True)
    if (counts > 1).any():
        raise InputError(f"the marker map puts two markers on vertex {int(vertices[counts > 1][0])}: one marker per vertex")
    n_rigid = int((roles == MAP_RIGID).sum())
    if 0 < n_rigid < 3:
        raise InputError(f"the marker map names {n_rigid} rigid marker(s): head motion needs at least 3 (or none)")
    return roles


def _landmark_of(label: str, landmarks: dict):
    """The landmark a take's marker ``label`` names, or None: ``nose_tip`` or ``lm_nose_tip``, in any case, after a
    subject's prefix as other systems write it (Vicon's ``Actor1:nose_tip``)."""
    name = label.rsplit(":", 1)[-1].strip()
    name = name[3:] if name.lower().startswith("lm_") else name
    if name in landmarks:
        return name
    return next((k for k in landmarks if k.lower() == name.lower()), None)


def bind_take(head: HeadModel, labels, points, neutral_frame: int = 0, head_pose=None,
              exclude_groups=NOT_SKIN, unseen: str = "error", unseen_limit_mm: float = UNSEEN_LIMIT_MM,
              marker_map: dict | None = None) -> Binding:
    """Register a take ``points (F, M, 3)`` (NaN = gap) to ``head``; see the module text.
    Markers not seen in the neutral frame are an error, or with ``unseen="drop"`` are left
    out (``Binding.dropped``; a tracker's markers first seen later in the take). With
    ``unseen="conjecture"`` their neutral-frame position is conjectured from the neighbours'
    learned relations (:func:`core.track.motion.conjecture_gaps`, the gap reaching back from
    their first sighting) and they are bound like the others (``Binding.conjectured_neutral``);
    one whose conjecture is expected off by more than ``unseen_limit_mm`` (3 sigma: the
    relations' sd grown with the square root of the frames to its first sighting) is left
    out. ``marker_map`` (:func:`load_marker_map`) binds named markers to given vertices or
    landmarks (they also anchor the registration), takes the head motion from its
    ``"rigid"`` markers (then not bound), and leaves out its ``"ignore"`` markers."""
    if unseen not in ("error", "drop", "conjecture"):
        raise ValueError("unseen must be 'error', 'drop' or 'conjecture'")
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    p = np.asarray(points, float)
    if p.ndim != 3 or p.shape[2] != 3:
        raise InputError("a take needs points of shape (frames, markers, 3)")
    if p.shape[0] == 0 or p.shape[1] == 0:
        raise InputError(f"the take holds {'no frame' if p.shape[0] == 0 else 'no marker'}: nothing to bind")
    F, M, _ = p.shape
    labels = [str(s) for s in labels]
    if len(labels) != M:
        raise InputError(f"{len(labels)} labels for {M} markers")
    if not 0 <= neutral_frame < F:
        raise InputError(f"the neutral frame {neutral_frame} is outside the take's {F} frames")
    roles = np.full(M, MAP_UNMAPPED, np.int64)
    if marker_map:
        roles = resolve_marker_map(marker_map, labels, head)
        keep = roles != MAP_IGNORE
        p, labels, roles = p[:, keep], [s for s, k in zip(labels, keep) if k], roles[keep]
        F, M, _ = p.shape
    valid = np.all(np.isfinite(p), axis=2)
    seen = valid[neutral_frame]
    dropped = [labels[i] for i in np.flatnonzero(~seen)]
    if dropped and unseen != "error" and seen.sum() < 3:
        raise InputError(f"only {int(seen.sum())} markers are seen in the neutral frame {neutral_frame}")
    if dropped and unseen == "drop":
        p, labels, valid, roles = p[:, seen], [s for s, k in zip(labels, seen) if k], valid[:, seen], roles[seen]
        F, M, _ = p.shape
        seen = valid[neutral_frame]
    late = ~seen if unseen == "conjecture" else np.zeros(M, bool)
    if not (seen | late).all():
        missing = [labels[i] for i in np.flatnonzero(~seen)]
        raise InputError(f"the take's marker count changes: {len(missing)} of {M} markers are missing in the "
                         f"neutral frame {neutral_frame} ({', '.join(missing[:5])}{', ...' if len(missing) > 5 else ''}); "
                         "choose a neutral frame where every marker is seen, place such markers from their "
                         "neighbours (--conjecture-unseen, the commands' default: a tracker's markers first seen "
                         "later) or leave them out (--drop-unseen)")
    head.validate()
    lms = head.landmarks()
    filled = ~valid
    p = fill_gaps(p)
    rigid = roles == MAP_RIGID
    if head_pose is None and rigid.any():    # the map's rigid markers carry the head motion
        if rigid.sum() < 3 or not valid[neutral_frame, rigid].all():
            raise InputError("the marker map's rigid markers must be at least 3 and all seen in the neutral frame")
        R, t = rigid_fit(p[neutral_frame, rigid], p[:, rigid])
    elif head_pose is None:
        R, t = estimate_head_pose(p, neutral_frame)
    else:
        hp = np.asarray(head_pose, float)
        if hp.shape != (F, 3, 4):
            raise InputError(f"head pose must have shape ({F}, 3, 4)")
        # camera = R_f q + t_f for head-frame q: relative to the neutral frame
        Rn, tn = hp[neutral_frame, :, :3], hp[neutral_frame, :, 3]
        R = hp[:, :, :3] @ Rn.T
        t = hp[:, :, 3] - np.einsum("fij,j->fi", R, tn)
    # undo the head motion: q = R^T (p - t), in the neutral frame's pose
    q = np.einsum("fji,fmj->fmi", R, p - t[:, None, :])
    conjectured_neutral = []
    if filled.any():  # gaps follow the neighbours that moved like the marker (time interpolation where none can)
        nidx, _ = neighbours(q[neutral_frame], GAP_NEIGHBOUR_RADIUS)
        # motion from the neutral frame; a marker first seen later: from its first sighting,
        # so its neutral position is the conjecture of the gap reaching back to the neutral frame
        first = np.argmax(valid, axis=0)
        base = q[np.where(late, first, neutral_frame), np.arange(M)]
        motion, sd = conjecture_gaps(q - base, valid, filled, nidx[:, :GAP_NEIGHBOURS])
        q = np.where(np.isfinite(motion[..., :1]), base + motion, q)
        if late.any():
            expected = 3.0 * grown_sd(sd[neutral_frame], np.abs(first - neutral_frame))
            keep = ~late | (expected <= unseen_limit_mm)  # NaN (no related neighbour): left out
            dropped = [labels[i] for i in np.flatnonzero(~keep)]
            conjectured_neutral = [labels[i] for i in np.flatnonzero(late & keep)]
            q, valid, filled, roles = q[:, keep], valid[:, keep], filled[:, keep], roles[keep]
            labels = [lab for lab, k in zip(labels, keep) if k]
            M = len(labels)
    if rigid.any():                          # headband markers: the head motion only, not the skin
        body = roles != MAP_RIGID
        q, valid, filled, roles = q[:, body], valid[:, body], filled[:, body], roles[body]
        labels = [lab for lab, k in zip(labels, body) if k]
        M = len(labels)
        if M == 0:
            raise InputError("the marker map leaves no marker to bind: every marker is rigid or ignored")
    named = [_landmark_of(s, lms) for s in labels]        # a label naming a landmark anchors it
    anchor = [(i, int(r) if r >= 0 else lms[named[i]]) for i, r in enumerate(roles) if r >= 0 or named[i]]
    pairs = [(i, named[i] or f"vertex {v}") for i, v in anchor]
    if len(anchor) >= 3:
        idx = np.array([i for i, _ in anchor])
        target = head.vertices[[v for _, v in anchor]]
        pts = q[neutral_frame, idx]
        if np.linalg.matrix_rank(pts - pts.mean(0), tol=1e-6 * max(1.0, np.abs(pts).max())) < 2:
            raise InputError("the take's landmark markers are collinear: the head's placement is undetermined")
        s, Rs, ts = similarity_fit(pts, target)
        aligned = s * q @ Rs.T + ts
        rms = float(np.sqrt(np.mean(np.sum((aligned[neutral_frame, idx] - target) ** 2, axis=1))))
        registration = "landmarks"
    else:
        s, Rs, ts, rms = register_to_surface(head, q[neutral_frame], exclude_groups)
        if not rms <= SURFACE_RMS_LIMIT_MM:
            raise InputError(f"the take's markers do not lie on the head's skin (surface registration leaves "
                             f"{rms:.1f} mm RMS, limit {SURFACE_RMS_LIMIT_MM} mm): fit the head to the subject first, or label at least 3 landmark "
                             f"markers ({', '.join('lm_' + n for n in sorted(lms)[:3])}, ...)")
        aligned = s * q @ Rs.T + ts
        registration = "surface"
    # bind each marker to its nearest allowed vertex, one marker per vertex (the map's own vertices first)
    vert = np.where(roles >= 0, roles, -1)
    free = np.flatnonzero(vert < 0)
    cand = np.setdiff1d(np.flatnonzero(head.skin_mask(exclude_groups)), vert[vert >= 0])
    if free.size:
        k = min(8, cand.size)
        dist, nn = cKDTree(head.vertices[cand]).query(aligned[neutral_frame, free], k=k)
        dist, nn = dist.reshape(free.size, k), nn.reshape(free.size, k)
        cols, inv = np.unique(nn, return_inverse=True)
        cost = np.full((free.size, cols.size), 1e9)
        cost[np.repeat(np.arange(free.size), k), inv.ravel()] = dist.ravel()
        rows, chosen = linear_sum_assignment(cost)
        if np.any(cost[rows, chosen] >= 1e9):
            raise InputError("markers are too crowded to bind one per vertex")
        vert[free[rows]] = cand[cols[chosen]]
    d = np.linalg.norm(aligned[neutral_frame] - head.vertices[vert], axis=1)
    # the head's motion in the head frame: x -> Rh x + th moves the neutral head onto frame f
    Rh = np.einsum("ij,fjk,lk->fil", Rs, R, Rs)
    th = ts - Rh @ ts + s * t @ Rs.T
    return Binding(labels=labels, vertices=vert, distance_mm=d, displacements=aligned - aligned[neutral_frame],
                   markers_head=aligned, scale=s, landmark_rms_mm=rms,
                   landmarks_used=[n for _, n in pairs] if registration == "landmarks" else [],
                   registration=registration, filled=filled, head_motion=(Rh, th),
                   dropped=dropped if unseen in ("drop", "conjecture") else [], conjectured_neutral=conjectured_neutral)
