"""``mirrorcap retarget``: a take onto another character.

``arkit``: TAKE.c3d -> :func:`core.face.bind.bind_take` on the actor's head (HEAD.blend: the
generic head or the head fitted to the performer, carrying the ARKit shape keys) ->
:func:`core.retarget.arkit.solve_weights` -> the target's shape keys of the same names
(matched case-insensitively) keyed on every frame in TARGET.blend, saved as OUT.blend; the
Live Link Face CSV and RETARGET.json beside it.

``transfer``: TAKE.c3d -> :func:`core.retarget.transfer.transfer_take` (the actor's dense motion,
carried onto the target's surface through its ``lm_<name>`` landmarks and scaled by feature
distances) -> frame shape keys or PCA keys on the target, as ``bake`` writes them.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import bpy
import numpy as np

from ...core.common.errors import InputError
from ...core.common.files import write_files_atomically
from ...core.face.animate import head_pose_from_report, take_frame_range
from ...core.face.bind import load_marker_map
from ...core.retarget.arkit import ARKIT_SHAPES, match_shape_names, retarget_take, shape_name_key
from ...core.retarget.livelink import livelink_csv, read_livelink_csv, timecode_rate
from ...core.retarget.transfer import TRANSFER_LANDMARKS, transfer_take
from ...core.take.c3d import read_c3d
from ..common.shape_keys import bake_displacements, check_keying
from ..common.headio import find_head_object, open_blend, read_head, read_shape_keys, save_blend_atomically
from ..common.keys import key_fcurves, keyed_frames, set_scene_rate

METHODS = ("arkit", "transfer")


def find_landmarked_object(name: str | None):
    """The named object, or the only mesh carrying ``lm_<name>`` landmark groups (motion transfer's target)."""
    if name:
        return find_target_object(name)
    found = [o for o in bpy.data.objects if o.type == "MESH"
             and any(vg.name.startswith("lm_") for vg in o.vertex_groups)]
    if len(found) == 1:
        return found[0]
    if not found:
        meshes = [o.name for o in bpy.data.objects if o.type == "MESH"]
        raise InputError("the target file has no mesh with landmark vertex groups ("
                         + ", ".join(f"lm_{n}" for n in TRANSFER_LANDMARKS[:3]) + ", ...); place them with the "
                         "Retarget panel's Place Landmarks, or name the object with --target-object"
                         + (f" (meshes: {', '.join(meshes)})" if meshes else ""))
    raise InputError("the target file has several meshes with landmarks; name one with --target-object: "
                     + ", ".join(o.name for o in found))


def find_target_object(name: str | None):
    """The named object, or the only mesh whose shape keys include ARKit names."""
    if name:
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise InputError(f"the target file has no object named {name!r} "
                             f"(objects: {', '.join(o.name for o in bpy.data.objects) or 'none'})")
        return obj
    arkit = {shape_name_key(n) for n in ARKIT_SHAPES}       # as other tools spell them too (blendShape1.jawOpen)
    found = [o for o in bpy.data.objects if o.type == "MESH" and o.data.shape_keys is not None
             and any(shape_name_key(kb.name) in arkit for kb in o.data.shape_keys.key_blocks)]
    if len(found) == 1:
        return found[0]
    if not found:
        raise InputError("the target file has no mesh with ARKit-named shape keys (eyeBlinkLeft, jawOpen, ...); "
                         "name the object with --target-object")
    raise InputError("the target file has several meshes with ARKit shape keys; name one with --target-object: "
                     + ", ".join(o.name for o in found))


def key_weights(obj, solved_names, weights, frame_start: int = 1) -> dict:
    """Key ``weights (F, K)`` on ``obj``'s shape keys named like ``solved_names`` from the scene frame ``frame_start``
    on (:func:`..common.keys.keyed_frames`); returns ``{"keyed": [...], "missing": [...]}``."""
    key = obj.data.shape_keys
    if key is None:
        raise InputError(f"{obj.name} has no shape keys")
    weights = np.asarray(weights, float)
    found, missing = match_shape_names([kb.name for kb in key.key_blocks if kb != key.reference_key], solved_names)
    if not found:
        raise InputError(f"{obj.name} has none of the ARKit shape keys (eyeBlinkLeft, jawOpen, ...)")
    if key.animation_data is None:
        key.animation_data_create()
    action = bpy.data.actions.new(f"{obj.name}_mirrorcap_arkit")
    key.animation_data.action = action
    cols = [solved_names.index(n) for n in found]
    targets = [found[n] for n in found]
    for t in targets:
        key.key_blocks[t].value = 0.0
    frames = keyed_frames(bpy.context.scene, frame_start, weights.shape[0])
    key_fcurves(key, action, targets, frames, weights[:, cols].T, "LINEAR")
    return {"keyed": targets, "missing": missing}


#: a Live Link Face take's rate when neither --rate nor its timecodes tell it (the app records at 60 frames/s)
LIVELINK_DEFAULT_RATE = 60.0
#: --rate and the timecodes' rate further apart than this share are warned about (run_livelink)
RATE_DISAGREEMENT = 0.02


def run_livelink(csv_path, target_blend, output, target_object=None, rate: float | None = None, report=None,
                 frames=None, frame_start: int = 1) -> dict:
    """Key a character from a Live Link Face CSV (an iPhone take, or one MirrorCap wrote): its
    52 weights on the target's shape keys of the same names, one CSV row per frame. The scene plays at ``rate``,
    else at the rate the rows' timecodes keep (:func:`core.retarget.livelink.timecode_rate`), else at
    :data:`LIVELINK_DEFAULT_RATE`; ``rate_source`` says which, and ``warnings`` a ``rate`` that disagrees with the
    timecodes (a 30 frames/s take played at 60 runs twice as fast)."""
    for path in (output, report):
        if path is not None and not Path(path).resolve().parent.is_dir():
            raise InputError(f"output folder {Path(path).resolve().parent} does not exist")
    if rate is not None and not rate > 0:
        raise InputError("--rate must be positive")
    table = read_livelink_csv(csv_path)
    weights = np.clip(table["weights"], 0.0, 1.0)
    if not len(weights):
        raise InputError(f"{csv_path} has no frames")
    kept = timecode_rate(table["timecodes"])                 # from the whole take's rows
    start, end = take_frame_range(frames, len(weights))
    weights = weights[start:end]
    warnings = []
    if rate is None:
        rate, source = (kept, "timecodes") if kept else (LIVELINK_DEFAULT_RATE, "default")
    else:
        source = "--rate"
        if kept and abs(rate / kept - 1.0) > RATE_DISAGREEMENT:
            warnings.append(f"--rate {rate:g} but the CSV's timecodes keep {kept:.2f} rows a second: the animation "
                            f"plays {rate / kept:.2f} times as fast as it was recorded (leave --rate out to follow "
                            "the timecodes)")
    open_blend(target_blend)
    target = find_target_object(target_object)
    keyed = key_weights(target, table["names"], weights, frame_start)
    set_scene_rate(bpy.context.scene, rate)
    save_blend_atomically(output)
    result = {"csv": str(csv_path), "target": str(target_blend), "target_object": target.name, "output": str(output),
              "frames": len(weights), "take_frames": [start, end], "frame_start": int(frame_start), "rate": rate,
              "rate_source": source, "timecode_rate": kept,
              "shapes_keyed": keyed["keyed"], "missing_shape_names": keyed["missing"],
              "missing_csv_columns": table["missing_columns"], "warnings": warnings}
    if report is not None:
        write_files_atomically({Path(report): json.dumps(result, indent=1) + "\n"})
    return result


def _take_and_actor(take, head_blend, head_object, head_pose_report, marker_map, outputs):
    """What both methods read first (output folders checked): the take, its frame count, head pose and
    marker map, and the actor's head, shape keys and name (HEAD.blend left open)."""
    for path in outputs:
        if path is not None and not Path(path).resolve().parent.is_dir():
            raise InputError(f"output folder {Path(path).resolve().parent} does not exist")
    data = read_c3d(take)
    F = data["points"].shape[0]
    pose = None if head_pose_report is None else head_pose_from_report(head_pose_report, F)
    mapping = load_marker_map(marker_map) if marker_map else None
    open_blend(head_blend)
    actor = find_head_object(head_object)
    head = read_head(actor)
    head.validate()
    return data, F, pose, mapping, head, read_shape_keys(actor), actor.name


def run_retarget(take, head_blend, target_blend, output, target_object=None, method: str = "arkit",
                 csv=None, head_pose_report=None, report=None, marker_map=None, neutral_frame: int = 0,
                 smoothness: float | None = None, head_object=None, unseen: str = "conjecture", mode: str = "frames",
                 n_modes: int = 8, progress=None, frames=None, frame_start: int = 1) -> dict:
    """The whole ``mirrorcap retarget``. Every output is written only once all succeeded.
    ``mode``/``n_modes``: how ``transfer`` keys the target (``bake``'s frame or PCA keys). ``frames``: the take
    frames ``(START, END)`` to key (END exclusive, None: to the end; the whole take is bound and solved, so each
    comes out as in the whole take's retarget), keyed from the scene frame ``frame_start`` on."""
    if method not in METHODS:
        raise InputError(f"--method must be one of {', '.join(METHODS)}")
    if method == "transfer":
        if csv is not None:
            raise InputError("--csv writes ARKit weights: it belongs to --method arkit")
        if smoothness is not None:
            raise InputError("--smoothness belongs to --method arkit")
        return run_transfer(take, head_blend, target_blend, output, target_object=target_object,
                            head_pose_report=head_pose_report, report=report, marker_map=marker_map,
                            neutral_frame=neutral_frame, head_object=head_object, unseen=unseen, mode=mode,
                            n_modes=n_modes, progress=progress, frames=frames, frame_start=frame_start)
    t0 = time.perf_counter()
    data, F, pose, mapping, head, shape_keys, actor_name = _take_and_actor(take, head_blend, head_object,
                                                                            head_pose_report, marker_map,
                                                                            (output, csv, report))
    start, end = take_frame_range(frames, F)
    t1 = time.perf_counter()
    binding, solve, angles = retarget_take(head, shape_keys, data["labels"], data["points"],
                                           neutral_frame=neutral_frame, head_pose=pose, marker_map=mapping,
                                           unseen=unseen, smoothness=smoothness)
    solve, angles = solve.frames(start, end), angles[start:end]       # the keyed stretch's weights and residuals
    t2 = time.perf_counter()
    open_blend(target_blend)
    target = find_target_object(target_object)
    keyed = key_weights(target, solve.names, solve.weights, frame_start)
    set_scene_rate(bpy.context.scene, data["rate"])
    result = {"take": str(take), "head": str(head_blend), "actor_object": actor_name, "target": str(target_blend),
              "target_object": target.name, "output": str(output), "method": method, "frames": end - start,
              "take_frames": [start, end], "take_length": F, "frame_start": int(frame_start),
              "rate": data["rate"], "markers": len(binding.labels), "registration": binding.registration,
              "landmark_rms_mm": binding.landmark_rms_mm, "solve_iterations": solve.iterations,
              "shapes_keyed": keyed["keyed"], "missing_shape_names": keyed["missing"], **solve.report(),
              "timings_s": {"read_s": t1 - t0, "bind_and_solve_s": t2 - t1}}
    save_blend_atomically(output)
    files = {}
    if csv is not None:
        files[Path(csv)] = livelink_csv(solve.weights, solve.names, data["rate"], head=angles)
    result["timings_s"]["total_s"] = time.perf_counter() - t0
    if report is not None:
        files[Path(report)] = json.dumps(result, indent=1) + "\n"
    write_files_atomically(files)
    return result


def run_transfer(take, head_blend, target_blend, output, target_object=None, head_pose_report=None, report=None,
                 marker_map=None, neutral_frame: int = 0, head_object=None, unseen: str = "conjecture",
                 mode: str = "frames", n_modes: int = 8, progress=None, frames=None, frame_start: int = 1) -> dict:
    """``mirrorcap retarget --method transfer``: the take's motion onto a character with landmarks
    and no shape keys (:func:`core.retarget.transfer.transfer_take`), keyed as ``bake`` keys a head."""
    check_keying(mode, n_modes)
    t0 = time.perf_counter()
    data, F, pose, mapping, head, shape_keys, actor_name = _take_and_actor(take, head_blend, head_object,
                                                                            head_pose_report, marker_map,
                                                                            (output, report))
    start, end = take_frame_range(frames, F)
    check_keying(mode, n_modes, end - start)
    open_blend(target_blend)
    target_obj = find_landmarked_object(target_object)
    target = read_head(target_obj)
    t1 = time.perf_counter()
    tr = transfer_take(head, shape_keys, target, data["labels"], data["points"], data["rate"],
                       neutral_frame=neutral_frame, head_pose=pose, marker_map=mapping,
                       unseen=unseen, frames=(start, end),
                       progress=None if progress is None else (lambda f, text: progress(0.8 * f, text)))
    t2 = time.perf_counter()
    keyed = bake_displacements(target_obj, target.vertices, tr.displacements, mode, n_modes, frame_start=frame_start,
                               progress=None if progress is None else (lambda f: progress(0.8 + 0.15 * f, "keys")))
    scene = bpy.context.scene
    set_scene_rate(scene, data["rate"])
    t3 = time.perf_counter()
    result = {"take": str(take), "head": str(head_blend), "actor_object": actor_name, "target": str(target_blend),
              "target_object": target_obj.name, "output": str(output), "method": "transfer", "frames": end - start,
              "take_frames": [start, end], "take_length": F,
              "rate": data["rate"], "markers": len(tr.binding.labels), **keyed, **tr.report(),
              "timings_s": {"read_s": t1 - t0, "transfer_s": t2 - t1, "keys_s": t3 - t2}}
    save_blend_atomically(output)
    result["timings_s"]["total_s"] = time.perf_counter() - t0
    if report is not None:
        write_files_atomically({Path(report): json.dumps(result, indent=1) + "\n"})
    return result
