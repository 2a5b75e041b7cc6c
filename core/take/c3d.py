"""C3D, the motion-capture interchange format, read and written with ezc3d.

Reading (:func:`read_c3d`) takes any file ezc3d reads: Intel and DEC processor formats
(a MIPS file is refused with its own message: ezc3d 1.7 does not read it), integer or floating-point data, analog channels (listed, not used), any first
frame, any ``POINT:UNITS`` (converted to millimetres), labels in ``LABELS``,
``LABELS2``, ... (duplicates and blanks made unique and reported). A gap is a point
whose fourth word is negative (ezc3d gives NaN), a NaN, or all three coordinates exactly
0 (how several writers mark a gap).

Writing (:func:`c3d_bytes`, :func:`write_c3d`) is ezc3d's writer, floating-point data:

* ``POINT:SCALE`` ``-(largest |coordinate|) / 32000`` as the specification asks,
  ``POINT:UNITS`` ``mm`` (or ``rel`` for an unscaled take), the first frame in the header;
* the fourth word of each point: ``-1`` and coordinates 0 for a gap; ``0`` for a
  *conjectured* marker (filled in from its neighbours: no camera, no residual, the
  specification's mark of an interpolated point); otherwise the residual in units of
  ``|POINT:SCALE|`` (at least 1) and the camera mask -- bit 0 the direct view, bit 1
  mirror 0, bit 2 mirror 1. ezc3d 1.7 puts the residual in the high byte and the mask in
  the low byte (the specification has them the other way round); ezc3d reads its files
  back as written, and the gap and conjectured marks read the same either way;
* a group ``MIRRORCAP`` (``VERSION``; ``FRAME``: ``camera: ...`` for the OpenCV camera frame
  of a tracked take, ``lab: ...`` for another system's axes, e.g. a stabilised vendor take).
"""

from __future__ import annotations

import struct
import tempfile
from pathlib import Path

import numpy as np

from ..common.errors import InputError
from ..common.files import write_files_atomically

BLOCK = 512
MAX_FRAMES = 2 ** 31 - 1

# POINT:UNITS -> millimetres. "rel" is MirrorCap's own mark of an unscaled take (kept as is).
UNIT_MM = {"mm": 1.0, "millimeter": 1.0, "millimeters": 1.0, "millimetre": 1.0, "millimetres": 1.0,
           "cm": 10.0, "dm": 100.0, "m": 1000.0, "meter": 1000.0, "meters": 1000.0, "metre": 1000.0,
           "metres": 1000.0, "in": 25.4, "inch": 25.4, "inches": 25.4, "ft": 304.8, "rel": 1.0}
PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS"}
FRAMES = {"camera": "camera: OpenCV x right, y down, z forward", "lab": "lab: the capture system's own axes"}


def _ezc3d():
    try:
        import ezc3d
    except ImportError as exc:  # pragma: no cover - pinned in requirements.txt and bundled in the extension
        raise InputError("reading and writing C3D needs the ezc3d package (pip install ezc3d==1.7.2)") from exc
    return ezc3d


