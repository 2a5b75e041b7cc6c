"""Synthetic performances on a head, for tests and benchmarks of the rig and the bake.

A performance is a sum of expression channels, each a fixed mix of the head's
ARKit-named faceunit shape keys (e.g. ``smile`` = both ``mouthSmile`` and half of
both ``cheekSquint``), with smooth random weights over time. Markers sit on skin
vertices spread by farthest-point sampling over the face regions, plus one on each
landmark (labelled ``lm_<name>``); the take is the markers' positions under the
performance and a rigid head motion, 600 mm in front of the camera.
"""

from __future__ import annotations

import numpy as np

from ..core.common.errors import InputError
from ..core.face.head import REGIONS, HeadModel, farthest_points
from ..core.geometry.rigid import rotation_zyx
from ..core.retarget.arkit import apply_exclusions

EXPRESSIONS = {
    "open": {"jawOpen": 0.6, "mouthLowerDownLeft": 0.3, "mouthLowerDownRight": 0.3},
    "smile": {"mouthSmileLeft": 1.0, "mouthSmileRight": 1.0, "cheekSquintLeft": 0.5, "cheekSquintRight": 0.5},
    "pucker": {"mouthPucker": 1.0, "mouthFunnel": 0.4},
    "brows": {"browInnerUp": 1.0, "browOuterUpLeft": 0.6, "browOuterUpRight": 0.6},
    "frown": {"browDownLeft": 1.0, "browDownRight": 1.0, "noseSneerLeft": 0.5, "noseSneerRight": 0.5},
    "twist": {"mouthLeft": 1.0, "mouthSmileLeft": 0.3},
    "press": {"mouthPressLeft": 1.0, "mouthPressRight": 1.0, "mouthShrugLower": 0.5},
    "stretch": {"mouthStretchLeft": 1.0, "mouthStretchRight": 1.0, "mouthUpperUpLeft": 0.4, "mouthUpperUpRight": 0.4},
}
#: the remaining non-eye faceunits, one channel each: a richer performance for the error-vs-K table
SINGLE_UNITS = ("cheekPuff", "jawForward", "jawLeft", "jawRight", "mouthClose", "mouthDimpleLeft", "mouthDimpleRight",
                "mouthFrownLeft", "mouthFrownRight", "mouthRight", "mouthRollLower", "mouthRollUpper",
                "mouthShrugUpper", "eyeSquintLeft", "eyeSquintRight", "eyeWideLeft", "eyeWideRight")


def _sample_times(n_frames: int, fps: float, at) -> np.ndarray:
    """Seconds of the samples: each frame's start, or ``at`` (frame numbers, fractions allowed:
    the same performance between frames, e.g. while a shutter is open)."""
    return (np.arange(n_frames) if at is None else np.asarray(at, float)) / fps


def channel_weights(n_frames: int, fps: float, n_channels: int, seed: int = 0, events_per_s: float = 0.6,
                    tempo: float = 1.0, at=None):
    """Smooth weights ``(F, C)`` in [0, 1]: random raised-cosine events (0.4-1.2 s long,
    divided by ``tempo``; ``tempo`` times as many), none before 0.1 s, so the first frame is
    the neutral face. ``at``: sample there instead (frame numbers, :func:`_sample_times`; the
    events are those of ``n_frames`` frames)."""
    rng = np.random.default_rng(seed)
    t = _sample_times(n_frames, fps, at)
    W = np.zeros((len(t), n_channels))
    T = n_frames / fps
    for c in range(n_channels):
        n_ev = rng.poisson(tempo * events_per_s * T / max(n_channels / 4, 1)) + 1
        starts = rng.uniform(0.1, max(T - 0.2, 0.2), n_ev)
        lengths = rng.uniform(0.4, 1.2, n_ev) / tempo
        amps = rng.uniform(0.3, 1.0, n_ev)
        s = (t[:, None] - starts) / lengths
        bump = np.where((s >= 0) & (s <= 1), 0.5 - 0.5 * np.cos(2 * np.pi * s), 0.0) * amps
        W[:, c] = np.clip(bump.sum(1), 0, 1)
    return W


def performance(head: HeadModel, shape_keys: dict, n_frames: int, fps: float = 30.0, seed: int = 0,
                channels: dict | None = None, singles: tuple = (), tempo: float = 1.0,
                at=None) -> tuple[np.ndarray, np.ndarray]:
    """Vertex displacements ``(F, V, 3)`` and channel weights ``(F, C)`` (``tempo``, ``at``: see
    :func:`channel_weights`)."""
    channels = dict(EXPRESSIONS if channels is None else channels)
    for u in singles:
        channels[u] = {u: 1.0}
    missing = sorted({u for mix in channels.values() for u in mix} - set(shape_keys))
    if missing:
        raise InputError("the head lacks the shape keys " + ", ".join(missing))
    basis = np.stack([sum(w * shape_keys[u] for u, w in mix.items()) for mix in channels.values()])  # (C, V, 3)
    W = channel_weights(n_frames, fps, len(channels), seed, tempo=tempo, at=at)
    return np.einsum("fc,cvd->fvd", W, basis), W


