"""MPEG-4 facial animation parameters (FAPs) from an animated head, and back (issue #21, part 5;
Lin 2003, sections 4.4 and 7.4, Appendix B).

**Feature points.** MPEG-4 names points of the face ``<group>.<index>`` (2.1 the chin, 8.3 the
left outer lip corner, ...). A head carries them as vertex groups ``fp_<group>.<index>`` (the
heaviest vertex is the point); those it lacks are found from its landmarks, regions, eyeballs
and eyelids by the rules of :func:`feature_points` (any head the product binds has those).

**FAPU** (the face's own units, from its neutral shape, each divided by 1024): ``ES`` eye
separation (3.5 to 3.6, the pupils), ``ENS`` eye to nose (the pupils' height to 9.15, the
bottom of the nose), ``MNS`` mouth to nose (9.15 to 2.2, the inner upper lip), ``MW`` mouth
width (8.3 to 8.4), ``IRISD`` the eye's opening (3.1 to 3.3); ``AU`` is 1e-5 rad.

**Low-level FAPs 3-68.** Each is one feature point's displacement from the neutral along one
of the head's axes (:meth:`..face.head.HeadModel.face_axes`: left = the subject's left, up,
forward), in its FAPU: ``value = d . axis / (FAPU / 1024)``. The lower lip and the chin boss
(FAPs 5, 10, 11, 16, 18, 52, 57, 58) are measured relative to the jaw point 2.1, as MPEG-4
players move them on top of the jaw (FAP 3 open_jaw, 14 thrust_jaw, 15 shift_jaw). Head
rotation (48-50) comes from the take's head motion. Written: :data:`WRITTEN_FAPS`. Masked off:
the eyelids (19-22: the face rig's blinks are synthetic, not measured), the eyeballs and pupils
(23-30), the tongue (43-47) and the ears (65-68) -- no marker measures them.

**High-level FAPs.** FAP 1 (viseme) and FAP 2 (expression, with intensity 0-63) are the nearest
pose of a library built from Appendix B's tables (:data:`VISEMES`, :data:`EXPRESSIONS`: each
entry a few low-level FAP values written from the table's description of the mouth or face):
a frame takes the pose whose FAP pattern its own matches best (cosine over the pose's FAPs,
at least :data:`MATCH_MIN`), viseme 0 / expression 0 when none does or the face is near neutral.

**The .fap text form**::

    2.1 NAME FPS FRAMES
    <68 mask bits, space separated>          one pair of lines per frame
    <frame number> <values of the masked FAPs, in FAP order>

FAP 1 contributes four values (``viseme_select1 viseme_select2 viseme_blend viseme_def``) and
FAP 2 six (``expression_select1 expression_intensity1 expression_select2
expression_intensity2 init_face expression_def``); every other FAP one integer. Lines starting
with ``#`` are comments.

**Replay** (:func:`feature_point_displacements`): the FAP values give each feature point's
displacement back (the jaw added to the lower lip), which the face rig interpolates over the
head like a sparse take's markers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..common.errors import InputError
from ..face.head import REGIONS

FAP_COUNT = 68
AU_RAD = 1e-5
UNIT_DIVISOR = 1024.0
FAPU_NAMES = ("ES", "ENS", "MNS", "MW", "IRISD")

# (number, name, feature point, FAPU, axis, relative to the jaw)  -- axes: left, right, up, down, forward
_LOW_LEVEL = [
    (3, "open_jaw", "2.1", "MNS", "down", False),
    (4, "lower_t_midlip", "2.2", "MNS", "down", False),
    (5, "raise_b_midlip", "2.3", "MNS", "up", True),
    (6, "stretch_l_cornerlip", "2.4", "MW", "left", False),
    (7, "stretch_r_cornerlip", "2.5", "MW", "right", False),
    (8, "lower_t_lip_lm", "2.6", "MNS", "down", False),
    (9, "lower_t_lip_rm", "2.7", "MNS", "down", False),
    (10, "raise_b_lip_lm", "2.8", "MNS", "up", True),
    (11, "raise_b_lip_rm", "2.9", "MNS", "up", True),
    (12, "raise_l_cornerlip", "2.4", "MNS", "up", False),
    (13, "raise_r_cornerlip", "2.5", "MNS", "up", False),
    (14, "thrust_jaw", "2.1", "MNS", "forward", False),
    (15, "shift_jaw", "2.1", "MW", "right", False),
    (16, "push_b_lip", "2.3", "MNS", "forward", True),
    (17, "push_t_lip", "2.2", "MNS", "forward", False),
    (18, "depress_chin", "2.10", "MNS", "up", True),
    (31, "raise_l_i_eyebrow", "4.1", "ENS", "up", False),
    (32, "raise_r_i_eyebrow", "4.2", "ENS", "up", False),
    (33, "raise_l_m_eyebrow", "4.3", "ENS", "up", False),
    (34, "raise_r_m_eyebrow", "4.4", "ENS", "up", False),
    (35, "raise_l_o_eyebrow", "4.5", "ENS", "up", False),
    (36, "raise_r_o_eyebrow", "4.6", "ENS", "up", False),
    (37, "squeeze_l_eyebrow", "4.1", "ES", "right", False),
    (38, "squeeze_r_eyebrow", "4.2", "ES", "left", False),
    (39, "puff_l_cheek", "5.1", "ES", "left", False),
    (40, "puff_r_cheek", "5.2", "ES", "right", False),
    (41, "lift_l_cheek", "5.3", "ENS", "up", False),
    (42, "lift_r_cheek", "5.4", "ENS", "up", False),
    (51, "lower_t_midlip_o", "8.1", "MNS", "down", False),
    (52, "raise_b_midlip_o", "8.2", "MNS", "up", True),
    (53, "stretch_l_cornerlip_o", "8.3", "MW", "left", False),
    (54, "stretch_r_cornerlip_o", "8.4", "MW", "right", False),
    (55, "lower_t_lip_lm_o", "8.5", "MNS", "down", False),
    (56, "lower_t_lip_rm_o", "8.6", "MNS", "down", False),
    (57, "raise_b_lip_lm_o", "8.7", "MNS", "up", True),
    (58, "raise_b_lip_rm_o", "8.8", "MNS", "up", True),
    (59, "raise_l_cornerlip_o", "8.3", "MNS", "up", False),
    (60, "raise_r_cornerlip_o", "8.4", "MNS", "up", False),
    (61, "stretch_l_nose", "9.1", "ENS", "left", False),
    (62, "stretch_r_nose", "9.2", "ENS", "right", False),
    (63, "raise_nose", "9.3", "ENS", "up", False),
    (64, "bend_nose", "9.3", "ENS", "right", False),
]
HEAD_ROTATION = [(48, "head_pitch"), (49, "head_yaw"), (50, "head_roll")]


@dataclass(frozen=True)
class LowLevelFap:
    number: int
    name: str
    point: str
    unit: str
    axis: str
    jaw_relative: bool


LOW_LEVEL_FAPS = [LowLevelFap(*row) for row in _LOW_LEVEL]
FAP_NAMES = {1: "viseme", 2: "expression", **{f.number: f.name for f in LOW_LEVEL_FAPS}, **dict(HEAD_ROTATION)}
#: the FAPs ``mirrorcap fap`` writes (1 and 2 only when a pose of the library matches)
WRITTEN_FAPS = sorted([1, 2] + [f.number for f in LOW_LEVEL_FAPS] + [n for n, _ in HEAD_ROTATION])
#: fields of the high-level FAPs in a .fap value line
HIGH_LEVEL_FIELDS = {1: 4, 2: 6}
MATCH_MIN = 0.8          # cosine a frame's FAP pattern needs with a library pose
NEUTRAL_UNITS = 60.0     # a frame whose pose FAPs are all within this of 0 is neutral (no viseme or expression)

# Appendix B, table B.1: each viseme's mouth as low-level FAPs (MNS / MW units; jaw, inner lips,
# corners, lip protrusion). Written from the table's phonemes: the shape the lips make.
_VISEME_FAPS = (3, 4, 5, 6, 7, 16, 17)
VISEMES = {
    1: ("p, b, m", {3: 60, 4: 60, 5: 120, 6: 0, 7: 0, 16: 0, 17: 0}),          # lips pressed together
    2: ("f, v", {3: 120, 4: -40, 5: 200, 6: 20, 7: 20, 16: -120, 17: 0}),      # lower lip to the upper teeth
    3: ("T, D", {3: 220, 4: -40, 5: -20, 6: 0, 7: 0, 16: 0, 17: 0}),           # tongue between the teeth
    4: ("t, d", {3: 180, 4: -60, 5: 20, 6: 40, 7: 40, 16: 0, 17: 0}),
    5: ("k, g", {3: 300, 4: -60, 5: -40, 6: 20, 7: 20, 16: 0, 17: 0}),
    6: ("tS, dZ, S", {3: 160, 4: -80, 5: -60, 6: -120, 7: -120, 16: 160, 17: 160}),  # lips forward
    7: ("s, z", {3: 80, 4: -60, 5: 40, 6: 120, 7: 120, 16: 0, 17: 0}),         # teeth together, lips apart
    8: ("n, l", {3: 200, 4: -40, 5: 0, 6: 40, 7: 40, 16: 0, 17: 0}),
    9: ("r", {3: 160, 4: -40, 5: -40, 6: -80, 7: -80, 16: 80, 17: 80}),
    10: ("A:", {3: 600, 4: -80, 5: -80, 6: 40, 7: 40, 16: 0, 17: 0}),          # jaw wide open
    11: ("e", {3: 320, 4: -80, 5: -60, 6: 120, 7: 120, 16: 0, 17: 0}),
    12: ("I", {3: 160, 4: -60, 5: 20, 6: 200, 7: 200, 16: 0, 17: 0}),          # corners stretched
    13: ("Q", {3: 480, 4: -80, 5: -80, 6: -160, 7: -160, 16: 80, 17: 80}),     # open, rounded
    14: ("U", {3: 160, 4: -40, 5: -40, 6: -240, 7: -240, 16: 200, 17: 200}),   # pursed forward
}
# Appendix B, table B.2: the six expressions as low-level FAPs (brows in ENS, lips in MNS / MW)
_EXPRESSION_FAPS = (3, 6, 7, 12, 13, 31, 32, 33, 34, 35, 36, 37, 38, 41, 42)
EXPRESSIONS = {
    1: ("joy", {3: 120, 6: 200, 7: 200, 12: 200, 13: 200, 41: 120, 42: 120}),
    2: ("sadness", {31: 150, 32: 150, 35: -60, 36: -60, 12: -150, 13: -150}),
    3: ("anger", {31: -150, 32: -150, 33: -120, 34: -120, 37: 100, 38: 100, 12: -60, 13: -60}),
    4: ("fear", {31: 200, 32: 200, 33: 150, 34: 150, 37: 80, 38: 80, 6: 80, 7: 80}),
    5: ("disgust", {12: 80, 13: 40, 41: 150, 42: 100, 3: 40}),
    6: ("surprise", {3: 400, 31: 200, 32: 200, 33: 250, 34: 250, 35: 200, 36: 200}),
}


# ----------------------------------------------------------------------------- feature points
def feature_points(head, jaw_open=None) -> dict:
    """``{"2.1": vertex, ...}``: every feature point the FAPs use, from the head's ``fp_<id>``
    vertex groups where it has them, else found on its surface (in the head's face frame: x to
    the subject's left, y down, z forward; "front surface" = skin vertices facing forward):

    - 2.1 jaw: ``lm_chin``; 8.1: ``lm_upper_lip``; 8.3 / 8.4 and 2.4 / 2.5: the mouth corners;
      9.3: ``lm_nose_tip``;
    - the lips: the front surface between the corners, from the nose tip to the chin; the lower
      lip is what a jaw-opening shape (``jaw_open (V, 3)``, e.g. the head's ``jawOpen`` key)
      carries down with the chin by at least 30 % as much, the upper lip the rest (without one:
      the ``region_upper_lip`` / ``region_lower_lip`` groups). 2.2 / 2.3 (inner lip, middle): the
      midline vertex of the upper lip nearest the slit, and of the lower lip; 2.6-2.9 the same
      halfway to the corners; 8.2 the lower lip's most forward midline vertex (``lm_lower_lip``
      without a jaw shape); 8.5-8.8 each lip halfway between its middle and a corner; 2.10 (chin
      boss) the midline halfway from 8.2 to 2.1;
    - 9.15 (nose bottom): the most recessed midline vertex between the nose tip and the upper
      lip; 9.1 / 9.2 (nostrils) at 35 % of the mouth width either side, 60 % of the way down
      from the tip to 9.15;
    - 3.5 / 3.6 (pupils): each eyeball's most forward vertex; 3.1 / 3.3 (upper / lower eyelid)
      the lid-margin vertices above and below its centre;
    - 4.1-4.6 (eyebrows): the front surface 40 % of ENS above the pupils at the inner eye
      corner, the pupil and the outer corner; 5.1 / 5.2 (cheeks) below the outer eye corners at
      the height between the nose bottom and the mouth; 5.3 / 5.4 (cheekbones) halfway down
      from the pupils to the nose bottom, a third of the way out to the outer corner.
    """
    groups = {g[3:]: int(np.argmax(w)) for g, w in head.groups.items() if g.startswith("fp_") and w.max() > 0}
    lm = head.landmarks()
    need = [n for n in ("chin", "upper_lip", "lower_lip", "mouth_corner_l", "mouth_corner_r", "nose_tip",
                        "eye_inner_l", "eye_outer_l", "eye_inner_r", "eye_outer_r") if n not in lm]
    if not need:
        return {**_derive_points(head, lm, jaw_open), **groups}
    missing = [p for p in _ALL_POINTS if p not in groups]
    if missing:
        raise InputError(f"the head {head.name!r} has no fp_<id> groups for {', '.join(missing)} and lacks the "
                         "landmarks to place them: " + ", ".join(f"lm_{n}" for n in need))
    return groups


_ALL_POINTS = sorted({f.point for f in LOW_LEVEL_FAPS} | {"3.1", "3.3", "3.5", "3.6", "9.15"})


def _derive_points(head, lm, jaw_open=None) -> dict:
    ax = head.face_axes()
    C = np.stack([ax["lateral"], ax["down"], ax["forward"]])
    P = (head.vertices - ax["origin"]) @ C.T                     # x left, y down, z forward
    skin = head.skin_mask()
    normals = head.vertex_normals() @ C.T
    front = np.flatnonzero(skin & (normals[:, 2] > 0.3))
    labels = head.region_labels()

    def nearest(xy, among=front):
        d = np.hypot(P[among, 0] - xy[0], P[among, 1] - xy[1])
        return int(among[np.argmin(d)])

    pts = {"2.1": lm["chin"], "8.1": lm["upper_lip"], "8.3": lm["mouth_corner_l"],
           "8.4": lm["mouth_corner_r"], "2.4": lm["mouth_corner_l"], "2.5": lm["mouth_corner_r"],
           "9.3": lm["nose_tip"]}
    corner = {s: P[lm[f"mouth_corner_{s}"]] for s in "lr"}
    slit_y = 0.5 * (corner["l"][1] + corner["r"][1])
    lips = front[(np.abs(P[front, 0]) < corner["l"][0] + 1.0) & (P[front, 1] > P[lm["nose_tip"], 1])
                 & (P[front, 1] < P[lm["chin"], 1]) & (P[front, 2] > P[lm["upper_lip"], 2] - 6.0)]
    if jaw_open is not None:                  # the lower lip is what the jaw carries
        drop = np.asarray(jaw_open, float) @ ax["down"]
        moving = drop > 0.3 * drop[lm["chin"]]
        upper, lower = lips[~moving[lips]], lips[moving[lips]]
        mid_lower = lower[np.abs(P[lower, 0]) < 2.5]
        pts["8.2"] = int(mid_lower[np.argmax(P[mid_lower, 2])]) if mid_lower.size else lm["lower_lip"]
    else:
        upper = lips[labels[lips] == REGIONS.index("upper_lip")]
        lower = lips[labels[lips] == REGIONS.index("lower_lip")]
        pts["8.2"] = lm["lower_lip"]
    if upper.size == 0 or lower.size == 0:
        raise InputError(f"the head {head.name!r}: cannot tell its upper lip from its lower lip to place the "
                         "MPEG-4 lip points; give them as fp_2.2, fp_2.3, ... vertex groups")
    for ids, region, toward in ((("2.2", "2.6", "2.7"), upper, 1.0), (("2.3", "2.8", "2.9"), lower, -1.0)):
        for pid, x in zip(ids, (0.0, 0.5 * corner["l"][0], 0.5 * corner["r"][0])):
            band = region[np.abs(P[region, 0] - x) < 2.5]
            if band.size == 0:
                band = region[np.argsort(np.abs(P[region, 0] - x))[:5]]
            pts[pid] = int(band[np.argmax(toward * P[band, 1])])      # nearest the slit
    for pid, mid, side, among in (("8.5", "8.1", "l", upper), ("8.6", "8.1", "r", upper),
                                  ("8.7", "8.2", "l", lower), ("8.8", "8.2", "r", lower)):
        pts[pid] = nearest(0.5 * (P[pts[mid], :2] + corner[side][:2]), among)
    pts["2.10"] = nearest(0.5 * (P[pts["8.2"], :2] + P[lm["chin"], :2]))
    tip, lip = P[lm["nose_tip"]], P[lm["upper_lip"]]
    mid = front[(np.abs(P[front, 0]) < 2.5) & (P[front, 1] > tip[1]) & (P[front, 1] < lip[1])
                & (P[front, 2] > min(tip[2], lip[2]) - 12.0)]
    pts["9.15"] = int(mid[np.argmin(P[mid, 2])]) if mid.size else nearest(0.5 * (tip[:2] + lip[:2]))
    mw = corner["l"][0] - corner["r"][0]
    y_nostril = tip[1] + 0.6 * (P[pts["9.15"], 1] - tip[1])
    pts["9.1"], pts["9.2"] = nearest((0.35 * mw, y_nostril)), nearest((-0.35 * mw, y_nostril))
    pupils = {}
    for side, pid, upper_id, lower_id in (("l", "3.5", "3.1", "3.3"), ("r", "3.6", "3.2", "3.4")):
        ball = head.members(f"eyeball_{side}")
        if ball.size:
            pts[pid] = int(ball[np.argmax(P[ball, 2])])
            centre, radius = head.eye(side)
            c = (centre - ax["origin"]) @ C.T
            ring = np.flatnonzero(skin & (np.linalg.norm(P - c, axis=1) < radius + 1.5) & (P[:, 2] > c[2]))
        else:                                             # no eyeballs: the eye corners' middle
            c = 0.5 * (P[lm[f"eye_inner_{side}"]] + P[lm[f"eye_outer_{side}"]])
            pts[pid] = nearest(c[:2])
            ring = front[np.hypot(P[front, 0] - c[0], P[front, 1] - c[1]) < 8.0]
        for lid, sign in ((upper_id, -1.0), (lower_id, 1.0)):
            band = ring[sign * (P[ring, 1] - c[1]) > 0]
            pts[lid] = int(band[np.argmin(np.abs(P[band, 0] - c[0]))]) if band.size else nearest((c[0], c[1] + 6 * sign))
        pupils[side] = P[pts[pid]]
    ens = P[pts["9.15"], 1] - 0.5 * (pupils["l"][1] + pupils["r"][1])     # eye-nose separation
    for side, inner_id, mid_id, outer_id in (("l", "4.1", "4.3", "4.5"), ("r", "4.2", "4.4", "4.6")):
        y = pupils[side][1] - 0.4 * ens
        pts[inner_id] = nearest((P[lm[f"eye_inner_{side}"], 0], y))
        pts[mid_id] = nearest((pupils[side][0], y))
        pts[outer_id] = nearest((P[lm[f"eye_outer_{side}"], 0], y))
    for side, cheek_id, bone_id in (("l", "5.1", "5.3"), ("r", "5.2", "5.4")):
        outer = P[lm[f"eye_outer_{side}"]]
        pts[cheek_id] = nearest((outer[0], 0.5 * (P[pts["9.15"], 1] + slit_y)))
        pts[bone_id] = nearest((pupils[side][0] + (outer[0] - pupils[side][0]) / 3.0,
                                pupils[side][1] + 0.5 * ens))
    return {k: int(v) for k, v in pts.items()}


# ----------------------------------------------------------------------------- units and axes
def fap_units(head, points: dict | None = None) -> dict:
    """The head's FAPU in mm (before the division by 1024), from its neutral shape."""
    points = points or feature_points(head)
    ax = head.face_axes()
    V = head.vertices
    lateral, down = ax["lateral"], ax["down"]
    eyes_y = 0.5 * (V[points["3.5"]] + V[points["3.6"]]) @ down
    units = {
        "ES": abs((V[points["3.5"]] - V[points["3.6"]]) @ lateral),
        "ENS": abs(V[points["9.15"]] @ down - eyes_y),
        "MNS": abs((V[points["2.2"]] - V[points["9.15"]]) @ down),
        "MW": abs((V[points["8.3"]] - V[points["8.4"]]) @ lateral),
        "IRISD": abs((V[points["3.1"]] - V[points["3.3"]]) @ down),
    }
    bad = [k for k, v in units.items() if not v > 0.5]
    if bad:
        raise InputError(f"the head {head.name!r} gives degenerate FAP units ({', '.join(bad)} under 0.5 mm): "
                         "check its feature points (fp_<id> groups) or landmarks")
    return units


def _axes(head) -> dict:
    ax = head.face_axes()
    return {"left": ax["lateral"], "right": -ax["lateral"], "down": ax["down"], "up": -ax["down"],
            "forward": ax["forward"]}


# ----------------------------------------------------------------------------- FAPs from motion
@dataclass
class FapTrack:
    """FAP values per frame: ``values (F, 68)`` (column k is FAP k + 1, low-level ones in their
    units, rounded on writing), ``mask (68,)`` which FAPs are present, the high-level fields
    ``viseme (F, 4)`` and ``expression (F, 6)`` (all 0 where FAP 1 / 2 is masked), ``fps``."""

    values: np.ndarray
    mask: np.ndarray
    viseme: np.ndarray
    expression: np.ndarray
    fps: float
    name: str = "mirrorcap"

    @property
    def frames(self) -> int:
        return self.values.shape[0]


def faps_from_motion(head, displacements, head_rotation=None, points: dict | None = None, fps: float = 30.0,
                     high_level: bool = True, name: str = "mirrorcap") -> FapTrack:
    """Low-level FAPs of a head's per-frame vertex ``displacements (F, V, 3)`` (mm, head frame,
    from its neutral), head rotation FAPs 48-50 from ``head_rotation (F, 3)`` (pitch down, yaw
    to the left, roll to the right, radians) when given, and FAPs 1-2 from the pose library."""
    points = points or feature_points(head)
    units = fap_units(head, points)
    axes = _axes(head)
    D = np.asarray(displacements, float)
    F = D.shape[0]
    values = np.zeros((F, FAP_COUNT))
    mask = np.zeros(FAP_COUNT, bool)
    jaw = D[:, points["2.1"]]
    for f in LOW_LEVEL_FAPS:
        d = D[:, points[f.point]] - (jaw if f.jaw_relative else 0.0)
        values[:, f.number - 1] = d @ axes[f.axis] / (units[f.unit] / UNIT_DIVISOR)
        mask[f.number - 1] = True
    if head_rotation is not None:
        rot = np.asarray(head_rotation, float).reshape(F, 3)
        for k, (number, _) in enumerate(HEAD_ROTATION):
            values[:, number - 1] = rot[:, k] / AU_RAD
            mask[number - 1] = True
    viseme, expression = np.zeros((F, 4), int), np.zeros((F, 6), int)
    if high_level:
        viseme, expression = classify_poses(values)
        mask[:2] = True
    return FapTrack(values=values, mask=mask, viseme=viseme, expression=expression, fps=float(fps), name=name)


def _library(table, columns):
    ids = np.array(sorted(table))
    A = np.array([[table[i][1].get(c, 0.0) for c in columns] for i in ids], float)
    return ids, A


def classify_poses(values):
    """FAP 1 and FAP 2 fields per frame from the low-level ``values (F, 68)``: the library pose
    whose pattern the frame matches best (cosine >= :data:`MATCH_MIN`, and the frame's pose FAPs
    not all within :data:`NEUTRAL_UNITS` of neutral); viseme blend 63 (the first viseme only),
    expression intensity the frame's projection on the pose, 0-63 (63 = the table's pose)."""
    values = np.asarray(values, float)
    F = values.shape[0]
    viseme, expression = np.zeros((F, 4), int), np.zeros((F, 6), int)
    for table, columns, out, is_viseme in ((VISEMES, _VISEME_FAPS, viseme, True),
                                           (EXPRESSIONS, _EXPRESSION_FAPS, expression, False)):
        ids, A = _library(table, columns)
        X = values[:, np.asarray(columns) - 1]
        norm = np.linalg.norm(A, axis=1)
        xn = np.linalg.norm(X, axis=1)
        cos = (X @ A.T) / np.maximum(xn[:, None] * norm[None], 1e-9)
        best = np.argmax(cos, axis=1)
        ok = (cos[np.arange(F), best] >= MATCH_MIN) & (np.abs(X).max(axis=1) > NEUTRAL_UNITS)
        if is_viseme:
            out[ok, 0] = ids[best[ok]]
            out[ok, 1] = ids[best[ok]]
            out[ok, 2] = 63
        else:
            intensity = (X @ A.T)[np.arange(F), best] / norm[best] ** 2
            out[ok, 0] = ids[best[ok]]
            out[ok, 1] = np.clip(np.rint(63 * intensity[ok]), 0, 63)
    return viseme, expression


def feature_point_displacements(track: FapTrack, head, points: dict | None = None):
    """The replay: each feature point's displacement ``(F, P, 3)`` (head frame, mm) that the
    track's low-level FAPs describe, for the points ``names (P,)`` that some present FAP moves;
    displacements along different axes of one point add up, the jaw is added back to the lower
    lip. Returns ``(names, vertices (P,), displacements)``."""
    points = points or feature_points(head)
    units = fap_units(head, points)
    axes = _axes(head)
    present = [f for f in LOW_LEVEL_FAPS if track.mask[f.number - 1]]
    if not present:
        raise InputError("the FAP track moves no feature point (no low-level FAP 3-64 in its mask)")
    names = sorted({f.point for f in present}, key=lambda p: tuple(int(v) for v in p.split(".")))
    index = {p: k for k, p in enumerate(names)}
    D = np.zeros((track.frames, len(names), 3))
    for f in present:
        D[:, index[f.point]] += (track.values[:, f.number - 1] * units[f.unit] / UNIT_DIVISOR)[:, None] * axes[f.axis]
    if "2.1" in index:
        jaw = D[:, index["2.1"]].copy()
        for p in {f.point for f in present if f.jaw_relative}:
            D[:, index[p]] += jaw
    return names, np.array([points[p] for p in names]), D


# ----------------------------------------------------------------------------- the .fap text form
def fap_text(track: FapTrack) -> str:
    """The track in the MPEG-4 FAP text form (module text). Values are rounded to integers."""
    name = "".join(c if c.isalnum() or c in "-_." else "_" for c in track.name) or "mirrorcap"
    fps = f"{track.fps:g}"
    lines = [f"2.1 {name} {fps} {track.frames}"]
    mask_line = " ".join("1" if m else "0" for m in track.mask)
    low = np.flatnonzero(track.mask[2:]) + 2
    ints = np.rint(track.values[:, low]).astype(np.int64)
    for f in range(track.frames):
        fields = [str(f)]
        if track.mask[0]:
            fields += [str(int(v)) for v in track.viseme[f]]
        if track.mask[1]:
            fields += [str(int(v)) for v in track.expression[f]]
        fields += [str(v) for v in ints[f]]
        lines += [mask_line, " ".join(fields)]
    return "\n".join(lines) + "\n"


def read_fap(path) -> FapTrack:
    """A .fap file (the MPEG-4 text form) as a :class:`FapTrack`; masks may change per frame
    (a FAP absent from a frame holds its last value, as players do). One clear message for a
    malformed file."""
    try:
        with open(path, encoding="utf-8") as fh:
            lines = [ln.split() for ln in fh if ln.strip() and not ln.lstrip().startswith("#")]
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path} is not a FAP text file") from None
    if not lines or len(lines[0]) < 4:
        raise InputError(f"{path}: the first line must be '2.1 NAME FPS FRAMES'")
    head = lines[0]
    try:
        fps, frames = float(head[-2]), int(head[-1])
    except ValueError:
        raise InputError(f"{path}: the first line must be '2.1 NAME FPS FRAMES' (FPS and FRAMES numbers)") from None
    if not (fps > 0 and math.isfinite(fps)) or frames < 1:
        raise InputError(f"{path}: FPS must be positive and FRAMES at least 1")
    body = lines[1:]
    if len(body) < 2 * frames:
        raise InputError(f"{path}: {frames} frames announced but {len(body) // 2} found")
    values = np.zeros((frames, FAP_COUNT))
    viseme, expression = np.zeros((frames, 4), int), np.zeros((frames, 6), int)
    ever = np.zeros(FAP_COUNT, bool)
    last = np.zeros(FAP_COUNT)
    last_vis, last_exp = np.zeros(4, int), np.zeros(6, int)
    for f in range(frames):
        mask_fields, value_fields = body[2 * f], body[2 * f + 1]
        where = f"{path}, frame {f}"
        if len(mask_fields) != FAP_COUNT or any(m not in ("0", "1") for m in mask_fields):
            raise InputError(f"{where}: the mask line must hold {FAP_COUNT} bits of 0 or 1, "
                             f"not {len(mask_fields)} fields")
        mask = np.array([m == "1" for m in mask_fields])
        need = 1 + sum(HIGH_LEVEL_FIELDS.get(k + 1, 1) for k in np.flatnonzero(mask))
        if len(value_fields) != need:
            raise InputError(f"{where}: the mask sets {int(mask.sum())} FAPs, which need {need} fields "
                             f"(frame number first), but the line holds {len(value_fields)}")
        try:
            nums = [int(v) for v in value_fields]
        except ValueError:
            raise InputError(f"{where}: FAP values must be integers") from None
        pos = 1
        if mask[0]:
            last_vis = np.array(nums[pos:pos + 4])
            pos += 4
        if mask[1]:
            last_exp = np.array(nums[pos:pos + 6])
            pos += 6
        low = np.flatnonzero(mask[2:]) + 2
        last[low] = nums[pos:]
        ever |= mask
        values[f], viseme[f], expression[f] = last, last_vis, last_exp
    return FapTrack(values=values, mask=ever, viseme=viseme, expression=expression, fps=fps, name=head[1])


