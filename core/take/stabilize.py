"""Head motion removed from any take, about the head's rotation pivot (Huang, Lin & Ouhyoung
2000, seed 001, section 2).

* Head motion from >= 3 markers on a rigid headband, per frame, either by the
  translation invariants of eq. 1-3 (:func:`motion_by_invariants`: unit edge vectors
  ``m_1, m_2``, the pseudo-correspondence ``m_3 = m_1 x m_2``, ``R`` from the 3x3 linear
  system of eq. 3, ``t`` by substitution into eq. 1) or by Arun's SVD fit over every rigid
  marker (:func:`..geometry.rigid.rigid_fit`). Both give ``p_i(f) = R_f p_i(0) + t_f``.
* The rotation pivot (eq. 4-8, :func:`find_pivot`): the point ``O`` about which the
  head turns, found by the six-direction bold-driver descent of eq. 7-8 on the objective
  of eq. 5 (:func:`pivot_objective`), starting from a guess below and behind the rigid
  markers (:func:`pivot_guess`, the paper's "domain knowledge").
* Section 2.3 alternates the two. Here: the motion from the rigid markers alone, then
  the pivot (searched as a point fixed in the take's coordinates), then the motion again
  with the pivot as one more rigid point, placed each frame where the first motion puts it
  smoothed in time (its sway; the window, 0.5-3 s, chosen by cross-validation: the pivot's
  place at the reference frame tilts every frame's head frame, so the longest window the data
  allow). The pivot lies ~100 mm from the headband, so it steadies the rotation, and a frame
  that lost one rigid marker is still posed from the two left.
  (Searching the pivot again over the sway-compensated markers makes every point a
  solution: the compensation moves the rotation onto the candidate, so one round it is.)
* The rigid markers' shape is their mean over the take (each frame brought into the
  reference frame), and the pose may be smoothed in time (``smooth_s``, a local quadratic)
  -- a single frame's noise would otherwise tilt every frame's head frame.
* Compensation (eq. 9): every marker in the head frame of the first frame,
  ``p(0) = R_f^T (p(f) - t_f)``.

Units: the take's, converted to millimetres by :func:`..take.c3d.read_c3d`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from ..common.errors import DegenerateError, InputError
from scipy.signal import savgol_filter

from ..geometry.rigid import rigid_fit, robust_rigid_fit

# eq. 5 weights and scales (documented in the README): w1 the angle term (radians times the
# mean pivot-marker distance, i.e. millimetres of arc), w2 the length term (mm), w3 the pull
# towards the guess (|p - guess| / C, C in mm).
PIVOT_WEIGHTS = (1.0, 1.0, 1.0)
PIVOT_PULL_MM = 100.0
PIVOT_SEARCH_FRAMES = 2000     # the pivot search looks at this many frames at most, evenly spread
# below this rotation (degrees) about some axis the pivot is not determined along that axis
MIN_PIVOT_ROTATION_DEG = 3.0
# the guess: this far below the rigid markers' centroid, in multiples of the distance from
# the rigid markers to the face markers' centroid, and this far behind the face (mm)
GUESS_BELOW = 1.5
GUESS_BEHIND_MM = 60.0
# the pivot's sway is smoothed by a local quadratic over one of these windows (seconds; chosen by
# cross-validation, :func:`_smoothed_sway`) before it serves as a rigid point
SWAY_WINDOWS_S = (0.5, 1.0, 2.0, 3.0)
PIVOT_POINT_WEIGHT = 1.0
# the reference frame's pose (the head frame every frame is written in) from a local quadratic over this long
REFERENCE_SMOOTHING_S = 0.5


@dataclass
class Stabilization:
    labels: list
    points: np.ndarray            # (F, M, 3) every marker in the head frame of the reference frame (eq. 9)
    rotation: np.ndarray          # (F, 3, 3) R_f: p(f) = R_f p(ref) + t_f
    translation: np.ndarray       # (F, 3)
    pose_source: np.ndarray       # (F,) "rigid", "rigid+pivot" or "none"
    rigid: list                   # the rigid markers' labels
    rigid_source: str             # "given" or "automatic"
    method: str                   # "invariants" or "arun"
    reference_frame: int          # index of the frame whose head frame the output is in
    rigid_residual_mm: np.ndarray  # (F,) RMS distance of the rigid markers from their fitted positions
    pivot_mm: np.ndarray | None = None   # (3,) the pivot, take coordinates at the reference frame
    pivot_status: str = "none"    # "estimated", "given", "none", "undetermined"
    pivot_undetermined_axis: list | None = None
    pivot_objective: float | None = None
    pivot_iterations: int = 0
    sway_mm: np.ndarray | None = None     # (F, 3) the pivot's own motion: R_f O + t_f - O
    sway_window_s: float | None = None    # the window its sway was smoothed over
    warnings: list = field(default_factory=list)

    def report(self) -> dict:
        rms = float(np.sqrt(np.nanmean(self.rigid_residual_mm ** 2))) if np.isfinite(self.rigid_residual_mm).any() else None
        rep = {"method": self.method, "rigid": self.rigid, "rigid_source": self.rigid_source,
               "reference_frame_index": self.reference_frame,
               "pivot_mm": None if self.pivot_mm is None else [round(float(v), 4) for v in self.pivot_mm],
               "pivot_status": self.pivot_status, "pivot_undetermined_axis": self.pivot_undetermined_axis,
               "pivot_objective": self.pivot_objective, "pivot_iterations": self.pivot_iterations,
               "frames_without_pose": int(np.sum(self.pose_source == "none")),
               "frames_posed_with_pivot": int(np.sum(self.pose_source == "rigid+pivot")),
               "rigid_residual_rms_mm": rms,
               "per_frame": {
                   "rotation": np.round(self.rotation, 7).tolist(),
                   "translation_mm": np.round(self.translation, 4).tolist(),
                   "pose_source": self.pose_source.tolist(),
                   "rigid_residual_mm": np.round(self.rigid_residual_mm, 4).tolist()},
               "warnings": self.warnings}
        if self.sway_mm is not None:
            sway = np.linalg.norm(self.sway_mm, axis=1)
            rep["sway_max_mm"] = float(np.nanmax(sway)) if np.isfinite(sway).any() else None
            rep["sway_window_s"] = self.sway_window_s
            rep["per_frame"]["sway_mm"] = np.round(self.sway_mm, 4).tolist()
        return rep


def motion_by_invariants(ref, cur):
    """``R (F, 3, 3), t (F, 3)`` by the translation invariants of eq. 1-3.

    Three points (the paper's case): ``m_1 = (p_2 - p_1)/|.|``, ``m_2 = (p_3 - p_2)/|.|``, the
    pseudo-correspondence ``m_3 = m_1 x m_2`` (unit), and ``[m_1 m_2 m_3]^T r_row = m'_row``
    for each row of ``R`` (eq. 3). More points (the rigid markers and the pivot, section
    2.3): every edge between two points is an invariant ``m``, and eq. 3 is solved in the
    least-squares sense, each edge weighted by its length (its direction is that much
    more precise). With noise
    the solution is not exactly a rotation: it is replaced by the nearest rotation (SVD).
    ``t`` then follows from eq. 1, averaged over the points. ``ref (n, 3)``, ``cur (F, n, 3)``."""
    ref = np.asarray(ref, float)
    cur = np.asarray(cur, float)
    n = cur.shape[1]
    if n == 3:
        pairs = np.array([[0, 1], [1, 2]])
    else:
        pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
    e_ref = ref[pairs[:, 1]] - ref[pairs[:, 0]]                # (k, 3)
    e_cur = cur[:, pairs[:, 1]] - cur[:, pairs[:, 0]]          # (F, k, 3)
    length = np.linalg.norm(e_ref, axis=1)
    m = e_ref / length[:, None]
    mp = e_cur / np.maximum(np.linalg.norm(e_cur, axis=2, keepdims=True), 1e-12)
    m3 = np.cross(m[0], m[1])
    m3p = np.cross(mp[:, 0], mp[:, 1])
    m = np.vstack([m, m3 / np.linalg.norm(m3)])
    mp = np.concatenate([mp, (m3p / np.maximum(np.linalg.norm(m3p, axis=1, keepdims=True), 1e-12))[:, None]], axis=1)
    we = np.r_[length, length[:2].mean()]                     # the pseudo-vector: its two edges' mean
    # eq. 3 per frame, weighted least squares: (M^T W M) R^T = M^T W M'
    A = np.einsum("ki,k,kj->ij", m, we, m)
    B = np.einsum("ki,k,fkj->fij", m, we, mp)
    R = np.swapaxes(np.linalg.solve(A[None], B), 1, 2)
    U, _, Vt = np.linalg.svd(R)
    D = np.ones(R.shape[:-1])
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    R = (U * D[:, None, :]) @ Vt
    t = np.mean(cur - ref @ np.swapaxes(R, 1, 2), axis=1)     # eq. 1 by substitution
    return R, t


def pivot_objective(candidates, rigid, guess=None, weights=PIVOT_WEIGHTS,
                    pull_mm: float = PIVOT_PULL_MM):
    """Eq. 5 for pivot candidates ``(K, 3)`` (fixed in the take's coordinates) over the rigid
    markers' tracks ``rigid (F, n, 3)`` (complete frames only):
    ``w1 * mean_f sum_j |theta_j(f) - theta_j| * L + w2 * mean_f sum_j |l_j(f) - l_j| + w3 |p - guess| / C``
    with ``l_j`` the distance from the pivot to rigid marker ``j``, ``theta_j`` the angle at
    the pivot between markers ``j`` and ``j+1``, their reference values the medians over the
    frames (the paper compares with one frame; the median is less noisy), and ``L`` the mean
    ``l_j`` (the angle term in millimetres of arc). Zero for a point about which the
    markers move rigidly. Returns ``(K,)``."""
    p = np.asarray(candidates, float)[:, None, None, :]        # (K, 1, 1, 3)
    v = np.asarray(rigid, float)[None] - p                      # (K, F, n, 3)
    length = np.linalg.norm(v, axis=3)                          # (K, F, n)
    u = v / length[..., None]
    cos = np.einsum("kfnc,kfnc->kfn", u, np.roll(u, -1, axis=2))
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    ref_len = np.median(length, axis=1, keepdims=True)
    ref_angle = np.median(angle, axis=1, keepdims=True)
    scale = ref_len.mean(axis=(1, 2))                          # L
    w1, w2, w3 = weights
    e = (w1 * np.abs(angle - ref_angle).sum(2).mean(1) * scale
         + w2 * np.abs(length - ref_len).sum(2).mean(1))
    if guess is not None:
        e = e + w3 * np.linalg.norm(np.asarray(candidates, float) - guess, axis=1) / pull_mm
    return e


def find_pivot(rigid, guess, step_mm: float = 8.0, grow: float = 1.2, shrink: float = 0.5,
               min_step_mm: float = 0.005, max_iterations: int = 3000, epsilon: float = 1e-9):
    """The pivot by the bold-driver descent of eq. 7 over the six directions of eq. 8: at each
    iteration the objective (eq. 5, :func:`pivot_objective`) is evaluated at ``p +- a e_k``;
    the best is taken and the step grows (``a <- rho a``) if it lowers the objective,
    otherwise the step shrinks (``a <- sigma a``). Stops when the step falls below
    ``min_step_mm``, after ``max_iterations``, or when the objective is below ``epsilon``.
    Returns ``(pivot (3,), objective, iterations)``."""
    p = np.asarray(guess, float).copy()
    directions = np.vstack([np.eye(3), -np.eye(3)])            # eq. 8
    e = float(pivot_objective(p[None], rigid, guess=guess)[0])
    a = step_mm
    it = 0
    for it in range(1, max_iterations + 1):
        trial = p + a * directions
        et = pivot_objective(trial, rigid, guess=guess)
        best = int(np.argmin(et))
        if et[best] < e:
            p, e, a = trial[best], float(et[best]), a * grow
        else:
            a *= shrink
        if a < min_step_mm or e < epsilon:
            break
    return p, e, it


def pivot_guess(rigid_ref, face_ref):
    """Where the head's pivot is expected, from the markers at the reference frame alone (the
    paper's "domain knowledge"): below the rigid headband markers, towards and past the face
    markers' centroid (``GUESS_BELOW`` times that distance), and ``GUESS_BEHIND_MM`` behind
    the face, "behind" pointing from the face markers to the centre of the sphere they lie
    on. Without face markers: the rigid markers' centroid."""
    top = np.mean(rigid_ref, axis=0)
    face = np.asarray(face_ref, float)
    face = face[np.all(np.isfinite(face), axis=1)]
    if len(face) < 4:
        return top
    mid = face.mean(axis=0)
    guess = top + GUESS_BELOW * (mid - top)
    # sphere through the face markers: |x|^2 = 2 c.x + (r^2 - |c|^2), linear least squares
    A = np.hstack([2 * face, np.ones((len(face), 1))])
    sol, *_ = np.linalg.lstsq(A, (face ** 2).sum(1), rcond=None)
    back = sol[:3] - mid
    down = mid - top
    back = back - down * (back @ down) / max(down @ down, 1e-12)  # behind, across the down direction
    if np.linalg.norm(back) > 1e-6 and np.isfinite(back).all():
        guess = guess + GUESS_BEHIND_MM * back / np.linalg.norm(back)
    return guess


def _rotation_spread(R):
    """Eigen-decomposition of ``mean_f (R_f - I)^T (R_f - I)``: for rotations about one axis
    ``u`` by ``theta`` it is ``2 (1 - cos theta) (I - u u^T)``, so an eigenvalue near 0 names
    an axis along which a fixed point is not determined."""
    D = R - np.eye(3)
    A = np.einsum("fji,fjk->ik", D, D) / len(R)
    vals, vecs = np.linalg.eigh(A)
    return vals, vecs


def _least_deforming(points, valid, ref_frame, count):
    """The markers that deform least over the take, at most ``count``: a robust rigid fit of
    all markers to the reference frame ranks them by RMS residual (over the frames where
    both are seen); fits of the ``count`` best, then three times of the three best, re-rank them (a face
    has more moving markers than still ones, so the first fit is only a start), and the
    residuals to the three best's motion decide. Beyond the three best,
    only markers about as still as they are (twice the third's RMS + 0.1 mm)."""
    ok = valid & valid[ref_frame][None]
    ref = np.where(valid[ref_frame][:, None], points[ref_frame], 0.0)
    cur = np.where(ok[..., None], points, 0.0)
    seen = ok.sum(0) >= max(3, 0.8 * ok.shape[0])
    weights = ok
    for best in (max(3, count), 3, 3, 3):
        R, t, _ = robust_rigid_fit(ref, cur, 5, mask=weights > 0)
        resid = np.linalg.norm(ref @ np.swapaxes(R, 1, 2) + t[:, None] - cur, axis=2)
        with np.errstate(invalid="ignore"):
            rms = np.sqrt(np.nanmean(np.where(ok, resid, np.nan) ** 2, axis=0))
        rms = np.where(seen & np.isfinite(rms), rms, np.inf)
        weights = ok * np.isin(np.arange(ok.shape[1]), np.argsort(rms)[:best])
    order = np.argsort(rms)[:max(3, count)]
    keep = rms[order] <= 2.0 * rms[order[2]] + 0.1
    keep[:3] = True
    return order[keep]


def _widest_triangle(ref):
    """Indices of the three points spanning the largest triangle (the best-conditioned eq. 3)."""
    i, j, k = np.array(list(combinations(range(len(ref)), 3))).T
    area = np.linalg.norm(np.cross(ref[j] - ref[i], ref[k] - ref[i]), axis=1)
    best = int(np.argmax(area))
    return [int(i[best]), int(j[best]), int(k[best])], float(area[best]) / 2


def stabilize(points, labels, rigid=None, method: str = "invariants", pivot="auto",
              n_auto_rigid: int = 4, rate: float | None = None, smooth_s: float = 0.2) -> Stabilization:
    """Remove the head motion from a take ``points (F, M, 3)`` mm, NaN in gaps.

    ``rigid``: labels of >= 3 markers on a rigid part of the head (a headband), or None to
    take the ``n_auto_rigid`` markers that deform least. ``method``: ``"invariants"`` (eq.
    1-3, the three rigid markers spanning the widest triangle) or ``"arun"`` (every rigid
    marker). ``pivot``: ``"auto"`` (eq. 4-8), ``None`` (no pivot), or a point ``(3,)`` mm.
    Raises :class:`InputError` / :class:`DegenerateError` with one sentence when the rigid
    markers cannot carry the motion."""
    pts = np.asarray(points, float)
    labels = [str(s) for s in labels]
    if pts.ndim != 3 or pts.shape[2] != 3 or pts.shape[1] != len(labels):
        raise InputError("points must have shape (frames, markers, 3), one label per marker")
    if method not in ("invariants", "arun"):
        raise InputError(f"unknown method {method!r} (invariants or arun)")
    F, M = pts.shape[:2]
    fps = rate or 60.0
    valid = np.all(np.isfinite(pts), axis=2)
    if not valid.any():
        raise InputError("the take holds no measured point (every marker-frame is a gap): no head motion to find")
    warnings = []
    if rigid is not None:
        names = list(dict.fromkeys(str(r) for r in rigid))
        missing = [r for r in names if r not in labels]
        if missing:
            raise InputError(f"rigid marker(s) not in the take: {', '.join(missing)} "
                             f"(the take has {M} labels; `mirrorcap info` lists them)")
        if len(names) < 3:
            raise InputError(f"head motion needs at least 3 rigid markers, {len(names)} given")
        idx = np.array([labels.index(r) for r in names])
        source = "given"
    else:
        if M < 4:
            raise InputError(f"the take has {M} markers: too few to find rigid ones; name >= 3 with --rigid")
        first_any = int(np.argmax(valid.sum(1)))
        idx = _least_deforming(pts, valid, first_any, max(3, n_auto_rigid))
        source = "automatic"
    complete = valid[:, idx].all(axis=1)
    if not complete.any():
        raise DegenerateError("the rigid markers are never all seen in the same frame")
    ref = int(np.argmax(complete))
    ref_rigid = pts[ref, idx]
    tri, area = _widest_triangle(ref_rigid)
    sides = [np.linalg.norm(ref_rigid[tri[a]] - ref_rigid[tri[b]]) for a, b in ((0, 1), (1, 2), (0, 2))]
    # collinear: the triangle's height is under 2 % of its longest side (or under 1 mm)
    if 2 * area / max(max(sides), 1e-9) < max(1.0, 0.02 * max(sides)):
        raise DegenerateError(f"the rigid markers {', '.join(labels[i] for i in idx)} are (nearly) collinear: "
                              "they cannot fix a rotation; use markers spanning a triangle")

    # the rigid markers' shape: their mean over the complete frames, each brought into the
    # reference frame (a single frame's shape would put its noise into every frame's motion)
    R1, t1 = rigid_fit(ref_rigid, pts[complete][:, idx])
    structure = np.mean((pts[complete][:, idx] - t1[:, None]) @ R1, axis=0)
    R, t, ok = _motion(structure, pts, valid, idx, tri, method)
    pose = np.where(ok, "rigid", "none").astype(object)
    st = Stabilization(labels=labels, points=pts, rotation=R, translation=t, pose_source=pose,
                       rigid=[labels[i] for i in idx], rigid_source=source, method=method, reference_frame=ref,
                       rigid_residual_mm=np.full(F, np.nan), warnings=warnings)
    # the rotation pivot (eq. 4-8), then the motion again with the pivot as a fourth rigid point (section 2.3)
    centre = centre_for_motion = None
    if isinstance(pivot, str) and pivot == "auto":
        vals, vecs = _rotation_spread(R[ok])
        limit = 2.0 * (1 - np.cos(np.radians(MIN_PIVOT_ROTATION_DEG)))
        if vals[-1] < limit:
            warnings.append(f"the head turns less than {MIN_PIVOT_ROTATION_DEG:g} deg: too little rotation to fix "
                            "a pivot; the motion estimate is kept without one")
        else:
            guess = pivot_guess(ref_rigid, pts[ref, np.setdiff1d(np.arange(M), idx)])
            tracks = pts[complete][:, idx]
            step = max(1, len(tracks) // PIVOT_SEARCH_FRAMES)   # a long take: every step-th frame is plenty
            centre, e, its = find_pivot(tracks[::step], guess)
            st.pivot_objective, st.pivot_iterations, st.pivot_status = float(e), its, "estimated"
            if vals[0] < limit:
                axis = vecs[:, 0] * np.sign(vecs[np.argmax(np.abs(vecs[:, 0])), 0])
                st.pivot_status = "undetermined"
                st.pivot_undetermined_axis = [round(float(v), 4) for v in axis]
                warnings.append("the head turns about one axis only (less than "
                                f"{MIN_PIVOT_ROTATION_DEG:g} deg about any other): the pivot is not determined "
                                f"along ({axis[0]:+.2f}, {axis[1]:+.2f}, {axis[2]:+.2f}) and stays at the guess "
                                "along that line; the motion is estimated from the rigid markers alone")
                centre_for_motion = None
            else:
                centre_for_motion = centre
    elif pivot is not None:
        centre = np.asarray(pivot, float).reshape(3)
        st.pivot_status = "given"
        centre_for_motion = centre
    if centre is not None:
        st.pivot_mm = centre
        # the pivot's own slow motion (sway) from the rigid markers' motion, smoothed in time
        sway = R @ centre + t - centre
        frames = np.arange(F)
        sway = np.stack([np.interp(frames, frames[ok], sway[ok, c]) for c in range(3)], axis=1)
        window, sway = _smoothed_sway(sway, fps)
        st.sway_window_s = round(window / fps, 4)
        if centre_for_motion is not None:
            R2, t2, ok2 = _motion(structure, pts, valid, idx, tri, method, pivot=(centre, sway))
            st.pose_source = np.where(ok2, np.where(ok, "rigid", "rigid+pivot"), "none").astype(object)
            st.rotation, st.translation, ok = R2, t2, ok2
        st.sway_mm = np.where(ok[:, None], sway, np.nan)
    if smooth_s > 0:
        _smooth_pose(st, ok, centre if centre is not None else np.mean(ref_rigid, axis=0), smooth_s * fps,
                     REFERENCE_SMOOTHING_S * fps)
    # the motion from the reference frame: p(f) = R_f R_ref^T (p(ref) - t_ref) + t_f
    R = st.rotation @ st.rotation[ref].T
    t = st.translation - R @ st.translation[ref]
    st.rotation, st.translation = R, t
    # eq. 9: every marker in the head frame of the reference frame
    out = (pts - t[:, None]) @ R                               # row-vector form of R^T (p - t)
    out[~ok] = np.nan
    st.points = out
    fitted = pts[ref, idx] @ np.swapaxes(R, 1, 2) + t[:, None]
    r = np.linalg.norm(fitted - pts[:, idx], axis=2)
    with np.errstate(invalid="ignore"):
        st.rigid_residual_mm = np.where(ok, np.sqrt(np.nanmean(r ** 2, axis=1)), np.nan)
    if (~ok).any():
        warnings.append(f"{int((~ok).sum())} of {F} frames have fewer than 3 rigid markers (and no pivot to stand in "
                        "for one): their markers are left as gaps")
    return st


def stabilize_file(take_path, output, report=None, *, rigid=None, method: str = "invariants", pivot="auto",
                   smooth_s: float = 0.2) -> tuple[dict, Stabilization, dict]:
    """``mirrorcap stabilize`` and the Stabilize operator: read ``take_path``, stabilise it
    (:func:`stabilize`), write ``output`` (C3D, same labels, rate, first frame and axes) and
    ``report`` (JSON) atomically. Returns the take as read, the stabilisation and the report."""
    import json

    from .. import __version__
    from ..common.files import write_files_atomically
    from .c3d import c3d_bytes, read_c3d

    take = read_c3d(take_path)
    st = stabilize(take["points"], take["labels"], rigid=rigid, method=method, pivot=pivot, rate=take["rate"],
                   smooth_s=smooth_s)
    rep = {"mirrorcap_version": __version__, "take": str(take_path), "units": take["units"],
           "first_frame": take["first_frame"], "rate": take["rate"], "smooth_s": smooth_s, **st.report()}
    files = {output: c3d_bytes(take["labels"], st.points, take["rate"], units=take["units"],
                               first_frame=take["first_frame"] - 1, frame=take["frame"])}
    if report is not None:
        files[report] = json.dumps(rep, indent=1) + "\n"
    write_files_atomically(files)
    return take, st, rep


def _odd_window(window_frames: float, n: int) -> int:
    """The Savitzky-Golay window for ``window_frames``: odd, at most ``n``."""
    return min(int(round(window_frames)) // 2 * 2 + 1, n if n % 2 else n - 1)


def _local_quadratic(values, window_frames: float):
    """``values (F, k)`` fitted by a local quadratic over ``window_frames`` (Savitzky-Golay;
    it keeps a signal's slope and curvature, also at the first and last frames, where a
    plain average would pull it towards the inside); unchanged when under 5 frames."""
    window = _odd_window(window_frames, len(values))
    if window < 5:
        return values
    return savgol_filter(values, window, 2, axis=0, mode="interp")


def _smoothed_sway(sway, fps: float):
    """The pivot's sway ``(F, 3)`` smoothed, and the window (frames) it took: the longest of
    ``SWAY_WINDOWS_S`` whose local quadratic predicts the frames it leaves out within one standard
    error of the best (leave-one-out cross-validation, in closed form for a linear smoother:
    residual / (1 - the filter's centre weight), over the inner frames; the one-standard-error
    rule). The sway is slow and its estimate at the reference frame sets every frame's head
    frame, so the longest window the data allow; a fast or large sway is followed with a short one."""
    from scipy.signal import savgol_coeffs

    scores, smoothed = [], {}
    for seconds in SWAY_WINDOWS_S:
        window = _odd_window(seconds * fps, len(sway))
        if window < 5 or window in smoothed:
            continue
        smoothed[window] = _local_quadratic(sway, window)
        h = savgol_coeffs(window, 2)[window // 2]
        inner = slice(window // 2, len(sway) - window // 2)
        loss = np.sum(((sway - smoothed[window])[inner] / (1.0 - h)) ** 2, axis=1)
        if loss.size >= 10:
            scores.append((window, float(loss.mean()), float(loss.std() / np.sqrt(loss.size))))
    if not scores:
        window = _odd_window(SWAY_WINDOWS_S[0] * fps, len(sway))
        return window, _local_quadratic(sway, window)
    best = min(scores, key=lambda s: s[1])
    window = max(w for w, cv, _ in scores if cv <= best[1] + best[2])
    return window, smoothed[window]


def _smooth_pose(st: Stabilization, ok, centre, window_frames: float, reference_window_frames: float) -> None:
    """The head pose smoothed in time: the rotation (as a rotation vector) and the motion of
    ``centre`` (the pivot, or the rigid markers' centroid) each fitted by a local quadratic
    over ``window_frames`` (Savitzky-Golay; a quadratic keeps the motion's own slope and
    curvature, also at the first and last frames), ``t`` rebuilt so that ``centre`` moves as
    smoothed. Over the posed frames only. The reference frame's pose, which every frame's
    output is expressed in, is fitted over the longer ``reference_window_frames``: its error
    tilts the whole take."""
    from scipy.spatial.transform import Rotation

    n = int(ok.sum())
    reference_window_frames = max(reference_window_frames, window_frames)
    if _odd_window(window_frames, n) < 5:
        return
    R, t = st.rotation[ok], st.translation[ok]
    rv_raw = Rotation.from_matrix(R).as_rotvec()
    moved_raw = R @ centre + t
    rv = _local_quadratic(rv_raw, window_frames)
    moved = _local_quadratic(moved_raw, window_frames)
    ref = int(np.searchsorted(np.flatnonzero(ok), st.reference_frame))
    if _odd_window(reference_window_frames, n) > _odd_window(window_frames, n):
        rv[ref] = _local_quadratic(rv_raw, reference_window_frames)[ref]
        moved[ref] = _local_quadratic(moved_raw, reference_window_frames)[ref]
    Rs = Rotation.from_rotvec(rv).as_matrix()
    st.rotation[ok] = Rs
    st.translation[ok] = moved - Rs @ centre


def _motion(structure, pts, valid, idx, tri, method, pivot=None):
    """``R (F, 3, 3), t (F, 3)`` carrying the rigid markers' ``structure (n, 3)`` to each
    frame, and the frames posed ``(F,)``. ``idx``: the rigid markers' columns in ``pts``;
    ``tri``: the three of them (positions in ``idx``) that the invariants use. ``pivot``:
    ``(centre (3,), its offset per frame (F, 3))``, used as one more rigid point; a frame then
    needs two rigid markers (with fewer than three it is fitted by Arun's method)."""
    F = len(pts)
    R = np.tile(np.eye(3), (F, 1, 1))
    t = np.zeros((F, 3))
    seen = valid[:, idx]
    full = seen[:, tri].all(1)
    cols = np.asarray(tri)
    A, B, w = structure, pts[:, idx], seen.astype(float)
    ok = seen.sum(1) >= 3
    if pivot is not None:
        centre, sway = pivot
        A = np.vstack([structure, centre])
        B = np.concatenate([B, (centre + sway)[:, None]], axis=1)
        w = np.concatenate([w, np.full((F, 1), PIVOT_POINT_WEIGHT)], axis=1)
        ok = seen.sum(1) >= 2
        cols = np.append(cols, len(idx))                      # the pivot's column
    B = np.where(w[..., None] > 0, B, 0.0)
    rest = ok
    if method == "invariants":
        R[full], t[full] = motion_by_invariants(A[cols], B[full][:, cols])
        rest = ok & ~full
    if rest.any():
        R[rest], t[rest] = rigid_fit(A, B[rest], w[rest])
    return R, t, ok