def c3d_bytes(labels, points, rate: float, units: str = "mm", residual=None, camera_mask=None,
              conjectured=None, descriptions=None, first_frame: int = 0, frame: str = "camera") -> bytes:
    """The bytes of a C3D file written by ezc3d: ``points`` ``(frames, markers, 3)`` with NaN
    for gaps; ``residual`` ``(frames, markers)`` in ``units`` (default one scale unit);
    ``camera_mask`` ``(frames, markers)`` 0..127 (default 1 = direct view); ``conjectured``
    ``(frames, markers)`` bool marks filled-in markers; ``first_frame`` the number of the
    first frame (0-based, as ezc3d counts; the header stores it plus 1); ``frame``: the
    coordinates' axes, ``"camera"`` (the OpenCV camera frame of a MirrorCap take) or ``"lab"``
    (another system's, kept as they came)."""
    if frame not in FRAMES:
        raise InputError(f"frame must be one of {', '.join(FRAMES)}")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise InputError("points must have shape (frames, markers, 3)")
    n_frames, n_points = pts.shape[:2]
    labels = [str(s) for s in labels]
    if len(labels) != n_points:
        raise InputError(f"{len(labels)} labels for {n_points} markers")
    if len(set(labels)) != len(labels):
        raise InputError("marker labels must be unique")
    if n_frames < 1:
        raise InputError("a C3D take holds at least one frame")
    if not (np.isfinite(rate) and rate > 0):
        raise InputError("the frame rate must be positive")
    gap = ~np.all(np.isfinite(pts), axis=2)
    mask = np.ones((n_frames, n_points), int) if camera_mask is None else np.asarray(camera_mask, int)
    conj = np.zeros((n_frames, n_points), bool) if conjectured is None else np.asarray(conjectured, bool)
    if np.any((mask < 0) | (mask > 127)):
        raise InputError("camera masks must be 0..127")
    largest = float(np.max(np.abs(pts[~gap]))) if (~gap).any() else 1.0
    scale = max(largest, 1e-6) / 32000.0
    res = np.zeros((n_frames, n_points)) if residual is None else np.asarray(residual, float)
    res_units = np.clip(np.round(res / scale), 1, 255)            # >= 1: a measured point
    res = np.where(gap, -1.0, np.where(conj, 0.0, res_units * scale))
    bits = (mask[..., None] >> np.arange(7)) & 1                   # (F, M, 7)
    cams = (bits.astype(bool) & ~conj[..., None] & ~gap[..., None]).transpose(2, 1, 0)
    data = np.ones((4, n_points, n_frames))
    data[:3] = np.where(gap[..., None], 0.0, pts).transpose(2, 1, 0)
    descriptions = [""] * n_points if descriptions is None else [str(d) for d in descriptions]

    ezc3d = _ezc3d()
    c = ezc3d.c3d()
    point = c["parameters"]["POINT"]
    point["RATE"]["value"] = [float(rate)]
    point["UNITS"]["value"] = [units]
    point["SCALE"]["value"] = [-scale]
    point["LABELS"]["value"] = labels[:255]
    point["DESCRIPTIONS"]["value"] = descriptions[:255]
    for chunk in range(255, n_points, 255):                       # LABELS2, LABELS3, ... past 255
        suffix = str(chunk // 255 + 1)
        c.add_parameter("POINT", "LABELS" + suffix, labels[chunk:chunk + 255])
        c.add_parameter("POINT", "DESCRIPTIONS" + suffix, descriptions[chunk:chunk + 255])
    c.add_parameter("MIRRORCAP", "VERSION", ["0.1.0"])
    c.add_parameter("MIRRORCAP", "FRAME", [FRAMES[frame]])
    c["header"]["points"]["first_frame"] = int(first_frame)
    c["data"]["points"] = data
    c["data"]["meta_points"]["residuals"] = res.T[None]
    c["data"]["meta_points"]["camera_masks"] = cams
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "take.c3d"
        c.write(str(out))
        return out.read_bytes()


def write_c3d(path, labels, points, rate: float, **kwargs) -> None:
    """Write a take to ``path`` atomically (see :func:`c3d_bytes`)."""
    write_files_atomically({path: c3d_bytes(labels, points, rate, **kwargs)})


def _check_structure(path: Path) -> str:
    """One clear error for a file that is not a complete C3D file (before ezc3d sees it:
    ezc3d can hang on a file cut inside its parameter section). Reads the header and the
    parameter section's first 4 bytes only. Returns the processor."""
    size = path.stat().st_size
    with path.open("rb") as fh:
        raw = fh.read(BLOCK)
        if len(raw) < BLOCK or raw[1] != 0x50 or raw[0] < 2:
            raise InputError(f"{path} is not a C3D file")
        pstart = (raw[0] - 1) * BLOCK
        fh.seek(pstart)
        section = fh.read(4)
    if len(section) < 4:
        raise InputError(f"{path}: the C3D file is truncated (its parameter section is missing)")
    processor = section[3]
    if processor not in PROCESSORS:
        raise InputError(f"{path} is not a C3D file (unknown processor type {processor})")
    if pstart + section[2] * BLOCK > size:
        raise InputError(f"{path}: the C3D file is truncated inside its parameter section")
    big = processor == 86
    words = struct.unpack((">" if big else "<") + "10H", raw[:20])
    n_points, analog_per_frame, first, last, data_start = words[1], words[2], words[3], words[4], words[8]
    scale_sign = raw[12] if big else (raw[13] if processor == 85 else raw[15])
    item = 4 if scale_sign & 0x80 else 2
    n_frames = max(last - first + 1, 0)
    need = (data_start - 1) * BLOCK + n_frames * (4 * n_points + analog_per_frame) * item
    if data_start < 2 or need > size:
        raise InputError(f"{path}: the C3D file is truncated: its header promises {n_frames} frames of "
                         f"{n_points} markers, the data section holds fewer")
    return PROCESSORS[processor]


def _unique_labels(labels: list) -> tuple[list, list]:
    """Labels made unique (``NAME``, ``NAME_2``, ...; a blank label becomes ``marker<i>``)
    and the renames ``[{"index", "from", "to"}]``."""
    out, renames, seen = [], [], set()
    for i, raw in enumerate(labels):
        name = raw.strip() or f"marker{i:03d}"
        base, k = name, 2
        while name in seen:
            name = f"{base}_{k}"
            k += 1
        seen.add(name)
        out.append(name)
        if name != raw:
            renames.append({"index": i, "from": raw, "to": name})
    return out, renames


def _parameter(params, group, name, default=None):
    try:
        return params[group][name]["value"]
    except KeyError:
        return default


def _chunked_labels(params, group) -> list:
    """``group:LABELS`` followed by ``LABELS2``, ``LABELS3``, ... (255 labels per chunk)."""
    labels = []
    for i in range(1, 1000):
        chunk = _parameter(params, group, "LABELS" if i == 1 else f"LABELS{i}")
        if chunk is None:
            break
        labels += [str(s) for s in chunk]
    return labels


def read_c3d(path) -> dict:
    """Read any C3D file ezc3d reads.

    Returns ``{"labels", "points" (F, M, 3) mm (or ``rel``) with NaN in gaps,
    "conjectured" (F, M) (in a MirrorCap take, residual exactly 0: filled in), "rate", "units"
    (``mm`` or ``rel``), "source_units" (as in the file), "first_frame" (the number of
    the first frame as the file counts, 1-based), "processor", "analog" ({"labels",
    "rate"}), "renamed" (labels made unique), "gaps" (F, M) bool, "frame" (``"camera"`` for
    a MirrorCap take in the camera frame, else ``"lab"``)}``. Raises
    :class:`InputError` with one sentence for anything unreadable.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"take {path} is a folder, not a C3D file")
    if not path.is_file():
        raise InputError(f"take {path} does not exist")
    processor = _check_structure(path)
    if processor == "MIPS":
        raise InputError(f"{path}: a MIPS (big-endian) C3D file, which ezc3d 1.7 does not read; convert it to the "
                         "Intel or DEC format (e.g. with Motion Lab Systems' C3Deditor) and try again")
    ezc3d = _ezc3d()
    try:
        c = ezc3d.c3d(str(path))
    except (OSError, ValueError, RuntimeError, IndexError) as exc:
        raise InputError(f"{path}: not a readable C3D file ({exc})") from None
    params = c["parameters"]
    labels = _chunked_labels(params, "POINT")
    data = np.asarray(c["data"]["points"], float)                 # (4, M, F)
    n_points = data.shape[1]
    labels = (labels + [""] * n_points)[:n_points]
    labels, renamed = _unique_labels(labels)
    units_list = _parameter(params, "POINT", "UNITS", []) or []
    source_units = str(units_list[0]).strip() if len(units_list) else ""
    key = source_units.lower() or "mm"
    if key not in UNIT_MM:
        raise InputError(f"{path}: unknown POINT:UNITS {source_units!r} (known: mm, cm, dm, m, in, ft)")
    pts = data[:3].transpose(2, 1, 0) * UNIT_MM[key]              # (F, M, 3)
    residual = np.asarray(c["data"]["meta_points"]["residuals"], float)
    residual = residual[0].T if residual.size else np.zeros(pts.shape[:2])
    gaps = ~np.all(np.isfinite(pts), axis=2) | np.all(pts == 0.0, axis=2) | (residual < 0)
    pts[gaps] = np.nan
    analog_labels = [s.strip() for s in _chunked_labels(params, "ANALOG")]
    analogs = np.asarray(c["data"]["analogs"])
    n_analog = int(analogs.shape[1]) if analogs.ndim == 3 else 0
    header = c["header"]
    # residual exactly 0 marks a conjectured marker in MirrorCap's takes; other writers leave it 0 freely
    conjectured = (residual == 0) & ~gaps if "MIRRORCAP" in params else np.zeros_like(gaps)
    frame_text = list(_parameter(params, "MIRRORCAP", "FRAME", None) or [""])
    frame = "camera" if str(frame_text[0]).startswith("camera") else "lab"
    return {"labels": labels, "points": pts, "conjectured": conjectured, "gaps": gaps, "frame": frame,
            "rate": float(header["points"]["frame_rate"]), "units": "rel" if key == "rel" else "mm",
            "source_units": source_units or "mm (not given)", "first_frame": int(header["points"]["first_frame"]) + 1,
            "processor": processor,
            "analog": {"labels": analog_labels[:n_analog] if n_analog else [], "channels": n_analog,
                       "rate": float(header["analogs"]["frame_rate"]) if n_analog else 0.0},
            "renamed": renamed}


def take_info(take: dict) -> dict:
    """What ``mirrorcap info`` prints for a take read by :func:`read_c3d`."""
    gaps = take["gaps"]
    F = gaps.shape[0]
    return {"frames": int(F), "rate": take["rate"], "first_frame": take["first_frame"],
            "last_frame": take["first_frame"] + F - 1, "units": take["units"], "source_units": take["source_units"],
            "processor": take["processor"], "markers": len(take["labels"]),
            "labels": take["labels"], "gaps_per_label": {lab: int(n) for lab, n in zip(take["labels"], gaps.sum(0))},
            "gap_fraction": float(gaps.mean()) if gaps.size else 0.0,
            "analog": take["analog"], "renamed": take["renamed"]}


def points_csv(take: dict) -> str:
    """``frame,label,x,y,z`` per frame and label (mm, or the take's relative units), frames
    numbered as in the file, a gap as empty cells."""
    pts = take["points"]
    F, M = pts.shape[:2]
    if F * M == 0:                      # a take of no markers (or no frames): the header alone
        return "frame,label,x,y,z\n"
    frames = np.repeat(np.arange(F) + take["first_frame"], M)
    labels = np.tile(np.array([_csv_cell(s) for s in take["labels"]], dtype=object), F)
    flat = pts.reshape(-1, 3)
    gap = ~np.all(np.isfinite(flat), axis=1)
    coords = np.char.mod("%.4f", np.where(gap[:, None], 0.0, flat))
    xyz = np.char.add(np.char.add(np.char.add(np.char.add(coords[:, 0], ","), coords[:, 1]), ","), coords[:, 2])
    xyz = np.where(gap, ",,", xyz)
    head = np.char.add(np.char.add(frames.astype(str), ","), labels.astype(str))
    rows = np.char.add(np.char.add(head, ","), xyz)
    return "frame,label,x,y,z\n" + "\n".join(rows.tolist()) + "\n"


def _csv_cell(text: str) -> str:
    return '"' + text.replace('"', '""') + '"' if any(c in text for c in ',"\n') else text
