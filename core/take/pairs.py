"""PAIRS.csv (real-vs-mirrored correspondences) and POINTS.csv (3D points).

PAIRS.csv -- one row per correspondence, header required, extra columns ignored::

    id,mirror,x,y,xm,ym
    nose_tip,0,640.2,355.1,212.7,340.9
    nose_tip,1,640.2,355.1,1071.3,341.4

``id`` names a marker (any text without commas); ``mirror`` is 0 or 1; ``x, y``
is the marker in the direct view and ``xm, ym`` its image in that mirror, in
pixels of the original (distorted) image. A marker may appear once per mirror;
its direct-view coordinates must then agree (within 1 px; they are averaged).

POINTS.csv -- one row per reconstructed marker::

    id,x,y,z,mirrors

in the OpenCV camera frame (x right, y down, z forward), millimetres when a known
length fixed the scale, else relative units; ``mirrors`` lists the mirrors the
marker was reconstructed from (``0``, ``1`` or ``0+1``).
"""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from ..common.errors import InputError
from ..common.files import read_text
from ..geometry.reconstruct import PairTable

PAIR_COLUMNS = ("id", "mirror", "x", "y", "xm", "ym")
MIRROR_IDS = (0, 1)
DIRECT_TOLERANCE_PX = 1.0


def _parse_float(text, row_no, column):
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise InputError(f"row {row_no}: column {column} is not a number ({text!r})") from None
    if not math.isfinite(value):
        raise InputError(f"row {row_no}: column {column} is not finite ({text!r})")
    return value


def parse_pairs(text: str, source: str = "PAIRS.csv") -> PairTable:
    """Parse and validate the text of a PAIRS.csv file (see module docstring)."""
    reader = csv.reader(io.StringIO(text))
    try:
        header = next(reader)
    except StopIteration:
        raise InputError(f"{source} is empty") from None
    header = [h.strip() for h in header]
    missing = [c for c in PAIR_COLUMNS if c not in header]
    if missing:
        raise InputError(f"{source} is missing column(s): {', '.join(missing)} "
                         f"(expected header {','.join(PAIR_COLUMNS)})")
    col = {c: header.index(c) for c in PAIR_COLUMNS}
    rows = {}
    for line_no, row in enumerate(reader, start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) < len(header):
            raise InputError(f"row {line_no}: expected {len(header)} fields, got {len(row)}")
        marker = row[col["id"]].strip()
        if not marker:
            raise InputError(f"row {line_no}: empty id")
        mirror_text = row[col["mirror"]].strip()
        if mirror_text not in ("0", "1"):
            raise InputError(f"row {line_no}: mirror must be 0 or 1, got {mirror_text!r}")
        mirror = int(mirror_text)
        vals = [_parse_float(row[col[c]].strip(), line_no, c) for c in ("x", "y", "xm", "ym")]
        if (marker, mirror) in rows:
            raise InputError(f"row {line_no}: marker {marker!r} appears twice for mirror {mirror}")
        rows[(marker, mirror)] = vals
    if not rows:
        raise InputError(f"{source} has a header but no correspondences")
    ids = sorted({m for m, _ in rows}, key=_natural_key)
    present = sorted({k for _, k in rows})
    n_mirrors = present[-1] + 1
    for k in range(n_mirrors):
        if k not in present:
            raise InputError(f"mirror {k} has no pairs (mirrors are numbered from 0)")
    index = {m: i for i, m in enumerate(ids)}
    direct = np.zeros((len(ids), 2))
    count = np.zeros(len(ids))
    mirror_px = np.full((n_mirrors, len(ids), 2), np.nan)
    visible = np.zeros((n_mirrors, len(ids)), dtype=bool)
    first_direct = {}
    for (marker, k), (x, y, xm, ym) in rows.items():
        i = index[marker]
        if marker in first_direct:
            fx, fy = first_direct[marker]
            if math.hypot(fx - x, fy - y) > DIRECT_TOLERANCE_PX:
                raise InputError(
                    f"marker {marker!r}: its direct-view position differs between its mirror rows "
                    f"({fx:g},{fy:g}) vs ({x:g},{y:g})"
                )
        else:
            first_direct[marker] = (x, y)
        direct[i] += (x, y)
        count[i] += 1
        mirror_px[k, i] = (xm, ym)
        visible[k, i] = True
    direct /= count[:, None]
    return PairTable(ids=ids, direct_px=direct, mirror_px=mirror_px, visible=visible)


def read_pairs(path) -> PairTable:
    return parse_pairs(read_text(path, "pairs file"), source=str(path))


def format_pairs(ids, direct_px, mirror_px, visible) -> str:
    """Text of a PAIRS.csv for grouped arrays (the inverse of :func:`parse_pairs`)."""
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(PAIR_COLUMNS)
    for k in range(visible.shape[0]):
        for i in np.flatnonzero(visible[k]):
            x, y = direct_px[i]
            xm, ym = mirror_px[k, i]
            w.writerow([ids[i], k, f"{x:.4f}", f"{y:.4f}", f"{xm:.4f}", f"{ym:.4f}"])
    return out.getvalue()


def format_points(ids, points, mirrors_label) -> str:
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    w.writerow(("id", "x", "y", "z", "mirrors"))
    for marker, (x, y, z), label in zip(ids, points, mirrors_label):
        w.writerow([marker, f"{x:.10g}", f"{y:.10g}", f"{z:.10g}", label])
    return out.getvalue()


def read_points(path) -> tuple[list, np.ndarray]:
    """Read a POINTS.csv back: ``ids``, ``points (n, 3)``."""
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    return [r["id"] for r in rows], np.array([[float(r[c]) for c in "xyz"] for r in rows]).reshape(-1, 3)


def _natural_key(text: str):
    """Sort ``m2`` before ``m10``."""
    import re

    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]
