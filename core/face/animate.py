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
from .shapes import FrameSource

UNSEEN_POLICIES = ("error", "drop", "conjecture")
SPARSE_MARKERS = 40              # a take binding at most this many markers is sparse (a VICON-style layout)
DENSE_BLINK_INTERVAL_S = 2.5     # Lin 2003, section 7.4
SPARSE_BLINK_INTERVAL_S = 4.0    # Huang et al. 2000, section 3.2


@dataclass
class Animation(FrameSource):
    """A take animated on a head: its frames ``frames[0]`` .. ``frames[1] - 1`` (the binding covers the whole
    take). The vertex displacements ``(F, V, 3)`` (mm, head frame) come from the face rig when asked for: all at
    once (:attr:`displacements`), at chosen frames (:meth:`at`) or a block of frames at a time (:meth:`blocks`),
    so that a long take is written without holding them all (0.11 MB a frame for a 4,600-vertex head)."""

    binding: Binding
    rig: FaceRig
    parts: dict                       # the face rig's parts per frame (jaw angle, blink, ...; FaceRig.motion)
    rate: float
    frames: tuple                     # (START, END): the take frames animated, END exclusive
    timings_s: dict = field(default_factory=dict)
    _deformed: np.ndarray | None = field(default=None, repr=False)    # all the frames', once deformed

    @property
    def n_frames(self) -> int:
        return self.frames[1] - self.frames[0]

    def at(self, index) -> np.ndarray:
        """The displacements ``(n, V, 3)`` at the animated frames ``index`` (a slice or indices, 0 = ``frames[0]``),
        as the whole take's deformation has them there (blinks included)."""
        if self._deformed is not None:
            return self._deformed[index]
        start, end = self.frames
        return self.rig.deform(self.binding.displacements[start:end][index], self.rate,
                               closure=self.parts["blink"][index])

    @property
    def displacements(self) -> np.ndarray:
        """All the animated frames' displacements ``(F, V, 3)`` (:meth:`deform_all`)."""
        return self.deform_all()

    def deform_all(self, progress=None) -> np.ndarray:
        """All the animated frames' displacements ``(F, V, 3)``, deformed a block of frames at a time with
        ``progress(fraction)`` after each, and kept as :attr:`displacements`."""
        if self._deformed is None:
            D = None
            for f0, block in self.blocks():
                if D is None:
                    D = np.empty((self.n_frames,) + block.shape[1:])
                D[f0:f0 + len(block)] = block
                if progress:
                    progress((f0 + len(block)) / self.n_frames)
            self._deformed = D
        return self._deformed

    @property
    def head_motion(self) -> tuple:
        """The binding's head motion ``(R (F, 3, 3), t (F, 3))`` over the animated frames."""
        R, t = self.binding.head_motion
        start, end = self.frames
        return R[start:end], t[start:end]

    def summary(self) -> dict:
        """The binding's and the rig's figures, as BAKE.json carries them."""
        b, parts = self.binding, self.parts
        return {
            "take_frames": [int(self.frames[0]), int(self.frames[1])],
            "take_length": int(len(b.displacements)),
            "landmarks_used": b.landmarks_used, "registration": b.registration,
            "markers_dropped_unseen": b.dropped, "markers_neutral_conjectured": b.conjectured_neutral,
            "landmark_rms_mm": b.landmark_rms_mm, "scale_head_mm_per_take_unit": b.scale,
            "binding_distance_mm": {"max": float(b.distance_mm.max()), "mean": float(b.distance_mm.mean())},
            "gaps_filled": int(b.filled[self.frames[0]:self.frames[1]].sum()),
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
    """:func:`.bind.bind_take`'s ``unseen`` from the add-on's two options (conjecture wins; neither: refuse)."""
    return "conjecture" if conjecture_unseen else "drop" if drop_unseen else "error"


def animate_take(head: HeadModel, labels, points, rate: float, *, neutral_frame: int = 0, head_pose=None,
                 unseen: str = "error", settings: RigSettings | None = None, progress=None,
                 marker_map: dict | None = None, frames: tuple | None = None) -> Animation:
    """Bind the take to ``head`` and set up the face rig on every frame, or on the take frames
    ``frames = (START, END)`` (END exclusive, None: the take's end; :func:`take_frame_range`): the
    whole take is bound (its neutral frame may lie outside them), and the frames come out as they
    do in the whole take's animation, blinks included.

    ``head_pose`` ``(F, 3, 4)`` is the tracker's (default: estimated from the markers);
    ``unseen`` says what happens to markers not seen in the neutral frame
    (:data:`UNSEEN_POLICIES`); ``marker_map`` binds named markers (:func:`.bind.load_marker_map`).
    Blinks come every ``settings.blink_interval_s`` on average, by default 2.5 s, or 4 s for a
    sparse take of at most :data:`SPARSE_MARKERS` bound markers (Huang et al. 2000, section 3.2:
    "a person's eyes blink once every four seconds"). ``progress(fraction, text)`` is called
    between the stages."""
    if unseen not in UNSEEN_POLICIES:
        raise InputError(f"unseen must be one of {', '.join(UNSEEN_POLICIES)}")
    start, end = take_frame_range(frames, len(points))
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
    closure = rig.closure(len(binding.displacements), rate)[start:end]      # the whole take's blinks
    parts = rig.motion(binding.displacements[start:end], closure)
    timings["rig_s"] = time.perf_counter() - t1
    if progress:
        progress(0.9, "face rig")
    return Animation(binding, rig, parts, float(rate), (start, end), timings)


def take_frame_range(frames, n_frames: int) -> tuple[int, int]:
    """``(START, END)`` of a take of ``n_frames`` frames (END exclusive; None: the take's end;
    :func:`..capture.video.parse_frame_range` reads ``--frames START:END``), checked against the take."""
    start, end = (0, None) if frames is None else frames
    end = n_frames if end is None else int(end)
    if not 0 <= start < end <= n_frames:
        raise InputError(f"frames {start}:{end} is not a stretch of the take's {n_frames} frames (0:{n_frames})")
    return int(start), end
