"""Baking in Blender, checked by reading the written .blend back with bpy in a fresh process
(not from the core's arrays): bound vertices follow their markers, the PCA mode reproduces a
faceunit performance, the operator works from a script, and bad input writes nothing."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT

from mirrorcap.core.face.bind import bind_take
from mirrorcap.core.take.c3d import write_c3d
from mirrorcap.core.face.headio import load_head_npz
from mirrorcap.synthetic.headsim import performance, synthetic_take

HEAD_BLEND = ROOT / "sample_scenes" / "generic_head" / "head.blend"
HEAD_NPZ = ROOT / "sample_scenes" / "generic_head" / "head.npz"
READBACK = ROOT / "tests" / "blender" / "readback.py"
TURN_HEAD = ROOT / "tests" / "blender" / "turn_head.py"


def _run(args, **kw):
    env = dict(os.environ, **kw.pop("env", {}))
    return subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True, timeout=600, env=env,
                          cwd=ROOT, **kw)


def _readback(blend, tmp_path, obj="GenericHead"):
    out = tmp_path / f"{os.path.basename(blend)}.readback.npz"       # np.load reads lazily: one file per blend
    res = _run([READBACK, blend, obj, out])
    assert res.returncode == 0, res.stdout + res.stderr
    return np.load(out)


def _to_core(p):
    p = np.asarray(p, float)
    return 1000.0 * np.stack([p[..., 0], -p[..., 2], p[..., 1]], -1)


@pytest.fixture(scope="module")
def head_and_keys():
    return load_head_npz(HEAD_NPZ, with_shape_keys=True)


def test_bake_frames_bound_vertices_follow_their_markers(tmp_path, head_and_keys):
    head, keys = head_and_keys
    labels, pts, verts, disp, pose = synthetic_take(head, keys, n_markers=150, n_frames=48, seed=6)
    pts[20:23, 40] = np.nan                                        # a gap the bake fills
    take = tmp_path / "take.c3d"
    write_c3d(take, labels, pts, 24.0)
    out = tmp_path / "out.blend"
    import json

    (tmp_path / "report.json").write_text(json.dumps({"head_pose": pose.tolist()}))
    res = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", out, "--report", tmp_path / "bake.json",
                "--head-pose", tmp_path / "report.json"])
    assert res.returncode == 0, res.stdout + res.stderr
    assert "baked 48 frames" in res.stdout
    rb = _readback(out, tmp_path)
    values = rb["values"]
    assert values.shape == (48, 48) and int(rb["fps"]) == 24
    assert np.array_equal(values, np.eye(48))                     # exactly that frame's key is 1
    basis = _to_core(rb["basis"])
    assert np.abs(basis - head.vertices).max() < 1e-3
    baked = _to_core(rb["keys"]) - basis[None]                    # (F, V, 3) displacements in the file
    binding = bind_take(head, labels, pts, head_pose=pose)        # the markers, placed on the head
    err = np.linalg.norm(baked[:, binding.vertices] - binding.displacements, axis=2)
    assert err.max() < 0.05
    assert np.array_equal(binding.vertices, verts)
    # and the performance's truth, where no gap was filled
    ok = ~binding.filled
    assert np.linalg.norm(baked[:, verts] - disp[:, verts], axis=2)[ok].max() < 0.01
    # what a user sees: the evaluated mesh at every keyed frame (every other shape key of the head at 0)
    seen = _to_core(rb["evaluated"]) - basis[None]
    assert np.linalg.norm(seen[:, binding.vertices] - binding.displacements, axis=2).max() < 0.05
    assert np.linalg.norm(seen[:, verts] - disp[:, verts], axis=2)[ok].max() < 0.01
    assert np.linalg.norm(seen - baked, axis=2).max() < 0.01


@pytest.mark.parametrize("by, parented", [("landmarks", False), ("surface", False), ("landmarks", True)])
def test_bake_onto_a_head_imported_in_centimetres_and_y_up(tmp_path, head_and_keys, by, parented):
    """A head whose own frame is not Blender's -- its data in centimetres and Y-up, the object scaled 0.01, turned
    90° about X and standing away from the origin, as an FBX import leaves it (tests/blender/turn_head.py) -- bakes
    to what the same head gives untouched: the evaluated meshes in world space agree at every keyed frame, the
    head motion included, registered by landmark labels or by the skin. (Read in its own frame it was a 17 m head
    lying on its back: the skin registration refused the take, 217 mm RMS, and the landmarks scaled the take onto
    it.) ``parented``: the head is also parented to a turned and moved empty, as a character's meshes are to its
    armature; the head motion is then keyed in the parent's frame."""
    head, keys = head_and_keys
    labels, pts, *_ = synthetic_take(head, keys, n_markers=150, n_frames=24, seed=8)
    if by == "surface":
        labels = [f"m{i:03d}" for i in range(len(labels))]          # no landmark labels: bound by the skin
    take = tmp_path / "take.c3d"
    write_c3d(take, labels, pts, 24.0)
    turned = tmp_path / "turned.blend"
    res = _run([TURN_HEAD, HEAD_BLEND, turned, *(["--parent"] if parented else [])])
    assert res.returncode == 0, res.stdout + res.stderr
    world = {}
    for name, head_blend in (("plain", HEAD_BLEND), ("turned", turned)):
        out = tmp_path / f"{name}.blend"
        res = _run(["-m", "mirrorcap", "bake", take, "--head", head_blend, "-o", out, "--head-motion"])
        assert res.returncode == 0, res.stdout + res.stderr
        world[name] = _readback(out, tmp_path)["world"]                 # metres
    face = np.linalg.norm(world["plain"] - world["plain"][:1], axis=2)
    assert face.max() > 2e-3                                          # the face and the head move
    placed = np.array([0.3, -0.2, 1.6])                               # where turn_head.py stands the head
    assert np.abs(world["turned"] - placed - world["plain"]).max() < 1e-5   # 0.01 mm, at every frame


