"""Motion transfer: a take captured on the actor's head drives another character's mesh, which
needs no shape keys and no MirrorCap groups -- only ``lm_<name>`` landmarks
(Lin 2003, section 7.3 and figure 7.13; Huang, Lin & Ouhyoung 2000, section 4).

1. **The actor's dense motion.** The take binds to the actor's head (:func:`..face.bind.bind_take`).
   Where the head carries the ARKit expressions (the generic head, and the head fitted to the
   performer through the same fit), their weights (:func:`.arkit.solve_weights`) give a dense prior
   ``sum_k w_k S_k``; the face rig (regions, jaw rule, inner lip; :class:`..face.facerig.FaceRig`)
   then scatters the markers' departures from that prior, so every marker's vertex still follows its
   marker exactly and motion outside the shapes' span is kept. The lids close where the actor's
   ``eyeBlink`` weights say (the rig's random blinks only when the head has no such shape).
2. **Correspondence** (:func:`correspond`). The actor's head is fitted onto the target's surface by
   the scan-fit path (:func:`..face.headfit.fit_head`: landmark similarity, landmark RBF of eq.
   7.1-7.2, then projection rounds). Each target vertex takes the nearest point of the fitted
   actor's triangles; its barycentric weights form the sparse transport matrix. Across the mouth
   slit and the upper lids, where the motion jumps, each side is voted over the target's own mesh
   so a vertex near a slit does not take the other side's motion.
3. **Scaling by feature distances** (seed 001, section 4). Displacements are expressed in the face's
   own axes (lateral, down, forward) and scaled per axis by the target-to-actor ratio of feature
   distances: for the upper face the distance between the eyes and from the eye line to the nose
   tip; for the lower face the mouth width and the nose-tip-to-chin distance; in depth the
   distance from the cheek line (the outer eye corners) forward to the upper lip. The upper and
   lower scales blend from the nose tip down to the upper lip. Then they are turned into the
   target's axes.

Shapes: actor motion ``(F, Va, 3)``, target motion ``(F, Vt, 3)``, millimetres, each head's frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..common.errors import InputError
from ..face.animate import take_frame_range
from ..face.bind import Binding, bind_take
from ..face.facerig import JAW_RIDING, FaceRig, RigSettings
from ..face.head import LANDMARKS, NOT_SKIN, REGIONS, HeadModel
from ..face.headfit import fit_head
from .arkit import arkit_basis, solve_weights

#: the landmarks motion transfer needs on both heads (``lm_lower_lip`` is optional)
TRANSFER_LANDMARKS = ("nose_tip", "eye_inner_l", "eye_outer_l", "eye_inner_r", "eye_outer_r", "mouth_corner_l",
                      "mouth_corner_r", "chin", "upper_lip", "tragus_l", "tragus_r")
#: the actor head's separate pieces: the target's main mesh never takes their motion
DETACHED_PARTS = ("teeth_upper", "teeth_lower", "eyeball_l", "eyeball_r")
FEATURES = ("eye_distance", "eye_to_nose", "mouth_width", "nose_to_chin", "cheek_to_lip")
FACING_PENALTY_MM = 2.0  # correspondence cost of a triangle facing the opposite way (x (1 - cos))
REACH_MM = 12.0          # a target vertex further than this from the fitted actor fades out of the motion


def missing_landmarks(head: HeadModel) -> list:
    """The :data:`TRANSFER_LANDMARKS` ``head`` lacks, as group names (``lm_<name>``)."""
    lms = head.landmarks()
    return [f"lm_{n}" for n in TRANSFER_LANDMARKS if n not in lms]


def check_landmarks(head: HeadModel, role: str) -> None:
    missing = missing_landmarks(head)
    if missing:
        raise InputError(f"the {role} {head.name!r} lacks the landmark vertex groups {', '.join(missing)} "
                         "(place them with the Retarget panel's Place Landmarks, or name vertex groups so)")


def face_frame(head: HeadModel) -> tuple[np.ndarray, np.ndarray]:
    """The face's axes as rows ``(3, 3)`` (lateral, down, forward) and its origin (between the tragi)."""
    ax = head.face_axes()
    return np.stack([ax["lateral"], ax["down"], ax["forward"]]), ax["origin"]


