"""Automatic marker extraction (Lin 2003, section 5.2) and the direct/mirror view split.

Per frame, vectorised over pixels and components (no per-marker Python loop):

1. **threshold** -- the pixel intensity, its brightest channel ``max(R, G, B)``, must
   exceed ``threshold``;
2. **connected components** -- 8-connected, OpenCV's ``connectedComponentsWithStats``;
3. **colour class** -- 1-NN in normalised colour ``(R, G, B) / (R + G + B)`` against the
   class samples. The paper labels every pixel and groups same-label pixels; we
   classify each component's mean colour (normalised rgb does not depend on
   brightness), which gives the same label for a one-colour marker at a fraction
   of the cost;
4. **merge** -- components of the same class whose centres are closer than the
   marker diameter are one marker (fragments from interlaced fields or broken
   labelling), merged with scipy's KD-tree and graph components;
5. **remove specks** -- markers under ``min_area`` pixels (default 4) are dropped;
6. **sub-pixel centre** -- the centroid weighted by ``intensity - threshold``;
7. **blob test** -- teeth and specular glints fluoresce or shine too, as pale, elongated
   blobs (between the lips, ~0.8 % of the detections on a real face), and two touching
   markers of different colours make one pale, elongated component. A blob whose colour is
   pale (saturation ``1 - 3 min(r, g, b)`` of its normalised mean colour below
   ``pale_saturation``; the blacklight paints sit at 0.42-0.58) *and* whose weighted second
   moments give an axis ratio above ``max_elongation`` is dropped (its centre is no marker's);
   with ``split_pale_blobs`` it is split by the colour class of each of its pixels and the
   parts that pass the test are kept (touching markers come back, but intermittently, as
   late markers that lower a take's completeness: off by default). Both must hold: a marker
   near the face's silhouette is foreshortened into an ellipse but keeps its colour, and a
   pale round blob may be a marker washed out by the lamp. Before the test, a blob of two
   touching dots is cut in two across its long axis where a weighted 2-means along it puts the
   cut (``split_touching``): its centroid lies half a dot spacing from either dot, each piece's
   within a tenth of a radius of its own. A clump is at least ``TOUCHING_AREA`` times the
   median area of its ``NEIGHBOUR_BLOBS`` nearest blobs (a mirror's dots image smaller than the
   direct view's, so the frame's median misses them), elongated (a foreshortened dot is
   smaller, not larger) and waisted: narrower across the cut than ``TOUCHING_WAIST`` of its
   narrower piece's middle (one dot smeared or foreshortened into an ellipse is widest in the
   middle). Pale clumps are cut too -- two touching dots of different colours (pink and purple
   at a mirror's grazing angle) mix to a pale blob -- and their pieces kept only if saturated,
   so teeth stay dropped.

OpenCV is used single-threaded by the benchmarks; the extractor reuses its frame
buffers between frames (:class:`MarkerExtractor`).

Colour classes (COLORS.json)::

    {"classes": [{"name": "pink", "samples": [[R, G, B], ...]}, ...]}

``samples`` are RGB triples (any scale; they are normalised by their sum). The
default classes are the four colours fluorescent markers show under blacklight-blue
lamps in the paper (pink, blue-green, dark blue, purple).

Views: every detection belongs to ``direct``, ``mirror0`` (the mirror imaged on
the left) or ``mirror1`` (on the right). Automatically, the two widest gaps in the
sorted x coordinates of the detections split the three views; a rig file
overrides that (RIG.json)::

    {"views": {"mirror0": [x0, y0, x1, y1], "direct": [x0, y0, x1, y1], "mirror1": [x0, y0, x1, y1]}}

with pixel rectangles (``x1``, ``y1`` exclusive); detections outside every
rectangle are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..common.errors import InputError
from ..common.files import read_json
from .detections import (MAX_DOT_PX, Detections, blob_moments, blob_shape, empty_detections, merge_fragments,
                         typical_dot_diameter_px)

LIGHTS = ("uv", "normal")  # fluorescent markers under black light; coloured dots under ordinary lamps

# Typical fluorescent colours under blacklight-blue lamps (section 5.2, figure 5.3(d)), RGB.
DEFAULT_CLASSES = {
    "pink": [[255, 110, 200], [240, 100, 190], [255, 130, 215], [230, 95, 170]],
    "blue-green": [[70, 230, 200], [60, 215, 185], [90, 240, 215], [55, 200, 170]],
    "dark-blue": [[60, 80, 255], [50, 70, 235], [75, 95, 255], [45, 65, 215]],
    "purple": [[175, 70, 255], [160, 60, 240], [190, 85, 255], [150, 55, 220]],
}

# Matte sticker colours as a camera sees them on skin under studio lamps (sRGB; only the
# chromaticity matters).
NORMAL_LIGHT_CLASSES = {
    "blue": [[30, 70, 230], [20, 50, 150], [40, 80, 200], [25, 60, 120]],
    "green": [[30, 175, 60], [25, 120, 45], [45, 160, 70], [20, 90, 35]],
    "yellow": [[245, 215, 20], [200, 170, 30], [230, 200, 60], [150, 120, 20]],
    "magenta": [[215, 30, 160], [170, 25, 120], [200, 50, 150], [130, 20, 95]],
}


@dataclass
class ColorClasses:
    """Colour classes for 1-NN labelling in normalised rgb."""

    names: list
    samples: np.ndarray  # (S, 3) normalised rgb
    labels: np.ndarray  # (S,) class index of each sample
    light: str | None = None  # the light the classes are for ("uv", "normal"), when the file says

    @classmethod
    def from_dict(cls, data, source: str = "colour classes") -> "ColorClasses":
        try:
            light = data.get("light")
            if light is not None and light not in LIGHTS:
                raise ValueError(f'"light" must be one of {", ".join(LIGHTS)}, not {light!r}')
            classes = data["classes"]
            names, samples, labels = [], [], []
            for k, entry in enumerate(classes):
                name = str(entry["name"])
                rgb = np.asarray(entry["samples"], dtype=float).reshape(-1, 3)
                if rgb.shape[0] == 0 or not np.all(np.isfinite(rgb)) or np.any(rgb < 0) or np.any(rgb.sum(1) <= 0):
                    raise ValueError(f"class {name!r} needs non-negative, non-black RGB samples")
                names.append(name)
                samples.append(rgb / rgb.sum(axis=1, keepdims=True))
                labels.append(np.full(rgb.shape[0], k))
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            detail = exc.args[0] if isinstance(exc, ValueError) and exc.args else "expected " \
                '{"classes": [{"name": ..., "samples": [[R, G, B], ...]}, ...], "light": "uv" | "normal"}'
            raise InputError(f"{source}: {detail}") from None
        if not names:
            raise InputError(f"{source}: no colour classes")
        if len(set(names)) != len(names):
            raise InputError(f"{source}: class names must be unique")
        return cls(names=names, samples=np.concatenate(samples), labels=np.concatenate(labels), light=light)

    @classmethod
    def default(cls, light: str = "uv") -> "ColorClasses":
        """The four blacklight paints, or under ``light="normal"`` the four sticker colours of
        :mod:`.colordots`."""
        table = DEFAULT_CLASSES if light == "uv" else NORMAL_LIGHT_CLASSES
        return cls.from_dict({"classes": [{"name": n, "samples": s} for n, s in table.items()], "light": light})

    @classmethod
    def load(cls, path) -> "ColorClasses":
        return cls.from_dict(read_json(path, "colour file"), source=f"colour file {path}")

    def to_dict(self) -> dict:
        out = {"classes": [{"name": n, "samples": np.round(self.samples[self.labels == k] * 1000, 2).tolist()}
                           for k, n in enumerate(self.names)]}
        return {**out, "light": self.light} if self.light else out

    def classify(self, rgb) -> np.ndarray:
        """Class index ``(n,)`` of colours ``(n, 3)`` (RGB, any scale) by 1-NN in
        normalised rgb."""
        rgb = np.asarray(rgb, dtype=float)
        s = rgb.sum(axis=1, keepdims=True)
        nrgb = rgb / np.where(s > 0, s, 1.0)
        # |a - b|^2 = |a|^2 - 2 a.b + |b|^2; |a|^2 is the same for every sample
        d2 = (self.samples**2).sum(axis=1)[None, :] - 2.0 * nrgb @ self.samples.T
        return self.labels[np.argmin(d2, axis=1)]

    def hue_centres(self) -> np.ndarray:
        """Each class's hue angle (radians): the circular mean of its samples' hues."""
        from .colordots import hue_saturation

        s_hue, _ = hue_saturation(self.samples)
        return np.angle(np.array([np.exp(1j * s_hue[self.labels == c]).mean() for c in range(len(self.names))]))

    def by_hue(self, rgb) -> tuple:
        """``(class (n,), hue difference in degrees (n,), saturation (n,))`` of colours ``(n, 3)``:
        the class whose samples' mean hue is nearest (hue: the angle of the colour about the grey
        axis, as in HSV; saturation ``1 - 3 min(r, g, b)`` of the normalised colour). Coloured
        dots keep their hue when the light on them changes or a mirror darkens them."""
        from .colordots import hue_apart, hue_saturation

        hue, sat = hue_saturation(rgb)
        diff = hue_apart(hue[:, None], self.hue_centres()[None])
        best = np.argmin(diff, axis=1) if diff.size else np.zeros(len(hue), int)
        return best, np.degrees(diff[np.arange(len(hue)), best]) if diff.size else np.zeros(0), sat


#: under black light only the dots glow and the face stays dark; under ordinary lamps the face is lit. The share of
#: the frame's centre -- the middle fifth of its width, the middle two fifths of its height: the direct view's face, by
#: the rig's design, whatever the backdrop or a mirror's frame -- whose brightest channel exceeds :data:`LIT_VALUE`
#: (the UV extractor's default threshold: what it would take for dots) tells them apart. Measured on the first frames
#: of the project's clips (stop 53): 2.7-6.6 % on the 30 UV clips, 93-100 % on the 19 normal-light ones, whatever
#: their skin or compression (the whole frame's share: 0.9-2.5 % against 15-43 %, where a glowing backdrop or a
#: saturated one would count)
LIT_VALUE = 60
#: ... above this share of the centre, the capture is under ordinary light
LIT_SHARE = 0.3


def lit_share(image) -> float:
    """The share of the centre of ``image`` (BGR, 8-bit; the middle fifth of its width, two fifths of its height: the
    direct view's face) whose brightest channel exceeds :data:`LIT_VALUE`."""
    image = np.asarray(image)
    h, w = image.shape[:2]
    centre = image[int(0.3 * h):int(0.7 * h) + 1, int(0.4 * w):int(0.6 * w) + 1]
    return float(np.mean(centre.max(axis=2) > LIT_VALUE))


def light_of_frame(image) -> str:
    """``"normal"`` when more than :data:`LIT_SHARE` of ``image``'s centre is lit (:func:`lit_share`), else
    ``"uv"``."""
    return "normal" if lit_share(image) > LIT_SHARE else "uv"


def capture_light(light: str | None, colors: "ColorClasses | None" = None, source=None, start: int = 0) -> str:
    """The light a capture is under: the user's choice (``--light``), else what the colour file
    says, else what frame ``start`` of the rig video ``source`` (a :class:`.video.VideoSource`) shows
    (:func:`light_of_frame`), else UV. A colour file made for the other light is refused."""
    if light is not None and light not in LIGHTS:
        raise InputError(f"light must be one of {', '.join(LIGHTS)}, not {light!r}")
    if colors is not None and colors.light and light and colors.light != light:
        raise InputError(f"the colour classes are for {colors.light} light but the capture is under {light} light")
    if not frame_says_light(light, colors):
        return light or colors.light
    if source is None:
        return "uv"
    return light_of_frame(next(iter(source.frames(start, start + 1)))[1])


def frame_says_light(light: str | None, colors: "ColorClasses | None" = None) -> bool:
    """Does the video's frame decide the light (:func:`capture_light`): neither the user (``light``) nor the
    colour file says it?"""
    return not light and not (colors is not None and colors.light)


#: :attr:`ExtractionSettings.washed_out`'s values
WASHED_OUT_CHOICES = ("auto", "keep", "drop")


@dataclass
class ExtractionSettings:
    light: str = "uv"  # "uv": fluorescent markers (this module); "normal": coloured dots (.colordots)
    threshold: float = 60.0  # on max(R, G, B), 0..255
    min_area: int = 4  # pixels; smaller markers are specks
    marker_diameter_px: float | None = None  # merge distance for fragments of one marker; None: each frame's
    # typical dot, at most MAX_DOT_PX (merge_marker_fragments)
    pale_saturation: float = 0.2  # blob test: paler than this ...
    max_elongation: float = 2.0  # ... and longer than this many times its width is not a marker
    split_pale_blobs: bool = False  # split such a blob by per-pixel class and keep its saturated parts
    split_clumps: bool = False  # split a blob of 1.8x a typical dot's area, elongated, by per-pixel class
    split_touching: bool = True  # split such a blob in two across its long axis (touching dots, any colours)
    # normal light (.colordots)
    min_difference: int = 20  # levels in some channel from the local background (first cut)
    min_contrast: float = 0.05  # chromaticity distance from the local background
    min_value: float = 20.0  # darker pixels have no reliable colour
    min_value_ratio: float = 0.45  # ... nor pixels this much darker than the skin around them (shadows)
    background_px: float = 24.0  # median window of the local background, pixels
    max_hue_deg: float = 35.0  # hue difference to the nearest class
    min_saturation: float = 0.25  # a dot's colour is saturated (skin sits at ~0.2)
    min_dot_contrast: float = 0.15  # a dot's mean chromaticity distance from the skin around it
    max_streak: float = 3.0  # axis ratio above which a blob is a streak, not a dot
    washed_out: str = "auto"  # dots whose hue fell between the colour classes: "keep", "drop", or "auto" -- kept
    # when the first frames hold more of them than capture.detect.BETWEEN_CLASSES_MAX_SHARE (DetectionStream)

    def __post_init__(self):
        if self.light not in LIGHTS:
            raise InputError(f"light must be one of {', '.join(LIGHTS)}, not {self.light!r}")
        if self.washed_out not in WASHED_OUT_CHOICES:
            raise InputError(f"washed_out must be one of {', '.join(WASHED_OUT_CHOICES)}, not {self.washed_out!r}")


CLUMP_AREA = 1.8  # split_clumps: a clump of touching dots has at least this many times the frame's median area
TOUCHING_AREA = 1.3  # split_touching: at least this many times its neighbours' typical dot (local_typical_area)
TOUCHING_ELONGATION = 1.6  # ... and this elongated (two equal discs 1.5 radii apart: 1.8; touching: 2.2)
TOUCHING_WAIST = 0.8  # ... and narrower across the cut than this share of the narrower piece's middle
TWO_MEANS_ROUNDS = 4  # rounds of the 1-D 2-means along a clump's long axis


def _split_across_long_axis(sums, blob, wgt, xs, ys):
    """Each blob of ``blob`` (per pixel: the index of the clump it belongs to, ``(P,)``; ``sums``
    the clumps' own :func:`_blob_sums`) cut in two across its long axis, where a weighted 2-means
    of the pixels' positions along that axis puts the cut. Returns each pixel's piece,
    ``2 * blob + side``, and each clump's waist ``(n,)``: the weight of its pixels within half a
    pixel of the cut over that of the lighter piece's pixels within half a pixel of its own mean.
    Two touching dots make a clump with a waist well under 1 (each piece's centroid lies within a
    tenth of a radius of its dot's centre while the clump's lies half a spacing off); one dot
    foreshortened or smeared into an ellipse is widest at its middle, a waist over 1."""
    cx, cy, sxx, syy, sxy = blob_moments(sums)
    angle = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)            # the long axis
    along = (xs - cx[blob]) * np.cos(angle)[blob] + (ys - cy[blob]) * np.sin(angle)[blob]
    cut = np.zeros(len(sums))
    n = 2 * len(sums)
    for _ in range(TWO_MEANS_ROUNDS):
        side = (along >= cut[blob]).astype(np.intp)
        piece = 2 * blob + side
        w = np.bincount(piece, wgt, n)
        mean = np.bincount(piece, wgt * along, n) / np.maximum(w, 1e-12)
        cut = 0.5 * (mean[0::2] + mean[1::2])
    piece = 2 * blob + (along >= cut[blob])
    across_cut = np.bincount(blob, wgt * (np.abs(along - cut[blob]) < 0.5), len(sums))
    middle = np.bincount(piece, wgt * (np.abs(along - mean[piece]) < 0.5), n).reshape(-1, 2)
    return piece, across_cut / np.maximum(middle.min(axis=1), 1e-12)


