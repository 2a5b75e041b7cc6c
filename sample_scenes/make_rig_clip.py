"""Render the embedded sample rig clip with Blender (Cycles on the CPU) -- `make rig-clip`.

What it makes, in ``sample_scenes/rig_clip/``:

- ``clip.mp4``      1280x720, 30 fps: a subject's head with 150 fluorescent-style markers
                    under black light, two plane mirrors beside the cheeks, the camera in front.
                    The subject performs a few seconds of expressions (the generic head's
                    faceunit shape keys, mixed by :mod:`core.headsim`) with a small head motion.
- ``camera.json``   the camera's intrinsics (no lens distortion: Blender's camera is ideal).
- ``truth.npz``     ground truth: ``labels (M,)``, ``points (F, M, 3)`` marker centres in the
                    camera frame in mm, ``pose (F, 3, 4)`` (camera = R q + t for subject-frame q),
                    ``mirror_normals (2, 3)`` and ``mirror_d (2,)`` (n.x = d, mm; mirror 0 is the
                    one imaged on the left), ``marker_vertices (M,)``, ``fps``; the subject's
                    neutral ``subject_vertices (V, 3)`` (the generic head's topology),
                    ``performance_seed`` (the performance is
                    ``core.headsim.performance(generic head, its shape keys, F, fps, seed)``) and
                    ``scan_rotation``, ``scan_translation`` (scan = R subject + t);
                    ``visible (F, 3, M)``: marker seen in the direct view, mirror 0, mirror 1
                    (skin within 73 degrees of facing the view, inside its rectangle, on the
                    panel, the light path clear of the head).
- ``scan.ply``      a scan-like mesh of the subject's neutral face: the front of the head only,
                    subdivided, with 0.15 mm of noise, in its own scanner frame (mm).
- ``rig.json``      the view rectangles: two vertical lines, each where the fewest dots of the
                    clip land in the wrong view (not the mirror panels' edges: the cheeks pass
                    in front of mirrors turned towards the face).
- ``scan_landmarks.json``  the scan's landmarks ``{name: [x, y, z]}``, as a user would click them.

The subject is the generic head with a smooth change of proportions (wider, a longer nose, a
lower chin), so fitting the generic head to the scan has work to do. Frames are rendered to
PNG in ``sample_scenes/.cache/<out folder name>_frames`` (an interrupted run resumes) and encoded to
H.264 by Blender's FFmpeg; the outputs are replaced only once everything is written.

    python sample_scenes/make_rig_clip.py [--frames 120] [--samples 8] [--preview FRAME]

Every property of the rig is an option, so other rigs make stress material
(``sample_scenes/stress/``, ``make stress-clips``): ``--out DIR``, ``--size W H``,
``--focal PX``, ``--markers N``, ``--marker-mm D`` (dot diameter), ``--mirror-deg L`` (the
mirrors' normals at +-L degrees from the optical axis, so the mirror planes sit at 90 - L
degrees to it; ``--mirror-deg L0 L1``: a rig set up by hand, each mirror at its own angle),
``--mirror-tilt T0 T1`` (each mirror's normal tilted from the horizontal, + looking up at the face
from below), ``--distance MM`` (camera to the head's origin), ``--head-offset X Y`` (the head's rest
position off the rig's axis, mm), ``--head-turn RX RY RZ`` (the pitch, yaw and roll the head motion
swings about: a subject turned to one side), ``--head-deg RX RY RZ`` (largest
pitch, yaw and roll of the head motion), ``--tempo T`` (expressions T times as fast and as
frequent), ``--shutter S`` (motion blur: each frame the mean, in linear light, of ``--blur-steps K``
moments spread over the fraction S of the frame interval around its moment; the truth is each dot's mean
position over them), ``--seed``. ``--truth-only`` recomputes an existing clip's truth.npz (same options)
and its rig.json's views without rendering, to add what a newer version records.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import shutil
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

from mirrorcap.core.common.files import write_files_atomically  # noqa: E402
from mirrorcap.core.geometry.camera import Camera  # noqa: E402
from mirrorcap.core.face.head import HeadModel  # noqa: E402
from mirrorcap.core.face.headfit import subdivide  # noqa: E402
from mirrorcap.core.face.headio import load_head_npz  # noqa: E402
from mirrorcap.synthetic.headsim import head_motion, performance, place_markers  # noqa: E402
from mirrorcap.core.capture.rig import ViewLayout  # noqa: E402
from mirrorcap.core.geometry.mirror import reflect_points  # noqa: E402
from mirrorcap.core.geometry.rigid import rotation_zyx  # noqa: E402
from mirrorcap.synthetic.simulate import mirror_plane_from_angles, visibility  # noqa: E402

OUT = HERE / "rig_clip"
FPS = 30
MIRROR_RADIUS_MM = 120.0          # mirrors tangent to a sphere around the face (fig. 6.4)
MIRROR_CENTRE_XY = (0.0, 20.0)    # the sphere's centre; its depth is the head's distance - 90 mm
MARKER_LIFT_MM = 0.5              # how far a dot's centre sits above the skin
VISIBLE_DEG = 73.0                # a marker is "seen" by a view within this angle of its skin normal
IMAGED_DEG = 87.0                 # ...and leaves a blob in the image within this one (where the views split)


# sRGB skin tones for normal-light clips (``--skin``), and the four matte paints of the dots there
SKIN_TONES = {"light": (226, 182, 152), "medium": (176, 124, 92), "dark": (104, 68, 48)}
NORMAL_PAINTS = {"blue": (30, 70, 230), "green": (30, 175, 60), "yellow": (245, 215, 20), "magenta": (215, 30, 160)}


@dataclasses.dataclass(frozen=True)
class ClipSpec:
    """The rig of a rendered clip; the defaults make the embedded sample."""

    image_size: tuple = (1280, 720)
    focal_px: float = 1400.0
    head_distance_mm: float = 650.0      # head-frame origin (between the ears) from the camera
    mirror_longitude_deg: float = 65.0   # each mirror's normal from the optical axis
    mirror1_longitude_deg: float | None = None  # mirror 1's, where the rig is not symmetric (None: the same)
    mirror_tilt_deg: tuple = (0.0, 0.0)  # each mirror's normal tilted from the horizontal (+: looking up at the face)
    head_offset_mm: tuple = (0.0, 0.0)   # the head's rest position off the rig's axis (x right, y down)
    head_turn_deg: tuple = (0.0, 0.0, 0.0)  # the pitch, yaw and roll the head's motion swings about
    marker_radius_mm: float = 1.25       # 2.5 mm dots
    n_markers: int = 150
    head_deg: tuple = (6.0, 6.0, 6.0)    # largest pitch, yaw, roll of the head motion
    tempo: float = 1.0                   # expression speed and frequency
    light: str = "uv"                    # "uv": fluorescent dots under black light; "normal": coloured dots
    skin_rgb: tuple = SKIN_TONES["light"]  # sRGB skin colour under normal light
    shutter: float = 0.0                 # fraction of the frame interval the shutter is open (0: no motion blur)
    blur_steps: int = 6                  # moments rendered and averaged per frame while it is open

    @property
    def mirror_centre(self):
        return (*MIRROR_CENTRE_XY, self.head_distance_mm - 90.0)

    @property
    def paints(self) -> dict:
        return PAINTS if self.light == "uv" else NORMAL_PAINTS
# sRGB colours of the four blacklight paints (core.markers' default classes)
PAINTS = {"pink": (255, 110, 200), "blue-green": (70, 230, 200), "dark-blue": (60, 80, 255),
          "purple": (175, 70, 255)}


def subject_from_generic(head: HeadModel) -> np.ndarray:
    """The subject's neutral vertices: the generic head wider by 5 %, 2 % shorter, with the
    nose 4 mm longer and the chin 3 mm lower (smooth Gaussian bumps)."""
    V = head.vertices * np.array([1.05, 0.98, 1.0])
    lm = head.landmarks()
    for name, move, sigma in (("nose_tip", (0.0, 0.0, -4.0), 14.0), ("chin", (0.0, 3.0, -1.0), 18.0)):
        c = V[lm[name]]
        w = np.exp(-np.sum((V - c) ** 2, axis=1) / (2 * sigma**2))
        V = V + w[:, None] * np.asarray(move)
    return V


def rig_planes(spec: ClipSpec):
    """Mirror 0 (imaged left) then mirror 1, as ``(normal, d)``."""
    right = spec.mirror_longitude_deg if spec.mirror1_longitude_deg is None else spec.mirror1_longitude_deg
    return [mirror_plane_from_angles(longitude, tilt, spec.mirror_centre, MIRROR_RADIUS_MM)
            for longitude, tilt in zip((-spec.mirror_longitude_deg, right), spec.mirror_tilt_deg)]


def rendered_triangles(head: HeadModel) -> np.ndarray:
    """The subject's triangles as rendered: MakeHuman's helper teeth poke through the chin when
    the jaw opens, so they are left out."""
    T = head.triangles()
    return T[np.all(head.skin_mask(("teeth_upper", "teeth_lower"))[T], axis=1)]


def view_rectangles(camera: Camera, planes, points, seen) -> dict:
    """RIG.json's views: two vertical lines through the image, each where the fewest dots land on
    the wrong side over the whole clip -- the direct view's dots ``points`` ``(F, M, 3)`` seen
    directly and each mirror's images of the dots it shows (``seen`` ``(F, 3, M)``, before any
    rectangle test). Within the best stretch the line runs through its middle.

    The mirror panels' imaged inner edges are not the split: with the mirrors turned towards the
    face (45 deg) the cheeks pass in front of the panels, and a line at the panels' edges gave the
    mirror views ~30 % direct-view dots. ``seen`` counts every dot that leaves a blob (up to
    ``IMAGED_DEG`` from its view), since a grazing dot put in the wrong view misleads the tracker as
    much as any other. Where the views overlap (no line clears every dot), the few dots on the
    wrong side count as not seen in truth.npz's ``visible`` (the rectangles decide)."""
    w, h = camera.image_size
    direct_x = camera.project(points[seen[:, 0]])[:, 0]
    bounds = []
    for k, (n, d) in enumerate(planes):
        mirror_x = camera.project(reflect_points(points[seen[:, 1 + k]], n, d))[:, 0]
        bounds.append(_best_split(mirror_x, direct_x) if k == 0 else w - _best_split(w - mirror_x, w - direct_x))
    b0, b1 = (float(np.round(b, 1)) for b in bounds)
    return {"mirror0": [0, 0, b0, h], "direct": [b0, 0, b1, h], "mirror1": [b1, 0, w, h]}