def feature_distances(head: HeadModel) -> dict:
    """Seed 001's feature distances (section 4) from the landmarks, in mm: see the module text."""
    check_landmarks(head, "head")
    lm, V = head.landmarks(), head.vertices
    A, _ = face_frame(head)
    p = {n: A @ V[i] for n, i in lm.items()}          # landmark coordinates in the face's axes
    eye_l = 0.5 * (p["eye_inner_l"] + p["eye_outer_l"])
    eye_r = 0.5 * (p["eye_inner_r"] + p["eye_outer_r"])
    eye_line = 0.5 * (eye_l[1] + eye_r[1])
    cheek = 0.5 * (p["eye_outer_l"][2] + p["eye_outer_r"][2])
    out = {"eye_distance": abs(eye_l[0] - eye_r[0]),
           "eye_to_nose": p["nose_tip"][1] - eye_line,
           "mouth_width": abs(p["mouth_corner_l"][0] - p["mouth_corner_r"][0]),
           "nose_to_chin": p["chin"][1] - p["nose_tip"][1],
           "cheek_to_lip": p["upper_lip"][2] - cheek}
    bad = [k for k, v in out.items() if not v > 1.0]
    if bad:
        raise InputError(f"the landmarks of {head.name!r} give no usable {', '.join(bad)} (landmarks misplaced?)")
    return {k: float(v) for k, v in out.items()}


def region_scales(actor: HeadModel, target: HeadModel) -> dict:
    """Per-axis scale factors ``{"upper": (lateral, down, forward), "lower": (...)}``, target over actor."""
    a, t = feature_distances(actor), feature_distances(target)
    r = {k: t[k] / a[k] for k in FEATURES}
    return {"upper": [r["eye_distance"], r["eye_to_nose"], r["cheek_to_lip"]],
            "lower": [r["mouth_width"], r["nose_to_chin"], r["cheek_to_lip"]],
            "feature_distances_mm": {"actor": a, "target": t}}


def lower_face_weight(head: HeadModel, points) -> np.ndarray:
    """0 above the nose tip, 1 below the upper lip, linear between (in the face's down axis)."""
    A, _ = face_frame(head)
    lm = head.landmarks()
    y = np.asarray(points, float) @ A[1]
    y0, y1 = head.vertices[lm["nose_tip"]] @ A[1], head.vertices[lm["upper_lip"]] @ A[1]
    return np.clip((y - y0) / max(y1 - y0, 1e-6), 0.0, 1.0)


