"""A clip's detections as the later stages read them, normalised once on ingest.

:class:`FrameDets` is one frame's detections per view in pixels (what the detector, the
add-on's clip tracks or the simulator give). :class:`ClipDetections` holds a whole clip
as flat arrays per view -- pixels, colour classes, frames and the *normalised camera*
coordinates (Lin 2003, ch. 3: undistorted, ``f = 1``) from one
:meth:`core.geometry.camera.Camera.normalize` call per view. Self-calibration, pairing,
the 3D candidates and the tracker all read ``norm`` from it; none of them undistorts
pixels again. Where the detector gives them, it keeps the blobs' areas too, from which the
tracker knows a mirror blob of two dots' images (:meth:`ClipDetections.merged`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .detections import typical_dot_diameter_px


#: a blob of at least this many times its typical dot's area (ClipDetections.area_share) is taken for two dots'
#: images run into one, where a mirror sees the face at a grazing angle: its centre lies between them, and a point
#: measured through it 1-4 mm along the direct ray. The tracker measures no marker through such a mirror blob
#: (track.gapfill, track.singleview). Over 17 stress clips points over 2 mm 194 -> 156 (dense 1 -> 0, webcam
#: 57 -> 21). With the gap fill's doubt alone: 161 at 2.0, 160 at 1.7, 177 at 1.5 (dense's merged images measure
#: 1.5-2.4, single ones 0.8-1.2), 184 at 2.5
MERGED_SHARE = 2.0


def frame_spaced(points, frame, within: float, *extent) -> np.ndarray:
    """``points`` ``(M, D)`` with the ``frame`` number ``(M,)`` as one more coordinate, in
    steps far larger than ``within`` and than any coordinate of ``points`` or of the other
    arrays in ``extent``: a KD-tree over such points pairs only points of the frames meant."""
    spacing = 10.0 * (sum(np.abs(a).max() for a in (points, *extent)) + within + 1.0)
    return np.c_[points, np.asarray(frame) * spacing]


@dataclass
class FrameDets:
    """One frame's detections per view (pixels, colour-class indices; blob areas in pixels where
    the detector gives them, else None)."""

    direct: np.ndarray
    direct_color: np.ndarray
    mirror: list = field(default_factory=list)
    mirror_color: list = field(default_factory=list)
    direct_area: np.ndarray = None
    mirror_area: list = None


@dataclass
class ClipDetections:
    """The detections of a whole clip as flat arrays, one entry per view (0: direct,
    1..K: mirrors), each sorted by frame: pixels ``xy`` ``(D, 2)``, undistorted
    normalised coordinates ``norm`` ``(D, 2)`` (one ``Camera.normalize`` call per view
    for the clip), colour classes ``colour`` ``(D,)``, ``frame`` ``(D,)`` and the offsets
    ``start`` ``(F + 1,)``: frame ``f`` of view ``v`` is ``start[v][f]:start[v][f + 1]``;
    ``area`` ``(D,)`` the blobs' areas in pixels, or None where the detections carry none (the
    add-on's 2D tracks). A detection's index in its view is its *global* blob index."""

    n_frames: int
    xy: list
    norm: list
    colour: list
    frame: list
    start: list
    area: list = None

    @classmethod
    def from_frames(cls, frames, camera) -> "ClipDetections":
        """From per-frame objects with ``direct``, ``direct_color``, ``mirror[k]`` and
        ``mirror_color[k]`` (:class:`FrameDets`, :class:`synthetic.simulate.FrameDetections`)."""
        F = len(frames)
        K = len(frames[0].mirror) if F else 0
        xy, norm, colour, frame, start = [], [], [], [], []
        with_area = F > 0 and all(getattr(f, "direct_area", None) is not None for f in frames)
        area = [] if with_area else None
        for v in range(K + 1):
            pos = [np.asarray(f.direct if v == 0 else f.mirror[v - 1], float).reshape(-1, 2) for f in frames]
            col = [np.asarray(f.direct_color if v == 0 else f.mirror_color[v - 1], int).reshape(-1) for f in frames]
            counts = np.array([len(p) for p in pos], int)
            xy.append(np.concatenate(pos) if F else np.zeros((0, 2)))
            norm.append(camera.normalize(xy[-1]) if len(xy[-1]) else np.zeros((0, 2)))
            colour.append(np.concatenate(col) if F else np.zeros(0, int))
            frame.append(np.repeat(np.arange(F), counts))
            start.append(np.r_[0, np.cumsum(counts)])
            if with_area:
                area.append(np.concatenate([np.asarray(f.direct_area if v == 0 else f.mirror_area[v - 1], float)
                                            .reshape(-1) for f in frames]))
        return cls(F, xy, norm, colour, frame, start, area)

    @classmethod
    def of(cls, frames, camera) -> "ClipDetections":
        """``frames`` as a :class:`ClipDetections`: itself when it is one already
        (nothing normalised again), else :meth:`from_frames`."""
        return frames if isinstance(frames, cls) else cls.from_frames(frames, camera)

    def __len__(self) -> int:
        return self.n_frames

    def typical_dot_px(self) -> list:
        """Per view, the diameter (pixels) of a disc of the median blob's area; None where the detections carry
        no areas (the add-on's 2D tracks) or the view has no blob."""
        if self.area is None:
            return [None] * len(self.xy)
        return [typical_dot_diameter_px(a) if len(a) else None for a in self.area]

    def typical_spacing(self, view: int, focal_px: float | None = None, frames: int = 20) -> float:
        """The median distance (pixels) from a blob of ``view`` to the nearest other blob of its frame,
        of any colour, over ``frames`` frames spread over the clip: undistorted (``norm`` times
        ``focal_px``) when ``focal_px`` is given, else as detected (``xy``). ``inf`` with fewer than 2
        blobs."""
        from scipy.spatial import cKDTree

        chosen = np.unique(np.linspace(0, self.n_frames - 1, frames).astype(int))
        pick = np.isin(self.frame[view], chosen)
        if pick.sum() < 2:
            return np.inf
        xy = self.xy[view][pick] if focal_px is None else self.norm[view][pick] * focal_px
        points = frame_spaced(xy, self.frame[view][pick], 0.0)                     # one tree for every frame
        d, _ = cKDTree(points).query(points, k=2)
        return float(np.median(d[:, 1]))

    def head(self, n: int) -> "ClipDetections":
        """The first ``n`` frames (views into the same arrays; blob indices unchanged)."""
        return self.window(0, n)

    def window(self, first: int, stop: int) -> "ClipDetections":
        """Frames ``first:stop`` as a clip of their own (array views; blob indices and frame
        numbers count from ``first``, so they are the window's own)."""
        a = max(0, min(int(first), self.n_frames))
        b = max(a, min(int(stop), self.n_frames))
        lo = [int(s[a]) for s in self.start]
        hi = [int(s[b]) for s in self.start]
        cut = [slice(x, y) for x, y in zip(lo, hi)]
        return ClipDetections(b - a, [v[c] for v, c in zip(self.xy, cut)], [v[c] for v, c in zip(self.norm, cut)],
                              [v[c] for v, c in zip(self.colour, cut)], [v[c] - a for v, c in zip(self.frame, cut)],
                              [s[a:b + 1] - x for s, x in zip(self.start, lo)],
                              None if self.area is None else [v[c] for v, c in zip(self.area, cut)])

    def frame_view(self, f: int, v: int) -> slice:
        return slice(int(self.start[v][f]), int(self.start[v][f + 1]))

    def per_frame(self, v: int, what: str = "xy") -> list:
        """View ``v``'s ``what`` (``"xy"``, ``"norm"`` or ``"colour"``) as a list over
        frames (array views, no copies)."""
        return np.split(getattr(self, what)[v], self.start[v][1:-1])

    def area_share(self, v: int, blobs=None) -> np.ndarray | None:
        """The area of each blob of view ``v`` (or of those indexed by ``blobs``) over its typical dot's
        there: the median area of its :data:`.markers.NEIGHBOUR_BLOBS` nearest blobs of the frame (itself
        included), as the detector reads it (:func:`.markers.local_typical_area`: a mirror's images are
        smaller than the direct view's, and shrink towards the face's edge). About 1 for a dot, 1.5-2.5
        for two dots' images run into one blob. None without areas."""
        from scipy.spatial import cKDTree

        if self.area is None:
            return None
        area = self.area[v]
        blobs = np.arange(area.size) if blobs is None else np.asarray(blobs, int).reshape(-1)
        k = self._neighbour_count(v)    # (a frame of fewer blobs borrows the nearest frame's)
        if k < 2:
            return np.ones(blobs.size)
        # the tracker's steps ask about a few blobs at a time, again and again: one tree per view, each
        # blob's share computed once
        cache = self.__dict__.setdefault("_area_share", {})
        if v not in cache:
            points = frame_spaced(self.xy[v], self.frame[v], 0.0)              # one tree for every frame
            cache[v] = (cKDTree(points), points, np.full(area.size, np.nan))
        tree, points, share = cache[v]
        todo = np.unique(blobs[np.isnan(share[blobs])])
        if todo.size:
            _, near = tree.query(points[todo], k=k, workers=-1)
            share[todo] = area[todo] / np.maximum(np.median(area[near], axis=1), 1e-9)
        return share[blobs]

    def merged(self, v: int, blobs=None) -> np.ndarray:
        """Which blobs of view ``v`` (or of those indexed by ``blobs``) are two dots' images run into one:
        at least :data:`MERGED_SHARE` times their typical dot's area (:meth:`area_share`). All False
        without areas. A blob smaller than that share of its frame's least typical area -- the area a median of
        any :data:`.markers.NEIGHBOUR_BLOBS` of the frame's blobs can be, at the least -- is not, and its share is
        not worked out (the direct view's blobs, asked about whole, cost the gap fill a tenth of a second)."""
        if self.area is None:
            return np.zeros(len(self.frame[v]) if blobs is None else np.size(blobs), bool)
        blobs = np.arange(len(self.frame[v])) if blobs is None else np.asarray(blobs, int).reshape(-1)
        maybe = self.area[v][blobs] >= MERGED_SHARE * self._least_typical_area(v)[self.frame[v][blobs]]
        out = np.zeros(blobs.size, bool)
        out[maybe] = self.area_share(v, blobs[maybe]) >= MERGED_SHARE
        return out

    def _least_typical_area(self, v: int) -> np.ndarray:
        """Per frame ``(F,)``, the least that :meth:`area_share`'s typical area can be for a blob of view ``v``: the
        frame's ``(k - 1) // 2``-th smallest area (``k`` the neighbours it takes), where the frame has ``k`` blobs
        or more (its nearest blobs are then its own, and any ``k`` of them have a median no smaller); 0 elsewhere."""
        cache = self.__dict__.setdefault("_least_typical", {})
        if v not in cache:
            area, counts = np.asarray(self.area[v], float), self.counts(v)
            k = self._neighbour_count(v)
            least = np.zeros(self.n_frames)
            full = np.flatnonzero(counts >= max(k, 1))
            if full.size:
                order = np.lexsort((area, self.frame[v]))            # by frame, then area
                least[full] = area[order[self.start[v][full] + (k - 1) // 2]]
            cache[v] = least
        return cache[v]

    def _neighbour_count(self, v: int) -> int:
        """How many blobs :meth:`area_share` takes as a blob of view ``v``'s neighbours, itself included:
        :data:`.markers.NEIGHBOUR_BLOBS`, or all the view has when fewer."""
        from .markers import NEIGHBOUR_BLOBS

        return min(NEIGHBOUR_BLOBS, len(self.area[v]))

    def counts(self, v: int) -> np.ndarray:
        """Detections per frame in view ``v`` ``(F,)``."""
        return np.diff(self.start[v])