def _best_split(left_x, right_x) -> float:
    """The x that puts the fewest of ``left_x`` at or right of it and of ``right_x`` left of it
    (the middle of the widest such stretch between consecutive values)."""
    x = np.r_[left_x, right_x]
    side = np.r_[np.ones(len(left_x)), np.zeros(len(right_x))]
    order = np.argsort(x, kind="stable")
    x, side = x[order], side[order]
    # a split between sorted positions i and i + 1: the left_x after it plus the right_x up to it
    wrong = ((side.sum() - np.cumsum(side)) + np.cumsum(1 - side))[:-1]
    cand = np.flatnonzero(wrong == wrong.min())
    i = cand[np.argmax(np.diff(x)[cand])]
    return 0.5 * (x[i] + x[i + 1])


def mirror_panels(spec: ClipSpec) -> list:
    """The two mirror panels' corners ``(4, 3)`` (camera frame, mm): from ~190 mm in front of the
    point where each plane touches the sphere around the face to ~45 mm behind it; corners 1 and
    2 are the edge beside the face."""
    panels = []
    for n, d in rig_planes(spec):
        n = np.asarray(n)
        foot = n * d                                      # closest point of the plane to the origin
        tangent = np.cross(n, [0.0, 1.0, 0.0])
        tangent /= np.linalg.norm(tangent)
        if tangent[2] < 0:
            tangent = -tangent                            # along the mirror, away from the camera
        touch = np.asarray(spec.mirror_centre) - n * MIRROR_RADIUS_MM
        along = (touch - foot) @ tangent
        s0, s1 = along - 190.0, along + 45.0
        up = np.array([0.0, 1.0, 0.0]) - n[1] * n            # in the plane (a tilted mirror leans)
        up /= np.linalg.norm(up)
        foot = foot + up * ((touch - foot) @ up - MIRROR_CENTRE_XY[1])  # a tilted panel: as high on the face
        panels.append(np.array([foot + tangent * s + up * h for s, h in ((s0, -150), (s1, -150), (s1, 170), (s0, 170))]))
    return panels


