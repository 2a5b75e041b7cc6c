"""Coloured dots on skin under normal light (issue #21, part 1).

Under ordinary lamps nothing glows: a dot is a patch whose *colour* differs from the skin
around it, and its brightness follows the shading, the highlights and the skin tone. So the
extraction works in chromaticity -- normalised rgb ``(R, G, B) / (R + G + B)``, which does not
change when a lamp dims or a surface turns away from it -- against the *local* background:

1. **local background** -- the frame shrunk 4x (area average), median-filtered over
   ``background_px`` (a dot is far smaller than that, so the median is the skin around it),
   and enlarged back; its chromaticity ``c_bg`` per pixel;
2. **contrast** -- ``|c - c_bg|`` per pixel, where ``c`` is the pixel's chromaticity; pixels
   with contrast above ``min_contrast`` and brightest channel above ``min_value`` and above
   ``min_value_ratio`` of the background's (too dark a pixel -- the shadow a dot casts, the
   inside of the mouth -- has no reliable colour) and, if brighter than twice ``min_value``, whose hue
   differs from the background's by :data:`FROM_SKIN_DEG` (shading keeps the skin's hue: a shadow beside
   a dot would join its blob) are candidate dot pixels. Only pixels that differ from the
   background by more than ``min_difference`` levels in some channel, averaged over 3x3 pixels,
   are looked at (a cheap first cut: a dot differs from skin by far more);
3. **connected components** (8-connected, OpenCV) of the candidate pixels, split by colour where dots
   of two classes touch (:func:`split_by_colour`: otherwise they mix to a blob of neither hue); each blob's
   chromaticity is the mean of its pixels' weighted by ``contrast - min_contrast`` (the dot's
   centre, not its edge blended with skin, decides) and so is its **sub-pixel centre**;
4. **colour class** -- by hue: the class (COLORS.json, as under UV light) whose samples' mean
   hue is nearest the blob's; a blob more than ``max_hue_deg`` from every class, or paler than
   ``min_saturation``, is no dot (lips, eyebrows, shadows in the eye corners, the rim of the
   face against the room). Hue, unlike the chromaticity itself, holds when a dot darkens in a
   mirror or turns from the lamp (video's halved colour resolution also shifts a small dot's
   chromaticity toward the skin, its hue far less). The blob's hue must also be nearer its
   class's than the skin's around it, and its mean chromaticity at least ``min_dot_contrast``
   from the skin's (a shadow or the inside of the mouth has the skin's hue). With
   ``max_hue_deg >= 180`` (learning classes, when there are none yet) any blob whose hue is
   :data:`FROM_SKIN_DEG` from the skin's counts;
5. **merge** fragments of one dot (same class, centres closer than half of
   ``marker_diameter_px``, by default ``MAX_DOT_PX``: no interlaced fields break a dot here, and two neighbouring dots of
   one colour at the face's silhouette must stay two) and drop **specks** under ``min_area``
   pixels;
6. **shape test** -- a blob longer than ``max_streak`` times its width (weighted second
   moments) is a streak (a specular edge, a crease), not a dot; foreshortened dots near the
   face's silhouette stay under it.

Blobs that pass every test but the hue's, with a hue at least :data:`BETWEEN_FROM_SKIN_DEG` from the
skin's, are dots whose colour fell *between the classes* (``Detections.between``). Video compression does that
to small dots (stop 41: 0.0-1.1 % as many as the kept blobs on the rendered clips, 2.4-9.0 % on clips
re-encoded until they lost 7-54 points of their seen marker-frames): it pulls the dot's colour towards the
skin's, so the blob's own hue drifts, but the hue of its colour *less the skin's* (:func:`difference_hue`)
still points to its paint -- the right class for every such blob on a dot in six clips (stops 41 and 42),
against 72-90 % for the blob's own hue. They are returned with that class and flagged; whether a take keeps them is
:class:`.detect.DetectionStream`'s decision (``ExtractionSettings.washed_out``).

The output is the UV extractor's :class:`~.detections.Detections` (``intensity`` is the blob's
mean brightest channel), so everything downstream -- views, DETECTIONS.csv, tracking -- is
shared. Default classes: the four matte sticker colours of the normal-light sample clips
(blue, green, yellow, magenta: :data:`.markers.NORMAL_LIGHT_CLASSES`); ``mirrorcap colors learn
--light normal`` learns others.
"""

