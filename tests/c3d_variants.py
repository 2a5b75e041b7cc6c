"""C3D files in the forms other systems write, made for the tests: ezc3d writes Intel
floating-point files (with analog channels, any units, any first frame, any labels); this
module converts such a file byte by byte to the DEC or MIPS processor format, or to integer
point data, by walking its header, parameter section and data section."""

from __future__ import annotations

import struct

import numpy as np

BLOCK = 512


def _vax(x: np.ndarray) -> bytes:
    """float32 values as DEC (VAX F) floats: the IEEE bits of 4x the value with the two
    16-bit halves swapped."""
    b = (np.asarray(x, "<f4") * 4).astype("<f4").view("<u2").reshape(-1, 2)[:, ::-1]
    return b.astype("<u2").tobytes()


def _floats(raw: bytes, fmt: str) -> bytes:
    v = np.frombuffer(raw, "<f4")
    return _vax(v) if fmt == "dec" else v.astype(">f4").tobytes()


def _ints(raw: bytes, fmt: str) -> bytes:
    return raw if fmt == "dec" else np.frombuffer(raw, "<i2").astype(">i2").tobytes()


def convert(data: bytes, fmt: str) -> bytes:
    """An Intel floating-point C3D file (``data``) in processor format ``fmt``: ``"dec"`` or
    ``"mips"``. The analog data must be floating point too (ezc3d writes it so)."""
    out = bytearray(data)
    pblock = data[0]
    p0 = (pblock - 1) * BLOCK
    # header: 16-bit words, floats at bytes 12 (scale) and 20 (rate)
    for pos in range(2, 512, 2):
        if pos in (12, 14, 20, 22):
            continue
        out[pos:pos + 2] = _ints(data[pos:pos + 2], fmt)
    out[12:16] = _floats(data[12:16], fmt)
    out[20:24] = _floats(data[20:24], fmt)
    out[p0 + 3] = 85 if fmt == "dec" else 86
    n_blocks = data[p0 + 2]
    pos = p0 + 4
    end = p0 + n_blocks * BLOCK
    data_start = None
    while pos + 4 <= end:
        n_chars, gid = struct.unpack("<bb", data[pos:pos + 2])
        if n_chars == 0:
            break
        name = data[pos + 2:pos + 2 + abs(n_chars)].decode("ascii")
        off = pos + 2 + abs(n_chars)
        offset = struct.unpack("<h", data[off:off + 2])[0]
        out[off:off + 2] = _ints(data[off:off + 2], fmt)
        body = off + 2
        if gid > 0:
            dtype, nd = struct.unpack("<bb", data[body:body + 2])
            dims = list(data[body + 2:body + 2 + nd])
            size = abs(dtype) * (int(np.prod(dims)) if dims else 1)
            start = body + 2 + nd
            chunk = data[start:start + size]
            if dtype == 4:
                out[start:start + size] = _floats(chunk, fmt)
            elif dtype == 2:
                out[start:start + size] = _ints(chunk, fmt)
            if name == "DATA_START" and data_start is None:  # POINT:DATA_START comes first
                data_start = struct.unpack("<H", chunk[:2])[0]
        if offset == 0:
            break
        pos = off + offset
    if data_start is None:
        data_start = struct.unpack("<H", data[16:18])[0]
    d0 = (data_start - 1) * BLOCK
    n_words = (len(data) - d0) // 4
    out[d0:d0 + 4 * n_words] = _floats(data[d0:d0 + 4 * n_words], fmt)
    return bytes(out)


def to_integer(data: bytes, scale: float) -> bytes:
    """An Intel floating-point C3D file without analog channels (``data``) with integer point
    data: every coordinate ``round(x / scale)`` as int16, the fourth word ``-1`` for a gap and
    0 otherwise, ``POINT:SCALE`` and the header's scale set to ``+scale``."""
    data_start = struct.unpack("<H", data[16:18])[0]
    n_points = struct.unpack("<H", data[2:4])[0]
    head = bytearray(data[:(data_start - 1) * BLOCK])
    head[12:16] = struct.pack("<f", scale)
    # POINT:SCALE in the parameter section
    p0 = (data[0] - 1) * BLOCK
    pos = p0 + 4
    while True:
        n_chars, gid = struct.unpack("<bb", head[pos:pos + 2])
        name = bytes(head[pos + 2:pos + 2 + abs(n_chars)]).decode("ascii")
        off = pos + 2 + abs(n_chars)
        offset = struct.unpack("<h", head[off:off + 2])[0]
        if gid > 0 and name == "SCALE":
            nd = head[off + 3]
            start = off + 4 + nd
            head[start:start + 4] = struct.pack("<f", scale)
            break
        pos = off + offset
    vals = np.frombuffer(data[(data_start - 1) * BLOCK:], "<f4")
    vals = vals[:len(vals) // (4 * n_points) * 4 * n_points].reshape(-1, n_points, 4)
    gap = vals[..., 3] < 0
    ints = np.zeros(vals.shape, "<i2")
    ints[..., :3] = np.round(vals[..., :3] / scale).astype("<i2")
    ints[..., 3] = np.where(gap, -1, 0)
    ints[gap, :3] = 0
    body = ints.tobytes()
    out = bytes(head) + body
    return out.ljust(len(out) + (-len(out)) % BLOCK, b"\0")