def marker_visibility(camera: Camera, planes, panels, skin_vertices, skin_triangles, centres,
                      normals, max_deg=(VISIBLE_DEG,)) -> np.ndarray:
    """``(A, 3, M)`` bool for one frame, one row per angle of ``max_deg``: marker seen in the direct
    view, mirror 0, mirror 1.

    A marker is seen in a view when its skin faces that view's (real or mirrored) camera within
    the angle (:func:`synthetic.simulate.visibility`), in a mirror the reflection point lies on the
    panel (``panels``, from
    :func:`mirror_panels`), and the light path to the camera misses the head (Blender's BVH ray
    cast: the marker to the mirror and the mirror to the camera; cast once per marker and path, for
    every angle). Camera frame, mm."""
    from mathutils import Vector
    from mathutils.bvhtree import BVHTree

    bvh = BVHTree.FromPolygons(np.asarray(skin_vertices, float).tolist(), np.asarray(skin_triangles).tolist())
    P = np.asarray(centres, float)
    facing = np.stack([visibility(camera, planes, P, normals, grazing_deg=deg) for deg in max_deg])
    out = facing.any(axis=0)                              # the widest angle's candidates, cast once

    def clear(a, b) -> bool:                              # the segment a -> b misses the head
        v = b - a
        dist = float(np.linalg.norm(v))
        return bvh.ray_cast(Vector(a + v / dist * 0.05), Vector(v / dist), dist - 0.1)[0] is None

    origin = np.zeros(3)
    out[0] = [c and clear(p, origin) for c, p in zip(out[0], P)]
    for k, ((n, d), panel) in enumerate(zip(planes, panels)):
        n = np.asarray(n)
        to_eye = reflect_points(origin, n, d) - P         # towards the mirrored camera centre
        s = (d - P @ n) / (to_eye @ n)                    # where the path meets the mirror
        hit = P + s[:, None] * to_eye
        u, w = panel[1] - panel[0], panel[3] - panel[0]
        a, b = (hit - panel[0]) @ u / (u @ u), (hit - panel[0]) @ w / (w @ w)
        out[1 + k] &= (s > 0) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1)
        out[1 + k] = [c and clear(p, h) and clear(h, origin) for c, p, h in zip(out[1 + k], P, hit)]
    return facing & out[None]


def inside_views(camera: Camera, planes, points, layout: ViewLayout) -> np.ndarray:
    """``(F, 3, M)``: each dot's direct image and mirror images inside their own view's rectangle."""
    images = [points, *(reflect_points(points, n, d) for n, d in planes)]
    out = []
    for v, X in enumerate(images):
        px = camera.project(X.reshape(-1, 3)).reshape(*X.shape[:2], 2)
        out.append(layout.assign(px[..., 0], px[..., 1]) == v)
    return np.stack(out, axis=1)