@pytest.mark.parametrize("rate", [29.97, 59.94, 25.0])
def test_bake_plays_at_the_takes_rate_exactly(tmp_path, head_and_keys, rate):
    """A take at a camera's NTSC rate plays at that rate in Blender (fps / fps_base), not rounded to 30 or 60:
    rounded, the animation ran 0.1 % fast and drifted from the take's sound by 60 ms a minute."""
    head, keys = head_and_keys
    labels, pts, *_ = synthetic_take(head, keys, n_markers=120, n_frames=6, seed=4)
    take = tmp_path / "take.c3d"
    write_c3d(take, labels, pts, rate)
    out = tmp_path / "out.blend"
    res = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", out])
    assert res.returncode == 0, res.stdout + res.stderr
    rb = _readback(out, tmp_path)
    assert abs(float(rb["rate"]) - rate) < 1e-4 and int(rb["fps"]) == int(np.ceil(rate))


def test_bake_pca_reproduces_a_faceunit_performance_with_eight_modes(tmp_path, head_and_keys):
    head, keys = head_and_keys
    D, _ = performance(head, keys, 120, fps=30.0, seed=3)
    np.save(tmp_path / "perf.npy", D)
    code = (
        "import sys, json, numpy as np, bpy\n"
        "from mirrorcap.addon.common.headio import open_blend, find_head_object, read_head, save_blend_atomically\n"
        "from mirrorcap.addon.common.shape_keys import bake_displacements\n"
        f"open_blend({str(HEAD_BLEND)!r})\n"
        "obj = find_head_object(None)\n"
        "head = read_head(obj)\n"
        f"D = np.load({str(tmp_path / 'perf.npy')!r})\n"
        "out = bake_displacements(obj, head.vertices, D, 'pca', 8)\n"
        f"save_blend_atomically({str(tmp_path / 'pca.blend')!r})\n"
        "print(json.dumps({k: out[k] for k in ('pca_max_error_mm', 'pca_mean_error_mm')}))\n"
    )
    res = _run(["-c", code])
    assert res.returncode == 0, res.stdout + res.stderr
    rb = _readback(tmp_path / "pca.blend", tmp_path)
    assert list(rb["names"]) == [f"mode_{k:02d}" for k in range(1, 9)]
    basis = _to_core(rb["basis"])
    modes = _to_core(rb["keys"]) - basis[None]
    rec = np.einsum("fk,kvd->fvd", rb["values"], modes)
    assert np.linalg.norm(_to_core(rb["evaluated"]) - basis[None] - rec, axis=2).max() < 0.01  # what a user sees
    err = np.linalg.norm(rec - D, axis=2)
    assert err.max() < 0.5
    assert err.max() > 0 or np.abs(D).max() == 0


