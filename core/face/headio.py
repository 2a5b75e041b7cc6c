"""HEAD.npz: the head model on disk without Blender (numpy's ``.npz``, compressed).

Arrays (all lengths in millimetres, the core's frame):

``vertices``        float64 (V, 3) neutral positions
``polygons``        int64 flat vertex indices of every polygon
``polygon_sizes``   int64 (P,) corners per polygon
``group_names``     str (G,) vertex-group names (see :mod:`core.face.head`)
``group_weights``   float32 (G, V) their weights
``hinge``           float64 (2, 3), optional: explicit jaw hinge points (left, right)
``key_names``       str (K,), optional: shape-key names
``key_offsets``     float32 (K, V, 3), optional: shape-key offsets from the neutral
``name``            str: the head's name
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..common.errors import InputError
from ..common.files import write_files_atomically
from .head import HeadModel


def head_npz_bytes(head: HeadModel, shape_keys: dict | None = None) -> bytes:
    names = sorted(head.groups)
    arrays = {
        "vertices": head.vertices, "polygons": head.polygons, "polygon_sizes": head.polygon_sizes,
        "group_names": np.array(names), "group_weights": np.array([head.groups[g] for g in names], np.float32),
        "name": np.array(head.name),
    }
    if head.hinge is not None:
        arrays["hinge"] = np.asarray(head.hinge, float)
    if shape_keys:
        keys = sorted(shape_keys)
        arrays["key_names"] = np.array(keys)
        arrays["key_offsets"] = np.array([shape_keys[k] for k in keys], np.float32)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def save_head_npz(path, head: HeadModel, shape_keys: dict | None = None) -> None:
    write_files_atomically({Path(path): head_npz_bytes(head, shape_keys)})


def load_head_npz(path, with_shape_keys: bool = False):
    """The :class:`HeadModel` in ``path`` (and ``{name: (V, 3) offsets}`` if asked)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"head file {path} does not exist")
    try:
        z = np.load(path, allow_pickle=False)
        groups = {str(n): w.astype(float) for n, w in zip(z["group_names"], z["group_weights"])}
        head = HeadModel(vertices=z["vertices"], polygons=z["polygons"], polygon_sizes=z["polygon_sizes"],
                         groups=groups, hinge=z["hinge"] if "hinge" in z.files else None, name=str(z["name"]))
        keys = {}
        if with_shape_keys and "key_names" in z.files:
            keys = {str(n): o.astype(float) for n, o in zip(z["key_names"], z["key_offsets"])}
    except (KeyError, ValueError, OSError) as exc:
        raise InputError(f"{path} is not a HEAD.npz file ({exc})") from None
    return (head, keys) if with_shape_keys else head