def make_scan(head: HeadModel, subject: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray, dict]:
    """Front-of-face triangles of the subject, subdivided twice, noised and moved into a scanner
    frame; returns vertices, triangles and the landmark positions in that frame."""
    T = head.triangles()
    front = subject[:, 2] < -20.0                    # the face side of the ears
    keep = np.all(front[T] & head.skin_mask()[T], axis=1)
    V, T = subdivide(subject, T[keep], levels=2)
    used = np.unique(T)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(used.size)
    V, T = V[used], remap[T]
    V = V + rng.normal(0.0, 0.15, V.shape)
    ang = np.radians([8.0, -5.0, 3.0])               # the scanner's own frame
    cx, cy, cz = np.cos(ang)
    sx, sy, sz = np.sin(ang)
    R = (np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
         @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]))
    t = np.array([12.0, -40.0, 310.0])
    return V @ R.T + t, T, scan_landmarks(head, subject, R, t), R, t


def scan_landmarks(head: HeadModel, subject: np.ndarray, R, t) -> dict:
    """The scan's landmarks ``{name: [x, y, z]}`` as a user clicks them (where the head defines them; the
    tragi are off the scan), in the scanner's frame ``R p + t``."""
    return {n: (R @ subject[i] + t).round(3).tolist() for n, i in head.landmarks().items() if not n.startswith("tragus")}


def rewrite_scan_landmarks(out: Path) -> int:
    """``--scan-landmarks-only``: an existing clip's scan_landmarks.json from its truth (the subject and
    the scanner's frame) at this version's landmark vertices of the generic head."""
    path, truth = out / "scan_landmarks.json", out / "truth.npz"
    if not path.is_file() or not truth.is_file():
        raise SystemExit(f"{out}: no scan_landmarks.json and truth.npz to rewrite")
    z = np.load(truth)
    head = load_head_npz(ROOT / "sample_scenes" / "generic_head" / "head.npz")
    lms = scan_landmarks(head, z["subject_vertices"].astype(float), z["scan_rotation"], z["scan_translation"])
    write_files_atomically({path: json.dumps(lms, indent=2) + "\n"})
    print(f"{path}: {len(lms)} landmarks rewritten")
    return 0


def ply_bytes(V, T) -> bytes:
    header = (f"ply\nformat binary_little_endian 1.0\ncomment MirrorCap sample scan, millimetres\n"
              f"element vertex {len(V)}\nproperty float x\nproperty float y\nproperty float z\n"
              f"element face {len(T)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    faces = np.zeros(len(T), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"], faces["v"] = 3, T
    return header + np.asarray(V, "<f4").tobytes() + faces.tobytes()