def test_bake_operator_from_a_script_and_its_error_report(tmp_path, head_and_keys):
    head, keys = head_and_keys
    labels, pts, *_ = synthetic_take(head, keys, n_markers=100, n_frames=20, seed=7)
    write_c3d(tmp_path / "t.c3d", labels, pts, 30.0)
    code = (
        "import bpy, mirrorcap\n"
        "mirrorcap.register()\n"
        f"bpy.ops.wm.open_mainfile(filepath={str(HEAD_BLEND)!r})\n"
        "obj = bpy.data.objects['GenericHead']\n"
        "bpy.context.view_layer.objects.active = obj\n"
        f"r = bpy.ops.mirrorcap.bake(take={str(tmp_path / 't.c3d')!r}, mode='pca', modes=4)\n"
        "assert r == {'FINISHED'}, r\n"
        "names = [k.name for k in obj.data.shape_keys.key_blocks if k.name.startswith('mode_')]\n"
        "assert names == ['mode_01', 'mode_02', 'mode_03', 'mode_04'], names\n"
        "try:\n"
        f"    bpy.ops.mirrorcap.bake(take={str(tmp_path / 'missing.c3d')!r})\n"
        "except RuntimeError as e:\n"
        "    print('REPORTED', str(e).strip().splitlines()[-1])\n"
        "print('ok')\n"
    )
    res = _run(["-c", code])
    assert res.returncode == 0, res.stdout + res.stderr
    assert "ok" in res.stdout
    assert "REPORTED" in res.stdout and "does not exist" in res.stdout


def _make_plain_blend(path):
    code = (
        "import bpy\n"
        "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
        "bpy.ops.mesh.primitive_cube_add()\n"
        f"bpy.ops.wm.save_as_mainfile(filepath={str(path)!r})\n"
    )
    res = _run(["-c", code])
    assert res.returncode == 0, res.stderr


