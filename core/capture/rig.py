"""The rig file (RIG.json): where each view lies in the image and which markers are rigid.

``{"views": {"direct": [x0, y0, x1, y1], "mirror0": [...], "mirror1": [...]},
"rigid": {"region": [x0, y0, x1, y1], "colors": ["yellow", ...]}}`` -- both keys optional.
Without views, detections are split at the two widest gaps in x; without rigid markers, the
tracker finds them (the markers that deform least). :func:`load_rig` reads the whole file
once; :func:`rigid_markers` is the one rule that picks the rigid markers from the user's
settings, the rig file or none.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..common.errors import InputError
from ..common.files import read_json

if TYPE_CHECKING:  # annotations only: rig files need no colour classes
    from .markers import ColorClasses

VIEW_NAMES = ("direct", "mirror0", "mirror1")


@dataclass
class ViewLayout:
    """How detections map to views: rectangles per view, or two x boundaries."""

    boundaries: tuple | None = None  # (b0, b1): x < b0 mirror0, b0 <= x < b1 direct, x >= b1 mirror1
    regions: dict = field(default_factory=dict)  # view name -> (x0, y0, x1, y1)
    note: str | None = None  # how an automatic split was made when the views touch (for the user)

    def assign(self, x, y) -> np.ndarray:
        """View index per detection: 0 direct, 1 mirror0, 2 mirror1, -1 outside every region."""
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        if self.regions:
            view = np.full(x.shape, -1, dtype=int)
            for k, name in enumerate(VIEW_NAMES):
                if name in self.regions:
                    x0, y0, x1, y1 = self.regions[name]
                    view[(x >= x0) & (x < x1) & (y >= y0) & (y < y1)] = k
            return view
        b0, b1 = self.boundaries
        return np.where(x < b0, 1, np.where(x < b1, 0, 2))

    def to_dict(self) -> dict:
        if self.regions:
            return {"views": {k: list(v) for k, v in self.regions.items()}}
        return {"boundaries_x": list(self.boundaries), **({"note": self.note} if self.note else {})}


def split_views_by_gaps(x, min_gap_px: float, stray_fraction: float = 0.01, min_view_fraction: float = 0.1) -> ViewLayout:
    """The two widest gaps in the sorted x coordinates (pooled over frames) separate
    mirror0 | direct | mirror1. A gap may hold a few stray detections (at most
    ``stray_fraction`` of them: markers at the very edge of a view, an ear beside a mirror
    image that nearly touches it); each view must keep ``min_view_fraction`` of the detections.
    Within each gap the boundary is the middle of its widest empty stretch. Without such gaps (the
    views touch) the emptiest lines are taken (:func:`_valley_split`, with a ``note`` for the
    user); refuses when there are none either: either gap under ``min_gap_px`` (with strays:
    under four times the typical span of as many detections) and no line emptier than
    ``VALLEY_MAX`` of the views' density (evenly spread detections show no views)."""
    xs = np.sort(np.asarray(x, dtype=float))
    n = xs.size
    if n < 6:
        raise InputError(f"too few markers ({n}) to split the direct and mirror views automatically")
    gaps = np.diff(xs)
    best = None
    for strays in sorted({0, int(stray_fraction * n)}):
        width = xs[strays + 1:] - xs[:n - strays - 1]          # gap k spans xs[k] .. xs[k + strays + 1]
        floor = min_gap_px if strays == 0 else max(min_gap_px, 4.0 * float(np.median(width)))
        order = np.argsort(width)[::-1][:200]
        for a_i, a in enumerate(order):
            for b in order[a_i + 1:]:
                k0, k1 = sorted((int(a), int(b)))
                if k1 <= k0 + strays + 1:                     # the two gaps overlap
                    continue
                parts = np.array([k0 + 1, k1 - k0 - strays - 1, n - k1 - strays - 1])
                if parts.min() < min_view_fraction * n:
                    continue
                score = min(width[k0], width[k1]) / floor
                if best is None or score > best[0] + 1e-9:
                    best = (score, k0, k1, strays)
                break                                         # b only gets narrower
        if best is not None and best[3] == 0 and best[0] >= 1.0:
            break                                             # clean gaps: no strays needed
    if best is None or best[0] < 1.0:
        valleys = _valley_split(xs, 0.5 * min_gap_px, min_view_fraction)
        if valleys is not None:
            return valleys
        w = np.sort(gaps)[-2:] if gaps.size >= 2 else gaps
        raise InputError(
            "cannot split the direct and mirror views automatically: no clear gap between them "
            f"(widest gaps {w[0]:.1f} and {w[-1]:.1f} px); give a rig file with --rig"
        )
    _, k0, k1, strays = best
    bounds = []
    for k in (k0, k1):
        inner = k + int(np.argmax(gaps[k:k + strays + 1]))      # the widest empty stretch of the gap
        bounds.append(float((xs[inner] + xs[inner + 1]) / 2))
    return ViewLayout(boundaries=tuple(bounds))


