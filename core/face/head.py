"""The head model: the plain intermediate representation between a head mesh in
Blender and the face rig (Lin 2003, sections 7.3-7.4).

A :class:`HeadModel` is arrays only -- neutral vertices in millimetres in the
core's frame (x to the subject's left = image right, y down, z away from the
camera), polygons, and named per-vertex weights (Blender's vertex groups):

``region_<name>``
    the 11 regions of figure 7.8 (:data:`REGIONS`), one label per vertex (weight
    ≥ 0.5 = member); vertices in no region (scalp, ears, neck) stay neutral.
``lm_<name>``
    landmarks: the heaviest vertex of the group is the landmark (:data:`LANDMARKS`
    lists the ones the rig needs).
``fixed``
    fixed points (neck base, back of the head): control points that never move.
``eyeball_l``, ``eyeball_r``
    the eyeball meshes (a sphere is fitted to each: the blink model's sphere).
``eyelid_upper_l``, ``eyelid_upper_r``
    how far each upper-lid vertex travels in a full blink (1 at the lid margin).
``teeth_upper``, ``teeth_lower``
    upper teeth follow the skull, lower teeth the jaw.
``inner_lip_lower``
    the inner lower lip, replaced by the Hermite surface of figure 7.9.

The jaw hinge axis is derived from the tragus landmarks (see :meth:`HeadModel.jaw_hinge`)
unless given explicitly.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..common.errors import InputError

REGIONS = ("jaw", "lower_mouth", "lower_lip", "upper_lip", "upper_mouth", "cheek_l", "cheek_r", "nose",
           "eye_l", "eye_r", "forehead")
LANDMARKS = ("nose_tip", "eye_inner_l", "eye_outer_l", "eye_inner_r", "eye_outer_r", "mouth_corner_l",
             "mouth_corner_r", "chin", "upper_lip", "lower_lip", "tragus_l", "tragus_r")
#: landmarks the rig itself uses (the others anchor registration only)
RIG_LANDMARKS = ("chin", "tragus_l", "tragus_r", "nose_tip")
#: where the jaw hinge sits relative to each tragus, in mm: (forward, down)
HINGE_OFFSET_MM = (10.0, 5.0)
#: groups that are not skin: markers never bind there and the scan fit leaves them alone
NOT_SKIN = ("eyeball_l", "eyeball_r", "teeth_upper", "teeth_lower", "inner_lip_lower")


def fit_sphere(points) -> tuple[np.ndarray, float]:
    """Least-squares sphere through ``points`` (n, 3): centre and radius."""
    p = np.asarray(points, float)
    if len(p) < 4:
        raise InputError("a sphere needs at least 4 points")
    A = np.c_[2 * p, np.ones(len(p))]
    s = np.linalg.lstsq(A, (p ** 2).sum(1), rcond=None)[0]
    c = s[:3]
    return c, float(np.sqrt(max(s[3] + c @ c, 0.0)))


def vertex_normals(points, triangles) -> np.ndarray:
    """Unit area-weighted vertex normals of a triangle mesh ``(N, 3)``, ``(T, 3)``."""
    v = np.asarray(points, float)
    t = np.asarray(triangles, np.int64)
    fn = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, t[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def farthest_points(points, n: int, seed: int = 0, initial_distance=None) -> np.ndarray:
    """Indices of ``n`` farthest-point samples of ``points`` (a random first one); with
    ``initial_distance`` (N,), points already near earlier picks (e.g. landmarks) count as covered."""
    P = np.asarray(points, float)
    rng = np.random.default_rng(seed)
    chosen = [int(rng.integers(len(P)))]
    d = np.linalg.norm(P - P[chosen[0]], axis=1)
    if initial_distance is not None:
        d = np.minimum(initial_distance, d)
    for _ in range(min(n, len(P)) - 1):
        j = int(np.argmax(d))
        chosen.append(j)
        d = np.minimum(d, np.linalg.norm(P - P[j], axis=1))
    return np.asarray(chosen, np.int64)


@dataclass
class HeadModel:
    vertices: np.ndarray                    # (V, 3) mm, neutral
    polygons: np.ndarray                    # flat vertex indices of all polygons
    polygon_sizes: np.ndarray               # (P,) corners per polygon
    groups: dict = field(default_factory=dict)  # name -> (V,) float weights
    hinge: np.ndarray | None = None         # (2, 3): left and right hinge points, if given
    name: str = "head"

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, float)
        self.polygons = np.asarray(self.polygons, np.int64)
        self.polygon_sizes = np.asarray(self.polygon_sizes, np.int64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or len(self.vertices) == 0:
            raise InputError("a head needs vertices of shape (V, 3)")
        if self.polygon_sizes.sum() != len(self.polygons):
            raise InputError("polygon sizes do not add up to the polygon index list")
        nv = len(self.vertices)
        for name, w in list(self.groups.items()):
            w = np.asarray(w, float)
            if w.shape != (nv,):
                raise InputError(f"vertex group {name!r} has {w.shape} weights for {nv} vertices")
            self.groups[name] = w

    # -- what the rig needs -------------------------------------------------
    def validate(self) -> None:
        """One clear message for a head the rig cannot use."""
        missing_regions = [r for r in REGIONS if self.members(f"region_{r}").size == 0]
        if len(missing_regions) == len(REGIONS):
            raise InputError(f"the head {self.name!r} has no region vertex groups (region_jaw, region_nose, ...; "
                             "see the README's head format)")
        if missing_regions:
            raise InputError(f"the head {self.name!r} lacks the region vertex groups "
                             + ", ".join(f"region_{r}" for r in missing_regions))
        lms = self.landmarks()
        if not lms:
            raise InputError(f"the head {self.name!r} has no landmark vertex groups (lm_<name>)")
        need = [n for n in RIG_LANDMARKS if n not in lms]
        if need:
            raise InputError(f"the head {self.name!r} lacks the landmark groups " + ", ".join(f"lm_{n}" for n in need))

    def members(self, group: str, threshold: float = 0.5) -> np.ndarray:
        w = self.groups.get(group)
        return np.zeros(0, np.int64) if w is None else np.flatnonzero(w >= threshold)

    def skin_mask(self, exclude=NOT_SKIN) -> np.ndarray:
        """``(V,)`` True for vertices in none of the ``exclude`` groups (any weight counts)."""
        mask = np.ones(len(self.vertices), bool)
        for g in exclude:
            mask[self.members(g, 0.01)] = False
        return mask

    def landmarks(self) -> dict:
        """``{name: vertex index}`` for every non-empty ``lm_<name>`` group."""
        out = {}
        for g, w in self.groups.items():
            if g.startswith("lm_") and w.max(initial=0.0) > 0:
                out[g[3:]] = int(np.argmax(w))
        return out

    def region_labels(self) -> np.ndarray:
        """``(V,)`` index into :data:`REGIONS`, -1 for vertices in no region (the heaviest group wins)."""
        W = np.stack([self.groups.get(f"region_{r}", np.zeros(len(self.vertices))) for r in REGIONS], 1)
        lab = np.argmax(W, 1)
        lab[W.max(1) < 0.5] = -1
        return lab

    def edges(self) -> np.ndarray:
        """Unique undirected edges ``(E, 2)`` of the polygons."""
        starts = np.r_[0, np.cumsum(self.polygon_sizes)[:-1]]
        nxt = np.arange(len(self.polygons)) + 1
        ends = np.repeat(starts + self.polygon_sizes, self.polygon_sizes)
        nxt = np.where(nxt == ends, np.repeat(starts, self.polygon_sizes), nxt)
        e = np.sort(np.c_[self.polygons, self.polygons[nxt]], 1)
        return np.unique(e, axis=0)

    def triangles(self) -> np.ndarray:
        """Fan triangulation ``(T, 3)`` of the polygons."""
        starts = np.r_[0, np.cumsum(self.polygon_sizes)[:-1]]
        tris = []
        for k in range(1, int(self.polygon_sizes.max(initial=3)) - 1):
            sel = self.polygon_sizes >= k + 2
            s = starts[sel]
            tris.append(np.c_[self.polygons[s], self.polygons[s + k], self.polygons[s + k + 1]])
        return np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)

    def vertex_normals(self, vertices=None) -> np.ndarray:
        return vertex_normals(self.vertices if vertices is None else vertices, self.triangles())

    def eye(self, side: str) -> tuple[np.ndarray, float]:
        """Centre and radius of the eyeball sphere on ``side`` ('l' or 'r')."""
        idx = self.members(f"eyeball_{side}")
        if idx.size < 4:
            raise InputError(f"the head {self.name!r} has no eyeball_{side} vertex group (needed for blinks)")
        return fit_sphere(self.vertices[idx])

    def face_axes(self) -> dict:
        """Lateral (to the subject's left), forward (out of the face) and down unit vectors from landmarks."""
        lm = self.landmarks()
        v = self.vertices
        lateral = v[lm["tragus_l"]] - v[lm["tragus_r"]]
        lateral /= np.linalg.norm(lateral)
        mid = 0.5 * (v[lm["tragus_l"]] + v[lm["tragus_r"]])
        fwd = v[lm["nose_tip"]] - mid
        fwd -= lateral * (fwd @ lateral)
        fwd /= np.linalg.norm(fwd)
        return {"lateral": lateral, "forward": fwd, "down": np.cross(lateral, fwd), "origin": mid}

    def jaw_hinge(self) -> np.ndarray:
        """``(2, 3)`` hinge points, left then right: given, or each tragus moved
        :data:`HINGE_OFFSET_MM` forward and down (the condyle sits just in front of the ear)."""
        if self.hinge is not None:
            return np.asarray(self.hinge, float).reshape(2, 3)
        ax = self.face_axes()
        lm = self.landmarks()
        off = HINGE_OFFSET_MM[0] * ax["forward"] + HINGE_OFFSET_MM[1] * ax["down"]
        return np.stack([self.vertices[lm["tragus_l"]] + off, self.vertices[lm["tragus_r"]] + off])
