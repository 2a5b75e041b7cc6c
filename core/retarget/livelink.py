"""The Live Link Face CSV, as Epic's iPhone app writes a take, and a reader for such files.

One header row, then one row per frame: ``Timecode`` (``HH:MM:SS:FF.mmm``: hours, minutes,
seconds, the frame within the second and a sub-frame fraction in thousandths),
``BlendShapeCount`` (61 on every row: the 52 shapes and 9 rotations), the 52 ARKit shapes in
PascalCase in the app's order (``JawRight`` before ``JawLeft``, ``MouthRight`` before
``MouthLeft``), then ``HeadYaw, HeadPitch, HeadRoll`` and each eye's yaw, pitch and roll in
radians.
"""

from __future__ import annotations

import numpy as np

from ..common.errors import InputError
from ..common.files import read_text
from .arkit import ARKIT_SHAPES

ROTATIONS = ["HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
             "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]
COLUMNS = ["Timecode", "BlendShapeCount"] + [n[0].upper() + n[1:] for n in ARKIT_SHAPES] + ROTATIONS
HEADER = ",".join(COLUMNS)
BLEND_SHAPE_COUNT = len(ARKIT_SHAPES) + len(ROTATIONS)   # 61


def timecode(frame: int, rate: float) -> str:
    """``HH:MM:SS:FF.mmm`` of take frame ``frame`` at ``rate`` frames/s from 00:00:00:00."""
    seconds = frame / rate
    whole = int(np.floor(seconds + 1e-9))
    in_second = (seconds - whole) * rate
    ff = int(np.floor(in_second + 1e-6))
    sub = int(round((in_second - ff) * 1000)) % 1000
    return f"{whole // 3600:02d}:{whole // 60 % 60:02d}:{whole % 60:02d}:{ff:02d}.{sub:03d}"


def livelink_csv(weights, names, rate: float, head=None, eyes=None) -> str:
    """The CSV text: ``weights (F, K)`` for ``names`` (shapes not given are 0), ``head (F, 3)``
    yaw, pitch, roll in radians (0 if None), ``eyes (F, 6)`` (0 if None)."""
    W = np.asarray(weights, float)
    F = W.shape[0]
    full = np.zeros((F, len(ARKIT_SHAPES)))
    for k, n in enumerate(names):
        full[:, ARKIT_SHAPES.index(n)] = W[:, k]
    rot = np.zeros((F, len(ROTATIONS)))
    if head is not None:
        rot[:, :3] = head
    if eyes is not None:
        rot[:, 3:] = eyes
    values = np.char.mod("%.6f", np.concatenate([full, rot], axis=1))
    rows = [",".join([timecode(f, rate), str(BLEND_SHAPE_COUNT), *values[f]]) for f in range(F)]
    return HEADER + "\n" + "\n".join(rows) + "\n"


def timecode_rate(timecodes) -> float | None:
    """A take's frame rate from its rows' ``HH:MM:SS:FF.mmm`` timecodes: the rows per second of the clock, averaged
    over the seconds the take spans whole (its first and last are cut). None when it spans no whole second, or a
    timecode cannot be read or runs backwards (a take across midnight)."""
    seconds = []
    for code in timecodes:
        parts = str(code).strip().split(":")
        if len(parts) != 4:
            return None
        try:
            h, m, s = (int(v) for v in parts[:3])
        except ValueError:
            return None
        seconds.append(3600 * h + 60 * m + s)
    seconds = np.asarray(seconds)
    if seconds.size < 2 or np.any(np.diff(seconds) < 0):
        return None
    whole = np.unique(seconds, return_counts=True)[1][1:-1]
    return float(whole.mean()) if whole.size else None


def read_livelink_csv(path) -> dict:
    """``{"names": ARKit names (camelCase), "weights" (F, 52), "rotations" (F, 9), "timecodes"}``
    from a Live Link Face CSV (columns found by name, so any order the app used)."""
    text = read_text(path, "Live Link Face CSV").strip("\n")
    lines = text.splitlines()
    if not lines:
        raise InputError(f"{path} is empty")
    header = [c.strip() for c in lines[0].split(",")]
    lookup = {c.lower(): i for i, c in enumerate(header)}
    missing = [c for c in COLUMNS[2:] if c.lower() not in lookup]
    if "timecode" not in lookup or len(missing) == len(COLUMNS) - 2:
        raise InputError(f"{path} is not a Live Link Face CSV (no Timecode and ARKit columns)")
    rows = [ln.split(",") for ln in lines[1:] if ln.strip()]
    if any(len(r) != len(header) for r in rows):
        bad = next(i for i, r in enumerate(rows) if len(r) != len(header))
        raise InputError(f"{path}: row {bad + 2} has {len(rows[bad])} cells, the header {len(header)}")
    try:
        table = np.array([[float(r[lookup[c.lower()]]) if c.lower() in lookup else 0.0 for c in COLUMNS[2:]]
                          for r in rows]).reshape(len(rows), len(COLUMNS) - 2)
    except ValueError as exc:
        raise InputError(f"{path}: a value is not a number ({exc})") from None
    return {"names": list(ARKIT_SHAPES), "weights": table[:, :len(ARKIT_SHAPES)],
            "rotations": table[:, len(ARKIT_SHAPES):], "timecodes": [r[lookup["timecode"]] for r in rows],
            "missing_columns": missing}
