"""A sparse marker take as a VICON-style system records it (seed 001, section 1): a rigid
headband triangle and 20 face markers, the head turning about a fixed pivot at the top of
the neck, with exact truth. For the tests and figures of ``mirrorcap stabilize``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.geometry.rigid import rotation_zyx

# head frame (mm): x to the performer's left, y up, z forward; origin inside the head
HEADBAND = np.array([[-68.0, 70.0, 20.0], [68.0, 70.0, 20.0], [0.0, 105.0, 60.0]])   # temples and forehead
FOREHEAD_TRIANGLE = np.array([[-35.0, 80.0, 70.0], [35.0, 80.0, 70.0], [0.0, 110.0, 55.0]])
PIVOT_HEAD = np.array([0.0, -90.0, -30.0])                                          # top of the neck


@dataclass
class SparseTake:
    labels: list
    points: np.ndarray        # (F, 23, 3) measured, mm, in the capture volume's coordinates
    pivot: np.ndarray         # (3,) the true pivot in the volume's coordinates
    head_frame0: np.ndarray   # (F, 23, 3) truth: every marker in the head frame of frame 0
    rate: float


def sparse_take(seed: int = 0, frames: int = 600, rate: float = 60.0, yaw_deg: float = 20.0,
                pitch_deg: float = 10.0, roll_deg: float = 5.0, sway_mm: float = 0.5, noise_mm: float = 0.15,
                expression_mm: float = 3.0, band=HEADBAND, sway_hz: float = 0.05) -> SparseTake:
    """``frames`` of 3 headband + 20 face markers: the head turns (``yaw_deg`` etc., slow
    sines) about the pivot, which sways by at most ``sway_mm``; the face markers move with
    an expression of ``expression_mm``; the sway's slowest component has ``sway_hz`` (the others
    1.4x and 0.6x it); Gaussian noise ``noise_mm`` per coordinate; the
    volume's axes are turned and offset as a mocap system's would be."""
    rng = np.random.default_rng(seed)
    th = rng.uniform(-0.9, 0.9, 20)
    ph = rng.uniform(-0.8, 0.4, 20)
    face = np.stack([75 * np.sin(th) * np.cos(ph), 100 * np.sin(ph), 90 * np.cos(th) * np.cos(ph)], 1)
    neutral = np.vstack([np.asarray(band, float), face])
    tt = np.arange(frames) / rate
    angles = np.stack([np.radians(pitch_deg) * np.sin(2 * np.pi * 0.23 * tt + 0.3),
                       np.radians(yaw_deg) * np.sin(2 * np.pi * 0.17 * tt),
                       np.radians(roll_deg) * np.sin(2 * np.pi * 0.31 * tt + 1.0)], 1)
    R = rotation_zyx(angles)
    expression = np.zeros((frames, 23, 3))
    expression[:, 3:] = rng.normal(0, 1, (1, 20, 3)) * expression_mm * np.sin(2 * np.pi * 0.5 * tt)[:, None, None]
    head = neutral[None] + expression
    hz = sway_hz * np.array([1.0, 1.4, 0.6])
    sway = sway_mm / np.sqrt(3) * np.stack([np.sin(2 * np.pi * hz[0] * tt), np.cos(2 * np.pi * hz[1] * tt),
                                            np.sin(2 * np.pi * hz[2] * tt + 2.0)], 1)
    volume_R = rotation_zyx(np.radians([5.0, 30.0, 180.0]))
    volume_t = np.array([200.0, 1500.0, 900.0])
    local = np.einsum("fij,fmj->fmi", R, head - PIVOT_HEAD) + PIVOT_HEAD + sway[:, None]
    points = local @ volume_R.T + volume_t + rng.normal(0, noise_mm, local.shape)
    frame0 = (np.einsum("ij,fmj->fmi", R[0], head - PIVOT_HEAD) + PIVOT_HEAD + sway[0]) @ volume_R.T + volume_t
    labels = ["band_left", "band_right", "band_top"] + [f"face{i:02d}" for i in range(20)]
    return SparseTake(labels, points, PIVOT_HEAD @ volume_R.T + volume_t, frame0, rate)