def build_scene(bpy, head: HeadModel, subject, marker_colors, spec: ClipSpec):
    from mirrorcap.addon.common.frames import core_to_blender

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.render.resolution_x, scene.render.resolution_y = spec.image_size
    scene.render.resolution_percentage = 100
    scene.render.fps = FPS
    scene.view_settings.view_transform = "Standard"
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = 2
    scene.cycles.diffuse_bounces = 0
    scene.cycles.glossy_bounces = 1
    scene.cycles.transmission_bounces = 0
    scene.cycles.volume_bounces = 0
    scene.cycles.transparent_max_bounces = 0
    scene.cycles.caustics_reflective = False
    scene.cycles.caustics_refractive = False
    scene.render.threads_mode = "AUTO"
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    scene.world = world

    # camera at the origin looking along core +z (Blender +y), core -y (up) = Blender +z
    cam_data = bpy.data.cameras.new("rig_camera")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.sensor_width = 36.0
    cam_data.lens = spec.focal_px / spec.image_size[0] * 36.0
    cam_data.clip_start = 0.01
    cam = bpy.data.objects.new("rig_camera", cam_data)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam

    def material(name, color=None, emission=None, glossy=False, roughness=None):
        mat = bpy.data.materials.new(name)
        mat.use_nodes = True
        nt = mat.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        if emission is not None:
            node = nt.nodes.new("ShaderNodeEmission")
            node.inputs["Color"].default_value = (*emission, 1.0)
            node.inputs["Strength"].default_value = 1.0
            nt.links.new(node.outputs[0], out.inputs["Surface"])
        elif glossy:
            node = nt.nodes.new("ShaderNodeBsdfGlossy")
            node.inputs["Color"].default_value = (0.92, 0.92, 0.92, 1.0)
            node.inputs["Roughness"].default_value = 0.0
            nt.links.new(node.outputs[0], out.inputs["Surface"])
        elif roughness is not None:                    # normal light: skin sheen and highlights
            node = nt.nodes.new("ShaderNodeBsdfPrincipled")
            node.inputs["Base Color"].default_value = (*color, 1.0)
            node.inputs["Roughness"].default_value = roughness
            nt.links.new(node.outputs[0], out.inputs["Surface"])
        else:
            node = nt.nodes.new("ShaderNodeBsdfDiffuse")
            node.inputs["Color"].default_value = (*color, 1.0)
            nt.links.new(node.outputs[0], out.inputs["Surface"])
        return mat

    # the subject's head (positions are set per frame)
    T = rendered_triangles(head)
    mesh = bpy.data.meshes.new("subject")
    mesh.vertices.add(len(subject))
    mesh.loops.add(T.size)
    mesh.polygons.add(len(T))
    mesh.loops.foreach_set("vertex_index", T.ravel().astype(np.int32))
    mesh.polygons.foreach_set("loop_start", np.arange(0, T.size, 3, dtype=np.int32))
    mesh.polygons.foreach_set("use_smooth", np.ones(len(T), bool))
    mesh.update()
    skin = bpy.data.objects.new("subject", mesh)
    if spec.light == "uv":
        skin.data.materials.append(material("skin_under_blacklight", color=(0.10, 0.07, 0.16)))
    else:
        skin.data.materials.append(material("skin", color=paint_linear(spec.skin_rgb), roughness=0.45))
    scene.collection.objects.link(skin)

    # markers: one mesh of 150 icospheres, one material per paint
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=spec.marker_radius_mm / 1000.0)
    proto = bpy.context.active_object
    unit = np.empty(len(proto.data.vertices) * 3, np.float32)
    proto.data.vertices.foreach_get("co", unit)
    unit = unit.reshape(-1, 3)
    tris = np.array([p.vertices[:] for p in proto.data.polygons], np.int64)
    bpy.data.objects.remove(proto)
    M = len(marker_colors)
    dots = bpy.data.meshes.new("markers")
    dots.vertices.add(M * len(unit))
    allt = (tris[None] + (np.arange(M) * len(unit))[:, None, None]).reshape(-1, 3)
    dots.loops.add(allt.size)
    dots.polygons.add(len(allt))
    dots.loops.foreach_set("vertex_index", allt.ravel().astype(np.int32))
    dots.polygons.foreach_set("loop_start", np.arange(0, allt.size, 3, dtype=np.int32))
    for name, rgb in spec.paints.items():
        if spec.light == "uv":
            dots.materials.append(material(f"paint_{name}", emission=paint_linear(rgb)))
        else:
            dots.materials.append(material(f"paint_{name}", color=paint_linear(rgb), roughness=0.7))
    dots.polygons.foreach_set("material_index", np.repeat(np.asarray(marker_colors, np.int32), len(tris)))
    dots.polygons.foreach_set("use_smooth", np.ones(len(allt), bool))
    dots.update()
    markers = bpy.data.objects.new("markers", dots)
    scene.collection.objects.link(markers)

    # the mirrors: finite panels beside the cheeks
    for k, corners in enumerate(mirror_panels(spec)):
        pm = bpy.data.meshes.new(f"mirror{k}")
        pm.from_pydata(core_to_blender(corners).tolist(), [], [(0, 1, 2, 3)])
        pm.materials.append(material(f"mirror{k}_glass", glossy=True))
        mo = bpy.data.objects.new(f"mirror{k}", pm)
        scene.collection.objects.link(mo)

    if spec.light == "normal":
        add_studio_lights(bpy, scene)
        return scene, skin, markers, unit
    # a dim black-light lamp above the camera: skin faintly visible, far below the marker threshold
    lamp = bpy.data.lights.new("blacklight", "AREA")
    lamp.energy = 0.35
    lamp.size = 0.4
    lamp.color = (0.55, 0.35, 1.0)
    lo = bpy.data.objects.new("blacklight", lamp)
    lo.location = core_to_blender(np.array([0.0, -250.0, 100.0]))
    lo.rotation_euler = (np.pi / 2 - 0.45, 0.0, 0.0)
    lo.visible_glossy = False                         # no lamp reflection in the mirrors
    scene.collection.objects.link(lo)
    return scene, skin, markers, unit


def add_studio_lights(bpy, scene):
    """Normal light: a grey room, a soft key light above and left of the camera, a dimmer fill
    on the right (shading across the face and highlights on the skin); the lamps themselves are not
    seen in the mirrors."""
    from mirrorcap.addon.common.frames import core_to_blender

    scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.03, 0.03, 0.03, 1.0)
    scene.cycles.diffuse_bounces = 1
    for name, xyz, energy, size in (("key", (-250.0, -300.0, 150.0), 5.0, 0.5),
                                    ("fill", (300.0, -50.0, 200.0), 2.0, 0.6)):
        lamp = bpy.data.lights.new(name, "AREA")
        lamp.energy = energy
        lamp.size = size
        lo = bpy.data.objects.new(name, lamp)
        lo.location = core_to_blender(np.array(xyz))
        target = core_to_blender(np.array([0.0, 0.0, 650.0]))
        direction = target - np.asarray(lo.location)
        lo.rotation_euler = _look_rotation(direction)
        lo.visible_glossy = False
        scene.collection.objects.link(lo)


