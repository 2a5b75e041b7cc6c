"""C3D output of a take (the motion-capture interchange format), written with numpy.

Layout written (Intel byte order, floating-point data, 512-byte blocks):

* block 1: the header (point count, first/last frame, frame rate, negative scale);
* blocks 2..: the parameter section -- groups ``POINT`` (``USED``, ``SCALE``, ``RATE``,
  ``DATA_START``, ``FRAMES``, ``UNITS``, ``LABELS``/``DESCRIPTIONS`` in chunks of 255
  as ``LABELS2``, ``LABELS3``, ... for larger takes), ``ANALOG`` (none), and
  ``MIRRORCAP`` (``VERSION``, ``FRAME``: ``camera`` = the OpenCV camera frame);
* the data section: per frame and point, ``x, y, z`` (float32) and a fourth word
  holding the residual and the camera mask.

Point conventions: coordinates in the OpenCV camera frame (x right, y down,
z forward), millimetres when the take is scaled. The fourth value follows the C3D
specification for floating-point data: ``-1`` for a gap (the marker was not
reported that frame; coordinates 0); otherwise, converted to an integer, its high
byte is the camera mask -- bit 0 the direct view, bit 1 mirror 0, bit 2 mirror 1,
the views that saw the marker -- and its low byte the residual in units of
``|POINT:SCALE|`` (at least 1 for a measured point). A *conjectured* marker
(filled from its neighbours) has the whole word 0, the specification's mark of an
interpolated point. (Some readers, ezc3d 1.7 among them, swap the two bytes; the
gap and conjectured marks read the same either way.) ``POINT:SCALE`` is
``-(largest |coordinate|) / 32000`` as the specification asks.
"""

from __future__ import annotations

import struct

import numpy as np

from ..common.errors import InputError
from ..common.files import write_files_atomically

BLOCK = 512
MAX_FRAMES = 65535


def _group(name: str, gid: int, desc: str = "") -> bytes:
    nb, db = name.upper().encode("ascii"), desc.encode("ascii")
    body = bytes([len(db)]) + db
    return struct.pack("<bb", len(nb), -gid) + nb + struct.pack("<h", 2 + len(body)) + body


def _param(name: str, gid: int, dtype: int, dims, data: bytes, desc: str = "") -> bytes:
    nb, db = name.upper().encode("ascii"), desc.encode("ascii")
    if any(not 0 <= d <= 255 for d in dims):
        raise InputError(f"C3D parameter {name}: a dimension exceeds 255")
    body = struct.pack("<bb", dtype, len(dims)) + bytes(dims) + data + bytes([len(db)]) + db
    return struct.pack("<bb", len(nb), gid) + nb + struct.pack("<h", 2 + len(body)) + body


def _chars(strings) -> tuple[list, bytes]:
    width = max(1, max((len(s) for s in strings), default=1))
    data = b"".join(s.encode("ascii", "replace").ljust(width, b" ") for s in strings)
    return [width, len(strings)], data


def _string_param(name, gid, strings, desc=""):
    dims, data = _chars(strings)
    return _param(name, gid, -1, dims, data, desc)