NEIGHBOUR_BLOBS = 9  # the blobs around a blob whose median area is its typical dot's


def local_typical_area(cx, cy, area, rows=None):
    """The typical dot area of each blob of ``rows`` (indices; None: every blob): the median area of
    its :data:`NEIGHBOUR_BLOBS` nearest blobs (itself included). A mirror's images lie further from
    the camera than the direct view's, so a frame's dots differ in size by view; their neighbours'
    do not."""
    rows = np.arange(len(area)) if rows is None else np.asarray(rows, int)
    k = min(NEIGHBOUR_BLOBS, len(area))
    if rows.size == 0:
        return np.zeros(0)
    # the rows are a frame's few elongated blobs: their distances to every blob, no tree to build
    d2 = (cx[rows, None] - cx[None]) ** 2 + (cy[rows, None] - cy[None]) ** 2
    near = np.argpartition(d2, k - 1, axis=1)[:, :k]
    return np.median(area[near], axis=1)


def merge_marker_fragments(sums, cls, settings: ExtractionSettings):
    """:func:`.detections.merge_fragments` at ``settings.marker_diameter_px`` when given, else at
    the frame's typical dot (:func:`.detections.typical_dot_diameter_px` of the blobs merged at
    ``MAX_DOT_PX``, those of at least ``min_area`` pixels), at most ``MAX_DOT_PX``. Interlaced
    fields break every dot into fragments a dot apart, which the first merge joins; on a 720x480
    rig with 2.2 mm dots (~4 px across) a fixed 6 px had merged neighbouring dots of one colour
    (4.5 % of the mirror images merged or pulled 1.5-4 px off their dot). Returns the merged sums
    and each blob's group (or None)."""
    if settings.marker_diameter_px is not None:
        return merge_fragments(sums, cls, settings.marker_diameter_px)
    merged, group = merge_fragments(sums, cls, MAX_DOT_PX)
    area = merged[:, 3]
    dot = typical_dot_diameter_px(area[area >= settings.min_area])
    return merge_fragments(sums, cls, dot) if 0 < dot < MAX_DOT_PX else (merged, group)