from __future__ import annotations

import numpy as np

from ..common.errors import InputError
from .detections import MAX_DOT_PX, Detections, blob_shape, empty_detections, merge_fragments

BACKGROUND_SHRINK = 4  # the background is estimated on a frame this many times smaller
#: a dot's hue differs from the skin around it by this much: each candidate pixel's (step 2), and, when the
#: classes are learned, each blob's
FROM_SKIN_DEG = 15.0
#: two touching dots of two colours: the pixels of each colour centred this far apart (split_by_colour)
SPLIT_APART_PX = 2.0
#: ... and, nearer than SPLIT_FAR_PX, each colour holding SPLIT_SHARE of the blob's weight: a dot's rim blended with
#: a dark skin or the room drifts to another class's hue on one side, 2-3 px from the dot's centre with 1-15 % of its
#: contrast (the dark clip's green dot at the silhouette took a yellow rim for a dot), where a touching dot lies a
#: diameter away or holds its own share
SPLIT_SHARE = 0.25
SPLIT_FAR_PX = 3.0
#: a blob that passes every test but its hue's -- more than ``max_hue_deg`` from every class, yet this far from the
#: skin's -- is a dot whose colour fell between the classes (:attr:`.detections.Detections.between`): what
#: video compression does to small dots (:func:`.detect.between_classes_warning`)
BETWEEN_FROM_SKIN_DEG = 60.0


def hue_angle(r, g, b) -> np.ndarray:
    """The hue angle (radians) of a colour direction given as channel columns ``(n,)``: its angle about the grey
    axis, ``atan2(sqrt(3) (g - b), 2 r - g - b)`` (any positive scale of ``r, g, b`` gives the same angle)."""
    return np.arctan2(np.sqrt(3.0) * (g - b), 2.0 * r - g - b)


def _normalised(r, g, b) -> tuple:
    """Channel columns scaled to sum 1 (a black colour left as it is)."""
    s = r + g + b
    s = np.where(s > 0, s, 1.0)
    return r / s, g / s, b / s


def hue_saturation(rgb) -> tuple:
    """Hue angle (radians) and saturation ``1 - 3 min`` of colours ``(n, 3)`` after normalising
    them to sum 1."""
    rgb = np.asarray(rgb, dtype=float).reshape(-1, 3)
    r, g, b = _normalised(rgb[:, 0], rgb[:, 1], rgb[:, 2])
    return hue_angle(r, g, b), 1.0 - 3.0 * np.minimum(np.minimum(r, g), b)


def hue_of_channels(r, g, b) -> np.ndarray:
    """:func:`hue_saturation`'s hue of colours given as three channel columns ``(n,)`` each (any float dtype,
    computed in float64), without forming an ``(n, 3)`` array: the per-pixel form of the extractor's step 2."""
    return hue_angle(*_normalised(*(np.asarray(c, dtype=float) for c in (r, g, b))))


def hue_apart(hue_a, hue_b) -> np.ndarray:
    """The angle (radians, 0 to pi) between hue angles ``hue_a`` and ``hue_b`` (broadcast), across the
    wrap at +-pi."""
    return np.abs((np.asarray(hue_a) - np.asarray(hue_b) + np.pi) % (2.0 * np.pi) - np.pi)



def difference_hue(rgb, skin_rgb) -> np.ndarray:
    """Hue angle (radians) of the chromaticity difference ``rgb - skin_rgb`` (both ``(n, 3)``, each normalised
    to sum 1): the direction in which a dot's colour lies from the skin's, as :func:`hue_saturation` measures a
    colour's direction from grey. A dot blended with the skin around it -- video compression, a small or
    grazing image -- moves along that direction, so its difference keeps the paint's hue."""
    d = np.asarray(rgb, float).reshape(-1, 3) - np.asarray(skin_rgb, float).reshape(-1, 3)
    return hue_angle(d[:, 0], d[:, 1], d[:, 2])