def place_markers(head: HeadModel, n_markers: int, seed: int = 0) -> tuple[np.ndarray, list]:
    """Marker vertices and labels: every landmark (``lm_<name>``) then farthest-point samples
    over the front-facing skin of the 11 regions (not the inner lip, eyeballs or teeth)."""
    lms = head.landmarks()
    verts = [lms[n] for n in sorted(lms)]
    labels = [f"lm_{n}" for n in sorted(lms)]
    region = np.zeros(len(head.vertices), bool)
    for r in REGIONS:
        region[head.members(f"region_{r}")] = True
    region &= head.skin_mask()
    for side in ("l", "r"):
        lid = head.groups.get(f"eyelid_upper_{side}")
        if lid is not None:
            region[lid > 0] = False  # blinks move the lids; markers there would turn synthetic blinks off
    normals = head.vertex_normals()
    ax = head.face_axes()
    region &= normals @ ax["forward"] > 0.2
    cand = np.flatnonzero(region)
    cand = np.setdiff1d(cand, verts)
    need = n_markers - len(verts)
    if need > cand.size:
        raise InputError(f"the head has room for {cand.size + len(verts)} markers, not {n_markers}")
    P = head.vertices[cand]
    to_landmarks = np.min(np.linalg.norm(P[:, None] - head.vertices[verts][None], axis=2), axis=1)
    chosen = farthest_points(P, need, seed, initial_distance=to_landmarks)
    verts += [int(c) for c in cand[chosen]]
    labels += [f"m{i:03d}" for i in range(need)]
    return np.asarray(verts, np.int64), labels


def head_motion(n_frames: int, fps: float, max_deg=10.0, seed: int = 0, at=None):
    """A smooth rigid head motion: ``R (F, 3, 3)``, ``t (F, 3)`` mm, starting at identity.
    ``max_deg``: the largest rotation about each axis, one number or ``(rx, ry, rz)`` --
    pitch, yaw and roll in the camera frame (eq. 5.4). ``at``: sampled there instead (frame
    numbers, :func:`_sample_times`)."""
    rng = np.random.default_rng(seed)
    t = _sample_times(n_frames, fps, at)
    freq = rng.uniform(0.1, 0.4, (3, 1))
    phase = rng.uniform(0, 2 * np.pi, (3, 1))
    amplitude = np.deg2rad(np.broadcast_to(np.asarray(max_deg, float), (3,)))
    ang = amplitude * (np.sin(2 * np.pi * freq * t + phase) - np.sin(phase)).T / 2
    R = rotation_zyx(ang)
    trans = 5.0 * (np.sin(2 * np.pi * freq * t + phase) - np.sin(phase)).T
    return R, trans


def synthetic_take(head: HeadModel, shape_keys: dict, n_markers: int = 150, n_frames: int = 90, fps: float = 30.0,
                   max_head_deg: float = 10.0, seed: int = 0, singles: tuple = ()):
    """``labels, points (F, M, 3)`` in the camera frame (head 600 mm away, turned by a smooth
    motion), the marker vertices, the true vertex displacements ``(F, V, 3)`` and the head pose
    ``(F, 3, 4)`` (camera = R q + t for head-frame q)."""
    verts, labels = place_markers(head, n_markers, seed)
    disp, _ = performance(head, shape_keys, n_frames, fps, seed, singles=singles)
    q = head.vertices[verts][None] + disp[:, verts]
    R, t = head_motion(n_frames, fps, max_head_deg, seed)
    t = t + np.array([0.0, 0.0, 600.0])
    pts = np.einsum("fij,fmj->fmi", R, q) + t[:, None]
    pose = np.concatenate([R, t[:, :, None]], axis=2)
    return labels, pts, verts, disp, pose


# ARKit shapes that move a ~150-marker layout's markers (not the eyeballs' look directions, the
# lids' widening or the tongue), exclusive pairs taken once: the retarget tests' and benchmark's channels
ARKIT_CHANNELS = ["eyeBlinkLeft", "eyeSquintLeft", "eyeBlinkRight", "eyeSquintRight", "jawForward", "jawRight",
                  "jawOpen", "mouthClose", "mouthFunnel", "mouthPucker", "mouthRight", "mouthSmileLeft",
                  "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthStretchRight",
                  "mouthRollLower", "mouthPressLeft", "mouthLowerDownRight", "mouthUpperUpLeft", "browDownLeft",
                  "browInnerUp", "browOuterUpRight", "cheekPuff", "cheekSquintLeft", "noseSneerRight"]


def arkit_take(head: HeadModel, shape_keys: dict, channels=ARKIT_CHANNELS, frames: int = 300, noise: float = 0.1,
               seed: int = 2, still: bool = False, fps: float = 30.0, full_blinks: bool = False):
    """A ~150-marker take ``labels, points (F, M, 3)`` of a performance with known ARKit weights
    ``(F, C)`` (one channel per shape, the exclusive pairs and ``mouthClose <= jawOpen``
    respected; ``still``: the neutral held), the head moving 10 deg, ``noise`` mm per coordinate.
    ``full_blinks``: the eyeBlink channels become blinks that shut fully (held 3 frames, about
    every 1.5 s, eyes together), as a real performer blinks."""
    rng = np.random.default_rng(seed)
    verts, labels = place_markers(head, 150, 1)
    _, W = performance(head, shape_keys, frames, fps, seed, channels={n: {n: 1.0} for n in channels})
    W = np.zeros_like(W) if still else apply_exclusions(W, channels)
    if full_blinks and not still:
        t = np.arange(frames)
        period = int(round(1.5 * fps))
        phase = (t + period // 2) % period
        blink = np.interp(phase, [0, 3, 6, 9, 12], [0.0, 1.0, 1.0, 1.0, 0.0])   # close, hold, open
        for n in ("eyeBlinkLeft", "eyeBlinkRight"):
            if n in channels:
                W[:, list(channels).index(n)] = blink
    D = np.einsum("fk,kvd->fvd", W, np.stack([shape_keys[n] for n in channels]))
    R, t = head_motion(frames, fps, 10.0, seed + 1)
    q = head.vertices[verts][None] + D[:, verts]
    pts = np.einsum("fij,fmj->fmi", R, q) + (t + [0.0, 0.0, 600.0])[:, None] + rng.normal(0, noise, (frames, 150, 3))
    return labels, pts, W