class MarkerExtractor:
    """Section 5.2 extraction for a stream of same-sized frames.

    Keeps its work buffers between frames (allocating fresh frame-sized arrays on
    every call costs more than the extraction itself on small VMs). Intensity is
    the brightest channel ``max(R, G, B)``: a saturated dark-blue marker is as
    bright as a white one."""

    def __init__(self, colors: ColorClasses, settings: ExtractionSettings | None = None):
        self.colors = colors
        self.settings = settings or ExtractionSettings()
        self._shape = None
        import cv2

        self._cv2 = cv2

    def _buffers(self, shape):
        if self._shape != shape:
            h, w = shape
            self._planes = [np.empty((h, w), np.uint8) for _ in range(3)]
            self._value = np.empty((h, w), np.uint8)
            self._mask = np.empty((h, w), np.uint8)  # 0/1, so that it can be read as booleans
            self._labels = np.empty((h, w), np.int32)
            self._labels16 = np.empty((h, w), np.uint16)
            self._shape = shape

    def __call__(self, frame_bgr: np.ndarray) -> Detections:
        cv2 = self._cv2
        s = self.settings
        if frame_bgr.ndim != 3 or frame_bgr.shape[2] != 3 or frame_bgr.dtype != np.uint8:
            raise InputError("frames must be 8-bit BGR images")
        self._buffers(frame_bgr.shape[:2])
        h, w = self._shape
        cv2.split(frame_bgr, self._planes)
        cv2.max(self._planes[0], self._planes[1], self._value)
        cv2.max(self._value, self._planes[2], self._value)
        t = int(np.clip(np.floor(s.threshold), 0, 254))
        cv2.threshold(self._value, t, 1, cv2.THRESH_BINARY, self._mask)
        # work inside the bounding box of the foreground only (one pass in C)
        x0, y0, bw, bh = cv2.boundingRect(self._mask)
        if bw == 0 or bh == 0:
            return empty_detections()
        roi = self._mask[y0:y0 + bh, x0:x0 + bw]
        labels = self._labels16[:bh, :bw]
        try:  # 16-bit labels halve the memory traffic; noisy frames can need 32 bits
            n, _ = cv2.connectedComponents(roi, labels, 8, cv2.CV_16U)
        except cv2.error:
            n = 65535
        if n >= 65535:
            labels = self._labels[:bh, :bw]
            n, _ = cv2.connectedComponents(roi, labels, 8, cv2.CV_32S)
        if n <= 1:
            return empty_detections()
        idx = np.flatnonzero(self._mask.view(np.bool_))
        ys, xs = np.divmod(idx, w)
        lab = labels[ys - y0, xs - x0].astype(np.intp)
        wgt = self._value.ravel().take(idx) - float(t)  # intensity - threshold, > 0
        b, g, r = (plane.ravel().take(idx) for plane in self._planes)
        sums = _blob_sums(lab, n, wgt, xs, ys, r, g, b, t)[1:]  # drop the background label
        cls = self.colors.classify(sums[:, 5:8])
        # merge fragments of one marker: same class, centres closer than a diameter
        sums, group = merge_marker_fragments(sums, cls, s)
        if group is None:
            group = np.arange(sums.shape[0])  # each component's marker
        else:
            cls = self.colors.classify(sums[:, 5:8])
        pixel_blob = None
        cx, cy, elongation, rgb, saturation = blob_shape(sums)
        odd = (saturation < s.pale_saturation) & (elongation > s.max_elongation)
        if s.split_touching and sums.shape[0] >= 10:
            touching = elongation > TOUCHING_ELONGATION     # the few elongated blobs: then their size
            rows = np.flatnonzero(touching)
            touching[rows] = sums[rows, 3] >= TOUCHING_AREA * local_typical_area(cx, cy, sums[:, 3], rows)
            if touching.any():
                sums, cls, pixel_blob, pale_parent = self._split_touching(sums, cls, group, lab, touching, odd, wgt,
                                                                          xs, ys, r, g, b, t)
                cx, cy, elongation, rgb, saturation = blob_shape(sums)
                odd = (saturation < s.pale_saturation) & ((elongation > s.max_elongation) | pale_parent)
        # step 7, the blob test; a failing blob of two touching markers of different colours is
        # split by the class of each pixel (the paper's per-pixel labelling) and its saturated parts kept
        keep = (sums[:, 3] >= s.min_area) & ~odd
        split = odd if s.split_pale_blobs else np.zeros_like(odd)
        if s.split_clumps and sums.shape[0] >= 10:
            # a clump: twice a typical dot's area and elongated -- dots of several colours touching
            # at a mirror image's foreshortened edge; split by the class of each pixel like a pale blob
            clump = (sums[:, 3] >= CLUMP_AREA * np.median(sums[:, 3])) & (elongation > s.max_elongation) & ~odd
            split = split | clump
            keep &= ~clump
        if split.any():
            odd = split
            pixel_blob = group[lab - 1] if pixel_blob is None else pixel_blob()
            pix = np.flatnonzero(odd[pixel_blob])
            pc = self.colors.classify(np.c_[r[pix], g[pix], b[pix]])
            key = pixel_blob[pix] * len(self.colors.names) + pc
            pieces, inv = np.unique(key, return_inverse=True)
            part = _blob_sums(inv, pieces.size, wgt[pix], xs[pix], ys[pix], r[pix], g[pix], b[pix], t)
            pcx, pcy, pel, prgb, psat = blob_shape(part)
            ok = (part[:, 3] >= s.min_area) & ~((psat < s.pale_saturation) & (pel > s.max_elongation))
            sums, cls = np.r_[sums[keep], part[ok]], np.r_[cls[keep], pieces[ok] % len(self.colors.names)]
            cx, cy = np.r_[cx[keep], pcx[ok]], np.r_[cy[keep], pcy[ok]]
            elongation, rgb = np.r_[elongation[keep], pel[ok]], np.r_[rgb[keep], prgb[ok]]
            keep = np.ones(sums.shape[0], bool)
        return Detections(x=cx[keep], y=cy[keep], color=cls[keep], area=sums[keep, 3].astype(int),
                          intensity=sums[keep, 4] / sums[keep, 3], rgb=rgb[keep], elongation=elongation[keep])


    def _split_touching(self, sums, cls, group, lab, touching, odd, wgt, xs, ys, r, g, b, t):
        """``split_touching``: each blob of ``touching`` (at least :data:`TOUCHING_AREA` times its
        neighbours' typical dot, more elongated than :data:`TOUCHING_ELONGATION`) that
        :func:`_split_across_long_axis` finds waisted (under :data:`TOUCHING_WAIST`) is replaced by
        the two pieces it cuts it into, each classed by its own mean colour. A pale clump (``odd``:
        touching dots of different colours mix to a pale blob, as teeth are) is cut too, and each
        of its pieces must then be saturated to be kept. ``group``: each component's blob, ``lab``:
        each pixel's component (from 1). Returns the new sums and classes, a function giving each
        pixel's new blob (for the per-pixel class split, when asked for: the whole frame's pixels
        are not touched otherwise) and which new blobs are pieces of a pale clump."""
        pix = np.flatnonzero(touching[group][lab - 1])
        clump = (np.cumsum(touching) - 1)[group[lab[pix] - 1]]      # each pixel's clump
        piece, waist = _split_across_long_axis(sums[touching], clump, wgt[pix], xs[pix], ys[pix])
        waisted = waist < TOUCHING_WAIST
        cut = np.flatnonzero(touching)[waisted]
        touching = np.zeros_like(touching)
        touching[cut] = True
        inside = waisted[clump]
        pix, piece = pix[inside], piece[inside]
        piece = 2 * (np.cumsum(waisted) - 1)[piece // 2] + piece % 2  # renumbered over the clumps cut
        part = _blob_sums(piece, 2 * cut.size, wgt[pix], xs[pix], ys[pix], r[pix], g[pix], b[pix], t)
        whole = np.flatnonzero(~touching)

        def pixel_blob():
            renumber = np.full(len(sums), -1)
            renumber[whole] = np.arange(whole.size)
            out = renumber[group[lab - 1]]
            out[pix] = whole.size + piece
            return out

        pale_parent = np.r_[np.zeros(whole.size, bool), np.repeat(odd[cut], 2)]
        return (np.r_[sums[whole], part], np.r_[cls[whole], self.colors.classify(part[:, 5:8])], pixel_blob,
                pale_parent)


def _blob_sums(label, n, wgt, xs, ys, r, g, b, threshold) -> np.ndarray:
    """Per-label sums ``(n, 11)``: weight, weighted x and y, pixel count, intensity, plain
    R, G, B, weighted x^2, y^2, xy (weights: intensity - threshold)."""
    count = np.bincount(label, None, n)
    weight = np.bincount(label, wgt, n)
    return np.stack([
        weight, np.bincount(label, wgt * xs, n), np.bincount(label, wgt * ys, n), count,
        weight + threshold * count,  # sum of intensities, without another pass
        np.bincount(label, r, n), np.bincount(label, g, n), np.bincount(label, b, n),  # colour: plain sums
        np.bincount(label, wgt * xs * xs, n), np.bincount(label, wgt * ys * ys, n),  # second moments
        np.bincount(label, wgt * xs * ys, n),
    ], axis=1)


def marker_extractor(colors: ColorClasses, settings: ExtractionSettings | None = None):
    """The extractor of the settings' light: :class:`MarkerExtractor` (UV) or
    :class:`.colordots.ColorDotExtractor` (normal light); call it on each 8-bit BGR frame."""
    settings = settings or ExtractionSettings()
    if settings.light == "normal":
        from .colordots import ColorDotExtractor

        return ColorDotExtractor(colors, settings)
    return MarkerExtractor(colors, settings)


def extract_markers(frame_bgr: np.ndarray, colors: ColorClasses,
                    settings: ExtractionSettings | None = None) -> Detections:
    """Find the markers in one 8-bit BGR frame (section 5.2, see module docstring; normal light:
    :mod:`.colordots`). For a stream of frames keep one :func:`marker_extractor` instead."""
    return marker_extractor(colors, settings)(frame_bgr)
