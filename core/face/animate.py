"""One take -> per-frame vertex displacements of a head: the one pipeline behind
``mirrorcap bake`` and ``batch``, the add-on's Bake operator and the demo.

In: a take's labels and 3D points ``(F, M, 3)``, its rate, a head model, and optionally the
tracker's head pose. Out: the binding (:func:`.bind.bind_take`: registration, head motion
removed, gaps filled) and the face rig's displacements ``(F, V, 3)`` in the head's frame
(:class:`.facerig.FaceRig`: regions, jaw rule, inner lip, blinks; Lin 2003, chapter 7),
with the figures a bake report carries. Writing them into Blender is the add-on's job.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..common.errors import InputError
from ..common.files import read_json
from ..geometry.rigid import rotation_zyx
from .bind import Binding, bind_take
from .facerig import FaceRig, RigSettings
from .head import HeadModel

UNSEEN_POLICIES = ("error", "drop", "conjecture")
SPARSE_MARKERS = 40              # a take binding at most this many markers is sparse (a VICON-style layout)
DENSE_BLINK_INTERVAL_S = 2.5     # Lin 2003, section 7.4
SPARSE_BLINK_INTERVAL_S = 4.0    # Huang et al. 2000, section 3.2


@dataclass
class Animation:
    """A take animated on a head: ``displacements (F, V, 3)`` in mm, head frame."""

    binding: Binding
    displacements: np.ndarray
    parts: dict                       # the face rig's parts (jaw angle, blink per frame, ...)
    rate: float
    timings_s: dict = field(default_factory=dict)

    def summary(self) -> dict:
        """The binding's and the rig's figures, as BAKE.json carries them."""
        b, parts = self.binding, self.parts
        return {
            "landmarks_used": b.landmarks_used, "registration": b.registration,
            "markers_dropped_unseen": b.dropped, "markers_neutral_conjectured": b.conjectured_neutral,
            "landmark_rms_mm": b.landmark_rms_mm, "scale_head_mm_per_take_unit": b.scale,
            "binding_distance_mm": {"max": float(b.distance_mm.max()), "mean": float(b.distance_mm.mean())},
            "gaps_filled": int(b.filled.sum()),
            "jaw_open_frames": int((parts["jaw_angle"] > 0).sum()),
            "max_jaw_angle_deg": float(np.rad2deg(parts["jaw_angle"].max())),
            "blink_frames": int((parts["blink"] > 0.5).sum()),
        }


def head_pose_from_report(path, n_frames: int) -> np.ndarray:
    """The tracker's per-frame head pose from REPORT.json as ``(F, 3, 4)`` ``[R | t]``
    (stored as ``(F, 6)`` rotation angles of eq. 5.4 and translation, or ``(F, 3, 4)``)."""
    rep = read_json(path, "REPORT.json")
    try:
        pose = np.asarray(rep["head_pose"], float)
    except (KeyError, TypeError, ValueError):
        raise InputError(f"{path} has no head_pose") from None
    if pose.shape == (n_frames, 6):
        pose = np.concatenate([rotation_zyx(pose[:, :3]), pose[:, 3:, None]], 2)
    if pose.shape != (n_frames, 3, 4):
        raise InputError(f"{path}: head_pose has shape {pose.shape}, not ({n_frames}, 6) or ({n_frames}, 3, 4)")
    return pose


def unseen_policy(drop_unseen: bool = False, conjecture_unseen: bool = False) -> str:
    """:func:`.bind.bind_take`'s ``unseen`` from the two user options (conjecture wins)."""
    return "conjecture" if conjecture_unseen else "drop" if drop_unseen else "error"


def animate_take(head: HeadModel, labels, points, rate: float, *, neutral_frame: int = 0, head_pose=None,
                 unseen: str = "error", settings: RigSettings | None = None, progress=None,
                 marker_map: dict | None = None) -> Animation:
    """Bind the take to ``head`` and run the face rig on every frame.

    ``head_pose`` ``(F, 3, 4)`` is the tracker's (default: estimated from the markers);
    ``unseen`` says what happens to markers not seen in the neutral frame
    (:data:`UNSEEN_POLICIES`); ``marker_map`` binds named markers (:func:`.bind.load_marker_map`).
    Blinks come every ``settings.blink_interval_s`` on average, by default 2.5 s, or 4 s for a
    sparse take of at most :data:`SPARSE_MARKERS` bound markers (Huang et al. 2000, section 3.2:
    "a person's eyes blink once every four seconds"). ``progress(fraction, text)`` is called
    between the stages."""
    if unseen not in UNSEEN_POLICIES:
        raise InputError(f"unseen must be one of {', '.join(UNSEEN_POLICIES)}")
    timings = {}
    t0 = time.perf_counter()
    if progress:
        progress(0.05, "binding")
    binding = bind_take(head, labels, points, neutral_frame=neutral_frame, head_pose=head_pose, unseen=unseen,
                        marker_map=marker_map)
    settings = settings or RigSettings()
    if settings.blink_interval_s is None:
        sparse = len(binding.labels) <= SPARSE_MARKERS
        settings = replace(settings, blink_interval_s=SPARSE_BLINK_INTERVAL_S if sparse else DENSE_BLINK_INTERVAL_S)
    timings["bind_s"] = time.perf_counter() - t0
    if progress:
        progress(0.2, "face rig")
    t1 = time.perf_counter()
    rig = FaceRig(head, binding.vertices, settings)
    D, parts = rig.deform(binding.displacements, fps=rate, with_parts=True)
    timings["rig_s"] = time.perf_counter() - t1
    if progress:
        progress(0.9, "face rig")
    return Animation(binding, D, parts, float(rate), timings)