def split_by_colour(lab, n_blobs: int, hue, xs, ys, weight, class_hues, settings) -> tuple:
    """Step 3's blobs ``lab`` ``(n,)`` (of ``n_blobs``) of the candidate pixels at ``xs``, ``ys``, each split by
    colour where dots of two classes touch: ``(labels (n,), count, weight (n,))``. A pixel whose hue (``hue``,
    radians: :func:`hue_saturation`) lies within ``max_hue_deg`` of a class's (``class_hues``, radians:
    :meth:`.ColorClasses.hue_centres`) is that class's. A blob is split where two classes or more each hold at
    least ``min_area`` such pixels, centred (by ``weight``) :data:`SPLIT_APART_PX` from the best-held class's and,
    nearer than :data:`SPLIT_FAR_PX`, holding :data:`SPLIT_SHARE` of the blob's weight: every such class a blob
    of its own, the blob's other
    pixels joining its best-held class. (A lone dot's rim, blended with the skin, drifts towards another
    class's hue, but rings the dot or holds little of its contrast.) In a split blob each pixel's weight is
    scaled by how near its hue lies to its piece's class, so the seam where the two colours blend pulls
    neither centre. Touching dots of two colours -- at a mirror's grazing angle, or two neighbours
    foreshortened into each other -- otherwise mix to one blob of neither hue, which step 4 drops: both dots
    lost (held-out tan720: 162 of its 308 unreported seen marker-frames had no mirror blob within 6 px)."""
    n_classes = len(class_hues)
    if lab.size == 0 or n_blobs == 0 or n_classes < 2 or settings.max_hue_deg >= 180.0:
        return lab, n_blobs, weight
    apart = hue_apart(np.asarray(hue)[:, None], np.asarray(class_hues)[None])              # (n, C)
    cls = np.argmin(apart, axis=1)
    own = apart[np.arange(cls.size), cls] <= np.radians(settings.max_hue_deg)
    cell = lab[own] * n_classes + cls[own]
    size = n_blobs * n_classes
    held = np.bincount(cell, minlength=size).reshape(n_blobs, n_classes)
    strong = held >= settings.min_area
    mixed = strong.sum(axis=1) >= 2
    if not mixed.any():
        return lab, n_blobs, weight
    w = np.bincount(cell, weight[own], size) + 1e-12
    cx = (np.bincount(cell, weight[own] * xs[own], size) / w).reshape(n_blobs, n_classes)
    cy = (np.bincount(cell, weight[own] * ys[own], size) / w).reshape(n_blobs, n_classes)
    w = w.reshape(n_blobs, n_classes)
    first = np.argmax(held, axis=1)
    rows = np.arange(n_blobs)
    dist = np.hypot(cx - cx[rows, first][:, None], cy - cy[rows, first][:, None])   # each class from the first
    share = w / w.sum(axis=1, keepdims=True)
    is_first = np.arange(n_classes)[None] == first[:, None]
    strong &= (dist >= SPLIT_APART_PX) | is_first
    mixed = strong.sum(axis=1) >= 2
    if not mixed.any():
        return lab, n_blobs, weight
    # a piece near the best-held one with little of the blob's weight is that dot's rim: cut off, and dropped
    rim = strong & ~is_first & (share < SPLIT_SHARE) & (dist < SPLIT_FAR_PX)
    piece = np.where(own & strong[lab, cls], cls, first[lab])
    key = lab.astype(np.int64) * n_classes + np.where(mixed[lab], piece, 0)
    present = np.zeros(size, bool)
    present[key] = True
    new = (np.cumsum(present) - 1)[key]          # the keys numbered in order, as np.unique's inverse, in O(n)
    # in a split blob a pixel weighs by how near its hue is to its piece's class: where the dots meet, their
    # colours blend to a hue of neither, and that seam would pull both centres towards it
    near = 1.0 - apart[np.arange(piece.size), piece] / np.radians(settings.max_hue_deg)
    weight = np.where(mixed[lab], weight * np.clip(near, 0.0, 1.0), weight)
    weight = np.where(mixed[lab] & rim[lab, piece], 0.0, weight)
    return new.astype(lab.dtype), int(present.sum()), weight


