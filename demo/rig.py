"""The main job on the embedded sample (``mirrorcap demo`` / ``make demo``).

``sample_scenes/rig_clip`` holds a rig clip rendered by Blender (Cycles) with its truth and a
scan of the same face. The demo runs the product end to end, as a user would:

1. ``track``   clip.mp4 -> take.c3d + take_report.json (markers, self-calibrated mirrors,
               3D tracking with head motion removed); scored against the clip's truth
               (:func:`synthetic.evaluate.score_take`);
2. ``fit``     the generic head -> the sample scan (landmarks from the scan's JSON);
3. ``bind``    the take to the fitted head by its skin surface (the take's markers carry
               no landmark labels);
4. ``bake``    the face rig on every frame -> shape keys; the baked displacements are
               compared with the performance the clip was rendered from;
5. ``retarget`` the take's motion transferred onto a second character
               (``sample_scenes/character``: other proportions and topology, landmarks only;
               :func:`core.retarget.transfer.transfer_take`), compared with that character's own
               expressions under the same performance;
6. outputs     ``demo.blend`` (fitted head and character with their shape keys, side by side; the
               take as empties),
               ``fitted_head.blend`` (the fitted head alone, for baking more takes),
               ``preview.mp4`` (Cycles, CPU), ``report.html``, ``demo.json``; a one-screen
               summary on stdout.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import bpy
import numpy as np

from ..core.common.errors import InputError
from ..core.common.files import output_folder, write_files_atomically

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sample_scenes" / "rig_clip"
CHARACTER = ROOT / "sample_scenes" / "character" / "character.npz"
PREVIEW_SIZE = (640, 360)
CHARACTER_OFFSET_M = 0.2        # the character stands this far to the actor's left in the scene (Blender x)


def _step(name, timings, fn, *args, **kw):
    t0 = time.perf_counter()
    out = fn(*args, **kw)
    timings[name] = time.perf_counter() - t0
    return out


def _render_preview(objects, frames: int, fps: float, path: Path) -> None:
    """Render the baked heads (actor and character, side by side) from the front to an H.264 file
    (Cycles, CPU, a few samples)."""
    from ..addon.common.frames import core_to_blender
    from ..addon.common.keys import set_scene_rate
    from ..addon.common.video_out import h264_output

    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 8
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 1
    scene.render.resolution_x, scene.render.resolution_y = PREVIEW_SIZE
    scene.render.resolution_percentage = 100
    set_scene_rate(scene, fps)
    scene.frame_start, scene.frame_end = 1, frames
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("preview") if scene.world is None else scene.world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.18, 0.19, 0.21, 1.0)
    scene.world = world
    skin = bpy.data.materials.new("preview_skin")
    skin.diffuse_color = (0.62, 0.47, 0.42, 1.0)
    skin.use_nodes = True
    bsdf = skin.node_tree.nodes.get("Principled BSDF")
    if bsdf is not None:
        bsdf.inputs["Base Color"].default_value = (0.62, 0.47, 0.42, 1.0)
        bsdf.inputs["Roughness"].default_value = 0.6
    centres = []
    bpy.context.view_layer.update()   # matrix_world of objects placed this run (the character's offset)
    for obj in objects:
        obj.data.materials.append(skin)
        co = np.empty(len(obj.data.vertices) * 3, np.float32)
        obj.data.vertices.foreach_get("co", co)
        centres.append(np.asarray(obj.matrix_world) @ np.r_[co.reshape(-1, 3).mean(0), 1.0])
    centre_b = np.mean(centres, axis=0)
    cam_data = bpy.data.cameras.new("preview_camera")
    cam_data.lens = 50.0
    cam = bpy.data.objects.new("preview_camera", cam_data)
    bpy.context.scene.collection.objects.link(cam)
    # 800 mm in front of the faces, looking at them (Blender: the face looks down -Y): both heads in frame
    cam.location = centre_b[:3] + core_to_blender(np.array([0.0, 0.0, -800.0]))
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    scene.camera = cam
    lamp = bpy.data.lights.new("preview_key", "AREA")
    lamp.energy = 4.0
    lamp.size = 0.5
    lo = bpy.data.objects.new("preview_key", lamp)
    lo.location = np.asarray(cam.location) + np.array([0.25, 0.0, 0.3])
    lo.rotation_euler = (np.radians(60), 0.0, np.radians(25))
    bpy.context.scene.collection.objects.link(lo)
    h264_output(scene.render, path, "MEDIUM")
    bpy.ops.render.render(animation=True)


def run_demo(out_dir, quiet: bool = False, sample: Path = SAMPLE, preview: bool = True) -> int:
    from ..addon.common.frames import core_to_blender
    from ..addon.common.keys import set_scene_rate
    from ..addon.common.shape_keys import bake_displacements
    from ..addon.common.headio import GENERIC_HEAD, new_head_object, save_blend_atomically
    from ..addon.common.take_io import import_take
    from ..core.capture.rig import load_rig_views
    from ..core.capture.video import open_source
    from ..core.face.animate import animate_take, head_pose_from_report
    from ..core.face.facerig import RigSettings
    from ..core.face.headfit import fit_head
    from ..core.face.headio import load_head_npz
    from ..core.face.scanio import read_landmarks, read_scan
    from ..core.retarget.transfer import transfer_take
    from ..core.geometry.camera import Camera
    from ..core.take.c3d import read_c3d
    from ..core.track.pipeline import run_track
    from ..synthetic.evaluate import score_take
    from ..synthetic.headsim import performance
    from .report import histogram, html_page, line_plot, table, top_view

    say = (lambda *a: None) if quiet else (lambda *a: print(*a, flush=True))
    if not (sample / "clip.mp4").is_file():
        raise InputError(f"the embedded sample is missing ({sample}); run the demo from a MirrorCap checkout")
    out_dir = output_folder(Path(out_dir).resolve())
    timings = {}
    t_all = time.perf_counter()

    # 1. track
    truth = np.load(sample / "truth.npz")
    camera = Camera.load(sample / "camera.json")
    source = open_source(sample / "clip.mp4")
    take_path, report_path = out_dir / "take.c3d", out_dir / "take_report.json"
    steps = 6 if preview else 5                                  # the preview is the sixth
    say(f"1/{steps} track      {sample / 'clip.mp4'} ({source.frame_count} frames, {source.size[0]}x{source.size[1]})")
    report = _step("track", timings, run_track, source, camera, take_path, report=report_path,
                   layout=load_rig_views(sample / "rig.json"))
    take = read_c3d(take_path)
    score = score_take(take["points"], truth["points"], camera, conjectured=take["conjectured"])
    fps = float(take["rate"])

    # 2. fit the generic head to the scan
    say(f"2/{steps} fit        generic head -> sample scan")
    head, keys = load_head_npz(GENERIC_HEAD, with_shape_keys=True)
    scan_V, scan_T = read_scan(sample / "scan.ply")
    fit = _step("fit", timings, fit_head, head, scan_V, scan_T, read_landmarks(sample / "scan_landmarks.json"))
    fitted = dataclasses.replace(head, vertices=fit.vertices, name="subject")
    # the fit against the subject's true shape, in the scan's frame
    true_scan = truth["subject_vertices"] @ truth["scan_rotation"].T + truth["scan_translation"]
    skin = head.skin_mask()
    face = skin & (truth["subject_vertices"][:, 2] < -20.0)
    fit_err = np.linalg.norm(fit.vertices - true_scan, axis=1)[face]

    # 3. bind (with the tracker's head pose) and 4. rig
    say(f"3/{steps} bind       take -> fitted head (skin-surface registration)")
    say(f"4/{steps} rig+bake   face rig on every frame -> shape keys")
    pose = head_pose_from_report(report_path, take["points"].shape[0])
    anim = animate_take(fitted, take["labels"], take["points"], fps, head_pose=pose, unseen="conjecture",
                        settings=RigSettings(blinks=True))
    t_rig = time.perf_counter()
    binding, D = anim.binding, anim.displacements
    timings["bind"] = anim.timings_s["bind_s"]
    timings["rig"] = anim.timings_s["rig_s"] + time.perf_counter() - t_rig
    # the baked motion against the rendered performance (same topology), in the scan's frame
    true_disp, _ = performance(head, keys, D.shape[0], fps, seed=int(truth["performance_seed"]))
    true_disp = true_disp @ truth["scan_rotation"].T
    region = np.zeros(len(head.vertices), bool)
    for g in [n for n in head.groups if n.startswith("region_")]:
        region[head.members(g)] = True
    region &= skin
    for side in ("l", "r"):                      # synthetic blinks are not in the rendered performance
        lid = head.groups.get(f"eyelid_upper_{side}")
        if lid is not None:
            region &= lid <= 0
    anim_err = np.linalg.norm(D[:, region] - true_disp[:, region], axis=2)
    per_region = []
    for g in sorted(n for n in head.groups if n.startswith("region_")):
        m = np.flatnonzero((head.groups[g] >= 0.5) & region)
        e = np.linalg.norm(D[:, m] - true_disp[:, m], axis=2)
        per_region.append((g[7:], int(np.isin(binding.vertices, m).sum()), float(np.sqrt(np.mean(e ** 2))),
                           float(np.sqrt(np.mean(np.sum(true_disp[:, m] ** 2, axis=2))))))

    # 5. retarget: the take's motion onto the second character (landmarks only, no shape keys)
    say(f"5/{steps} retarget   take -> second character (motion transfer)")
    character, character_keys = load_head_npz(CHARACTER, with_shape_keys=True)
    transfer = _step("retarget", timings, transfer_take, fitted, keys, character, take["labels"], take["points"],
                     fps, head_pose=pose, unseen="conjecture")
    own, _ = performance(character, character_keys, D.shape[0], fps, seed=int(truth["performance_seed"]))
    moving = np.linalg.norm(own, axis=2) > 1.0
    transfer_err = np.linalg.norm(transfer.displacements - own, axis=2)[moving]

    # 6. Blender scene, preview, report
    t0 = time.perf_counter()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    # the generic head's 52 ARKit expressions ride along (their offsets, as Fit Head keeps them), so
    # fitted_head.blend can be the actor of `mirrorcap retarget`; they stay at 0 (the rest shape shows)
    obj = new_head_object(fitted, keys, name="subject_head")
    save_blend_atomically(out_dir / "fitted_head.blend")        # for `mirrorcap bake/batch` of more takes
    bake = bake_displacements(obj, fitted.vertices, D, "frames")
    char_obj = new_head_object(character, name="Character")
    # beside the actor: the character's centre at the actor's, moved along Blender x
    char_obj.location = core_to_blender(fitted.vertices.mean(0)) - core_to_blender(character.vertices.mean(0)) \
        + np.array([CHARACTER_OFFSET_M, 0.0, 0.0])
    bake_displacements(char_obj, character.vertices, transfer.displacements, "frames")
    set_scene_rate(bpy.context.scene, fps)
    timings["bake"] = time.perf_counter() - t0
    if preview:
        say(f"6/{steps} preview    Cycles (CPU) render of the baked head and the character, side by side")
        tmp_video = out_dir / ".preview.tmp.mp4"
        _step("preview", timings, _render_preview, [obj, char_obj], D.shape[0], fps, tmp_video)
    import_take(bpy.context, take_path, name="sample")
    t0 = time.perf_counter()
    save_blend_atomically(out_dir / "demo.blend")
    timings["save"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all

    withheld = int(sum(report["per_frame"].get("withheld", [])))  # conjectures left as gaps
    summary = {
        "clip": {"frames": int(source.frame_count), "fps": fps, "size": list(source.size)},
        "tracking": {**{k: v for k, v in score.items() if not isinstance(v, np.ndarray)},
                     "withheld": withheld, "withheld_fraction": withheld / max(score["aligned"].shape[0]
                                                                                 * score["aligned"].shape[1], 1)},
        "tracking_report": {"units": report["units"], "mirrors": report["mirrors"],
                            "tracking_frames_per_s": report["timings_s"]["tracking_frames_per_s"]},
        "fit": {"residual_to_scan_rms_mm": fit.residual_rms_mm, "landmark_rms_mm": fit.landmark_rms_mm,
                "error_to_true_face_rms_mm": float(np.sqrt(np.mean(fit_err ** 2))),
                "error_to_true_face_p95_mm": float(np.percentile(fit_err, 95))},
        "bind": {"registration": binding.registration, "surface_rms_mm": binding.landmark_rms_mm,
                 "markers": len(binding.labels), "markers_neutral_conjectured": binding.conjectured_neutral,
                 "markers_left_out": binding.dropped,
                 "take_units_to_mm": binding.scale},
        "animation": {"vertices_scored": int(region.sum()),
                      "displacement_error_rms_mm": float(np.sqrt(np.mean(anim_err ** 2))),
                      "displacement_error_p95_mm": float(np.percentile(anim_err, 95)),
                      "true_displacement_rms_mm": float(np.sqrt(np.mean(np.sum(true_disp[:, region] ** 2, 2)))),
                      "shape_keys": bake["frames"],
                      "per_region": [{"region": r, "markers": n, "error_rms_mm": e, "true_motion_rms_mm": tm}
                                     for r, n, e, tm in per_region]},
        "retarget": {"character_vertices": int(len(character.vertices)),
                     "region_scales": transfer.report()["region_scales"],
                     "moving_vertex_error_mean_mm": float(transfer_err.mean()),
                     "moving_vertex_error_p95_mm": float(np.percentile(transfer_err, 95)),
                     "own_motion_mean_mm": float(np.linalg.norm(own, axis=2)[moving].mean())},
        "timings_s": timings,
    }

    # report.html
    ids, aligned, err = score["ids"], score["aligned"], score["error_mm"]
    frames = np.arange(take["points"].shape[0])
    ok_markers = np.flatnonzero(ids >= 0)
    moving = ok_markers[np.argsort(-np.nanstd(truth["points"][:, ids[ok_markers], 1], axis=0))[:2]]
    traj = []
    for m in moving:
        traj.append(line_plot(frames, {"tracked y": aligned[:, m, 1], "true y": truth["points"][:, ids[m], 1],
                                       "tracked z": aligned[:, m, 2], "true z": truth["points"][:, ids[m], 2]},
                              f"marker {take['labels'][m]}: trajectory (mm, camera frame)", "frame", "mm",
                              dashed=("true y", "true z")))
    meas = np.all(np.isfinite(take["points"]), axis=2) & ~take["conjectured"] & (ids[None] >= 0)
    pf = report["per_frame"]
    plots = [
        ("Trajectories against the truth", "".join(traj)),
        ("3D error", histogram(err[meas], "3D error of measured markers after one similarity (mm)", "mm")
         + line_plot(frames, {"measured": pf["measured"], "conjectured": pf["conjectured"],
                              "false tracking": pf["false_tracking"]}, "per-frame counts", "frame", "markers")),
        ("Mirror planes", top_view(aligned[0][np.all(np.isfinite(aligned[0]), 1)],
                                   [(np.asarray(m["normal"]), m["d"] * score["scale_to_mm"])
                                    for m in report["mirrors"]], "markers and mirror planes from above (mm)")
         + table([(m["mirror"], " ".join(f"{v:+.4f}" for v in m["normal"]), f"{m['d'] * score['scale_to_mm']:.1f}",
                   f"{tn:+.4f} {tn2:+.4f} {tn3:+.4f}", f"{td:.1f}")
                  for m, (tn, tn2, tn3), td in zip(report["mirrors"], truth["mirror_normals"], truth["mirror_d"])],
                 ["mirror", "normal (self-calibrated)", "d (mm, scaled)", "true normal", "true d (mm)"])),
        ("Head fit and animation", line_plot(frames, {"baked RMS": np.sqrt(np.mean(anim_err ** 2, axis=1)),
                                                       "true motion RMS": np.sqrt(np.mean(np.sum(
                                                           true_disp[:, region] ** 2, 2), axis=1))},
                                              "face displacement per frame (mm)", "frame", "mm",
                                              dashed=("true motion RMS",))
         + table([(r, n, f"{e:.2f}", f"{tm:.2f}") for r, n, e, tm in per_region],
                 ["region", "markers bound", "baked vs true RMS (mm)", "true motion RMS (mm)"])),
    ]
    figures = [
        ("3D RMS error of the take (after one similarity)", f"{score['rms_mm']:.3f} mm"),
        ("3D error p95 / max", f"{score['p95_mm']:.3f} / {score['max_mm']:.3f} mm"),
        ("markers tracked / matched to truth / in the clip", f"{score['markers_tracked']} / "
                                                           f"{score['markers_matched']} / {score['markers_true']}"),
        ("identity switches (measurements nearer another true marker)", score["identity_switches"]),
        ("measurements of the right marker more than 2 px off", score["off_marker"]),
        ("conjectured points (RMS / max error)", f"{score['conjectured']} ({score['conjectured_rms_mm']:.2f} / "
                                                  f"{score['conjectured_max_mm']:.2f} mm)"),
        ("conjectures withheld (expected error over the limit: left as gaps)", withheld),
        ("head fit: residual to the scan / error to the true face",
         f"{fit.residual_rms_mm:.2f} / {summary['fit']['error_to_true_face_rms_mm']:.2f} mm RMS"),
        ("bind: registration residual", f"{binding.landmark_rms_mm:.2f} mm ({binding.registration})"),
        ("animation: baked vs true displacement", f"{summary['animation']['displacement_error_rms_mm']:.2f} mm RMS "
                                                  f"(true motion {summary['animation']['true_displacement_rms_mm']:.2f} mm RMS)"),
        ("retarget: character's moving vertices vs its own expression",
         f"{summary['retarget']['moving_vertex_error_mean_mm']:.2f} mm mean (their motion "
         f"{summary['retarget']['own_motion_mean_mm']:.2f} mm mean)"),
    ]
    time_rows = [(k, f"{v:.2f} s") for k, v in timings.items()]
    page = html_page("MirrorCap demo: sample rig clip -> baked head -> second character",
                     [("Figures", table(figures, ["figure", "value"]))] + plots
                     + [("Timings", table(time_rows, ["step", "seconds"]))],
                     video="preview.mp4" if preview else None)
    files = {out_dir / "report.html": page, out_dir / "demo.json": json.dumps(summary, indent=1) + "\n"}
    if preview:
        files[out_dir / "preview.mp4"] = tmp_video.read_bytes()
    write_files_atomically(files)
    if preview:
        tmp_video.unlink()

    say("")
    say("MirrorCap demo: rig clip -> 3D take -> fitted head -> baked shape keys")
    say(f"  tracking    {score['markers_tracked']} markers x {len(frames)} frames, 3D RMS error {score['rms_mm']:.3f} mm "
        f"(p95 {score['p95_mm']:.3f}, max {score['max_mm']:.3f}) after one similarity; "
        f"{score['identity_switches']} identity switches, {score['off_marker']} measurements > 2 px off their marker")
    say(f"  mirrors     self-calibrated from the markers; normals within "
        f"{max(np.degrees(np.arccos(min(1.0, abs(float(np.dot(m['normal'], tn)))))) for m, tn in zip(report['mirrors'], truth['mirror_normals'])):.3f} deg of the truth")
    say(f"  head fit    {fit.residual_rms_mm:.2f} mm RMS to the scan, {summary['fit']['error_to_true_face_rms_mm']:.2f} mm "
        f"to the true face")
    say(f"  bind        {binding.registration} registration, {binding.landmark_rms_mm:.2f} mm RMS")
    say(f"  animation   baked face motion within {summary['animation']['displacement_error_rms_mm']:.2f} mm RMS of the "
        f"rendered performance (its motion: {summary['animation']['true_displacement_rms_mm']:.2f} mm RMS)")
    say(f"  retarget    onto a second character ({len(character.vertices)} vertices, landmarks only): its moving "
        f"vertices within {summary['retarget']['moving_vertex_error_mean_mm']:.2f} mm mean of its own expression")
    say(f"  time        {timings['total']:.1f} s (" + ", ".join(f"{k} {v:.1f}" for k, v in timings.items()
                                                           if k != "total") + ")")
    say(f"  outputs     {out_dir / 'demo.blend'}, {out_dir / 'report.html'}"
        + (f", {out_dir / 'preview.mp4'}" if preview else ""))
    return 0
