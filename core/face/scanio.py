"""Reading a subject's scan (the input of the head fit): PLY or OBJ triangle meshes, and landmarks.

PLY: ``ascii`` or ``binary_little_endian``/``binary_big_endian``; the vertex element's ``x y z``
(any numeric type, other properties skipped) and the face element's index list (polygons are
fanned into triangles). OBJ: ``v`` and ``f`` lines (``f a/b/c ...``, negative indices allowed).
Units are whatever the file holds; MirrorCap reads them as millimetres.

Landmarks: a JSON object ``{"nose_tip": [x, y, z], ...}`` in the scan's frame, names as the
head's ``lm_<name>`` groups (``lm_`` prefixes are accepted).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..common.errors import InputError
from ..common.files import read_json

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def _fan(polys) -> np.ndarray:
    tris = [(p[0], p[i], p[i + 1]) for p in polys for i in range(1, len(p) - 1)]
    return np.asarray(tris, np.int64).reshape(-1, 3)


def _read_ply(path: Path):
    data = path.read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise InputError(f"{path} is not a PLY file (no 'ply' ... 'end_header')")
    body_start = data.index(b"\n", end) + 1
    header = data[:end].decode("ascii", "replace").splitlines()
    fmt, elements = None, []
    for line in header:
        w = line.split()
        if not w:
            continue
        if w[0] == "format":
            fmt = w[1]
        elif w[0] == "element":
            elements.append({"name": w[1], "count": int(w[2]), "props": []})
        elif w[0] == "property" and elements:
            if w[1] == "list":
                elements[-1]["props"].append((w[4], "list", _PLY_TYPES.get(w[2]), _PLY_TYPES.get(w[3])))
            else:
                elements[-1]["props"].append((w[2], _PLY_TYPES.get(w[1]), None, None))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise InputError(f"{path}: unsupported PLY format {fmt!r}")
    V, polys = None, []
    if fmt == "ascii":
        tokens = data[body_start:].split()
        pos = 0
        for el in elements:
            rows = []
            for _ in range(el["count"]):
                row = []
                for name, kind, ctype, itype in el["props"]:
                    if kind == "list":
                        n = int(tokens[pos])
                        row.append([int(x) for x in tokens[pos + 1:pos + 1 + n]])
                        pos += 1 + n
                    else:
                        row.append(float(tokens[pos]))
                        pos += 1
                rows.append(row)
            if el["name"] == "vertex":
                names = [p[0] for p in el["props"]]
                V = np.array([[r[names.index(c)] for c in "xyz"] for r in rows], float)
            elif el["name"] == "face":
                li = [i for i, p in enumerate(el["props"]) if p[1] == "list"][0]
                polys = [r[li] for r in rows]
        return V, _fan(polys)
    order = "<" if fmt == "binary_little_endian" else ">"
    pos = body_start
    for el in elements:
        if all(p[1] != "list" for p in el["props"]):
            dt = np.dtype([(p[0], order + p[1]) for p in el["props"]])
            arr = np.frombuffer(data, dt, el["count"], pos)
            pos += dt.itemsize * el["count"]
            if el["name"] == "vertex":
                V = np.stack([arr[c].astype(float) for c in "xyz"], axis=1)
            continue
        # list element: fast path for all-triangle faces with only the index list
        props = el["props"]
        if len(props) == 1 and el["name"] == "face":
            _, _, ctype, itype = props[0]
            cdt, idt = np.dtype(order + ctype), np.dtype(order + itype)
            first = int(np.frombuffer(data, cdt, 1, pos)[0])
            rec = np.dtype([("n", cdt), ("v", idt, (first,))])
            arr = np.frombuffer(data, rec, el["count"], pos)
            if np.all(arr["n"] == first):
                polys_arr = arr["v"].astype(np.int64)
                pos += rec.itemsize * el["count"]
                polys = polys_arr if first == 3 else _fan(polys_arr.tolist())
                continue
        rows = []
        for _ in range(el["count"]):
            row = []
            for name, kind, ctype, itype in props:
                if kind == "list":
                    n = int(np.frombuffer(data, order + ctype, 1, pos)[0])
                    pos += np.dtype(ctype).itemsize
                    row.append(np.frombuffer(data, order + itype, n, pos).tolist())
                    pos += n * np.dtype(itype).itemsize
                else:
                    pos += np.dtype(kind).itemsize
            rows.append(row)
        if el["name"] == "face":
            polys = _fan([r[0] for r in rows])
    if V is None:
        raise InputError(f"{path}: no vertex element")
    T = np.asarray(polys, np.int64).reshape(-1, 3) if len(polys) else np.zeros((0, 3), np.int64)
    return V, T


def _read_obj(path: Path):
    V, polys = [], []
    for line in path.read_text(errors="replace").splitlines():
        w = line.split()
        if not w:
            continue
        if w[0] == "v":
            V.append([float(x) for x in w[1:4]])
        elif w[0] == "f":
            idx = [int(x.split("/")[0]) for x in w[1:]]
            polys.append([i - 1 if i > 0 else len(V) + i for i in idx])
    return np.asarray(V, float).reshape(-1, 3), _fan(polys)


def read_scan(path):
    """``vertices (N, 3), triangles (T, 3)`` of a PLY or OBJ file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"scan {path} does not exist")
    suffix = path.suffix.lower()
    try:
        if suffix == ".ply":
            V, T = _read_ply(path)
        elif suffix == ".obj":
            V, T = _read_obj(path)
        else:
            raise InputError(f"scan {path}: use a .ply or .obj file")
    except (ValueError, IndexError) as exc:
        raise InputError(f"scan {path} is damaged ({exc})") from None
    if len(V) < 4 or not np.all(np.isfinite(V)):
        raise InputError(f"scan {path} has {len(V)} usable vertices")
    if len(T) and (T.min() < 0 or T.max() >= len(V)):
        raise InputError(f"scan {path}: a face refers to a vertex that does not exist")
    return V, T


def read_landmarks(path) -> dict:
    """``{name: (3,) array}`` from a landmarks JSON file."""
    data = read_json(path, "landmarks file")
    if not isinstance(data, dict) or not data:
        raise InputError(f"landmarks file {path}: expected {{\"nose_tip\": [x, y, z], ...}}")
    out = {}
    for name, xyz in data.items():
        try:
            p = np.asarray(xyz, float).reshape(3)
        except (TypeError, ValueError):
            raise InputError(f"landmarks file {path}: {name!r} must be [x, y, z]") from None
        out[name[3:] if name.startswith("lm_") else name] = p
    return out