def test_bake_bad_input_fails_with_one_message_and_writes_nothing(tmp_path, head_and_keys):
    head, keys = head_and_keys
    labels, pts, *_ = synthetic_take(head, keys, n_markers=60, n_frames=10, seed=8)
    good = tmp_path / "good.c3d"
    write_c3d(good, labels, pts, 30.0)
    anon = tmp_path / "anon.c3d"
    write_c3d(anon, [f"x{i}" for i in range(5)], pts[:, :5], 30.0)
    holey_pts = pts.copy()
    holey_pts[0, 30] = np.nan
    holey = tmp_path / "holey.c3d"
    write_c3d(holey, labels, holey_pts, 30.0)
    plain = tmp_path / "plain.blend"
    _make_plain_blend(plain)
    (tmp_path / "junk.c3d").write_bytes(b"not a take" * 100)
    cases = [
        ([good, "--head", plain], "no mesh with region_"),
        ([anon, "--head", HEAD_BLEND], "too few to register"),
        ([holey, "--head", HEAD_BLEND, "--refuse-unseen"], "marker count changes"),
        ([tmp_path / "junk.c3d", "--head", HEAD_BLEND], "not a C3D file"),
        ([good, "--head", tmp_path / "nope.blend"], "does not exist"),
        ([good, "--head", HEAD_BLEND, "--mode", "pca", "--modes", "50"], "--modes must be between 1"),
    ]
    for args, message in cases:
        out = tmp_path / "out.blend"
        res = _run(["-m", "mirrorcap", "bake", *args, "-o", out])
        assert res.returncode == 2, (args, res.stdout, res.stderr)
        errors = [ln for ln in res.stderr.splitlines() if ln.startswith("mirrorcap: error:")]
        assert len(errors) == 1 and message in errors[0], (message, res.stderr)
        assert "Traceback" not in res.stderr
        assert not out.exists()
        assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_a_stretch_of_a_take_baked_at_a_pipelines_start_frame(tmp_path, head_and_keys):
    """`--frames 22:50 --frame-start 1001`: the stretch is keyed at scene frames 1001..1028 (the scene's range
    set to them), and what a user sees there -- the evaluated mesh in world space, head motion and blinks
    included -- is what a bake of the whole take shows at its frames 23..50. The neutral frame (0) lies outside
    the stretch. Bad ranges and start frames are refused before any work, and nothing is written."""
    import json

    head, keys = head_and_keys
    labels, pts, *_ = synthetic_take(head, keys, n_markers=140, n_frames=60, seed=11)
    take = tmp_path / "take.c3d"
    write_c3d(take, labels, pts, 24.0)
    common = ["--head-motion", "--blink-interval", "0.4"]        # a blink or more inside the stretch
    whole = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", tmp_path / "whole.blend", *common])
    assert whole.returncode == 0, whole.stdout + whole.stderr
    part = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", tmp_path / "part.blend", *common,
                 "--frames", "22:50", "--frame-start", "1001", "--report", tmp_path / "bake.json"])
    assert part.returncode == 0, part.stdout + part.stderr
    assert "baked 28 frames (22:50)" in part.stdout and "scene frames 1001-1028" in part.stdout
    report = json.loads((tmp_path / "bake.json").read_text())
    assert report["take_frames"] == [22, 50] and report["frame_start"] == 1001 and report["blink_frames"] > 0
    rb_whole, rb_part = _readback(tmp_path / "whole.blend", tmp_path), _readback(tmp_path / "part.blend", tmp_path)
    assert list(rb_part["frames"]) == list(range(1001, 1029)) and list(rb_whole["frames"]) == list(range(1, 61))
    assert np.array_equal(rb_part["values"], np.eye(28))          # frame_00001 is 1 at 1001 only, and so on
    seen_whole, seen_part = rb_whole["world"][22:50], rb_part["world"]
    assert np.linalg.norm(seen_whole - seen_whole[:1], axis=2).max() > 2e-3     # the stretch moves
    assert np.abs(seen_part - seen_whole).max() < 1e-6            # 1 micrometre, at every keyed frame
    for bad, message in ((["--frames", "50:70"], "is not a stretch of the take's 60 frames"),
                         (["--frames", "30:20"], "is empty"),
                         (["--frame-start", "-5"], "starts at frame 0 or later"),
                         (["--frame-start", "1048570"], "must lie within Blender's frames")):
        res = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", tmp_path / "bad.blend", *bad])
        assert res.returncode == 2 and message in res.stderr, (bad, res.stdout + res.stderr)
    assert not (tmp_path / "bad.blend").exists()


def test_a_long_frames_mode_bake_warns_of_its_size(tmp_path, head_and_keys):
    """A frames-mode bake of more than FRAMES_MODE_WARNING frames (5,000; 10 here) says what its one shape key a
    frame will cost, and the ways out; a PCA bake of as many frames does not."""
    head, keys = head_and_keys
    labels, pts, *_ = synthetic_take(head, keys, n_markers=120, n_frames=12, seed=2)
    write_c3d(tmp_path / "take.c3d", labels, pts, 24.0)
    code = ("import json, sys\n"
            "from mirrorcap.addon.bake import bake\n"
            "bake.FRAMES_MODE_WARNING = 10\n"
            "for mode in ('frames', 'pca'):\n"
            f"    r = bake.run_bake({str(tmp_path / 'take.c3d')!r}, {str(HEAD_BLEND)!r}, {str(tmp_path / 'o.blend')!r}, "
            "mode=mode, n_modes=4)\n"
            "    print('RESULT', json.dumps(r['warnings']))\n")
    res = _run(["-c", code])
    assert res.returncode == 0, res.stdout + res.stderr
    frames, pca = [__import__("json").loads(ln.split("RESULT ", 1)[1]) for ln in res.stdout.splitlines()
                   if ln.startswith("RESULT ")]
    assert pca == [] and len(frames) == 1
    assert frames[0].startswith("12 frames as one shape key each: about 1 MB") and "--mode pca" in frames[0]