class ColorDotExtractor:
    """The normal-light extractor for a stream of same-sized frames: call it with an 8-bit BGR
    frame, get :class:`~.detections.Detections` (see the module text for the steps)."""

    def __init__(self, colors, settings):
        import cv2

        self.colors, self.settings = colors, settings
        self._mask = None
        self._class_hues = colors.hue_centres()
        self._cv2 = cv2

    def _background(self, frame):
        """Per-pixel local background colour (8-bit BGR), from the shrunk, median-filtered frame."""
        cv2 = self._cv2
        h, w = frame.shape[:2]
        small = cv2.resize(frame, (max(w // BACKGROUND_SHRINK, 1), max(h // BACKGROUND_SHRINK, 1)),
                           interpolation=cv2.INTER_AREA)
        k = int(round(self.settings.background_px / BACKGROUND_SHRINK)) | 1
        med = cv2.medianBlur(small, max(k, 3))
        return cv2.resize(med, (w, h), interpolation=cv2.INTER_LINEAR)

    def candidates(self, frame_bgr: np.ndarray):
        """Step 2: ``(idx, contrast, value, bgr, background, hue)`` of the candidate dot pixels -- flat
        pixel indices, their chromaticity distance ``|c - c_bg|`` from the local background, their
        brightest channel, their colour and the background's (float32 BGR), and their hue (radians). Only
        pixels whose colour differs from the background by more than ``min_difference`` levels in some
        channel, averaged over 3x3 pixels, are looked at (a fast first cut; a dot differs from skin by far
        more)."""
        cv2 = self._cv2
        s = self.settings
        bg = self._background(frame_bgr)
        diff = cv2.absdiff(cv2.blur(frame_bgr, (3, 3)), bg)        # 3x3: sensor noise is no dot
        b_diff, g_diff, r_diff = cv2.split(diff)
        idx = np.flatnonzero(cv2.max(cv2.max(b_diff, g_diff), r_diff) > s.min_difference)   # some channel over
        px = frame_bgr.reshape(-1, 3).take(idx, axis=0).astype(np.float32)
        pb = bg.reshape(-1, 3).take(idx, axis=0).astype(np.float32)
        b, g, r = px[:, 0], px[:, 1], px[:, 2]
        bb, bg_g, br = pb[:, 0], pb[:, 1], pb[:, 2]
        s_px = np.maximum(b + g + r, 1.0)
        s_bg = np.maximum(bb + bg_g + br, 1.0)
        d0, d1, d2 = b / s_px - bb / s_bg, g / s_px - bg_g / s_bg, r / s_px - br / s_bg
        contrast = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        value = np.maximum(np.maximum(b, g), r)
        ok = np.flatnonzero((contrast > s.min_contrast) & (value >= s.min_value)
                            & (value >= s.min_value_ratio * np.maximum(np.maximum(bb, bg_g), br)))
        idx, contrast, value, px, pb = idx[ok], contrast[ok], value[ok], px[ok], pb[ok]
        # ... and a hue of its own: shading of the skin (the jaw's shadow, a crease) keeps the skin's hue, and
        # joined to a dot beside it pulled the blob's centre 8 px off (full HD: a blue dot at the jaw line
        # never tracked). Below twice min_value a pixel's hue is noise: there the test is left out (a dark
        # region cut into its noisy pieces gave the light clip a false dot at a view boundary)
        hue = hue_of_channels(px[:, 2], px[:, 1], px[:, 0])
        from_skin = np.degrees(hue_apart(hue, hue_of_channels(pb[:, 2], pb[:, 1], pb[:, 0])))
        ok = (from_skin >= FROM_SKIN_DEG) | (value < 2.0 * s.min_value)
        return idx[ok], contrast[ok], value[ok], px[ok], pb[ok], hue[ok]

    def __call__(self, frame_bgr: np.ndarray):
        cv2 = self._cv2
        s = self.settings
        if frame_bgr.ndim != 3 or frame_bgr.shape[2] != 3 or frame_bgr.dtype != np.uint8:
            raise InputError("frames must be 8-bit BGR images")
        idx, contrast, value, bgr, bg, hue = self.candidates(frame_bgr)
        if idx.size == 0:
            return empty_detections()
        h, w = frame_bgr.shape[:2]
        if self._mask is None or self._mask.shape != (h, w):
            self._mask = np.zeros((h, w), np.uint8)
        mask = self._mask
        mask.fill(0)
        mask.ravel()[idx] = 1
        n, labels = cv2.connectedComponents(mask, None, 8, cv2.CV_32S)
        ys, xs = np.divmod(idx, w)
        wgt = contrast - s.min_contrast
        # r, g, b chromaticity of each pixel and of its background (column sums: numpy's reductions
        # over a length-3 axis cost more than the arithmetic)
        chroma = bgr[:, ::-1] / np.maximum(bgr[:, 0] + bgr[:, 1] + bgr[:, 2], 1.0)[:, None]
        bg_chroma = bg[:, ::-1] / np.maximum(bg[:, 0] + bg[:, 1] + bg[:, 2], 1.0)[:, None]
        lab, m, wgt = split_by_colour(labels.ravel().take(idx) - 1, n - 1, hue, xs, ys, wgt, self._class_hues, s)
        sums = np.stack([np.bincount(lab, wgt, m), np.bincount(lab, wgt * xs, m), np.bincount(lab, wgt * ys, m),
                         np.bincount(lab, None, m), np.bincount(lab, value, m),
                         *(np.bincount(lab, wgt * chroma[:, c], m) for c in range(3)),
                         np.bincount(lab, wgt * xs * xs, m), np.bincount(lab, wgt * ys * ys, m),
                         np.bincount(lab, wgt * xs * ys, m),
                         *(np.bincount(lab, wgt * bg_chroma[:, c], m) for c in range(3))], axis=1)
        sums = sums[sums[:, 0] > 0]
        cls = self.colors.by_hue(sums[:, 5:8])[0]
        diameter = MAX_DOT_PX if s.marker_diameter_px is None else s.marker_diameter_px
        sums, _ = merge_fragments(sums, cls, 0.5 * diameter)                             # step 5: fragments
        cx, cy, elongation, rgb, saturation = blob_shape(sums)          # columns 0-10 as the UV extractor's
        blob_contrast = np.linalg.norm(rgb - sums[:, 11:14] / sums[:, :1], axis=1)
        cls, hue_diff, _ = self.colors.by_hue(rgb)
        from_skin = np.degrees(hue_apart(hue_saturation(rgb)[0], hue_saturation(sums[:, 11:14])[0]))
        if s.max_hue_deg < 180.0:
            hue_ok = (hue_diff <= s.max_hue_deg) & (hue_diff < from_skin)
        else:                         # no classes yet (colors learn): any colour that is not the skin's
            hue_ok = from_skin >= FROM_SKIN_DEG
        dot_like = ((saturation >= s.min_saturation) & (sums[:, 3] >= s.min_area) & (elongation <= s.max_streak)
                    & (blob_contrast >= s.min_dot_contrast))
        # dots between the classes (none while learning classes: any hue FROM_SKIN_DEG from the skin's passes),
        # classed by the hue of their colour less the skin's (module text)
        between = dot_like & ~hue_ok & (from_skin >= BETWEEN_FROM_SKIN_DEG)
        if between.any():
            skin = sums[between, 11:14] / sums[between, :1]
            cls[between] = np.argmin(hue_apart(difference_hue(rgb[between], skin)[:, None], self._class_hues[None]),
                                     axis=1)
        keep = (hue_ok & dot_like) | between
        return Detections(x=cx[keep], y=cy[keep], color=cls[keep], area=sums[keep, 3].astype(int),
                          intensity=sums[keep, 4] / sums[keep, 3], rgb=rgb[keep], elongation=elongation[keep],
                          contrast=blob_contrast[keep], between=between[keep])