def _closest_on_triangles(P, A, B, C):
    """Closest points of ``P (n, 3)`` on triangles ``A, B, C (n, 3)``: barycentric ``(n, 3)`` and distance."""
    AB, AC, AP = B - A, C - A, P - A
    d1, d2 = np.einsum("ij,ij->i", AB, AP), np.einsum("ij,ij->i", AC, AP)
    BP, CP = P - B, P - C
    d3, d4 = np.einsum("ij,ij->i", AB, BP), np.einsum("ij,ij->i", AC, BP)
    d5, d6 = np.einsum("ij,ij->i", AB, CP), np.einsum("ij,ij->i", AC, CP)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    bary = np.zeros((len(P), 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        den = va + vb + vc
        v, w = vb / den, vc / den
        bary[:] = np.c_[1 - v - w, v, w]                                     # inside the face
        # Voronoi regions of the vertices and edges (Ericson, Real-Time Collision Detection, 5.1.5)
        e_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        t = d1 / (d1 - d3)
        bary[e_ab] = np.c_[1 - t, t, 0 * t][e_ab]
        e_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        t = d2 / (d2 - d6)
        bary[e_ac] = np.c_[1 - t, 0 * t, t][e_ac]
        e_bc = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        bary[e_bc] = np.c_[0 * t, 1 - t, t][e_bc]
    bary[(d1 <= 0) & (d2 <= 0)] = [1, 0, 0]
    bary[(d3 >= 0) & (d4 <= d3)] = [0, 1, 0]
    bary[(d6 >= 0) & (d5 <= d6)] = [0, 0, 1]
    bary = np.nan_to_num(bary, nan=1.0 / 3.0)
    Q = bary[:, :1] * A + bary[:, 1:2] * B + bary[:, 2:] * C
    return bary, np.linalg.norm(P - Q, axis=1)


def guess_landmarks(generic: HeadModel, target: HeadModel, rounds: int = 4) -> dict:
    """A first guess of the landmarks ``target`` lacks, from the ones it has (at least 4 the generic head
    shares): the generic head fitted onto the target by the scan-fit path (:func:`..face.headfit.fit_head`),
    each missing landmark at the target vertex nearest the fitted generic landmark.
    Returns ``{name: target vertex}`` for the missing ones."""
    from scipy.spatial import cKDTree

    have, glm = target.landmarks(), generic.landmarks()
    shared = [n for n in have if n in glm]
    if len(shared) < 4:
        raise InputError(f"a first guess needs at least 4 landmarks placed on {target.name!r} "
                         f"(it has {len(shared)}: {', '.join(sorted(shared)) or 'none'})")
    fit = fit_head(generic, target.vertices, target.triangles(), {n: target.vertices[have[n]] for n in shared},
                   rounds=rounds)
    missing = [n for n in LANDMARKS if n in glm and n not in have]
    if not missing:
        return {}
    _, idx = cKDTree(target.vertices).query(fit.vertices[[glm[n] for n in missing]])
    return {n: int(i) for n, i in zip(missing, np.atleast_1d(idx))}

def _candidate_triangles(V, T, points, k: int, sample_mm: float):
    """Pairs ``(point index, triangle index)``, sorted: the triangles of the ``k`` sample spots nearest each point,
    the triangles sampled on a barycentric grid no coarser than ``sample_mm`` (long slivers too); a spot that
    several triangles share (a vertex, an edge's points) brings them all."""
    import scipy.sparse as sp
    from scipy.spatial import cKDTree

    edges = np.stack([np.linalg.norm(V[T[:, a]] - V[T[:, b]], axis=1) for a, b in ((0, 1), (1, 2), (2, 0))], 1)
    n_div = np.clip(np.ceil(edges.max(1) / sample_mm), 1, 8).astype(int)
    samples, owner = [], []
    for n in np.unique(n_div):
        sel = np.flatnonzero(n_div == n)
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = (i + j) <= n
        bary = np.c_[i[keep], j[keep], n - i[keep] - j[keep]] / n                  # (S, 3)
        pts = np.einsum("sk,tkd->tsd", bary, V[T[sel]])                            # (t, S, 3)
        samples.append(pts.reshape(-1, 3))
        owner.append(np.repeat(sel, len(bary)))
    samples, owner = np.concatenate(samples), np.concatenate(owner)
    # a vertex or an edge point is sampled once per triangle that holds it: such a sample counts once and brings
    # every triangle that holds it (else the k nearest can all be one spot's copies, which of them float rounding
    # decides: a character made from the head by subdivision and imported in centimetres missed, for one vertex
    # on an edge, the triangle the plain import takes, and took the other one on that edge)
    spot, first, of_spot = np.unique(np.round(samples, 6), axis=0, return_index=True, return_inverse=True)
    holds = sp.csr_matrix((np.ones(len(owner)), (of_spot.ravel(), owner)), shape=(len(spot), len(T)))
    _, nn = cKDTree(samples[first]).query(points, k=min(k, len(spot)))
    nn = nn.reshape(len(points), -1)
    near = sp.csr_matrix((np.ones(nn.size), (np.repeat(np.arange(len(points)), nn.shape[1]), nn.ravel())),
                         shape=(len(points), len(spot)))
    pairs = near @ holds                                                          # each triangle once per point
    pairs.sort_indices()
    pairs = pairs.tocoo()
    return pairs.row.astype(int), pairs.col.astype(int)


SIDE_VOTE_RINGS = 3      # mesh rings over which the side of a slit (lips, lids) is voted


def motion_classes(head: HeadModel) -> np.ndarray:
    """Per vertex, which side of a slit in the motion it is on: 0 the rest, 1 riding the jaw (the
    regions below the mouth slit, the lower teeth and inner lip), 2 and 3 the left and right upper lids."""
    lab = head.region_labels()
    out = np.zeros(len(head.vertices), np.int64)
    out[np.isin(lab, [REGIONS.index(r) for r in JAW_RIDING])] = 1
    out[head.members("teeth_lower")] = 1
    out[head.members("inner_lip_lower")] = 1
    out[head.members("eyelid_upper_l")] = 2
    out[head.members("eyelid_upper_r")] = 3
    return out


SKIN, PARTS, ANY = 0, 1, 2   # which of the actor's triangles a target vertex may take (correspond)


def _candidates_by_kind(Vf, T, P, verts, tri_ok, kind, skin_tri, candidates: int, sample_mm: float):
    """:func:`_candidate_triangles` of the target vertices ``verts`` among the triangles ``tri_ok``, each
    vertex further limited by its ``kind`` (per target vertex): ``SKIN`` the actor's skin triangles
    (``skin_tri``), ``PARTS`` the others, ``ANY`` all. Returns ``(target vertex, triangle)`` pairs, sorted
    by target vertex."""
    rows, tris = [np.zeros(0, int)], [np.zeros(0, int)]
    for k, allowed in ((SKIN, tri_ok & skin_tri), (PARTS, tri_ok & ~skin_tri), (ANY, tri_ok)):
        vs, ts = verts[kind[verts] == k], np.flatnonzero(allowed)
        if vs.size and ts.size:
            r, t = _candidate_triangles(Vf, T[ts], P[vs], candidates, sample_mm=sample_mm)
            rows.append(vs[r])
            tris.append(ts[t])
    rows, tris = np.concatenate(rows), np.concatenate(tris)
    order = np.argsort(rows, kind="stable")
    return rows[order], tris[order]


def _facing_cost(Vf, T, tn, P, normals, rows, tris):
    """For pairs ``(point rows, triangle tris)``: the closest point's barycentric weights, its distance,
    and the cost -- the distance plus :data:`FACING_PENALTY_MM` per unit of ``1 - cos`` between the
    triangle's normal ``tn`` and the point's ``normals``."""
    bary, dist = _closest_on_triangles(P[rows], *(Vf[T[tris, j]] for j in range(3)))
    return bary, dist, dist + FACING_PENALTY_MM * (1.0 - np.einsum("ij,ij->i", tn[tris], normals[rows]))


def _vertex_adjacency(head: HeadModel):
    """The head's vertex adjacency (symmetric, CSR) from its mesh edges."""
    import scipy.sparse as sp

    e = head.edges()
    n = len(head.vertices)
    return sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                         shape=(n, n)).tocsr()


def _mesh_pieces(head: HeadModel) -> np.ndarray:
    """Per vertex, the connected piece of the head's mesh it belongs to."""
    from scipy.sparse.csgraph import connected_components

    return connected_components(_vertex_adjacency(head), directed=False)[1]


def _cheapest(rows, cost, n: int) -> np.ndarray:
    """Per point ``0..n-1``, the index (into ``rows``/``cost``) of its cheapest candidate."""
    order = np.lexsort((cost, rows))
    first = np.unique(rows[order], return_index=True)[1]
    out = np.full(n, -1)
    out[rows[order[first]]] = order[first]
    return out


def _vote_on_mesh(head: HeadModel, labels, rings: int) -> np.ndarray:
    """``labels (V,)`` after ``rings`` rounds of each vertex taking the most common label of itself and
    its mesh neighbours (a tie keeps its own)."""
    A = _vertex_adjacency(head)
    n = A.shape[0]
    lab = np.asarray(labels, np.int64)
    k = int(lab.max(initial=0)) + 1
    for _ in range(rings):
        onehot = np.zeros((n, k))
        onehot[np.arange(n), lab] = 1.0
        votes = A @ onehot + 1.5 * onehot          # its own label counts 1.5: ties keep it
        lab = np.argmax(votes, axis=1)
    return lab


@dataclass
class Correspondence:
    transport: object              # scipy.sparse (Vt, Va): target displacement = transport @ actor displacement
    fitted: np.ndarray             # (Va, 3) the actor's head fitted onto the target (target frame, mm)
    distance_mm: np.ndarray        # (Vt,) each target vertex to the fitted actor's surface
    lower_weight: np.ndarray       # (Vt,) 0 upper face .. 1 lower face, at each target vertex's actor point
    fit_report: dict = field(default_factory=dict)


def correspond(actor: HeadModel, target: HeadModel, rounds: int = 4, reach_mm: float = REACH_MM,
               candidates: int = 12, exclude_groups=NOT_SKIN) -> Correspondence:
    """Fit ``actor`` onto ``target``'s surface and tie every target vertex to the nearest point of the
    fitted actor's triangles (among those of its ``candidates`` nearest triangle samples; a triangle
    facing away costs :data:`FACING_PENALTY_MM` per unit of ``1 - cos``). Across a slit in the motion
    (:func:`motion_classes`) the side is voted over the target's mesh and a vertex that landed on the
    other side takes its nearest triangle on its own. A target vertex further than ``reach_mm`` fades
    out linearly (to no motion at twice the reach)."""
    import scipy.sparse as sp

    check_landmarks(actor, "actor's head")
    check_landmarks(target, "target")
    lt = target.landmarks()
    fit = fit_head(actor, target.vertices, target.triangles(), {n: target.vertices[i] for n, i in lt.items()},
                   rounds=rounds, exclude_groups=exclude_groups)
    Vf = fit.vertices
    T = actor.triangles()
    P = target.vertices
    # Skin and separate parts do not mix. The target's main mesh (its skin, the inside of its lips) never
    # takes the motion of the actor's separate parts (teeth, eyeballs): behind a thin lip the actor's lower
    # teeth can be nearer than its inner lip, and a character's inner lip then stayed with the teeth while
    # its lip moved (a crumple below the lip). Each other piece of the target's mesh (its teeth, its eyes)
    # takes either parts or skin, as most of its vertices land, so a tooth near the lip moves with its tooth.
    parts = np.zeros(len(Vf), bool)
    for g in DETACHED_PARTS:
        if g in actor.groups:
            parts[actor.members(g)] = True
    skin_tri = ~parts[T].all(axis=1)
    piece = _mesh_pieces(target)
    main = piece == np.argmax(np.bincount(piece))
    kind = np.where(main, SKIN, ANY)
    # where two surfaces touch (the closed lips, a lid on the eyeball) the nearest point can lie on the
    # wrong one: a triangle facing away from the target vertex's normal costs extra
    tn = np.cross(Vf[T[:, 1]] - Vf[T[:, 0]], Vf[T[:, 2]] - Vf[T[:, 0]])
    tn /= np.maximum(np.linalg.norm(tn, axis=1, keepdims=True), 1e-12)
    normals = target.vertex_normals()
    rows, tris = _candidates_by_kind(Vf, T, P, np.arange(len(P)), np.ones(len(T), bool), kind, skin_tri,
                                     candidates, 1.5 * fit.scale)
    if not main.all():
        landed = tris[_cheapest(rows, _facing_cost(Vf, T, tn, P, normals, rows, tris)[2], len(P))]
        share = np.bincount(piece, ~skin_tri[landed]) / np.bincount(piece)
        kind = np.where(main, SKIN, np.where(share[piece] > 0.5, PARTS, SKIN))
        others = np.flatnonzero(~main)        # their candidates again, among their piece's kind
        r2, t2 = _candidates_by_kind(Vf, T, P, others, np.ones(len(T), bool), kind, skin_tri, candidates,
                                     1.5 * fit.scale)
        keep = main[rows]
        rows, tris = np.r_[rows[keep], r2], np.r_[tris[keep], t2]
    bary, dist, cost = _facing_cost(Vf, T, tn, P, normals, rows, tris)
    pick = _cheapest(rows, cost, len(P))
    # the lips' slit and the lids' slit: the motion jumps across them, and a target vertex within a few
    # mm of one can land on the wrong side. Each side is a connected piece of the target's own mesh, so
    # the side is voted over its neighbours and the vertices that landed on the other side move back
    tri_class = motion_classes(actor)[T]
    tri_class = np.where(tri_class[:, 0] == tri_class[:, 1], tri_class[:, 0], tri_class[:, 2])   # majority
    side = _vote_on_mesh(target, tri_class[tris[pick]], SIDE_VOTE_RINGS)
    tri, w, best = tris[pick], bary[pick], dist[pick]
    for c in np.unique(side):
        move = np.flatnonzero((side == c) & (tri_class[tri] != c))
        if move.size == 0 or not (tri_class == c).any():
            continue
        # their nearest triangles on their own side (the first candidates were all across the slit)
        r2, t2 = _candidates_by_kind(Vf, T, P, move, tri_class == c, kind, skin_tri, candidates, 1.5 * fit.scale)
        r2 = np.searchsorted(move, r2)
        if r2.size == 0:
            continue
        b2, d2, c2 = _facing_cost(Vf, T, tn, P[move], normals[move], r2, t2)
        p2 = _cheapest(r2, c2, move.size)
        has = p2 >= 0
        tri[move[has]], w[move[has]], best[move[has]] = t2[p2[has]], b2[p2[has]], d2[p2[has]]
    r = np.arange(len(P))
    fade = np.clip(2.0 - best / (reach_mm * fit.scale), 0.0, 1.0)
    transport = sp.csr_matrix(((w * fade[r, None]).ravel(), (np.repeat(r, 3), T[tri].ravel())),
                              shape=(len(P), len(Vf)))
    lower = transport @ lower_face_weight(actor, actor.vertices)
    lower = np.where(fade > 0, lower / np.maximum(fade, 1e-12), lower)
    return Correspondence(transport=transport, fitted=Vf, distance_mm=best, lower_weight=np.clip(lower, 0, 1),
                          fit_report={"scale": fit.scale, "landmark_rms_mm": fit.landmark_rms_mm,
                                      "residual_rms_mm": fit.residual_rms_mm, "residual_max_mm": fit.residual_max_mm,
                                      "target_vertices_within_reach": int((best <= reach_mm * fit.scale).sum()),
                                      "target_vertices": int(len(P))})


def actor_motion(head: HeadModel, shape_keys: dict | None, binding: Binding, rate: float,
                 settings: RigSettings | None = None, frames: tuple | None = None) -> tuple[np.ndarray, dict]:
    """The actor head's dense motion ``(F, Va, 3)`` (step 1 of the module text) at the take frames ``frames =
    (START, END)`` (default: all) and its parts there: ``weights`` (the ARKit prior's, or None), ``blink``. The
    prior is solved over the whole take and the lids blink as in the whole take, so a stretch moves as it does
    there."""
    settings = settings or RigSettings()
    n_take = binding.displacements.shape[0]
    start, end = take_frame_range(frames, n_take)
    F = end - start
    prior = np.zeros((F, len(head.vertices), 3))
    parts = {"weights": None, "names": [], "prior_solve": None}
    arkit = {}
    if shape_keys:
        try:
            names, basis = arkit_basis(shape_keys, binding.vertices)
            arkit = {"names": names, "basis": basis}
        except InputError:
            arkit = {}
    if arkit:
        solve = solve_weights(arkit["basis"], binding.displacements, arkit["names"])
        by_lower = {k.lower(): k for k in shape_keys}
        S = np.stack([np.asarray(shape_keys[by_lower[n.lower()]], float) for n in solve.names])   # (K, Va, 3)
        solve = solve.frames(start, end)                                               # the stretch's
        prior = (solve.weights @ S.reshape(len(S), -1)).reshape(F, -1, 3)              # one BLAS product
        parts.update(weights=solve.weights, names=solve.names, prior_solve=solve)
        if any(n.lower().startswith("eyeblink") for n in solve.names):
            settings = replace(settings, blinks=False)        # the prior closes the lids as the actor's do
    rig = FaceRig(head, binding.vertices, settings)
    D, rig_parts = rig.deform(binding.displacements[start:end] - prior[:, binding.vertices], fps=rate, with_parts=True,
                              closure=rig.closure(n_take, rate)[start:end])
    parts.update(jaw_angle=rig_parts["jaw_angle"], blink=rig_parts["blink"])
    return prior + D, parts


def transfer_displacements(actor: HeadModel, target: HeadModel, corr: Correspondence, motion,
                           scales: dict, dtype=np.float32) -> np.ndarray:
    """The actor's motion ``(F, Va, 3)`` carried onto the target ``(F, Vt, 3)``: transported by the
    correspondence, scaled per axis in the face's axes (upper and lower face blended), turned into
    the target's axes."""
    A, _ = face_frame(actor)
    B, _ = face_frame(target)
    M = np.asarray(motion)
    F, Va, _ = M.shape
    # actor axes, vertex-major (Va, F * 3): the transport is one sparse product over every frame
    local = np.ascontiguousarray((M.reshape(-1, 3) @ A.T).reshape(F, Va, 3).transpose(1, 0, 2), dtype=dtype)
    moved = (corr.transport.astype(dtype) @ local.reshape(Va, F * 3)).reshape(-1, F, 3)       # (Vt, F, 3)
    up, low = np.asarray(scales["upper"], float), np.asarray(scales["lower"], float)
    # the per-vertex scale blends two fixed maps (upper, lower face: scale per axis, then the target's
    # axes), so each is one (n, 3) x (3, 3) BLAS product over a block of frames
    w = corr.lower_weight.astype(dtype)[:, None, None]
    T_up, T_low = (up[:, None] * B).astype(dtype), (low[:, None] * B).astype(dtype)
    Vt = moved.shape[0]
    out = np.empty((F, Vt, 3), dtype)
    for f0 in range(0, F, 128):
        blk = moved[:, f0:f0 + 128]
        n = blk.shape[1]
        flat = blk.reshape(-1, 3)
        mixed = (flat @ T_up).reshape(Vt, n, 3) * (1 - w) + (flat @ T_low).reshape(Vt, n, 3) * w
        out[f0:f0 + n] = mixed.transpose(1, 0, 2)
    return out


@dataclass
class Transfer:
    displacements: np.ndarray      # (F, Vt, 3) target mm, target frame
    binding: Binding
    correspondence: Correspondence
    scales: dict
    parts: dict

    def report(self) -> dict:
        c = self.correspondence
        w = self.parts.get("weights")
        out = {"region_scales": {"upper": self.scales["upper"], "lower": self.scales["lower"],
                                 "axes": ["lateral", "down", "forward"]},
               "feature_distances_mm": self.scales["feature_distances_mm"],
               "correspondence": c.fit_report,
               "binding": {"markers": len(self.binding.labels), "registration": self.binding.registration,
                           "landmark_rms_mm": self.binding.landmark_rms_mm},
               "lids": "actor's eyeBlink weights" if w is not None and any(
                   n.lower().startswith("eyeblink") for n in self.parts["names"]) else "random blinks (face rig)"}
        if self.parts.get("prior_solve") is not None:
            out["residual_mm"] = self.parts["prior_solve"].report()["residual_mm"]
        return out


def transfer_take(actor: HeadModel, shape_keys: dict | None, target: HeadModel, labels, points, rate: float, *,
                  neutral_frame: int = 0, head_pose=None, marker_map: dict | None = None, unseen: str = "error",
                  settings: RigSettings | None = None, progress=None, frames: tuple | None = None) -> Transfer:
    """The whole transfer (module text): bind, the actor's dense motion, correspondence, scaling; of the take
    frames ``frames = (START, END)`` (default: all; the whole take bound, :func:`actor_motion`)."""
    check_landmarks(target, "target")
    if progress:
        progress(0.05, "binding")
    binding = bind_take(actor, labels, points, neutral_frame=neutral_frame, head_pose=head_pose,
                        marker_map=marker_map, unseen=unseen)
    if progress:
        progress(0.2, "actor motion")
    motion, parts = actor_motion(actor, shape_keys, binding, rate, settings, frames)
    if progress:
        progress(0.45, "correspondence")
    corr = correspond(actor, target)
    scales = region_scales(actor, target)
    if progress:
        progress(0.6, "transfer")
    D = transfer_displacements(actor, target, corr, motion, scales)
    return Transfer(D, binding, corr, scales, parts)