def test_bake_places_markers_first_seen_later_by_default(tmp_path, head_and_keys):
    """A tracker's markers first seen after the neutral frame are bound from a conjectured neutral position
    (BAKE.json lists them), by default as in the add-on (before: the command refused such a take unless given
    `--conjecture-unseen`, which still says the same); `--refuse-unseen` refuses it and names the ways out."""
    import json

    head, keys = head_and_keys
    labels, pts, *_ = synthetic_take(head, keys, n_markers=120, n_frames=40, seed=7)
    late = [i for i, name in enumerate(labels) if not name.startswith("lm_")][:3]
    pts[:5, late] = np.nan
    take = tmp_path / "take.c3d"
    write_c3d(take, labels, pts, 24.0)
    refused = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", tmp_path / "no.blend",
                    "--refuse-unseen"])
    assert refused.returncode == 2 and "marker count changes" in refused.stderr
    assert "--conjecture-unseen" in refused.stderr and "--drop-unseen" in refused.stderr   # the two ways out named
    both = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", tmp_path / "no.blend",
                 "--drop-unseen", "--conjecture-unseen"])
    assert both.returncode == 2 and "not allowed with" in both.stderr
    reports = []
    for flag in ([], ["--conjecture-unseen"]):
        res = _run(["-m", "mirrorcap", "bake", take, "--head", HEAD_BLEND, "-o", tmp_path / "out.blend", *flag,
                    "--report", tmp_path / "bake.json"])
        assert res.returncode == 0, res.stdout + res.stderr
        reports.append(json.loads((tmp_path / "bake.json").read_text()))
    report = reports[0]
    assert sorted(report["markers_neutral_conjectured"]) == sorted(labels[i] for i in late)
    assert report["markers"] == 120 and report["markers_dropped_unseen"] == []
    assert reports[1]["markers_neutral_conjectured"] == report["markers_neutral_conjectured"]
    assert reports[1]["binding_distance_mm"] == report["binding_distance_mm"]
    assert not (tmp_path / "no.blend").exists()


def test_shipped_generic_head_shows_its_rest_shape(tmp_path):
    """sample_scenes/generic_head/head.blend as Blender shows it: its 52 expression keys at 0,
    so the evaluated mesh is the rest shape (Blender 5.0 leaves a new key at 1.0)."""
    code = (
        "import bpy, numpy as np\n"
        f"bpy.ops.wm.open_mainfile(filepath={str(HEAD_BLEND)!r})\n"
        "obj = bpy.data.objects['GenericHead']\n"
        "n = len(obj.data.vertices); rest = np.empty(3 * n); obj.data.vertices.foreach_get('co', rest)\n"
        "ev = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()\n"
        "seen = np.empty(3 * n); ev.vertices.foreach_get('co', seen)\n"
        "print('RESULT', len(obj.data.shape_keys.key_blocks), max(abs(kb.value) for kb in obj.data.shape_keys.key_blocks[1:]),\n"
        "      float(np.abs(seen - rest).max() * 1000))\n"
    )
    res = _run(["-c", code])
    assert res.returncode == 0, res.stdout + res.stderr
    keys, top_value, off_mm = res.stdout.split("RESULT ", 1)[1].split()
    assert int(keys) == 53 and float(top_value) == 0.0 and float(off_mm) < 1e-6


