"""What a marker extractor returns for one frame: :class:`Detections` (UV markers,
:mod:`.markers`; coloured dots, :mod:`.colordots`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Detections:
    """Markers found in one frame (arrays of equal length)."""

    x: np.ndarray
    y: np.ndarray
    color: np.ndarray  # class index
    area: np.ndarray  # pixels
    intensity: np.ndarray  # mean max(R, G, B) over the marker's pixels
    rgb: np.ndarray = None  # (n, 3) mean colour, normalised to sum 1
    elongation: np.ndarray = None  # (n,) axis ratio from the weighted second moments (1: round)
    contrast: np.ndarray = None  # (n,) normal light: the dot's chromaticity distance from the skin around it
    between: np.ndarray = None  # (n,) bool, normal light: a dot whose hue fell between the colour classes, classed
    # by its colour less the skin's (colordots); None: no such blobs looked for (UV)

    def between_count(self) -> int:
        """How many of the blobs are :attr:`between` the colour classes (0 where none were looked for)."""
        return 0 if self.between is None else int(np.count_nonzero(self.between))

    def subset(self, keep) -> "Detections":
        """The blobs where ``keep`` ``(n,)`` (bool) holds, every per-blob array cut alike."""
        return Detections(**{name: (value[keep] if isinstance(value, np.ndarray) else value)
                             for name, value in self.__dict__.items()})

    def __len__(self):
        return self.x.size


def empty_detections() -> Detections:
    return Detections(np.zeros(0), np.zeros(0), np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros(0),
                      np.zeros((0, 3)), np.zeros(0))


MAX_DOT_PX = 6.0  # a dot's diameter when ExtractionSettings.marker_diameter_px is not given, and the most
# the typical dot may set it to: fragments of one marker lie within a dot of each other, at most this far


def disc_diameter_px(area) -> float:
    """The diameter (pixels) of a disc of ``area`` pixels."""
    return float(2.0 * np.sqrt(area / np.pi))


def typical_dot_diameter_px(areas) -> float:
    """The diameter of a disc of the median blob area (pixels): a frame's typical dot. 0 without blobs."""
    areas = np.asarray(areas, float)
    return disc_diameter_px(np.median(areas)) if areas.size else 0.0


def merge_fragments(sums, cls, radius_px: float):
    """Blobs of one class whose centres lie within ``radius_px`` of each other are fragments of
    one marker (interlaced fields, broken labelling): ``sums (n, k)`` of per-blob sums whose
    columns 0-2 are the weight and the weighted x and y, ``cls (n,)`` their classes. Returns the
    merged sums (rows added up; scipy's KD-tree and graph components) and each blob's group
    ``(n,)``, or the input and ``None`` when nothing merges."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    if sums.shape[0] < 2 or radius_px <= 0:
        return sums, None
    cx, cy = sums[:, 1] / sums[:, 0], sums[:, 2] / sums[:, 0]
    pairs = cKDTree(np.c_[cx, cy]).query_pairs(radius_px, output_type="ndarray")
    if pairs.size:
        pairs = pairs[cls[pairs[:, 0]] == cls[pairs[:, 1]]]
    if not pairs.size:
        return sums, None
    n = sums.shape[0]
    k, group = connected_components(coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)),
                                    directed=False)
    merged = np.zeros((k, sums.shape[1]))
    np.add.at(merged, group, sums)
    return merged, group


def blob_moments(sums):
    """Weighted centre ``cx, cy`` and covariance ``sxx, syy, sxy`` of blobs from their per-blob
    sums (:func:`blob_shape`)."""
    cx, cy = sums[:, 1] / sums[:, 0], sums[:, 2] / sums[:, 0]
    w = sums[:, 0]
    return cx, cy, sums[:, 8] / w - cx * cx, sums[:, 9] / w - cy * cy, sums[:, 10] / w - cx * cy


def blob_shape(sums):
    """Centre, axis ratio (weighted covariance; + 1/12, a pixel's own extent, so a
    one-pixel-wide streak has a finite ratio), normalised mean colour and its saturation
    ``1 - 3 min(r, g, b)`` of blobs from their per-blob sums ``(n, >= 11)``: weight, weighted x
    and y, pixel count, intensity, colour R, G, B (any weighting), weighted x^2, y^2, xy
    (:func:`.markers._blob_sums`; :class:`.colordots.ColorDotExtractor` adds columns after these)."""
    cx, cy, sxx, syy, sxy = blob_moments(sums)
    half_trace, root = 0.5 * (sxx + syy), np.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy)
    elongation = np.sqrt((half_trace + root + 1.0 / 12.0) / (np.maximum(half_trace - root, 0.0) + 1.0 / 12.0))
    rgb = sums[:, 5:8] / np.maximum(sums[:, 5:8].sum(axis=1, keepdims=True), 1e-12)
    return cx, cy, elongation, rgb, 1.0 - 3.0 * rgb.min(axis=1)
