"""The face rig: marker displacements -> head vertex displacements, every frame
(Lin 2003, section 7.4 and figure 7.9; Huang, Lin & Ouhyoung 2000, section 4.2).

Control points are the marker-bound vertices, the head's ``fixed`` points (zero
displacement) and hypothetical jaw points near the ears. Per frame:

1. **Regions.** Each of the 11 regions of figure 7.8 (plus the "rest" of the head)
   has its own RBF scattering (eq. 7.1-7.2) from the control points inside it and in
   its neighbours on the same side of the jaw, so e.g. lower-lip markers never pull
   the upper lip. Region membership is smoothed
   over the mesh for a few rings (``blend_rings``) so there is no seam at a border;
   a marker belongs to every region it has weight in, so its vertex follows it exactly.
2. **Jaw rule.** The chin (``lm_chin``) is compared with its neutral position by its
   angle about the hinge axis (near the ears). Above neutral: the lower teeth clamp
   to the upper teeth and the jaw region returns to neutral except around the tip
   (the hypothetical points near the ears hold it). Below: the jaw rotates about the
   hinge axis and stretches (the chin's distance to the axis), a rigid motion; the
   region's RBF then carries only the markers' departures from it.
3. **Inner lower lip.** A Hermite surface (figure 7.9): each column runs from the
   outer lip's inner edge, leaving along the outer lip's surface tangent, to its
   attachment on the lower teeth, arriving along the jaw's tangent.
4. **Blinks.** A seedable random process (mean interval 2.5 s); each upper-lid
   vertex turns about the eyeball's horizontal axis through its centre, so it moves on
   a sphere about the eye, by its ``eyelid_upper`` weight times the angle that shuts
   the lid margin onto the lower lid.
5. **Teeth.** Upper teeth follow the skull (no displacement in the head frame),
   lower teeth the jaw's rigid motion.

Shapes: markers ``(F, M, 3)``, vertices ``(F, V, 3)``, all millimetres in the head frame.
Everything per frame is array code; the per-region systems are factored once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..common.errors import DegenerateError, InputError
from .head import REGIONS, HeadModel
from .rbf import PAPER_K, RBFScattering

REST = "rest"
#: regions below the mouth slit that ride the jaw: they take its rigid motion when it opens, and their
#: RBF carries only the markers' departures from it (section 7.4's rule for the jaw, extended to the
#: lower lip and lower mouth, which sit on the mandible)
JAW_RIDING = ("jaw", "lower_mouth", "lower_lip")


#: the grid (mm) of the coordinates the inner lip's columns pick their vertices on (FaceRig._setup_inner_lip)
SELECTION_GRID_MM = 1e-3


@dataclass
class RigSettings:
    k: float = PAPER_K             # eq. 7.1's kernel constant, mm
    blend_rings: int = 1           # mesh rings over which neighbouring regions blend
    blinks: bool = True
    blink_interval_s: float | None = 2.5  # mean time between blinks (Lin 2003, section 7.4); None: by density (animate_take)
    blink_duration_s: float = 0.25
    blink_seed: int = 0
    jaw_stretch_limits: tuple = (0.9, 1.1)
    hypothetical_jaw_points: int = 8
    # region pairs that never blend (the mouth slit), except within `corner_blend_mm` of the mouth corners
    hard_borders: tuple = (("upper_lip", "lower_lip"),)
    corner_blend_mm: float = 6.0
    # a region with fewer markers of its own than this also takes its neighbours' on the same side of the
    # jaw; None: every region does (measured over 15 layouts of 40-250 markers: 1.14 mm RMS against 1.24 mm
    # with 4, the cliff at which one more correct upper-lip marker had made the demo's face 0.1 mm worse)
    min_region_markers: int | None = None


def blink_closure(n_frames: int, fps: float, interval_s: float = 2.5, duration_s: float = 0.25,
                  seed: int = 0) -> np.ndarray:
    """Lid closure in [0, 1] per frame: blinks at gamma-distributed intervals (shape 4,
    mean ``interval_s``, at least ``duration_s`` apart), each a smooth bump that closes
    in 40 % and reopens in 60 % of ``duration_s``; exactly 1 at mid-blink when a frame
    falls there."""
    if not (fps > 0 and interval_s > 0 and duration_s > 0):
        raise InputError("blink timing must be positive")
    rng = np.random.default_rng(seed)
    T = n_frames / fps
    n_draw = int(T / interval_s * 3) + 8
    gaps = np.maximum(rng.gamma(4.0, interval_s / 4.0, n_draw), 2 * duration_s)
    onsets = np.cumsum(gaps) - gaps[0] * rng.uniform(0.3, 1.0)
    onsets = onsets[(onsets > -duration_s) & (onsets < T)]
    # each blink's own few frames (B, k), not every frame against every blink: a long take has hundreds of blinks
    frame = np.floor(onsets * fps).astype(int)[:, None] - 1 + np.arange(int(np.ceil(duration_s * fps)) + 3)
    s = frame / fps - onsets[:, None]                      # time since the blink's onset
    close, hold = 0.4 * duration_s, 0.6 * duration_s
    up = np.clip(s / close, 0, 1)
    down = np.clip((s - close) / hold, 0, 1)
    shape = np.where(s < close, np.sin(0.5 * np.pi * up) ** 2, np.cos(0.5 * np.pi * down) ** 2)
    inside = (s >= 0) & (s <= duration_s) & (frame >= 0) & (frame < n_frames)
    closure = np.zeros(n_frames)
    np.maximum.at(closure, frame[inside], shape[inside])
    return closure


DEFORM_BLOCK_FRAMES = 64  # frames per BLAS product in FaceRig.deform (a 7 MB buffer at 4,600 vertices)


def _rotate(v, axis, angle):
    """Rodrigues: rotate vectors ``v (..., 3)`` about unit ``axis`` by ``angle (...)``."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return v * c + np.cross(axis, v) * s + axis * (v @ axis)[..., None] * (1 - c)


