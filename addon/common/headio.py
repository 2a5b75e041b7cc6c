"""Heads in Blender: a mesh object with MirrorCap's vertex groups <-> :class:`core.face.head.HeadModel`.

Writing uses ``foreach_set`` for vertices, loops, polygons and shape keys, and one
``VertexGroup.add`` call per distinct weight. Reading vertex groups is the one
place with a pass over vertices in Python: Blender has no bulk accessor for
vertex-group weights (it runs once per bake, ~10 ms for the generic head).
"""

from __future__ import annotations

import os
from pathlib import Path

import bpy
import numpy as np

from ...core.common.errors import InputError
from ...core.face.head import HeadModel
from .frames import blender_to_core, core_to_blender, object_axes

HINGE_PROPERTY = "mirrorcap_jaw_hinge"
#: the generic head that ships with the extension (HEAD.npz, with its faceunit shape keys)
GENERIC_HEAD = Path(__file__).resolve().parents[2] / "sample_scenes" / "generic_head" / "head.npz"


def new_head_object(head: HeadModel, shape_keys: dict | None = None, name: str | None = None):
    """Create a mesh object for ``head`` in the current scene (shape keys: ``{name: (V, 3) mm offsets}``)."""
    name = name or head.name
    mesh = bpy.data.meshes.new(name)
    V = core_to_blender(head.vertices)
    nv, nl, npoly = len(V), len(head.polygons), len(head.polygon_sizes)
    mesh.vertices.add(nv)
    mesh.vertices.foreach_set("co", V.astype(np.float32).ravel())
    mesh.loops.add(nl)
    mesh.loops.foreach_set("vertex_index", head.polygons.astype(np.int32))
    mesh.polygons.add(npoly)
    starts = np.r_[0, np.cumsum(head.polygon_sizes)[:-1]].astype(np.int32)
    mesh.polygons.foreach_set("loop_start", starts)
    mesh.polygons.foreach_set("use_smooth", np.ones(npoly, bool))
    mesh.update()
    if mesh.validate(verbose=False):
        raise InputError(f"the head {name!r} has invalid geometry")
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    for gname in sorted(head.groups):
        w = np.round(head.groups[gname], 3)
        vg = obj.vertex_groups.new(name=gname)
        for value in np.unique(w[w > 0]):
            vg.add(np.flatnonzero(w == value).tolist(), float(value), "REPLACE")
    if head.hinge is not None:
        obj[HINGE_PROPERTY] = core_to_blender(np.asarray(head.hinge, float)).ravel().tolist()
    if shape_keys:
        obj.shape_key_add(name="Basis", from_mix=False)
        for kname in sorted(shape_keys):
            kb = obj.shape_key_add(name=kname, from_mix=False)
            kb.value = 0.0  # Blender 5.0 leaves a new key at 1.0: the head must show its rest shape
            kb.points.foreach_set("co", core_to_blender(head.vertices + shape_keys[kname]).astype(np.float32).ravel())
        mesh.shape_keys.use_relative = True
    return obj