BOUNDARY_CROWDED = 0.25   # a view boundary is crowded when the dots near it reach this share of a view's density


def view_boundaries(layout: ViewLayout) -> list:
    """``[(x, left view, right view)]``: the vertical lines that separate the views of
    ``layout`` (its two x boundaries, or the direct rectangle's left and right edges)."""
    if not layout.regions:
        b0, b1 = layout.boundaries
        return [(float(b0), "mirror0", "direct"), (float(b1), "direct", "mirror1")]
    x0, _, x1, _ = layout.regions["direct"]
    return [(float(x0), "mirror0", "direct"), (float(x1), "direct", "mirror1")]


class XHistogram:
    """The detections' image x pooled over a stream, for :func:`check_view_boundaries`, in bins of
    ``1 / BINS_PER_PX`` pixel: its memory is the image's width, not the stream's length (a
    10,000-frame stream of 557 dots a frame held 45 MB of x). ``add`` a frame's x; ``len`` is the
    count."""

    BINS_PER_PX = 16

    def __init__(self):
        self.counts = np.zeros(0, np.int64)

    def add(self, x) -> None:
        i = np.maximum(np.floor(np.asarray(x, float) * self.BINS_PER_PX), 0).astype(np.int64)
        if i.size:
            if i.max() >= self.counts.size:
                self.counts = np.r_[self.counts, np.zeros(int(i.max()) + 1 - self.counts.size, np.int64)]
            self.counts += np.bincount(i, minlength=self.counts.size)

    def __len__(self) -> int:
        return int(self.counts.sum())

    def below(self, v) -> np.ndarray:
        """How many x lie below ``v`` (to the bins' width)."""
        cum = np.r_[0, np.cumsum(self.counts)]
        return cum[np.clip(np.ceil(np.asarray(v, float) * self.BINS_PER_PX).astype(np.int64), 0, cum.size - 1)]

    def span(self) -> tuple:
        filled = np.flatnonzero(self.counts)
        return filled[0] / self.BINS_PER_PX, (filled[-1] + 1) / self.BINS_PER_PX


def _line_counts(below, lo: float, hi: float, half: float):
    """Every vertical line ``centres`` (1 px apart) over ``lo``..``hi``, the detections within
    ``half`` of each (``counts``; ``below(v)``: how many lie below ``v``) and the views' ``typical``
    count (the median over the lines that hold any)."""
    centres = np.arange(np.floor(lo), np.ceil(hi) + 1.0)
    counts = below(centres + half) - below(centres - half)
    return centres, counts, float(np.median(counts[counts > 0]))