def c3d_bytes(labels, points, rate: float, units: str = "mm", residual=None, camera_mask=None,
              conjectured=None, descriptions=None) -> bytes:
    """The bytes of a C3D file: ``points`` ``(frames, markers, 3)`` with NaN for gaps;
    ``residual`` ``(frames, markers)`` in ``units`` (default 0); ``camera_mask``
    ``(frames, markers)`` 0..127 (default 1 = direct view); ``conjectured``
    ``(frames, markers)`` bool marks filled-in markers."""
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise InputError("points must have shape (frames, markers, 3)")
    n_frames, n_points = pts.shape[:2]
    labels = [str(s) for s in labels]
    if len(labels) != n_points:
        raise InputError(f"{len(labels)} labels for {n_points} markers")
    if len(set(labels)) != len(labels):
        raise InputError("marker labels must be unique")
    if not 1 <= n_frames <= MAX_FRAMES:
        raise InputError(f"a C3D take holds 1 to {MAX_FRAMES} frames, got {n_frames}")
    if not (np.isfinite(rate) and rate > 0):
        raise InputError("the frame rate must be positive")
    gap = ~np.all(np.isfinite(pts), axis=2)
    res = np.zeros((n_frames, n_points)) if residual is None else np.asarray(residual, float)
    mask = np.ones((n_frames, n_points), int) if camera_mask is None else np.asarray(camera_mask, int)
    conj = np.zeros((n_frames, n_points), bool) if conjectured is None else np.asarray(conjectured, bool)
    if np.any((mask < 0) | (mask > 127)):
        raise InputError("camera masks must be 0..127")
    largest = float(np.max(np.abs(pts[~gap]))) if (~gap).any() else 1.0
    scale = max(largest, 1e-6) / 32000.0
    res_byte = np.clip(np.round(res / scale), 1, 255).astype(int)  # >= 1: a measured point
    word = np.where(conj, 0, (mask << 8) | res_byte)
    fourth = np.where(gap, -1.0, word.astype(np.float64))
    data = np.concatenate([np.where(gap[..., None], 0.0, pts), fourth[..., None]], axis=2).astype("<f4")
    descriptions = [""] * n_points if descriptions is None else [str(d) for d in descriptions]

    def build_params(data_start: int) -> bytes:
        recs = [_group("POINT", 1, "3D points"),
                _param("USED", 1, 2, [], struct.pack("<h", n_points)),
                _param("SCALE", 1, 4, [], struct.pack("<f", -scale)),
                _param("RATE", 1, 4, [], struct.pack("<f", rate)),
                _param("DATA_START", 1, 2, [], struct.pack("<H", data_start)),
                _param("FRAMES", 1, 2, [], struct.pack("<H", n_frames)),
                _string_param("UNITS", 1, [units])]
        for chunk in range(0, max(n_points, 1), 255):
            suffix = "" if chunk == 0 else str(chunk // 255 + 1)
            recs.append(_string_param("LABELS" + suffix, 1, labels[chunk:chunk + 255] or [""]))
            recs.append(_string_param("DESCRIPTIONS" + suffix, 1, descriptions[chunk:chunk + 255] or [""]))
        recs += [_group("ANALOG", 2, "analog data"),
                 _param("USED", 2, 2, [], struct.pack("<h", 0)),
                 _param("RATE", 2, 4, [], struct.pack("<f", rate)),
                 _group("MIRRORCAP", 3, "MirrorCap take"),
                 _string_param("VERSION", 3, ["0.1.0"]),
                 _string_param("FRAME", 3, ["camera: OpenCV x right, y down, z forward"])]
        # the last record's offset is 0: the end of the parameter section
        last = bytearray(recs[-1])
        name_len = abs(struct.unpack("<b", last[:1])[0])
        last[2 + name_len:4 + name_len] = struct.pack("<h", 0)
        recs[-1] = bytes(last)
        return b"".join(recs)

    body = build_params(0)
    n_param_blocks = (4 + len(body) + BLOCK - 1) // BLOCK
    data_start = 2 + n_param_blocks
    body = build_params(data_start)
    params = struct.pack("<BBBB", 1, 0x50, n_param_blocks, 84) + body
    params = params.ljust(n_param_blocks * BLOCK, b"\0")
    header = np.zeros(256, "<u2")
    header[0] = 2 | (0x50 << 8)
    header[1] = n_points
    header[2] = 0
    header[3] = 1
    header[4] = n_frames
    header[5] = 10
    header_bytes = bytearray(header.tobytes())
    header_bytes[12:16] = struct.pack("<f", -scale)
    header_bytes[16:18] = struct.pack("<H", data_start)
    header_bytes[18:20] = struct.pack("<H", 0)
    header_bytes[20:24] = struct.pack("<f", rate)
    return bytes(header_bytes) + params + data.tobytes()


def write_c3d(path, labels, points, rate: float, **kwargs) -> None:
    """Write a take to ``path`` atomically (see :func:`c3d_bytes`)."""
    write_files_atomically({path: c3d_bytes(labels, points, rate, **kwargs)})


def _parse_parameters(raw: bytes) -> dict:
    """``{(GROUP, NAME): (dtype, dims, data bytes)}`` from a parameter section (after its 4-byte header)."""
    groups, params, pos = {}, {}, 0
    while pos + 4 <= len(raw):
        n_chars, gid = struct.unpack("<bb", raw[pos:pos + 2])
        if n_chars == 0:
            break
        name = raw[pos + 2:pos + 2 + abs(n_chars)].decode("ascii", "replace").upper()
        off_pos = pos + 2 + abs(n_chars)
        offset = struct.unpack("<h", raw[off_pos:off_pos + 2])[0]
        body = off_pos + 2
        if gid < 0:
            groups[-gid] = name
        else:
            dtype, nd = struct.unpack("<bb", raw[body:body + 2])
            dims = list(raw[body + 2:body + 2 + nd])
            size = abs(dtype) * int(np.prod(dims)) if dims else abs(dtype)
            start = body + 2 + nd
            params[(gid, name)] = (dtype, dims, raw[start:start + size])
        if offset == 0:
            break
        pos = off_pos + offset
    return {(groups.get(g, str(g)), n): v for (g, n), v in params.items()}


def _strings(entry) -> list:
    dtype, dims, data = entry
    if dtype != -1:
        raise InputError("a C3D label parameter is not text")
    if len(dims) < 2:
        return [data.decode("ascii", "replace").strip()]
    w = dims[0]
    return [data[i * w:(i + 1) * w].decode("ascii", "replace").strip() for i in range(dims[1])]


def read_c3d(path) -> dict:
    """Read a C3D take (Intel byte order; floating-point or integer point data).

    Returns ``{"labels", "points" (F, M, 3) with NaN in gaps, "conjectured" (F, M),
    "rate", "units"}``. Raises :class:`InputError` with one message for anything else.
    """
    from pathlib import Path

    path = Path(path)
    if not path.is_file():
        raise InputError(f"take {path} does not exist")
    raw = path.read_bytes()
    if len(raw) < 2 * BLOCK or raw[1] != 0x50:
        raise InputError(f"{path} is not a C3D file")
    pblock = raw[0]
    pstart = (pblock - 1) * BLOCK
    if pstart + 4 > len(raw) or raw[pstart + 3] != 84:
        raise InputError(f"{path}: only Intel-format C3D files are supported")
    n_blocks = raw[pstart + 2]
    params = _parse_parameters(raw[pstart + 4:pstart + n_blocks * BLOCK])

    def number(group, name, fmt):
        entry = params.get((group, name))
        if entry is None:
            raise InputError(f"{path}: the C3D parameter {group}:{name} is missing")
        return struct.unpack("<" + fmt, entry[2][:struct.calcsize(fmt)])[0]

    n_points = number("POINT", "USED", "h")
    scale = number("POINT", "SCALE", "f")
    rate = number("POINT", "RATE", "f")
    data_start = number("POINT", "DATA_START", "H")
    n_frames = number("POINT", "FRAMES", "H")
    labels = []
    for suffix in [""] + [str(i) for i in range(2, 2 + n_points // 255 + 1)]:
        if ("POINT", "LABELS" + suffix) in params:
            labels += _strings(params[("POINT", "LABELS" + suffix)])
    labels = labels[:n_points]
    if len(labels) < n_points:
        labels += [f"marker{i:03d}" for i in range(len(labels), n_points)]
    units = (_strings(params[("POINT", "UNITS")]) if ("POINT", "UNITS") in params else []) or ["mm"]
    units = units[0] or "mm"
    analog_used = number("ANALOG", "USED", "h") if ("ANALOG", "USED") in params else 0
    if analog_used:
        raise InputError(f"{path}: C3D files with analog channels are not supported")
    itemsize = 4 if scale < 0 else 2
    start = (data_start - 1) * BLOCK
    count = n_frames * n_points * 4
    if start + count * itemsize > len(raw):
        raise InputError(f"{path}: the C3D data section is shorter than {n_frames} frames of {n_points} markers")
    dtype = "<f4" if scale < 0 else "<i2"
    data = np.frombuffer(raw, dtype=dtype, count=count, offset=start).astype(np.float64).reshape(n_frames, n_points, 4)
    if scale > 0:
        data[..., :3] *= scale
    fourth = data[..., 3]
    gap = fourth < 0
    pts = data[..., :3].copy()
    pts[gap] = np.nan
    return {"labels": labels, "points": pts, "conjectured": (fourth == 0) & ~gap, "rate": float(rate),
            "units": units}
