"""What the tracker is told and what it returns: :class:`TrackSettings`, :class:`TrackResult`,
and the rule by which a tracked marker earns its place in the take (:func:`keep_measured`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

COLOUR_SPACING_MM = 1.0e4  # colour classes as a 4th coordinate: one KD-tree serves every class


@dataclass
class TrackSettings:
    band_px: float = 1.0  # mirrored epipolar band half-width (about 3 sigma of the detections)
    gate_mm: float = 3.0  # largest distance between a marker's prediction and its candidate
    min_gate_mm: float = 0.5  # each marker's gate: 4x its recent innovation + 0.3 mm, within these
    init_frames: int = 15  # frames used to pair direct and mirror tracks
    wide_band_factor: float = 2.0  # unpaired tracks: paired in a band this much wider when both mirrors agree in 3D
    neighbour_radius_mm: float = 25.0  # neighbours in the neutral face (eq. 5.6-5.8)
    false_threshold: float = 3.0  # JF above this is false tracking (eq. 5.6)
    follow_2d_tracks: bool = True  # final pass: a marker's candidate on the 2D tracks of its last measurement
    # (direct view and a mirror) is not judged by the neighbour test of eq. 5.6 when in the gate; past the
    follow_2d_max_mm: float = 12.0  # gate (a dot faster than it) it is taken up to this far off, its step
    # along the line of sight within the widest gate (gate_mm) and under half the step, and judged by eq. 5.6
    measure_sigma_mm: float = 0.1  # measurement noise for the marker filters
    conjecture_sigma_mm: float = 1.0  # conjectured positions are trusted less
    accel_sigma_mm: float = 1.0  # velocity change per frame, marker filters
    pose_accel_sigma: tuple = (0.01, 1.0)  # rotation (rad) and translation (mm) per frame
    pose_measure_sigma: tuple = (0.0005, 0.05)
    depth_margin_mm: float = 200.0  # candidates deeper/shallower than the neutral face +- this are dropped
    conjecture_max_sd_mm: float = 2.0 / 3.0  # a conjecture expected off by more (1 sigma) is left a gap
    reacquire_mm: float = 3.0  # a marker back after a gap takes only a candidate with a like one this near
    # in the frame before or after (a marker's image lasts; a stray blob paired by chance seldom does)
    rigid_fraction: float = 0.2  # share of the markers that carry the head pose when none are named
    min_measured_frames: int = 10  # a marker measured in fewer frames is not reported (a chain of chance
    # pairings -- a direct blob with another marker's mirror image -- seldom lasts ten frames)
    min_measured_fraction: float = 0.25  # ... nor one this rarely measured that is lost for good (see keep_measured)
    single_views: bool = True  # offline, after the passes: dots followed through gaps and conjectures measured
    # where their dot is seen after all (core.track.singleview)

    @classmethod
    def with_conjecture_limit(cls, limit_mm: float, **kw) -> "TrackSettings":
        """Settings whose conjectures are withheld where expected off by more than
        ``limit_mm`` at 3 sigma (``--conjecture-limit``)."""
        return cls(conjecture_max_sd_mm=limit_mm / 3.0, **kw)


@dataclass
class TrackResult:
    labels: list
    points: np.ndarray  # (F, N, 3) camera frame; NaN where not reported
    conjectured: np.ndarray  # (F, N)
    camera_mask: np.ndarray  # (F, N) bit 0 direct, bit 1 mirror 0, bit 2 mirror 1; 0 when conjectured
    head_pose: np.ndarray  # (F, 6): rx, ry, rz (rad, eq. 5.4) and tx, ty, tz
    neutral: np.ndarray  # (N, 3) the first frame, camera frame
    first_blob: np.ndarray  # (N,) the direct blob index of each marker in the first frame (-1: absent there)
    assigned_blob: np.ndarray  # (F, N) direct blob index each frame, -1 when not measured
    colour: np.ndarray  # (N,) colour class of each marker
    head_frame: np.ndarray = None  # (F, N, 3) positions with head motion removed (NaN where not reported)
    candidate: np.ndarray = None  # (F, N) the clip candidate each marker took (core.track.candidates.ClipCandidates), -1: none
    rigid: np.ndarray = None  # markers that carried the head pose
    stats: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)  # seconds per stage of :func:`track`
    undecided: list = field(default_factory=list)  # direct-view markers of the first frames never paired (rows)


def camera_mask_of(mirror_blob) -> np.ndarray:
    """:attr:`TrackResult.camera_mask` of measurements from the direct view and the mirrors whose blob
    ``mirror_blob`` ``(..., K)`` gives (-1: not seen in that mirror): bit 0 direct, bit ``k + 1`` mirror ``k``."""
    mirror_blob = np.asarray(mirror_blob)
    return 1 | ((mirror_blob >= 0) * (2 << np.arange(mirror_blob.shape[-1]))).sum(axis=-1)


def earns_place(measured, min_frames: int, min_fraction: float) -> np.ndarray:
    """The markers that :func:`keep_measured` keeps, from ``measured`` ``(F, N)``."""
    F = measured.shape[0]
    first = np.argmax(measured, axis=0)
    last = F - 1 - np.argmax(measured[::-1], axis=0)
    span = F - first
    count = measured.sum(axis=0)
    lost = (count < min_fraction * span) & (F - 1 - last > 0.75 * span)
    return (count >= min_frames) & ~lost


def keep_measured(result: TrackResult, min_frames: int, min_fraction: float = 0.0) -> TrackResult:
    """A marker must earn its place. Dropped: one measured in fewer than ``min_frames``
    frames; and one measured in fewer than ``min_fraction`` of its frames (from its first
    measurement on) that is also never measured again in the last three quarters of them -- a wrong
    direct/mirror pairing whose 3D point stops matching real candidates, and would be
    conjectured, wrongly, for the rest of the take. (A marker that is merely often hidden
    keeps coming back, and stays.) Nothing is reported for a marker before its first
    measurement."""
    measured = result.assigned_blob >= 0
    first = np.argmax(measured, axis=0)
    keep = np.flatnonzero(earns_place(measured, min_frames, min_fraction))
    before = np.arange(measured.shape[0])[:, None] < first[None, :]
    result.points[before] = np.nan
    result.head_frame[before] = np.nan
    result.conjectured[before] = False
    result.camera_mask[before] = 0
    old_to_new = np.full(measured.shape[1], -1)
    old_to_new[keep] = np.arange(keep.size)
    rigid = old_to_new[result.rigid]
    result.rigid = rigid[rigid >= 0]
    for name in ("points", "conjectured", "camera_mask", "assigned_blob", "head_frame", "candidate"):
        setattr(result, name, getattr(result, name)[:, keep])
    for name in ("neutral", "first_blob", "colour"):
        setattr(result, name, getattr(result, name)[keep])
    # the tracker's own labels are numbered afresh; names the user gave (SEEDS.csv) stay
    kept = [result.labels[i] for i in keep]
    result.labels = [lab if not _automatic_label(lab) else f"m{j:03d}" for j, lab in enumerate(kept)]
    result.stats["markers_dropped_unmeasured"] = np.array([measured.shape[1] - keep.size])
    return result


def _automatic_label(label: str) -> bool:
    """``m000``...: a label the tracker made (not a designation's name)."""
    return len(label) >= 4 and label[0] == "m" and label[1:].isdigit()