def check_view_boundaries(x, layout: ViewLayout, frames: int, dot_px: float) -> dict:
    """Do the view boundaries of ``layout`` run between the views' dots? ``x``: the detections'
    image x pooled over ``frames`` frames (an array, or an :class:`XHistogram` of them); ``dot_px``:
    a dot's diameter in pixels.

    Per boundary: ``dots_per_frame`` within ``dot_px`` of it and ``crowding``, the detection
    density there (a window ``2 dot_px`` wide) over the views' typical density (the median of
    the windows that hold any detection), and the emptiest line within a tenth of the image's
    span on either side (``emptiest_x``, ``emptiest_crowding``). A boundary is ``crowded`` above
    ``BOUNDARY_CROWDED``: either it cuts through a view (a split at the mirrors' edges does, once
    the mirrors are turned so far towards the face that the cheeks pass in front of them) or the
    views touch there; either way dots near it are read in the wrong view. Density alone cannot
    tell the two apart -- a mirror image is densest at its foreshortened edge -- so the report
    gives the emptiest line nearby for the user to judge. ``automatic``: the lines were split from the
    first frames' detections (no rig file), whose ``note`` (views that touch, :func:`_valley_split`) is
    carried along."""
    half = max(float(dot_px), 2.0)
    out = {"boundaries": [], "crowded": False, "automatic": not layout.regions,
           **({"note": layout.note} if layout.note else {})}
    if len(x) < 10 or frames < 1:
        return out
    if isinstance(x, XHistogram):
        below, (lo, hi) = x.below, x.span()
    else:
        xs = np.sort(np.asarray(x, dtype=float))
        below, lo, hi = (lambda v: np.searchsorted(xs, v)), xs[0], xs[-1]
    centres, counts, typical = _line_counts(below, lo, hi, half)
    reach = 0.1 * (hi - lo)
    for b, left, right in view_boundaries(layout):
        near = int(below(b + half) - below(b - half))
        window = np.flatnonzero((centres >= b - reach) & (centres <= b + reach))
        i = window[np.argmin(counts[window])] if window.size else None
        best_x, best = (float(centres[i]), int(counts[i])) if i is not None else (b, near)
        entry = {"x": b, "between": [left, right], "dots_per_frame": near / frames, "crowding": near / typical,
                 "emptiest_x": best_x, "emptiest_crowding": best / typical,
                 "crowded": bool(near / typical > BOUNDARY_CROWDED)}
        out["boundaries"].append(entry)
        out["crowded"] |= entry["crowded"]
    return out


def view_boundary_warnings(check: dict | None) -> list:
    """One sentence per crowded boundary of a :func:`check_view_boundaries` result, after the
    automatic split's ``note`` when it had to split views that touch."""
    out = [check["note"]] if check and check.get("note") else []
    for b in (check or {}).get("boundaries", []):
        if b["crowded"]:
            left, right = b["between"]
            if check.get("automatic"):   # split from the first frames: the head may cross the line later
                cause = (f"the views touch there, or the face moved across the line after the first frames it was "
                         f"split from (the emptiest line nearby, over the take, is x = {b['emptiest_x']:.0f})")
                fix = "give a rig file with --rig to place the views, or move the mirrors out or turn them away " \
                      "from the face"
            else:
                cause = (f"the views touch there, or the rig file's views are misplaced (the emptiest line nearby is "
                         f"x = {b['emptiest_x']:.0f})")
                fix = "check the views, or move the mirrors out or turn them away from the face"
            out.append(f"the view boundary at x = {b['x']:.0f} ({left} | {right}) runs through dots "
                       f"({b['dots_per_frame']:.1f} detections per frame within a dot of it): {cause}; "
                       f"dots on the wrong side are read as the other view's -- {fix}")
    return out


VALLEY_MAX = 0.35  # an automatic split where the views touch: its lines at most this share of a view's density