def _look_rotation(direction):
    """An Euler rotation that turns a light's -z axis along ``direction`` (Blender frame)."""
    from mathutils import Vector

    return Vector(direction).to_track_quat("-Z", "Y").to_euler()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--samples", type=int, default=8)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--preview", type=int, help="render only this frame to sample_scenes/.cache/preview.png")
    ap.add_argument("--out", type=Path, default=OUT, help="folder to write (default sample_scenes/rig_clip)")
    ap.add_argument("--size", type=int, nargs=2, metavar=("W", "H"), default=ClipSpec.image_size)
    ap.add_argument("--focal", type=float, default=ClipSpec.focal_px, help="focal length in pixels")
    ap.add_argument("--markers", type=int, default=ClipSpec.n_markers)
    ap.add_argument("--marker-mm", type=float, default=2 * ClipSpec.marker_radius_mm, help="dot diameter")
    ap.add_argument("--mirror-deg", type=float, nargs="+", metavar="DEG", default=[ClipSpec.mirror_longitude_deg],
                    help="each mirror's normal from the optical axis (the plane is at 90 - this); two values: "
                         "mirror 0's (imaged left), then mirror 1's")
    ap.add_argument("--mirror-tilt", type=float, nargs=2, metavar=("DEG0", "DEG1"), default=ClipSpec.mirror_tilt_deg,
                    help="each mirror's normal tilted from the horizontal (+: the mirror looks up at the face "
                         "from below)")
    ap.add_argument("--head-offset", type=float, nargs=2, metavar=("X", "Y"), default=ClipSpec.head_offset_mm,
                    help="the head's rest position off the rig's axis, mm (x right, y down)")
    ap.add_argument("--head-turn", type=float, nargs=3, metavar=("RX", "RY", "RZ"), default=ClipSpec.head_turn_deg,
                    help="the pitch, yaw and roll the head motion swings about (a subject turned to one side)")
    ap.add_argument("--distance", type=float, default=ClipSpec.head_distance_mm, help="camera to head, mm")
    ap.add_argument("--head-deg", type=float, nargs=3, metavar=("RX", "RY", "RZ"), default=ClipSpec.head_deg,
                    help="largest pitch, yaw, roll of the head motion")
    ap.add_argument("--tempo", type=float, default=ClipSpec.tempo, help="expressions this many times as fast")
    ap.add_argument("--light", choices=("uv", "normal"), default="uv",
                    help="uv: fluorescent dots under black light; normal: matte coloured dots under studio light")
    ap.add_argument("--skin", default="light",
                    help=f"skin under normal light: {', '.join(SKIN_TONES)} or R,G,B (sRGB 0-255)")
    ap.add_argument("--shutter", type=float, default=ClipSpec.shutter,
                    help="motion blur: the fraction of each frame's interval the shutter is open (0.5: 1/60 s "
                         "at 30 frames/s), rendered as --blur-steps moments averaged in linear light; 0: none")
    ap.add_argument("--blur-steps", type=int, default=ClipSpec.blur_steps,
                    help="moments rendered per frame while the shutter is open (each with --samples)")
    ap.add_argument("--no-scan", action="store_true", help="write no scan.ply / scan_landmarks.json")
    ap.add_argument("--truth-only", action="store_true",
                    help="render nothing: recompute the truth of an existing clip made with the same options "
                         "(checked against its truth.npz) and add what this version records (visibility, rig.json's views)")
    ap.add_argument("--scan-landmarks-only", action="store_true",
                    help="render nothing: rewrite an existing clip's scan_landmarks.json at the generic head's "
                         "current landmark vertices (from the clip's truth.npz)")
    args = ap.parse_args(argv)
    if args.scan_landmarks_only:
        return rewrite_scan_landmarks(args.out.resolve())
    if len(args.mirror_deg) > 2:
        ap.error("--mirror-deg takes one angle (both mirrors) or two (mirror 0's, mirror 1's)")
    spec = ClipSpec(image_size=tuple(args.size), focal_px=args.focal, head_distance_mm=args.distance,
                    mirror_longitude_deg=args.mirror_deg[0],
                    mirror1_longitude_deg=args.mirror_deg[1] if len(args.mirror_deg) == 2 else None,
                    mirror_tilt_deg=tuple(args.mirror_tilt), head_offset_mm=tuple(args.head_offset),
                    head_turn_deg=tuple(args.head_turn), marker_radius_mm=args.marker_mm / 2,
                    n_markers=args.markers, head_deg=tuple(args.head_deg), tempo=args.tempo,
                    light=args.light, skin_rgb=skin_colour(args.skin), shutter=args.shutter,
                    blur_steps=args.blur_steps)
    if not 0 <= spec.shutter <= 1 or spec.blur_steps < 2:
        ap.error("--shutter takes a fraction of the frame interval in [0, 1], --blur-steps at least 2")
    out = args.out.resolve()
    cache = HERE / ".cache" / f"{out.name}_frames"

    import bpy
    import cv2

    from mirrorcap.addon.common.frames import core_to_blender
    from mirrorcap.addon.common.video_out import h264_output

    head, keys = load_head_npz(ROOT / "sample_scenes" / "generic_head" / "head.npz", with_shape_keys=True)
    rng = np.random.default_rng(args.seed)
    subject = subject_from_generic(head)
    sub_head = dataclasses.replace(head, vertices=subject, name="subject")
    verts, labels = place_markers(sub_head, spec.n_markers, seed=args.seed)
    disp, _ = performance(head, keys, args.frames, FPS, seed=args.seed, tempo=spec.tempo)
    R, t = head_pose(spec, args.frames, args.seed)
    marker_colors = np.arange(len(verts)) % len(spec.paints)
    rng.shuffle(marker_colors)

    camera = Camera.ideal(spec.focal_px, spec.image_size)
    planes, panels = rig_planes(spec), mirror_panels(spec)
    skin_T = rendered_triangles(head)
    if not args.truth_only:
        scene, skin, markers, unit = build_scene(bpy, head, subject, marker_colors, spec)
        scene.cycles.samples = args.samples
        cache.mkdir(parents=True, exist_ok=True)
    frames = [args.preview] if args.preview is not None else [] if args.truth_only else range(args.frames)
    points = np.empty((args.frames, len(verts), 3))
    visible = np.zeros((args.frames, 3, len(verts)), bool)
    imaged = np.zeros_like(visible)                     # any dot not edge-on or hidden: the detector finds it
    t0 = time.perf_counter()

    def placed(q, R_f, t_f):
        """The skin's vertices, the dots' centres and their normals in the camera frame."""
        normals = sub_head.vertex_normals(q)
        centre_q = q[verts] + MARKER_LIFT_MM * normals[verts]
        return q @ R_f.T + t_f, centre_q @ R_f.T + t_f, normals[verts] @ R_f.T

    def render(png, cam_v, dots_at):
        skin.data.vertices.foreach_set("co", core_to_blender(cam_v).astype(np.float32).ravel())
        skin.data.update()
        dots = (core_to_blender(dots_at)[:, None, :] + unit[None]).reshape(-1, 3)
        markers.data.vertices.foreach_set("co", dots.astype(np.float32).ravel())
        markers.data.update()
        scene.render.filepath = str(png)
        bpy.ops.render.render(write_still=True)

    for f in range(args.frames):
        cam_v, points[f], dot_normals = placed(subject + disp[f], R[f], t[f])
        if args.preview is None:
            visible[f], imaged[f] = marker_visibility(camera, planes, panels, cam_v, skin_T, points[f],
                                                      dot_normals, max_deg=(VISIBLE_DEG, IMAGED_DEG))
        if spec.shutter > 0:  # the shutter open around the frame's moment: the dots' smear, centred on their mean
            at = f + spec.shutter * ((np.arange(spec.blur_steps) + 0.5) / spec.blur_steps - 0.5)
            sub_disp, _ = performance(head, keys, args.frames, FPS, seed=args.seed, tempo=spec.tempo, at=at)
            sub_R, sub_t = head_pose(spec, args.frames, args.seed, at=at)
            moments = [placed(subject + d, r, tt)[:2] for d, r, tt in zip(sub_disp, sub_R, sub_t)]
            points[f] = np.mean([dots_at for _, dots_at in moments], axis=0)
        if f not in frames:
            continue
        png = cache / f"frame_{f:04d}.png" if args.preview is None else HERE / ".cache" / "preview.png"
        if png.is_file() and args.preview is None:
            continue
        scene.render.image_settings.file_format = "PNG"
        if spec.shutter <= 0:
            render(png, cam_v, points[f])
        else:
            scene.render.image_settings.color_depth = "16"
            open_png = png.with_name(png.stem + "_open.png")
            light = 0.0
            for moment_v, dots_at in moments:
                render(open_png, moment_v, dots_at)
                light = light + srgb_to_linear(cv2.imread(str(open_png), cv2.IMREAD_UNCHANGED) / 65535.0)
            cv2.imwrite(str(png), np.round(linear_to_srgb(light / len(moments)) * 255).astype(np.uint8))
            open_png.unlink()
        done = f + 1
        print(f"frame {done}/{args.frames}  {time.perf_counter() - t0:.0f} s", flush=True)
    if args.preview is not None:
        return 0
    views = view_rectangles(camera, planes, points, imaged)
    visible &= inside_views(camera, planes, points, ViewLayout(regions=views))
    if args.truth_only:
        return rewrite_truth(out, points, visible, views)

    # encode the PNGs to H.264 with Blender's FFmpeg through the sequencer
    tmp_dir = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp_dir, ignore_errors=True)
    tmp_dir.mkdir(parents=True)
    enc = bpy.data.scenes.new("encode")
    enc.render.resolution_x, enc.render.resolution_y = spec.image_size
    enc.render.resolution_percentage = 100
    enc.render.fps = FPS
    enc.frame_start, enc.frame_end = 1, args.frames
    enc.view_settings.view_transform = "Standard"
    seq = enc.sequence_editor_create()
    strips = seq.strips if hasattr(seq, "strips") else seq.sequences
    strip = strips.new_image("frames", str(cache / "frame_0000.png"), channel=1, frame_start=1)
    for f in range(1, args.frames):
        strip.elements.append(f"frame_{f:04d}.png")
    h264_output(enc.render, tmp_dir / "clip.mp4", "PERC_LOSSLESS", gop_size=FPS)
    with bpy.context.temp_override(scene=enc):
        bpy.ops.render.render(animation=True, scene=enc.name)
    rig = {"views": views}
    scan_V, scan_T, scan_lms, scan_R, scan_t = make_scan(head, subject, rng)
    truth_npz = npz_bytes(labels=np.array(labels), points=points.astype(np.float32),
                          pose=np.concatenate([R, t[:, :, None]], axis=2), marker_vertices=verts,
                          marker_colors=marker_colors, mirror_normals=np.array([p[0] for p in planes]),
                          mirror_d=np.array([p[1] for p in planes]), fps=np.float64(FPS),
                          subject_vertices=subject.astype(np.float32), performance_seed=np.int64(args.seed),
                          scan_rotation=scan_R, scan_translation=scan_t, visible=visible)
    info = {"frames": args.frames, "fps": FPS, "markers": len(verts), "samples_per_pixel": args.samples,
            "image_size": list(spec.image_size), "focal_px": spec.focal_px,
            "head_distance_mm": spec.head_distance_mm, "mirror_longitude_deg": spec.mirror_longitude_deg,
            **({"mirror1_longitude_deg": spec.mirror1_longitude_deg} if spec.mirror1_longitude_deg is not None else {}),
            **({"mirror_tilt_deg": list(spec.mirror_tilt_deg)} if any(spec.mirror_tilt_deg) else {}),
            **({"head_offset_mm": list(spec.head_offset_mm)} if any(spec.head_offset_mm) else {}),
            **({"head_turn_deg": list(spec.head_turn_deg)} if any(spec.head_turn_deg) else {}),
            "marker_diameter_mm": 2 * spec.marker_radius_mm, "head_deg": list(spec.head_deg), "tempo": spec.tempo,
            **({"shutter": spec.shutter, "blur_steps": spec.blur_steps} if spec.shutter > 0 else {}),
            "seed": args.seed, "light": spec.light, "paints": spec.paints,
            **({"skin_rgb": list(spec.skin_rgb)} if spec.light == "normal" else {}), "made_by": "sample_scenes/make_rig_clip.py"}
    out.mkdir(parents=True, exist_ok=True)
    files = {
        out / "clip.mp4": (tmp_dir / "clip.mp4").read_bytes(),
        out / "camera.json": json.dumps(camera.to_dict(), indent=2) + "\n",
        out / "truth.npz": truth_npz,
        out / "clip.json": json.dumps(info, indent=2) + "\n",
        out / "rig.json": json.dumps(rig, indent=2) + "\n",
    }
    if not args.no_scan:
        files[out / "scan.ply"] = ply_bytes(scan_V, scan_T)
        files[out / "scan_landmarks.json"] = json.dumps(scan_lms, indent=2) + "\n"
    write_files_atomically(files)
    shutil.rmtree(tmp_dir, ignore_errors=True)
    size = (out / "clip.mp4").stat().st_size
    print(f"{out / 'clip.mp4'}: {size / 1e6:.2f} MB, {args.frames} frames; truth, scan and camera beside it")
    return 0