def _sparse_take(head, keys, n_frames=40, seed=9):
    """A VICON-style take on the generic head: a rigid headband of 3 markers off the skin, 20 face
    markers named without landmark labels (two of them on landmarks), and a marker to ignore."""
    from mirrorcap.synthetic.headsim import head_motion, place_markers

    lms = head.landmarks()
    others, _ = place_markers(head, 24, seed)
    others = [v for v in others if v not in (lms["nose_tip"], lms["chin"])][:18]
    verts = np.array([lms["nose_tip"], lms["chin"], *others])
    disp, _ = performance(head, keys, n_frames, 30.0, seed)
    band = head.vertices[lms["nose_tip"]] + np.array([[-60.0, 90.0, -40.0], [60.0, 90.0, -40.0], [0.0, 120.0, -20.0]])   # above the brows
    q = np.concatenate([np.broadcast_to(band, (n_frames, 3, 3)), head.vertices[verts][None] + disp[:, verts],
                        np.random.default_rng(seed).normal(0, 30, (n_frames, 1, 3)) + [0.0, -150.0, 0.0]], axis=1)
    R, t = head_motion(n_frames, 30.0, 12.0, seed)
    pts = np.einsum("fij,fmj->fmi", R, q) + (t + [0.0, 0.0, 650.0])[:, None]
    labels = ["LFHD", "RFHD", "TFHD"] + [f"F{i:02d}" for i in range(20)] + ["STRN"]
    mapping = {"LFHD": "rigid", "RFHD": "rigid", "TFHD": "rigid", "F00": "lm_nose_tip", "F01": "lm_chin",
               **{f"F{i:02d}": int(verts[i]) for i in range(2, 20)}, "STRN": "ignore"}
    return labels, pts, verts, disp, mapping


def test_a_sparse_take_with_a_marker_map_bakes_under_its_markers(tmp_path, head_and_keys):
    """#20: a 20-marker face and a headband, no landmark labels: the map binds them; the evaluated
    mesh puts the mapped vertices under the markers in every frame (within 0.05 mm)."""
    import json

    head, keys = head_and_keys
    labels, pts, verts, disp, mapping = _sparse_take(head, keys)
    write_c3d(tmp_path / "sparse.c3d", labels, pts, 30.0)
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    out = tmp_path / "sparse.blend"
    res = _run(["-m", "mirrorcap", "bake", tmp_path / "sparse.c3d", "--head", HEAD_BLEND, "-o", out,
                "--marker-map", tmp_path / "map.json", "--report", tmp_path / "bake.json"])
    assert res.returncode == 0, res.stdout + res.stderr
    report = json.loads((tmp_path / "bake.json").read_text())
    assert report["registration"] == "landmarks" and report["landmark_rms_mm"] < 0.01
    rb = _readback(out, tmp_path)
    basis = _to_core(rb["basis"])
    seen = _to_core(rb["evaluated"]) - basis[None]                # what a user sees, every keyed frame
    err = np.linalg.norm(seen[:, verts] - disp[:, verts], axis=2)
    print(f"sparse bake: max {err.max():.4f} mm under the markers")
    assert seen.shape[0] == 40 and err.max() < 0.05
    # the face moves: the check is not trivially met
    assert np.linalg.norm(disp[:, verts], axis=2).max() > 2.0


def test_bad_marker_maps_are_refused_and_nothing_is_written(tmp_path, head_and_keys):
    import json

    head, keys = head_and_keys
    labels, pts, verts, disp, mapping = _sparse_take(head, keys, n_frames=6)
    write_c3d(tmp_path / "sparse.c3d", labels, pts, 30.0)
    cases = {"unknown label": ({**mapping, "NOPE": 12}, "does not have: NOPE"),
             "unknown landmark": ({**mapping, "F05": "lm_earlobe"}, "lm_earlobe"),
             "vertex out of range": ({**mapping, "F05": 999999}, "vertex 999999"),
             "two on one vertex": ({**mapping, "F05": int(verts[6])}, "two markers"),
             "two rigid": ({**mapping, "TFHD": "ignore"}, "at least 3"),
             "bad role": ({**mapping, "F05": "cheek"}, "maps to 'cheek'")}
    for name, (bad, words) in cases.items():
        (tmp_path / "map.json").write_text(json.dumps(bad))
        out = tmp_path / "out.blend"
        res = _run(["-m", "mirrorcap", "bake", tmp_path / "sparse.c3d", "--head", HEAD_BLEND, "-o", out,
                    "--marker-map", tmp_path / "map.json"])
        assert res.returncode == 2 and words in res.stderr, (name, res.stderr)
        assert res.stderr.strip().count("\n") == 0 and not out.exists(), name