class FaceRig:
    """Precomputed rig for one head and one set of marker-bound vertices."""

    def __init__(self, head: HeadModel, marker_vertices, settings: RigSettings | None = None):
        head.validate()
        self.head, self.s = head, settings or RigSettings()
        V = head.vertices
        nv = len(V)
        self.marker_vertices = mv = np.asarray(marker_vertices, np.int64)
        if mv.ndim != 1 or mv.size == 0:
            raise InputError("the rig needs at least one marker-bound vertex")
        if np.unique(mv).size != mv.size:
            raise InputError("two markers are bound to the same vertex")
        self.fixed = np.setdiff1d(head.members("fixed"), mv)
        if self.fixed.size < 4:
            raise InputError(f"the head {head.name!r} needs at least 4 vertices in its 'fixed' group")
        lm = head.landmarks()
        self.chin = lm["chin"]
        hinge = head.jaw_hinge()
        self.hinge_point = hinge.mean(0)
        self.hinge_axis = (hinge[0] - hinge[1]) / np.linalg.norm(hinge[0] - hinge[1])
        labels = head.region_labels()
        names = list(REGIONS) + [REST]
        labels = np.where(labels < 0, len(REGIONS), labels)
        W = self._blend_weights(labels, len(names))                  # (V, R+1)
        self.region_weights = W
        jaw = REGIONS.index("jaw")
        riding = [names.index(r) for r in JAW_RIDING]
        # hypothetical points: jaw-region vertices nearest the hinge (the jaw "near the ear")
        jaw_members = np.flatnonzero(labels == jaw)
        d_h = np.minimum(np.linalg.norm(V[jaw_members] - hinge[0], axis=1),
                         np.linalg.norm(V[jaw_members] - hinge[1], axis=1))
        hyp = jaw_members[np.argsort(d_h)]
        hyp = np.setdiff1d(hyp[: self.s.hypothetical_jaw_points], mv)
        self.hypothetical = hyp
        # control vector layout: markers, fixed, hypothetical
        self.controls = np.r_[mv, self.fixed, hyp]
        n_m, n_f = mv.size, self.fixed.size
        G_main = np.zeros((nv, self.controls.size))
        G_jaw = np.zeros((nv, self.controls.size))
        adjacent = self._adjacent_regions(labels, len(names))
        self.region_markers = {}
        for r, name in enumerate(names):
            rows = np.flatnonzero(W[:, r] > 0)
            if rows.size == 0:
                continue
            own = W[mv, r] > 0
            few = self.s.min_region_markers is None or own.sum() < self.s.min_region_markers
            if few and r != len(REGIONS):
                # the region also takes the markers of its neighbours on the same side of the jaw (never
                # across the mouth slit): a region's own few markers leave its far parts to extrapolation
                # or the fixed points' rest (a region riding the jaw carries residuals from its rigid motion)
                same = [n for n in adjacent[r] if (n in riding) == (r in riding)]
                own |= np.any(W[mv][:, same] > 0, axis=1)
            self.region_markers[name] = np.flatnonzero(own)
            if r in riding:
                # regions riding the jaw: their markers and the hypothetical points, which ride the rigid
                # jaw; no fixed points (they would pull the rigid motion, an affine field, back to rest)
                cols = np.r_[np.flatnonzero(own), n_m + n_f + np.arange(hyp.size)]
            else:
                cols = np.r_[np.flatnonzero(own), n_m + np.arange(n_f)]
            try:
                rbf = RBFScattering(V[self.controls[cols]], k=self.s.k)
            except DegenerateError:
                if r not in riding:
                    raise
                continue  # too few controls: the region moves with the rigid jaw only
            E = rbf.influence_matrix(V[rows])                          # (rows, cols)
            target = G_jaw if r in riding else G_main
            target[np.ix_(rows, cols)] += W[rows, r][:, None] * E
        self.G_main, self.G_jaw = G_main, G_jaw
        # the blocks deform() multiplies: the jaw region's few rows and controls, and the
        # controls some region uses (a dense product with the zeros costs ~0.5 s per minute)
        self._main_cols = np.flatnonzero(np.any(G_main != 0, axis=0))
        self._G_main_block = np.ascontiguousarray(G_main[:, self._main_cols].T)       # (cols, V)
        self._jaw_rows = np.flatnonzero(np.any(G_jaw != 0, axis=1))
        self._jaw_cols = np.flatnonzero(np.any(G_jaw != 0, axis=0))
        self._G_jaw_block = np.ascontiguousarray(G_jaw[np.ix_(self._jaw_rows, self._jaw_cols)].T)  # (cols, rows)
        self.jaw_weight = W[:, riding].sum(1)
        # chin displacement from all markers (one global RBF row; exact if a marker sits on the chin)
        chin_rbf = RBFScattering(V[np.r_[mv, self.fixed]], k=self.s.k)
        self.chin_row = chin_rbf.influence_matrix(V[[self.chin]])[0]  # (n_m + n_f,)
        r0 = V[self.chin] - self.hinge_point
        self.chin_radial0 = r0 - self.hinge_axis * (r0 @ self.hinge_axis)
        self.teeth_lower = head.members("teeth_lower")
        self.jaw_moving = np.union1d(np.flatnonzero(self.jaw_weight > 0), self.teeth_lower)
        self._setup_inner_lip()
        self._setup_eyelids()

    # -- precomputation ---------------------------------------------------------------
    def _blend_weights(self, labels, n_regions):
        V = self.head.vertices
        e = self.head.edges()
        n = len(V)
        names = list(REGIONS) + [REST]
        lms = self.head.landmarks()
        corners = [V[lms[c]] for c in ("mouth_corner_l", "mouth_corner_r") if c in lms]
        for a, b in self.s.hard_borders:
            ia, ib = names.index(a), names.index(b)
            la, lb = labels[e[:, 0]], labels[e[:, 1]]
            across = ((la == ia) & (lb == ib)) | ((la == ib) & (lb == ia))
            if corners:
                mid = 0.5 * (V[e[:, 0]] + V[e[:, 1]])
                near = np.min([np.linalg.norm(mid - c, axis=1) for c in corners], axis=0) < self.s.corner_blend_mm
                across &= ~near
            e = e[~across]
        A = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n))
        A = (A + sp.identity(n)).tocsr()
        A = sp.diags(1.0 / np.asarray(A.sum(1)).ravel()) @ A
        W = np.zeros((n, n_regions))
        W[np.arange(n), labels] = 1.0
        for _ in range(self.s.blend_rings):
            W = A @ W
        W[W < 1e-6] = 0.0
        return W / W.sum(1, keepdims=True)

    def _adjacent_regions(self, labels, n_regions) -> list:
        """Per region, the regions sharing a mesh edge with it (not across a hard border, not the rest)."""
        e = self.head.edges()
        la, lb = labels[e[:, 0]], labels[e[:, 1]]
        A = np.zeros((n_regions, n_regions), bool)
        A[la, lb] = A[lb, la] = True
        names = list(REGIONS) + [REST]
        for a, b in self.s.hard_borders:
            A[names.index(a), names.index(b)] = A[names.index(b), names.index(a)] = False
        A[:, -1] = False
        np.fill_diagonal(A, False)
        return [np.flatnonzero(A[r]) for r in range(n_regions)]

    def _setup_inner_lip(self):
        head, V = self.head, self.head.vertices
        inner = np.setdiff1d(head.members("inner_lip_lower"), self.marker_vertices)
        self.inner = inner
        if inner.size == 0 or self.teeth_lower.size == 0:
            return
        lower_lip = head.members(f"region_{'lower_lip'}")
        e = head.edges()
        is_inner = np.zeros(len(V), bool)
        is_inner[inner] = True
        is_lip = np.zeros(len(V), bool)
        is_lip[lower_lip] = True
        touch = (is_inner[e[:, 0]] & ~is_inner[e[:, 1]] & is_lip[e[:, 1]]) | \
                (is_inner[e[:, 1]] & ~is_inner[e[:, 0]] & is_lip[e[:, 0]])
        edge_set = np.unique(np.where(is_inner[e[touch, 0]], e[touch, 1], e[touch, 0]))
        if edge_set.size == 0:
            self.inner = np.zeros(0, np.int64)
            return
        from scipy.spatial import cKDTree

        # the columns' vertices are picked on coordinates rounded to SELECTION_GRID_MM: a symmetric mesh's ties (two
        # neighbours equally far) then break the same way whatever float noise the head's file frame left on them
        # (a head imported in centimetres and Y-up: its midline Q0 flipped sides, and the open mouth's inner lip
        # moved 2 mm otherwise)
        Vs = np.round(V / SELECTION_GRID_MM) * SELECTION_GRID_MM
        # P0: the outer lip's inner edge; Q0: the outer-lip neighbour of P0 furthest from the inner lip
        p0 = edge_set[cKDTree(Vs[edge_set]).query(Vs[inner])[1]]
        nb = {}
        outer_lip = is_lip & ~is_inner
        for a, b in e[(outer_lip[e[:, 0]] & outer_lip[e[:, 1]])]:
            nb.setdefault(a, []).append(b)
            nb.setdefault(b, []).append(a)
        centre = np.round(Vs[inner].mean(0) / SELECTION_GRID_MM) * SELECTION_GRID_MM
        q_of = {}
        for p in np.unique(p0):
            cand = sorted(c for c in nb.get(p, []) if c not in set(edge_set)) or nb.get(p, [p])
            far = np.round(np.linalg.norm(Vs[cand] - centre, axis=1) / SELECTION_GRID_MM)
            q_of[p] = cand[int(np.argmax(far))]          # of equally far ones, the first (lowest index)
        q0 = np.array([q_of[p] for p in p0])
        # P1: the lower-teeth vertex nearest each column's deepest point; B: the teeth vertex below it
        teeth = self.teeth_lower
        tree = cKDTree(Vs[teeth])
        p1 = teeth[tree.query(Vs[inner])[1]]
        down = self.head.face_axes()["down"]
        b1 = teeth[tree.query(Vs[p1] + 4.0 * down)[1]]
        d0 = np.linalg.norm(V[inner] - V[p0], axis=1)
        d1 = np.linalg.norm(V[inner] - V[p1], axis=1)
        self.lip_t = d0 / np.maximum(d0 + d1, 1e-9)
        self.lip_idx = (p0, q0, p1, b1)
        H0 = self._hermite(V[p0], V[q0], V[p1], V[b1], self.lip_t)
        self.lip_offset = V[inner] - H0

    @staticmethod
    def _hermite(P0, Q0, P1, B1, t):
        """Cubic Hermite column: from P0 leaving along (P0 - Q0), to P1 arriving along (B1 - P1);
        both tangents scaled to the chord |P1 - P0|. Works on (..., n, 3) with t (n,)."""
        L = np.linalg.norm(P1 - P0, axis=-1, keepdims=True)
        T0 = (P0 - Q0) / np.maximum(np.linalg.norm(P0 - Q0, axis=-1, keepdims=True), 1e-9) * L
        T1 = (B1 - P1) / np.maximum(np.linalg.norm(B1 - P1, axis=-1, keepdims=True), 1e-9) * L
        t = t[:, None]
        h00, h10 = 2 * t ** 3 - 3 * t ** 2 + 1, t ** 3 - 2 * t ** 2 + t
        h01, h11 = -2 * t ** 3 + 3 * t ** 2, t ** 3 - t ** 2
        return h00 * P0 + h10 * T0 + h01 * P1 + h11 * T1

    def _setup_eyelids(self):
        head, V = self.head, self.head.vertices
        self.eyelids = []
        if not self.s.blinks:
            return
        axis = head.face_axes()["lateral"]
        for side in ("l", "r"):
            w = head.groups.get(f"eyelid_upper_{side}")
            if w is None or not np.any(w > 0):
                continue
            if np.any(w[self.marker_vertices] >= 0.75):
                continue  # eyelid markers drive this lid through the RBF; no synthetic blinks
            c, r = head.eye(side)
            lids = np.flatnonzero(w > 0)
            upper = lids[np.argmax(w[lids])]
            # the lower lid margin: skin on or just outside the eyeball's front, below its centre
            skin = np.setdiff1d(np.arange(len(V)), np.r_[head.members(f"eyeball_{side}"), lids])
            rel = V[skin] - c
            d = np.linalg.norm(rel, axis=1)
            ax_ = head.face_axes()
            ring = skin[(d > r - 0.25) & (d < r + 3.0) & (rel @ ax_["down"] > 0) & (rel @ ax_["forward"] > 0.6 * r)]
            if ring.size == 0:
                continue
            ru = V[upper] - c
            ru -= axis * (ru @ axis)
            proj = V[ring] - c
            proj -= np.outer(proj @ axis, axis)
            cosang = proj @ ru / (np.linalg.norm(proj, axis=1) * np.linalg.norm(ru))
            lower = ring[np.argmax(cosang - 0.02 * np.abs((V[ring] - V[upper]) @ axis))]
            rl = V[lower] - c
            rl -= axis * (rl @ axis)
            angle = np.arctan2(np.cross(ru, rl) @ axis, ru @ rl)
            keep = np.setdiff1d(lids, self.marker_vertices)
            self.eyelids.append({"side": side, "centre": c, "axis": axis, "vertices": keep, "weights": w[keep],
                                 "angle": float(angle), "upper": int(upper), "lower": int(lower)})

    # -- per frame ---------------------------------------------------------------------
    def jaw_motion(self, chin_disp):
        """The jaw rule of section 7.4: the opening angle about the hinge axis (positive = chin below
        neutral) and the stretch, per frame, from the chin displacement ``(F, 3)``."""
        a = self.hinge_axis
        r0 = self.chin_radial0
        r = r0 + chin_disp - np.outer(chin_disp @ a, a)
        theta = np.arctan2(np.cross(r0, r) @ a, r @ r0)
        stretch = np.clip(np.linalg.norm(r, axis=1) / np.linalg.norm(r0), *self.s.jaw_stretch_limits)
        opened = theta > 0
        return np.where(opened, theta, 0.0), np.where(opened, stretch, 1.0)

    def _jaw_displacement(self, points, theta, stretch):
        """Rigid rotation (and radial stretch) about the hinge axis: displacements ``(F, n, 3)``."""
        a, h = self.hinge_axis, self.hinge_point
        rel = points - h
        par = np.outer(rel @ a, a)
        rot = _rotate(rel[None] - par[None], a, np.broadcast_to(theta[:, None], (len(theta), len(points))))
        return rot * stretch[:, None, None] + par[None] - rel[None]

    def closure(self, n_frames: int, fps: float) -> np.ndarray:
        """The lids' closure ``(n_frames,)`` over a take of ``n_frames`` frames: its blinks (:func:`blink_closure`,
        section 7.4), zero without eyelids or with ``blinks`` off."""
        if not self.eyelids:
            return np.zeros(n_frames)
        interval = self.s.blink_interval_s if self.s.blink_interval_s is not None else 2.5
        return blink_closure(n_frames, fps, interval, self.s.blink_duration_s, self.s.blink_seed)

    def _controls(self, marker_disp):
        """Marker displacements ``(F, M, 3)`` checked, as the controls' ``(F, C, 3)`` (fixed and hypothetical
        points at 0), and the chin's displacement ``(F, 3)``."""
        U = np.asarray(marker_disp, float)
        n_m = self.marker_vertices.size
        if U.ndim != 3 or U.shape[1:] != (n_m, 3):
            raise InputError(f"marker displacements must have shape (frames, {n_m}, 3), not {U.shape}")
        if not np.all(np.isfinite(U)):
            raise InputError("marker displacements must be finite (fill gaps first)")
        Uc = np.zeros((U.shape[0], self.controls.size, 3))
        Uc[:, :n_m] = U
        return Uc, np.einsum("c,fcd->fd", self.chin_row, Uc[:, : n_m + self.fixed.size])

    def motion(self, marker_disp, closure) -> dict:
        """The rig's per-frame parts without the vertices: the chin's displacement, the jaw's angle and stretch
        (:meth:`jaw_motion`) and the lids' ``closure``."""
        return self._parts(self._controls(marker_disp)[1], closure)

    def _parts(self, chin, closure) -> dict:
        """:meth:`motion`'s parts from the chin's displacement ``(F, 3)`` and the lids' ``closure (F,)``."""
        theta, stretch = self.jaw_motion(chin)
        return {"jaw_angle": theta, "jaw_stretch": stretch, "blink": np.asarray(closure, float), "chin": chin}

    def deform(self, marker_disp, fps: float = 30.0, with_parts: bool = False, closure=None):
        """Vertex displacements ``(F, V, 3)`` for marker displacements ``(F, M, 3)``. ``closure (F,)``: the lids'
        closure per frame (default: the blinks of a take of these ``F`` frames at ``fps``, :meth:`closure`); a
        stretch of a take passes the whole take's closure at its frames, so that it deforms as it does there."""
        Uc, chin = self._controls(marker_disp)
        F, V = Uc.shape[0], self.head.vertices
        n_m = self.marker_vertices.size
        closure = self.closure(F, fps) if closure is None else np.asarray(closure, float)
        if closure.shape != (F,):
            raise InputError(f"a closure per frame: ({F},), not {closure.shape}")
        parts = self._parts(chin, closure)
        theta, stretch = parts["jaw_angle"], parts["jaw_stretch"]
        # jaw: rigid part at the jaw-moving vertices and at the controls, residual through the RBF
        J_ctrl = self._jaw_displacement(V[self.controls], theta, stretch)
        n_f = self.fixed.size
        resid = Uc - J_ctrl
        resid[:, n_m + n_f:] = 0.0                       # hypothetical points ride the rigid jaw
        # BLAS products (F*3, C) @ (C, V) over blocks of frames, each laid out as (F, V, 3)
        # through one small reused buffer: the (F, V, 3) result is the only take-sized array
        cm, rj, cj = self._main_cols, self._jaw_rows, self._jaw_cols
        D = np.empty((F, len(V), 3))
        Um = Uc[:, cm].transpose(0, 2, 1).reshape(F * 3, cm.size)
        block = min(F, DEFORM_BLOCK_FRAMES)
        buf = np.empty((block * 3, len(V)))
        for f0 in range(0, F, block):
            f1 = min(F, f0 + block)
            out = buf[: (f1 - f0) * 3]
            np.matmul(Um[f0 * 3:f1 * 3], self._G_main_block, out=out)
            out = out.reshape(f1 - f0, 3, len(V))
            for k in range(3):
                D[f0:f1, :, k] = out[:, k]
        if rj.size:
            D[:, rj] += ((resid[:, cj].transpose(0, 2, 1).reshape(F * 3, cj.size) @ self._G_jaw_block)
                         .reshape(F, 3, rj.size).transpose(0, 2, 1))
        moving = self.jaw_moving
        J = self._jaw_displacement(V[moving], theta, stretch)
        D[:, moving] += self.jaw_weight[moving][None, :, None] * J
        D[:, self.teeth_lower] = self._jaw_displacement(V[self.teeth_lower], theta, stretch)
        D[:, self.head.members("teeth_upper")] = 0.0
        if self.inner.size:
            p0, q0, p1, b1 = self.lip_idx
            H = self._hermite(*(V[i][None] + D[:, i] for i in (p0, q0, p1, b1)), self.lip_t)
            off = _rotate(np.broadcast_to(self.lip_offset, (F,) + self.lip_offset.shape), self.hinge_axis,
                          np.broadcast_to(theta[:, None], (F, self.inner.size)))
            D[:, self.inner] = H + off - V[self.inner]
        if self.eyelids:
            shut = np.flatnonzero(closure > 0)  # blinks: a few frames of the take
            for lid in self.eyelids:
                idx = lid["vertices"]
                rel = V[idx] - lid["centre"]
                ang = closure[shut, None] * lid["weights"][None, :] * lid["angle"]
                D[np.ix_(shut, idx)] += _rotate(np.broadcast_to(rel, (shut.size,) + rel.shape), lid["axis"],
                                                ang) - rel[None]
        return (D, parts) if with_parts else D