def head_pose(spec: ClipSpec, n_frames: int, seed: int, at=None):
    """The head's pose ``R (F, 3, 3)``, ``t (F, 3)`` at each frame (or at the frame numbers
    ``at``, fractions allowed): the performance's motion about the spec's turn and offset."""
    R, t = head_motion(n_frames, FPS, max_deg=spec.head_deg, seed=seed, at=at)
    if any(spec.head_turn_deg):
        R = rotation_zyx(np.radians(spec.head_turn_deg)) @ R        # the motion swings about a turned head
    return R, t + np.array([*spec.head_offset_mm, spec.head_distance_mm])


def srgb_to_linear(c):
    """sRGB-encoded values in [0, 1] -> linear light (IEC 61966-2-1)."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def paint_linear(rgb) -> list:
    """An sRGB colour (0-255) as the linear RGB a material takes."""
    return srgb_to_linear(np.asarray(rgb, float) / 255.0).tolist()


def linear_to_srgb(c):
    """Linear light in [0, 1] -> sRGB-encoded values."""
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def skin_colour(text: str) -> tuple:
    if text in SKIN_TONES:
        return SKIN_TONES[text]
    try:
        rgb = tuple(int(c) for c in text.split(","))
    except ValueError:
        rgb = ()
    if len(rgb) != 3 or not all(0 <= c <= 255 for c in rgb):
        raise SystemExit(f"--skin {text!r}: give one of {', '.join(SKIN_TONES)} or R,G,B with 0-255 values")
    return rgb


def npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def rewrite_truth(out: Path, points, visible, views) -> int:
    """``--truth-only``: the existing clip's truth.npz with this version's ``visible`` added and
    its rig.json with this version's views, after checking that the same options give the same
    marker positions."""
    path = out / "truth.npz"
    if not path.is_file():
        raise SystemExit(f"{path}: no such file (render the clip first)")
    old = dict(np.load(path))
    err = float(np.max(np.abs(old["points"] - points.astype(np.float32))))
    if old["points"].shape != points.shape or err > 1e-3:
        raise SystemExit(f"{path}: these options do not reproduce the clip's markers "
                         f"(shape {old['points'].shape} vs {points.shape}, max difference {err:.4g} mm)")
    old["visible"] = visible
    rig_path = out / "rig.json"
    rig = json.loads(rig_path.read_text()) if rig_path.is_file() else {}
    if rig.get("views") != views:
        print(f"{rig_path}: views {rig.get('views')} -> {views}")
    rig["views"] = views
    write_files_atomically({path: npz_bytes(**old), rig_path: json.dumps(rig, indent=2) + "\n"})
    seen = visible[:, 0] & (visible[:, 1] | visible[:, 2])
    print(f"{path}: visibility added; {seen.mean():.1%} of marker-frames seen in the direct view and a mirror")
    return 0


if __name__ == "__main__":
    sys.exit(main())