def read_head(obj) -> HeadModel:
    """The :class:`HeadModel` of a Blender mesh object: its rest shape in core mm, the object's own frame turned
    and scaled to Blender's axes and metres (:func:`.frames.object_axes`: a head imported in centimetres and Y-up
    reads as the same head)."""
    if obj is None or obj.type != "MESH":
        raise InputError("the head must be a mesh object")
    mesh = obj.data
    nv = len(mesh.vertices)
    if nv == 0:
        raise InputError(f"the head {obj.name!r} has no vertices")
    co = np.empty(nv * 3, np.float32)
    if mesh.shape_keys is not None:
        mesh.shape_keys.reference_key.points.foreach_get("co", co)
    else:
        mesh.vertices.foreach_get("co", co)
    sizes = np.empty(len(mesh.polygons), np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    loops = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    names = [vg.name for vg in obj.vertex_groups]
    W = np.zeros((len(names), nv))
    pairs = [(v.index, g.group, g.weight) for v in mesh.vertices for g in v.groups]
    if pairs:
        a = np.array(pairs)
        W[a[:, 1].astype(int), a[:, 0].astype(int)] = a[:, 2]
    hinge = obj.get(HINGE_PROPERTY)
    axes = object_axes(obj)
    return HeadModel(vertices=blender_to_core(co.reshape(-1, 3), axes), polygons=loops, polygon_sizes=sizes,
                     groups=dict(zip(names, W)), name=obj.name,
                     hinge=None if hinge is None else blender_to_core(np.asarray(hinge, float).reshape(2, 3), axes))


def read_shape_keys(obj) -> dict:
    """``{name: (V, 3) offsets in core mm}`` of a mesh object's shape keys (relative to its
    reference key; the reference itself left out), in the frame :func:`read_head` reads the head in."""
    key = obj.data.shape_keys if obj is not None and obj.type == "MESH" else None
    if key is None:
        return {}
    nv = len(obj.data.vertices)
    base = np.empty(nv * 3, np.float32)
    key.reference_key.points.foreach_get("co", base)
    axes = object_axes(obj)
    base = blender_to_core(base.reshape(-1, 3), axes)
    out = {}
    co = np.empty(nv * 3, np.float32)
    for kb in key.key_blocks:
        if kb == key.reference_key:
            continue
        kb.points.foreach_get("co", co)
        out[kb.name] = blender_to_core(co.reshape(-1, 3), axes) - base
    return out


def find_head_object(name: str | None = None):
    """The named mesh object, or the only mesh object with region groups in the file."""
    if name:
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise InputError(f"no object named {name!r} in the head file")
        return obj
    heads = [o for o in bpy.data.objects if o.type == "MESH" and any(g.name.startswith("region_") for g in o.vertex_groups)]
    if len(heads) == 1:
        return heads[0]
    meshes = [o.name for o in bpy.data.objects if o.type == "MESH"]
    if not heads:
        raise InputError("the head file has no mesh with region_* vertex groups"
                         + (f" (meshes: {', '.join(meshes)})" if meshes else " (no meshes at all)"))
    raise InputError("the head file has several heads; name one with --object: " + ", ".join(o.name for o in heads))


def open_blend(path) -> None:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path} does not exist")
    try:
        bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
    except RuntimeError as exc:
        raise InputError(f"{path} is not a readable .blend file ({str(exc).strip().splitlines()[-1]})") from None


def save_blend_atomically(path) -> None:
    """Save the current session to ``path`` via a temporary file in the same folder, then rename."""
    path = Path(path).resolve()
    if not path.parent.is_dir():
        raise InputError(f"output folder {path.parent} does not exist")
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.blend")
    try:
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp), compress=True, copy=True, check_existing=False)
        os.replace(tmp, path)
    finally:
        for leftover in (tmp, Path(str(tmp) + "1")):
            if leftover.exists():
                leftover.unlink()


def write_head_blend(head: HeadModel, path, shape_keys: dict | None = None) -> None:
    """A fresh .blend holding only the head (used by sample_scenes/make_generic_head.py)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    new_head_object(head, shape_keys)
    save_blend_atomically(path)


def replace_head_vertices(obj, old_core, new_core) -> None:
    """Move ``obj``'s rest shape from ``old_core`` to ``new_core`` (core mm, as :func:`read_head` reads them); every
    shape key moves with it, keeping its offsets from the basis."""
    axes = object_axes(obj)
    delta = (core_to_blender(new_core, axes) - core_to_blender(old_core, axes)).astype(np.float32).ravel()
    mesh = obj.data
    n = len(mesh.vertices) * 3
    if delta.size != n:
        raise InputError(f"the fitted head has {delta.size // 3} vertices, {obj.name!r} has {n // 3}")
    co = np.empty(n, np.float32)
    if mesh.shape_keys is not None:
        for kb in mesh.shape_keys.key_blocks:
            kb.points.foreach_get("co", co)
            kb.points.foreach_set("co", co + delta)
    mesh.vertices.foreach_get("co", co)
    mesh.vertices.foreach_set("co", co + delta)
    mesh.update()


def head_feature_points(obj, head: HeadModel) -> dict:
    """The head's MPEG-4 feature points (:func:`core.retarget.mpeg4.feature_points`), its
    jaw-opening shape key (``jawOpen``, any case) telling the lower lip from the upper lip."""
    from ...core.retarget.mpeg4 import feature_points

    jaw_open = None
    key = obj.data.shape_keys
    block = next((kb for kb in key.key_blocks if kb.name.lower() == "jawopen"), None) if key is not None else None
    if block is not None:
        nv = len(obj.data.vertices)
        base, co = np.empty(nv * 3, np.float32), np.empty(nv * 3, np.float32)
        key.reference_key.points.foreach_get("co", base)
        block.points.foreach_get("co", co)
        jaw_open = blender_to_core((co - base).reshape(-1, 3), object_axes(obj))
    return feature_points(head, jaw_open)
