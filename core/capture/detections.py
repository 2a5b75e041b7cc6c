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

    def __len__(self):
        return self.x.size


def empty_detections() -> Detections:
    return Detections(np.zeros(0), np.zeros(0), np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros(0),
                      np.zeros((0, 3)), np.zeros(0))