def _valley_split(xs, half_px: float, min_view_fraction: float) -> ViewLayout | None:
    """Where the views touch (no empty gap, e.g. mirrors turned 45 deg towards the face, the cheeks in
    front of them): the two emptiest lines -- the fewest detections within ``half_px`` -- that leave
    each view ``min_view_fraction`` of the sorted detections ``xs``; each in the middle of its run of
    equally empty lines. None when even they hold over ``VALLEY_MAX`` of a view's typical density
    (evenly spread detections: no views to find), or when another line inside the views, more than
    four dots from both, is as empty as the emptier of them (sparse markers leave empty columns
    within a view: the split would be a guess); a line within eight dots of a chosen one and joined to it
    by lines under ``VALLEY_MAX`` of the density is the same valley (:func:`_same_trough`)."""
    half = max(float(half_px), 2.0)
    centres, counts, typical = _line_counts(lambda v: np.searchsorted(xs, v), xs[0], xs[-1], half)
    share = np.searchsorted(xs, centres) / xs.size            # detections left of each line (non-decreasing)
    f = min_view_fraction
    # for each first line i, the emptiest second line j (the first of equals) with share[j] in
    # [share[i] + f, 1 - f]: a suffix minimum over counts up to the last such line
    last = int(np.searchsorted(share, 1.0 - f, side="right")) - 1
    first_i = np.flatnonzero((share >= f) & (share <= 1.0 - 2.0 * f))
    j_from = np.searchsorted(share, share[first_i] + f, side="left")
    ok = j_from <= last
    if last < 0 or not ok.any():
        return None
    first_i, j_from = first_i[ok], j_from[ok]
    L = len(counts)
    key = counts[:last + 1].astype(np.int64) * L + np.arange(last + 1)   # count, then index
    best_j = np.minimum.accumulate(key[::-1])[::-1][j_from] % L
    total = counts[first_i] + counts[best_j]
    k = int(np.argmin(total))
    best = (int(total[k]), int(first_i[k]), int(best_j[k]))
    if best[0] / 2.0 > VALLEY_MAX * typical:
        return None
    # the lines must stand out: another line inside the views as empty as the emptier of the two
    # (sparse markers leave empty columns within a view) makes the split a guess
    inner = (share >= f) & (share <= 1.0 - f)
    empty = inner & (counts <= min(counts[best[1]], counts[best[2]]))
    from_chosen = np.minimum(np.abs(centres - centres[best[1]]), np.abs(centres - centres[best[2]]))
    near_chosen = (from_chosen <= 4.0 * half) | (
        (from_chosen <= 8.0 * half) & _same_trough(counts <= VALLEY_MAX * typical, (best[1], best[2])))
    if (empty & ~near_chosen).any():
        return None

    def middle(k):                                            # the middle of the run of equal counts
        lo = hi = k
        while lo > 0 and counts[lo - 1] == counts[k]:
            lo -= 1
        while hi + 1 < len(counts) and counts[hi + 1] == counts[k]:
            hi += 1
        return float(0.5 * (centres[lo] + centres[hi]))

    b0, b1 = middle(best[1]), middle(best[2])
    return ViewLayout(boundaries=(b0, b1), note=(
        f"no empty gap between the views: split at the emptiest lines x = {b0:.0f} and {b1:.0f} "
        f"({best[0] / 2.0 / typical:.2f} of a view's dot density there); dots near them may be read in the wrong "
        "view -- give a rig file with --rig to place the views yourself"))


def _same_trough(low, lines) -> np.ndarray:
    """Which lines share a trough with one of ``lines`` (indices): the run of consecutive ``low`` lines
    around each. Between a face and its mirror image the emptiest stretch can hold two empty lines with
    a few stray dots between them (an ear, a cheek's edge: the close clip's 452 and 479 px, 27 px apart);
    they are one valley, not an empty column inside a view (the caller takes such lines within 8 dots)."""
    run = np.cumsum(np.r_[True, low[1:] != low[:-1]])          # a run number per line
    chosen = [run[i] for i in lines if low[i]]
    return low & np.isin(run, chosen)


def load_rig_views(path) -> ViewLayout | None:
    """The ``views`` rectangles of a RIG.json (see module docstring); None when the file
    only names the rigid markers (the views are then split automatically)."""
    data = read_json(path, "rig file")
    views = data.get("views") if isinstance(data, dict) else None
    if views is None and isinstance(data, dict) and "rigid" in data:
        return None
    if not isinstance(views, dict) or "direct" not in views:
        raise InputError(f"rig file {path}: needs \"views\" with at least \"direct\" (and mirror0, mirror1)")
    regions = {}
    for name, rect in views.items():
        if name not in VIEW_NAMES:
            raise InputError(f"rig file {path}: unknown view {name!r} (use {', '.join(VIEW_NAMES)})")
        regions[name] = rectangle(rect, f"rig file {path}: view {name!r}")
    return ViewLayout(regions=regions)