def replay_take(track: FapTrack, head, points: dict | None = None):
    """A .fap track as a sparse take on ``head``: ``(labels, points (F, P, 3), marker_map,
    head_pose (F, 3, 4))`` -- one marker ``fp_<id>`` per moved feature point, at its vertex plus
    its displacement (head frame, mm), bound to that vertex by the marker map, ready for
    :func:`..face.animate.animate_take`. The head turns as FAPs 48-50 say (pitch, yaw, roll about the
    head's axes through its origin; :func:`.arkit.rotations_from_angles`), and the pose says so, so
    the binding recovers it as the take's head motion (``bake --head-motion`` keys it); without them
    the head is still. Feature points on one vertex (the inner and outer lip corners of a head with a
    thin lip) are one marker, at the mean of their displacements."""
    from .arkit import rotations_from_angles

    names, vertices, D = feature_point_displacements(track, head, points)
    unique, group = np.unique(vertices, return_inverse=True)
    counts = np.bincount(group)
    merged = np.zeros((D.shape[0], unique.size, 3))
    np.add.at(merged, (slice(None), group), D)
    D = merged / counts[None, :, None]
    labels = ["fp_" + "+".join(n for n, g in zip(names, group) if g == k) for k in range(unique.size)]
    vertices = unique
    pts = head.vertices[vertices][None] + D
    pose = np.tile(np.c_[np.eye(3), np.zeros(3)], (track.frames, 1, 1))
    rot = [number - 1 for number, _ in HEAD_ROTATION]
    if track.mask[rot].any():
        pitch_yaw_roll = np.where(track.mask[rot], track.values[:, rot], 0.0) * AU_RAD
        R = rotations_from_angles(pitch_yaw_roll[:, [1, 0, 2]], head.face_axes())
        pts = np.einsum("fij,fmj->fmi", R, pts)
        pose[:, :, :3] = R
    return labels, pts, dict(zip(labels, (int(v) for v in vertices))), pose


def take_faps(head, labels, points, rate: float, *, feature: dict | None = None, neutral_frame: int = 0,
              head_pose=None, unseen: str = "error", marker_map: dict | None = None, high_level: bool = True,
              name: str = "mirrorcap", progress=None):
    """A take's FAPs on ``head``: bound and animated as ``bake`` does (:func:`..face.animate.animate_take`,
    without synthetic blinks: the eyelids are not measured), the low-level FAPs measured on the
    animated head, FAPs 48-50 from the take's head motion. Returns ``(animation, track)``."""
    from ..face.animate import animate_take
    from ..face.facerig import RigSettings
    from .arkit import head_angles

    anim = animate_take(head, labels, points, rate, neutral_frame=neutral_frame, head_pose=head_pose, unseen=unseen,
                        settings=RigSettings(blinks=False), marker_map=marker_map, progress=progress)
    yaw_pitch_roll = head_angles(anim.binding.head_motion[0], head.face_axes())
    track = faps_from_motion(head, anim.displacements, yaw_pitch_roll[:, [1, 0, 2]], points=feature, fps=rate,
                             high_level=high_level, name=name)
    return anim, track