def rectangle(values, what: str) -> tuple:
    """``(x0, y0, x1, y1)`` floats from four numbers, ``x1 > x0`` and ``y1 > y0``; otherwise
    an input error naming ``what``."""
    try:
        x0, y0, x1, y1 = (float(v) for v in values)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be [x0, y0, x1, y1]") from None
    if not (x1 > x0 and y1 > y0):
        raise InputError(f"{what} is an empty rectangle")
    return x0, y0, x1, y1


@dataclass
class RigidMarkers:
    """Which markers carry the head pose, as a RIG.json names them (``"rigid"``): those
    whose first-frame image lies in ``region`` ``(x0, y0, x1, y1)`` pixels (e.g. a box
    around the forehead and nose bridge) and/or whose colour class is one of ``colors``
    (e.g. a head band's markers in a colour of their own). Either may be None."""

    region: tuple | None = None
    colors: tuple | None = None  # colour-class names


def load_rig_rigid(path) -> RigidMarkers | None:
    """The optional ``"rigid"`` entry of a RIG.json: ``{"region": [x0, y0, x1, y1],
    "colors": ["green", ...]}`` (either or both); None when the file names no rigid markers."""
    data = read_json(path, "rig file")
    entry = data.get("rigid") if isinstance(data, dict) else None
    if entry is None:
        return None
    if not isinstance(entry, dict) or not ({"region", "colors"} & set(entry)) or set(entry) - {"region", "colors"}:
        raise InputError(f"rig file {path}: \"rigid\" must be {{\"region\": [x0, y0, x1, y1], \"colors\": [names]}} "
                         "(either or both)")
    region = rectangle(entry["region"], f"rig file {path}: the rigid region") if "region" in entry else None
    colors = None
    if "colors" in entry:
        names = entry["colors"]
        if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
            raise InputError(f"rig file {path}: rigid colors must be a list of colour-class names")
        colors = tuple(names)
    return RigidMarkers(region=region, colors=colors)


@dataclass
class Rig:
    """RIG.json: the views (``None``: split at the gaps) and the rigid markers (``None``: automatic)."""

    views: ViewLayout | None = None
    rigid: RigidMarkers | None = None


def load_rig(path) -> Rig:
    """The whole rig file, checked once (a bad ``"rigid"`` entry is an error even for a
    command that only needs the views). ``path`` ``None``: the defaults."""
    if path is None:
        return Rig()
    return Rig(views=load_rig_views(path), rigid=load_rig_rigid(path))


def rigid_selection(rigid: RigidMarkers | None, classes: ColorClasses) -> tuple | None:
    """Rigid markers as :func:`..track.tracker.track` takes them: ``(region, colour
    class indices)``; colour names not among ``classes`` are an input error."""
    if rigid is None:
        return None
    unknown = [n for n in (rigid.colors or ()) if n not in classes.names]
    if unknown:
        raise InputError(f"RIG.json names rigid colour classes {', '.join(unknown)} that are not among "
                         f"{', '.join(classes.names)}")
    return rigid.region, None if rigid.colors is None else tuple(classes.names.index(n) for n in rigid.colors)


def rigid_markers(region, colour_names, rig: Rig, classes: ColorClasses) -> tuple[tuple | None, str]:
    """The rigid markers the tracker uses and where they came from: the user's ``region``
    ``(x0, y0, x1, y1)`` (all 0: none) and/or ``colour_names`` if given ("settings"), else the
    rig file's (``"rig file"``), else none (``"automatic"``: the tracker finds them).
    Returns ``(spec for the tracker or None, source)``."""
    region = tuple(int(v) for v in region)
    names = tuple(n.strip() for n in colour_names if n.strip())
    if any(region) or names:
        box = rectangle(region, f"the rigid region {region}") if any(region) else None
        rigid, source = RigidMarkers(region=box, colors=names or None), "settings"
    else:
        rigid, source = rig.rigid, "rig file"
    spec = rigid_selection(rigid, classes)
    return spec, (source if spec is not None else "automatic")
