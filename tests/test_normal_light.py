"""Issue #21: coloured dots under normal light, on Cycles-rendered clips of the project's own
(``make_rig_clip.py --light normal``: 1280x720 H.264, four dot colours, a light and a dark skin),
through the command line as a user runs it, with no user input."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from conftest import scored_take
from mirrorcap.cli import parser as cli
from mirrorcap.core.capture.markers import ColorClasses, ExtractionSettings, marker_extractor
from mirrorcap.core.capture.rig import split_views_by_gaps
from mirrorcap.core.capture.video import open_source
from mirrorcap.core.common.errors import InputError
from mirrorcap.core.geometry.camera import Camera
from mirrorcap.core.geometry.mirror import reflect_points
from mirrorcap.core.take.c3d import read_c3d
from mirrorcap.synthetic.evaluate import score_take

ROOT = Path(__file__).resolve().parents[1]
CLIPS = {tone: ROOT / "sample_scenes" / "normal" / tone for tone in ("light", "dark")}


def _run(args, capsys):
    code = cli.main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _tracked(name, tmp_path, capsys, *options, out_name: str | None = None) -> str:
    """``mirrorcap track`` on ``sample_scenes/normal/<name>`` as a user runs it (its rig file's views, no light given:
    the first frame shows it, any further ``options``), the take and its report written to ``tmp_path / <out_name or name>.c3d`` and
    ``.json``; returns what it printed."""
    clip = ROOT / "sample_scenes" / "normal" / name
    out_name = out_name or name
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json",
                           "--rig", clip / "rig.json", "-o", tmp_path / f"{out_name}.c3d", "--report",
                           tmp_path / f"{out_name}.json", *options], capsys)
    assert code == 0, err
    return out + err


def _tracked_and_scored(name, tmp_path, capsys) -> tuple:
    """:func:`_tracked` quietly, the take scored against the clip's truth: ``(scores, points over 2 mm)``."""
    _tracked(name, tmp_path, capsys, "-q")
    s, _, _ = scored_take(ROOT / "sample_scenes" / "normal" / name, tmp_path / f"{name}.c3d", tmp_path / f"{name}.json")
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    return s, int(np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0))


def _projections(truth, camera, f):
    P = truth["points"][f]
    return [camera.project(P)] + [camera.project(reflect_points(P, truth["mirror_normals"][k], truth["mirror_d"][k]))
                                  for k in range(2)]


def test_the_light_is_read_from_the_first_frame(tmp_path, capsys):
    """Stop 53: with no --light and no colour file saying, the first frame's centre tells the light -- every committed
    clip (30 UV, 20 normal-light: skins, compressions, blur, small dots) as its clip.json says it was rendered, with a
    margin of 2x both ways; a lit backdrop around a UV face does not change it. Then as a
    user runs it: `detect` and `colors learn` on the light-skin clip with no --light say and use normal light (a
    hs4-like clip was refused with "cannot split the direct and mirror views" before); on a UV clip, UV; a colour
    file's light is taken without a word."""
    from mirrorcap.core.capture.markers import LIT_SHARE, lit_share, light_of_frame

    shares = {"uv": [], "normal": []}
    for mp4 in sorted((ROOT / "sample_scenes").glob("*/**/clip.mp4")):
        made = mp4.parent / "clip.json"
        light = json.loads(made.read_text()).get("light", "uv") if made.is_file() else "uv"
        frame = next(iter(open_source(mp4).frames(0, 1)))[1]
        assert light_of_frame(frame) == light, mp4
        shares[light].append(lit_share(frame))
    assert len(shares["uv"]) >= 28 and len(shares["normal"]) >= 18
    assert max(shares["uv"]) < LIT_SHARE / 2 and min(shares["normal"]) > 2 * LIT_SHARE    # a margin both ways
    uv_frame = next(iter(open_source(ROOT / "sample_scenes" / "stress" / "sparse" / "clip.mp4").frames(0, 1)))[1].copy()
    h, w = uv_frame.shape[:2]
    uv_frame[:, : w // 4] = (255, 120, 150)           # a backdrop glowing under the lamps, beside the left mirror ...
    uv_frame[: h // 5] = (255, 255, 255)              # ... and above the head: 40 % of the frame
    assert light_of_frame(uv_frame) == "uv"
    code, out, err = _run(["detect", CLIPS["light"] / "clip.mp4", "--frames", "0:3", "-o", tmp_path / "d.csv"], capsys)
    assert code == 0, err
    assert "light: ordinary (coloured dots), as frame 0 shows it (--light uv to say otherwise)" in out
    report = json.loads((tmp_path / "d.json").read_text())
    assert report["settings"]["light"] == "normal" and report["counts"]["direct"] > 3 * 100     # under UV: 8 a frame
    code, out, err = _run(["colors", "learn", CLIPS["light"] / "clip.mp4", "--classes", "4", "--frames", "0:10",
                           "-o", tmp_path / "c.json"], capsys)
    assert code == 0 and "light: ordinary" in out and ColorClasses.load(tmp_path / "c.json").light == "normal"
    code, out, err = _run(["detect", CLIPS["light"] / "clip.mp4", "--colors", tmp_path / "c.json", "--frames", "0:2",
                           "-o", tmp_path / "e.csv"], capsys)
    assert code == 0 and "light:" not in out and json.loads((tmp_path / "e.json").read_text())["settings"]["light"] \
        == "normal"
    uv_clip = ROOT / "sample_scenes" / "stress" / "sparse" / "clip.mp4"
    code, out, err = _run(["detect", uv_clip, "--frames", "0:2", "-o", tmp_path / "u.csv"], capsys)
    assert code == 0 and "light: UV, as frame 0 shows it (--light normal to say otherwise)" in out
    assert json.loads((tmp_path / "u.json").read_text())["settings"]["light"] == "uv"


@pytest.mark.parametrize("tone", ["light", "dark"])
def test_coloured_dots_are_found_in_every_view_on_both_skins(tone):
    """Every 15th frame of the video: the dots the truth says are seen (within 73 degrees of a
    view, unoccluded) are found within 1.5 px with the right colour; few blobs are not dots."""
    from scipy.spatial import cKDTree

    clip = CLIPS[tone]
    truth = np.load(clip / "truth.npz")
    camera = Camera.load(clip / "camera.json")
    extract = marker_extractor(ColorClasses.default("normal"), ExtractionSettings(light="normal"))
    found = right = seen = detections = stray = 0
    errors = []
    for f, frame in open_source(clip / "clip.mp4").frames(0, None, 15):
        det = extract(frame)
        tree = cKDTree(np.c_[det.x, det.y])
        views = _projections(truth, camera, f)
        for v, px in enumerate(views):
            vis = truth["visible"][f, v]
            d, j = tree.query(px[vis])
            ok = d < 1.5
            seen += vis.sum()
            found += ok.sum()
            right += np.sum(ok & (det.color[j] == truth["marker_colors"][vis]))
            errors.append(d[ok])
        d_all = cKDTree(np.concatenate(views)).query(np.c_[det.x, det.y])[0]
        detections += len(det)
        stray += np.sum(d_all > 3.0)                      # nowhere near any dot, seen or grazing
    errors = np.concatenate(errors)
    assert found / seen > 0.96, found / seen              # light 98 %, dark 97 % measured
    assert right == found                                 # colour classes right on every dot found
    assert np.median(errors) < 0.35 and np.percentile(errors, 95) < 1.0   # px; light 0.20 / 0.6, dark 0.28 / 0.84
    assert stray / detections < 0.02, stray / detections


def test_the_uv_extractor_says_what_to_do_with_a_normal_light_clip(tmp_path, capsys):
    clip = CLIPS["light"]
    code, out, err = _run(["detect", clip / "clip.mp4", "--frames", "0:10", "--light", "uv", "-o", tmp_path / "d.csv"],
                          capsys)                      # stop 53: said, as the first frame would tell normal light
    if code == 0:        # a few bright pixels may pass the UV threshold; they are no markers
        rows = (tmp_path / "d.csv").read_text().splitlines()[1:]
        assert len(rows) < 10 * 40
    else:
        assert "--light normal" in err and not (tmp_path / "d.csv").exists()
    code, out, err = _run(["detect", clip / "clip.mp4", "--frames", "0:10", "--light", "normal",
                           "-o", tmp_path / "n.csv"], capsys)
    assert code == 0, err
    per_frame = json.loads((tmp_path / "n.json").read_text())["counts"]
    assert per_frame["direct"] / 10 > 110 and per_frame["mirror0"] / 10 > 60 and per_frame["mirror1"] / 10 > 60


def test_colour_classes_learned_from_the_clip_find_the_dots(tmp_path, capsys):
    """`mirrorcap colors learn --light normal` on the light-skin clip: four classes, one per
    paint, recorded as normal-light classes; they find the dark-skin clip's dots as well as the
    defaults do. A UV colour file with --light normal is refused."""
    out = tmp_path / "colors.json"
    code, _, err = _run(["colors", "learn", CLIPS["light"] / "clip.mp4", "--light", "normal", "--classes", "4",
                         "--frames", "0:20", "-o", out], capsys)
    assert code == 0, err
    learned = ColorClasses.load(out)
    assert learned.light == "normal" and len(learned.names) == 4
    paints = ColorClasses.default("normal")
    cls, hue_diff, _ = paints.by_hue(np.stack([learned.samples[learned.labels == k].mean(0) for k in range(4)]))
    assert sorted(cls.tolist()) == [0, 1, 2, 3] and hue_diff.max() < 15
    frame = next(iter(open_source(CLIPS["dark"] / "clip.mp4").frames(30, 31, 1)))[1]
    n_default = len(marker_extractor(paints, ExtractionSettings(light="normal"))(frame))
    n_learned = len(marker_extractor(learned, ExtractionSettings(light="normal"))(frame))
    assert abs(n_learned - n_default) <= 0.05 * n_default
    uv = tmp_path / "uv.json"
    uv.write_text(json.dumps({**ColorClasses.default().to_dict(), "light": "uv"}))
    code, _, err = _run(["detect", CLIPS["light"] / "clip.mp4", "--colors", uv, "--light", "normal",
                         "-o", tmp_path / "x.csv"], capsys)
    assert code == 2 and "for uv light" in err and not (tmp_path / "x.csv").exists()


@pytest.mark.parametrize("tone", ["light", "dark"])
def test_a_normal_light_clip_is_tracked_with_no_user_input(tone, tmp_path, capsys):
    """`mirrorcap track --light normal` on the video alone (mirrors self-calibrated, views split
    automatically): scored against the truth by the 3D identity test."""
    clip = CLIPS[tone]
    take, rep = tmp_path / "take.c3d", tmp_path / "report.json"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--light", "normal",
                           "-o", take, "--report", rep], capsys)
    assert code == 0, err
    truth = np.load(clip / "truth.npz")
    data = read_c3d(take)
    seen = truth["visible"][:, 0] & (truth["visible"][:, 1] | truth["visible"][:, 2])
    s = score_take(data["points"], truth["points"], Camera.load(clip / "camera.json"),
                   conjectured=data["conjectured"], seen=seen)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert s["rms_mm"] < 0.5 and s["max_mm"] < 2.0                # 0.21 / 0.22 mm RMS, 1.7 / 1.5 mm max measured
    assert s["conjectured_max_mm"] < 2.0                           # no reported point more than 2 mm off
    # issue #21's target: 98.2 % (light) and 98.9 % (dark) of the marker-frames seen in the direct view
    # and a mirror are reported (97.7 and 98.3 % before dots were followed through gaps and conjectures
    # measured where their dots are seen, core.track.singleview; 91.9 and 95.7 % before 2D continuity
    # and the both-mirror pairing of the midline)
    assert s["seen_reported_fraction"] > 0.98, s["seen_reported_fraction"]
    assert json.loads(rep.read_text())["mirror_agreement"]["consistent"] is True


def test_views_split_even_when_a_few_markers_sit_in_the_gap():
    """The direct view's ear nearly touching a mirror image: a handful of detections in the gap
    between two views no longer decides the split; three views must each keep their share."""
    rng = np.random.default_rng(3)
    x = np.r_[rng.uniform(150, 440, 3000), rng.uniform(475, 810, 5000), rng.uniform(835, 1130, 3000)]
    strays = np.r_[np.full(30, 452.0), np.full(25, 461.0), np.full(20, 822.0)]   # dots at the views' edges
    layout = split_views_by_gaps(np.r_[x, strays], 12.0)
    b0, b1 = layout.boundaries
    assert 440 < b0 < 475 and 810 < b1 < 835
    with pytest.raises(InputError, match="no clear gap"):
        split_views_by_gaps(rng.uniform(0, 1280, 5000), 12.0)


def test_bad_input_under_normal_light_is_one_message_and_nothing_written(tmp_path, capsys):
    """A clip of bare skin (no dots), and a .fap whose mask is not 68 bits played with bake --fap:
    exit 2, one line naming the problem, no output file."""
    import cv2

    frames = tmp_path / "skin"
    frames.mkdir()
    rng = np.random.default_rng(0)
    for f in range(6):
        img = np.clip(np.full((360, 640, 3), (150, 180, 220), float) + rng.normal(0, 3, (360, 640, 3)), 0, 255)
        cv2.imwrite(str(frames / f"{f:03d}.png"), img.astype(np.uint8))
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps(Camera.ideal(700.0, (640, 360)).to_dict()))
    for command in (["detect", frames, "--light", "normal", "-o", tmp_path / "d.csv"],
                    ["track", frames, "--camera", camera, "--light", "normal", "-o", tmp_path / "t.c3d"]):
        code, out, err = _run(command, capsys)
        assert code == 2 and err.count("\n") == 1 and err.startswith("mirrorcap: error:")
        assert "coloured dots" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["camera.json", "skin"]
    bad = tmp_path / "bad.fap"
    bad.write_text("2.1 x 30 1\n" + " ".join(["0"] * 60) + "\n0\n")
    code, out, err = _run(["bake", "--fap", bad, "--head", ROOT / "sample_scenes" / "generic_head" / "head.blend",
                           "-o", tmp_path / "out.blend"], capsys)
    assert code == 2 and "68 bits" in err and not (tmp_path / "out.blend").exists()


def _seeds_from_truth(clip, every=6, limit=20):
    """SEEDS.csv rows a user would click on the first frame: the true dots the extractor finds
    there (within 1 px), every ``every``-th of those seen in the direct view and a mirror."""
    from scipy.spatial import cKDTree

    truth, camera = np.load(clip / "truth.npz"), Camera.load(clip / "camera.json")
    frame = next(iter(open_source(clip / "clip.mp4").frames(0, 1, 1)))[1]
    det = marker_extractor(ColorClasses.default("normal"), ExtractionSettings(light="normal"))(frame)
    tree = cKDTree(np.c_[det.x, det.y])
    views = _projections(truth, camera, 0)
    found = np.stack([tree.query(views[v])[0] < 1.0 for v in range(3)]) & truth["visible"][0]
    picked = [m for m in range(found.shape[1]) if found[0, m] and found[1:, m].any()][::every][:limit]
    rows = ["id,view,x,y"]
    for m in picked:
        for v, name in enumerate(("direct", "mirror0", "mirror1")):
            if found[v, m]:
                rows.append(f"dot{m:03d},{name},{views[v][m, 0]:.2f},{views[v][m, 1]:.2f}")
    return "\n".join(rows) + "\n", picked


def test_markers_designated_in_seeds_keep_their_names_and_their_dots(tmp_path, capsys):
    """`track --seeds SEEDS.csv`: each designated marker is paired as given, carries its id as its
    label, and follows its own dot through the take (3D identity test); bad seed files are refused
    before anything is written."""
    clip = CLIPS["light"]
    text, picked = _seeds_from_truth(clip)
    seeds = tmp_path / "seeds.csv"
    seeds.write_text(text)
    take = tmp_path / "take.c3d"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--light", "normal",
                           "--seeds", seeds, "-o", take, "-q"], capsys)
    assert code == 0, err
    data = read_c3d(take)
    truth = np.load(clip / "truth.npz")
    s = score_take(data["points"], truth["points"], Camera.load(clip / "camera.json"), conjectured=data["conjectured"])
    named = {label: i for i, label in enumerate(data["labels"]) if label.startswith("dot")}
    assert sorted(named) == sorted(f"dot{m:03d}" for m in picked) and len(picked) >= 12
    assert all(s["ids"][i] == int(label[3:]) for label, i in named.items())
    assert s["identity_switches"] == 0 and s["rms_mm"] < 0.5
    bad = {"unknown view": "a,direct,600,400\na,mirror2,100,400\n",
           "off the 1280x720 image": "a,direct,600,400\na,mirror0,1300,400\n",
           "no point in the direct view": "a,mirror0,200,400\n",
           "no point in either mirror": "a,direct,600,400\n",
           "designated twice": "a,direct,600,400\na,direct,601,400\na,mirror0,200,400\n",
           "no marker within 4 px": "a,direct,5,5\na,mirror0,200,400\n"}
    for message, body in bad.items():
        seeds.write_text("id,view,x,y\n" + body)
        code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--light", "normal",
                               "--seeds", seeds, "-o", tmp_path / "bad.c3d"], capsys)
        assert code == 2 and message in err and err.count("\n") == 1, (message, err)
        assert not (tmp_path / "bad.c3d").exists()


def test_wrong_designations_are_fixed_in_the_clip_and_re_solve_repairs_the_take(tmp_path, capsys):
    """#21: with 10 % of SEEDS.csv wrong (five designations' mirror points on another dot), the take
    loses those designations (each is tracked under an automatic label, or not at all). Written to the
    clip as tracks, the five are fixed as a user fixes them in the Movie Clip Editor (their tracks
    renamed to the designation), a stretch of another track is muted, and Re-solve re-estimates the
    mirrors from the tuned tracks and recomputes the take: every designation is back, on its own dot."""
    import subprocess
    import sys

    clip = CLIPS["light"]
    text, picked = _seeds_from_truth(clip, every=2, limit=50)
    truth, camera = np.load(clip / "truth.npz"), Camera.load(clip / "camera.json")
    views = _projections(truth, camera, 0)
    wrong = picked[:: len(picked) // 5][:5]
    rows = []
    for row in text.strip().splitlines()[1:]:
        name, view, x, y = row.split(",")
        m = int(name[3:])
        if m in wrong and view.startswith("mirror"):        # the nearest undesignated marker's dot in that mirror
            k = int(view[-1])
            d = np.linalg.norm(views[1 + k] - views[1 + k][m], axis=1)
            d[picked], d[~truth["visible"][0, 1 + k]] = np.inf, np.inf
            x, y = views[1 + k][int(np.argmin(d))]
            row = f"{name},{view},{x:.2f},{y:.2f}"
        rows.append(row)
    (tmp_path / "seeds.csv").write_text("id,view,x,y\n" + "\n".join(rows) + "\n")
    assert len(picked) >= 40 and len(wrong) == 5
    take = tmp_path / "take.c3d"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--light", "normal",
                           "--seeds", tmp_path / "seeds.csv", "-o", take, "--report", tmp_path / "take_report.json",
                           "-q"], capsys)
    assert code == 0, err
    data = read_c3d(take)
    s = score_take(data["points"], truth["points"], camera, conjectured=data["conjectured"])
    lost = [f"dot{m:03d}" for m in picked if f"dot{m:03d}" not in data["labels"]]
    assert lost == [f"dot{m:03d}" for m in wrong], lost        # the wrong designations did not hold, the rest did
    assert "5 designation(s) of the seeds file did not hold" in json.loads((tmp_path / "take_report.json").read_text())[
        "warnings"][0]
    # the user's fix for each: rename the track that follows that marker's dot; where no track does, track
    # the dot anew (here: the extractor's dot nearest its true image in each view and frame, as Blender's
    # tracker would follow it from a click)
    from scipy.spatial import cKDTree

    fixes, new_tracks = {}, {}
    extract = marker_extractor(ColorClasses.default("normal"), ExtractionSettings(light="normal"))
    frames = [fr for _, fr in open_source(clip / "clip.mp4").frames(0, 120, 1)]
    for m in wrong:
        hits = [data["labels"][i] for i in np.flatnonzero(s["ids"] == m)]
        if hits:
            fixes[f"dot{m:03d}"] = hits[0]
            continue
        rows = {}
        for f, img in enumerate(frames):
            det = extract(img)
            d, j = cKDTree(np.c_[det.x, det.y]).query(np.stack([v[m] for v in _projections(truth, camera, f)]))
            for v in np.flatnonzero((d < 1.5) & truth["visible"][f, :, m]):
                rows.setdefault(("direct", "mirror0", "mirror1")[v], []).append([f, float(det.x[j[v]]), float(det.y[j[v]])])
        new_tracks[f"dot{m:03d}"] = rows
    # ... and delete a track that jumps between dots (the user sees it leave its dot in the clip)
    from scipy.spatial import cKDTree as _Tree

    delete = []
    for i in np.flatnonzero(s["ids"] >= 0):
        f_ok = np.flatnonzero(np.all(np.isfinite(s["aligned"][:, i]), axis=1) & ~data["conjectured"][:, i])
        near = [_Tree(truth["points"][f]).query(s["aligned"][f, i])[1] for f in f_ok]
        if np.any(np.asarray(near) != s["ids"][i]):
            delete.append(data["labels"][i])
    (tmp_path / "fixes.json").write_text(json.dumps({"rename": fixes, "track": new_tracks, "delete": delete}))
    res = subprocess.run([sys.executable, ROOT / "tests" / "blender" / "resolve_ops.py", tmp_path, clip],
                         capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    o = json.loads(res.stdout.split("RESULT ", 1)[1])
    assert o["resolve_first"][0] == "ERROR" and "Take To Clip" in o["resolve_first"][1]
    assert o["to_clip"] == ["FINISHED"] and o["tracks"] > 2 * len(data["labels"])
    assert o["resolve_cancel"] == ["CANCELLED"] and o["cancel_unchanged"]
    assert o["resolve"] == ["FINISHED"]
    fixed = read_c3d(take)
    s2 = score_take(fixed["points"], truth["points"], camera)
    named = {lab: i for i, lab in enumerate(fixed["labels"]) if lab.startswith("dot")}
    print(f"re-solve: {len(fixes)} of 5 lost designations fixed by renaming, {len(new_tracks)} by tracking anew, "
          f"{len(delete)} track(s) deleted ({s['identity_switches']} switches before); "
          f"RMS {s['rms_mm']:.3f} -> "
          f"{s2['rms_mm']:.3f} mm, switches {s2['identity_switches']}, mirrors moved "
          f"{o['report']['mirror_change_deg']} deg, {o['report']['rejected_correspondences']} correspondences left out")
    assert all(name in named and s2["ids"][named[name]] == int(name[3:]) for name in list(fixes) + list(new_tracks))
    assert sorted(named) == sorted(f"dot{m:03d}" for m in picked)              # every designation is back
    assert s2["identity_switches"] == 0 and s2["rms_mm"] < 0.5 and max(o["report"]["mirror_change_deg"]) < 0.1
    assert len(fixes) + len(new_tracks) + len(delete) <= 6                  # five fixes and at most one deletion
    assert not set(delete) & set(fixed["labels"]) and sorted(o["report"]["markers_without_a_frame"]) == sorted(delete)


def test_re_solve_from_tracks_re_estimates_the_mirrors_and_rejects_a_wrong_correspondence():
    """core.track.resolve: the take from per-view 2D tracks (here the clip's true dots with 0.2 px noise):
    the mirrors re-estimated, every marker-frame with a direct and a mirror point reconstructed in the
    earlier take's units; tracks that follow another marker's dot in a mirror are rejected, not
    reconstructed."""
    from mirrorcap.core.track.resolve import resolve_tracks

    clip = CLIPS["light"]
    truth, camera = np.load(clip / "truth.npz"), Camera.load(clip / "camera.json")
    F, M = truth["points"].shape[:2]
    rng = np.random.default_rng(0)
    tracks = np.full((F, M, 3, 2), np.nan)
    for f in range(F):
        for v, px in enumerate(_projections(truth, camera, f)):
            ok = truth["visible"][f, v]
            tracks[f, ok, v] = px[ok] + rng.normal(0, 0.2, (ok.sum(), 2))
    previous = [{"normal": truth["mirror_normals"][0].tolist(), "d": float(truth["mirror_d"][0])}]
    labels = [f"m{i:03d}" for i in range(M)]
    res = resolve_tracks(labels, tracks, camera, previous)
    s = score_take(res.points, truth["points"], camera)
    assert s["rms_mm"] < 0.2 and s["identity_switches"] == 0 and abs(s["scale_to_mm"] - 1) < 0.002
    both = np.isfinite(tracks[:, :, 0, 0]) & np.isfinite(tracks[:, :, 1:, 0]).any(axis=2)
    assert np.array_equal(np.isfinite(res.points[..., 0]), both) and res.report["rejected_correspondences"] == 0
    for k, pl in enumerate(res.planes):
        assert np.degrees(np.arccos(abs(pl.normal @ truth["mirror_normals"][k]))) < 0.05
    # five markers' mirror-1 tracks follow the next marker's dot: those correspondences are left out
    bad = np.array([5, 30, 60, 90, 120])
    wrong = tracks.copy()
    wrong[:, bad, 2] = tracks[:, bad + 1, 2]
    only_m1 = np.isfinite(wrong[:, bad, 2, 0]) & ~np.isfinite(wrong[:, bad, 1, 0]) & np.isfinite(wrong[:, bad, 0, 0])
    res = resolve_tracks(labels, wrong, camera, previous)
    s = score_take(res.points, truth["points"], camera)
    print(f"re-solve from tracks: {res.report['rejected_correspondences']} correspondences rejected, "
          f"RMS {s['rms_mm']:.3f} mm, max {s['max_mm']:.2f}")
    assert res.rejected[:, bad].sum() >= 0.9 * only_m1.sum() and only_m1.sum() > 20 and res.report["mirrors_disagree"] > 0
    assert s["identity_switches"] == 0 and s["max_mm"] < 2.0


@pytest.mark.parametrize("name, rms_mm, reported, ratio, over_2mm", [("hd", 0.33, 0.965, 0.004, 4),
                                                                    ("med720", 0.4, 0.955, 0.006, 10),
                                                                    ("deep720", 0.4, 0.955, 0.004, 12)])
def test_held_out_normal_light_clips(tmp_path, capsys, name, rms_mm, reported, ratio, over_2mm):
    """Normal-light clips rendered after every setting here was chosen (`make normal-clips`). hd (1920x1080,
    medium skin, 180 dots of 3 mm, mirrors at 40 deg, +-14 deg yaw): no identity switch, the take within
    0.45 mm RMS after one similarity (measured 0.35), 92.5 % of the seen marker-frames reported; the mirror
    images' centroids sit 0.8-1.0 px outwards of the dots' centres here (0.15 px at 720p): the dots are
    spheres half a millimetre proud of the skin, and a mirror sees them from the side. med720 (1280x720,
    medium skin, 170 dots of 2.8 mm, mirrors at 43 deg, +-12 deg yaw; rendered at stop 36): 93.1 %, 75
    points over 2 mm, 0.53 mm RMS. Stop 36, a candidate pixel's hue must differ from the skin's
    (colordots.FROM_SKIN_DEG; the shadow of the skin's hue beside a dot moved it): hd 94.4 % and 0.27 mm,
    med720 94.7 % and 0.44 mm (37 points over 2 mm); 92.5 % and 93.1 % fail these bounds. med720's mirror
    scales are linked 0.42 % off (0.26 % before the change; the agreement check passes either way). Stop 38:
    touching dots of two colours split (colordots.split_by_colour) and late rivals on one direct track
    (late.RIVAL_ALONG_MM): hd 94.4 -> 97.7 % (2 -> 1 point over 2 mm, 0.26 mm RMS), med720 95.0 -> 96.2 %
    (23 -> 6 points, 0.42 -> 0.35 mm); deep720 (a deep skin, 200 dots of 2.6 mm, mirrors at 42 deg; rendered at
    stop 38 and used in choosing its changes) 92.5 -> 96.5 %, 103 -> 3 points, 0.66 -> 0.34 mm. The bounds
    fail on the code before."""

    clip = ROOT / "sample_scenes" / "normal" / name
    code, _, err = _run(["track", clip / "clip.mp4", "--light", "normal", "--camera", clip / "camera.json",
                         "--rig", clip / "rig.json", "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json",
                         "-q"], capsys)
    assert code == 0, err
    s, report, ratio_error = scored_take(clip, tmp_path / "take.c3d", tmp_path / "take.json")
    assert abs(ratio_error) < ratio
    assert report["mirror_agreement"]["scattered"] is False      # stop 41's checks say nothing on a sound take
    assert not any("mirrors" in w and ("scales rest on" in w or "do not agree" in w) for w in report["warnings"])
    assert s["identity_switches"] == 0 and s["markers_tracked"] >= 100
    assert s["rms_mm"] < rms_mm
    assert s["seen_reported_fraction"] >= reported
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= over_2mm


def test_a_dot_paired_with_a_like_dots_grazing_image_is_not_a_late_marker(tmp_path, capsys):
    """#18, stop 38: tan720 (1280x720, a tanned skin, 190 dots of 2.7 mm, mirrors at 44 deg, +-12 deg yaw), rendered
    at the stop's start and held out. Between the eyes three magenta dots sit in a row, along the mirrors'
    epipolar lines; mirror 1 sees two of them as one blob at the nose's silhouette and not the third. Two late
    chains each paired a dot with a like dot's grazing image (its own hidden) -- 8-9 mm along its ray, off the
    face, but within the 10 mm that add_late_markers allowed: 53 points over 2 mm (up to 9.4 mm), 0.66 mm RMS. At
    late.LATE_OFF_FACE_MM (7 mm) both are refused: 14 points, 0.39 mm RMS, at most 3.3 mm, 94.2 % of the seen
    marker-frames reported. Then touching dots of two colours split (colordots.split_by_colour) found more dots
    and with them more such chains, each on the direct 2D track of a chain kept, resting 6-8 mm from it along the
    ray: of two such rivals the one nearer the face is kept (late.RIVAL_ALONG_MM): 96.8 %, 4 points, 0.33 mm.
    Stop 47: a late marker whose rest is read from an earlier stretch of it has its distance from the face read
    there too -- a stretch first seen at an extreme of the head's turn lay 14.7 mm off a loosely fitting face
    plane, and a wrong pairing 6 mm off replaced it: 97.5 %, 4 points, 0.33 mm."""
    clip = ROOT / "sample_scenes" / "normal" / "tan720"
    code, _, err = _run(["track", clip / "clip.mp4", "--light", "normal", "--camera", clip / "camera.json",
                         "--rig", clip / "rig.json", "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json",
                         "-q"], capsys)
    assert code == 0, err
    s, _, ratio_error = scored_take(clip, tmp_path / "take.c3d", tmp_path / "take.json")
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    over = np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0)
    print(f"tan720: {over} points over 2 mm, RMS {s['rms_mm']:.3f} mm, max {s['max_mm']:.2f} mm, "
          f"{100 * s['seen_reported_fraction']:.1f} % reported")
    assert s["identity_switches"] == 0 and s["split_markers"] == 0 and abs(ratio_error) < 0.006
    assert over <= 8 and s["max_mm"] < 4.0 and s["rms_mm"] < 0.37
    assert s["seen_reported_fraction"] >= 0.97


def test_two_dots_on_one_epipolar_line_keep_their_own_mirror_images(tmp_path, capsys):
    """#18, stop 47: ruddy540 (960x540, a ruddy skin, 200 dots of 2.8 mm, mirrors at 46 deg), held out at stop 39.
    Two like dots 12.6 mm apart lie on one mirrored epipolar line of mirror 0 throughout, and so do two images
    there: the first dot's own and the second's grazing one (beyond 73 deg of the mirror's axis). Both ways of
    pairing the two dots with the two images sit in the band; the first frames leave them undecided, and the late
    markers took them up. The chance pairing's chain was the longest, so it took the first dot, and the second dot
    then took the first's image: 10 identity switches (up to 9.3 mm), 24 points over 2 mm, 0.53 mm RMS, 92.6 % of
    the seen marker-frames. Of two late chains that share blobs, the one on the better supported pairing of 2D
    tracks over the clip now stays (pairing.chain_pairing_support; measured: 0 switches, 9 points over 2 mm, 0.46 mm RMS,
    92.8 %)."""
    s, over = _tracked_and_scored("ruddy540", tmp_path, capsys)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert over <= 12 and s["rms_mm"] < 0.48
    assert s["seen_reported_fraction"] >= 0.925


def test_a_mirror_image_two_like_dots_contest_goes_to_the_one_the_other_mirror_confirms(tmp_path, capsys):
    """#18, stop 47: blur540n (960x540, a medium skin, 200 dots of 3.2 mm, expressions 2.5x as fast, each frame
    blurred over a 1/60 s shutter), rendered at the stop and held out. The nose-tip dot and the like dot beside it
    sit at one height, on one mirrored epipolar line of each mirror; mirror 0 shows only the nose tip's image.
    In the first frames both dots sat in that image's band (0.32 and 0.25 px RMS), each with no other partner
    there, and the assignment gave it to the nearer, the wrong dot; the nose tip then paired in mirror 1 with the
    other's image: two markers wrong from the first frame, 68 identity switches, 180 points over 2 mm, 1.6 mm RMS
    -- with no warning. The contested image now goes to the dot that mirror 1 puts at the same 3D point
    (initial._settle_contests; measured: no switch, 43 points over 2 mm, 0.47 mm RMS, 96.2 %)."""
    s, over = _tracked_and_scored("blur540n", tmp_path, capsys)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert over <= 60 and s["rms_mm"] < 0.55
    assert s["seen_reported_fraction"] >= 0.955


def test_a_contested_image_the_other_mirror_cannot_see_goes_to_the_dot_whose_pairing_holds(tmp_path, capsys):
    """#18, stop 48: touch576 (1024x576, a skin of sRGB 190,140,110, 220 dots of 2.8 mm, mirrors at 44 deg, their
    views touching the direct one), rendered at stop 47 and held out. A dot on the cheek seen only directly and a
    like dot at its height seen directly and in mirror 1 sat, over the first frames, in the band of the one image on
    their line (0.19 and 0.29 px RMS, the wrong dot nearer). Mirror 0 sees neither, so it could not settle the
    contest, and the assignment gave the image to the wrong dot: 17 identity switches, 49 points over 2 mm, 0.76 mm
    RMS. Now the image goes to the dot whose 2D track stays in its band over the whole clip (45 of 46 frames,
    against 20 of 46; initial._settle_by_clip_support). Measured: no switch, 24 points over 2 mm, 0.45 mm, 92.6 %."""
    s, over = _tracked_and_scored("touch576", tmp_path, capsys)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert over <= 35 and s["rms_mm"] < 0.5
    assert s["seen_reported_fraction"] >= 0.92


def test_a_video_compressed_too_hard_links_the_mirrors_by_head_motion_and_says_so(tmp_path, capsys):
    """#18, stop 41: the rendered clips are kept near-losslessly (H.264 CRF 17); cameras and screen recorders
    compress harder. hd (1080p, normal light) re-encoded at CRF 26 (`make compressed-clips`: 1.6 MB for 3 s,
    4.1 Mbit/s) shows 3 markers in both mirrors, their images mostly paired wrongly: their depth ratios spread
    1.6 % and the link put mirror 1's distance 1.4 % off, the take 3.0 mm RMS with 6,590 points over 2 mm -- and
    the agreement check, whose median difference the link sets to zero, passed it. Now a shared markers' link
    that spreads over 0.5 % (the 40 sound clips: 0.01-0.27 %) gives way to the head-motion link, and a scatter
    ten times the expected sd (the 40 clips: 0.6-4.2 times) is a warning: 0.56 mm RMS, 32 points over 2 mm. At
    CRF 29 with its washed-out dots dropped (``--washed-out drop``, as before stop 42) one marker is seen in both
    mirrors and the head-motion link is refused: the take is 3.8 mm off, and says that its mirrors' scales rest on
    one marker. (Kept, as they are by default at CRF 29, those dots give 0.59 mm: the next test.)"""
    from mirrorcap.core.track.mirrorscale import LINK_MAX_SPREAD

    runs = {}
    for name, options in (("hd_crf26", ()), ("hd_crf29", ("--washed-out", "drop"))):
        text = _tracked(name, tmp_path, capsys, *options)
        clip = ROOT / "sample_scenes" / "normal" / name
        runs[name] = (*scored_take(clip, tmp_path / f"{name}.c3d", tmp_path / f"{name}.json"), text)
    for name, (_, report, _, text) in runs.items():     # the video's compression, recorded
        assert report["video"]["bits_per_pixel"] < 0.07 and report["video"]["mbit_per_s"] < 4.2
    s, report, ratio_error, text = runs["hd_crf26"]
    link = report["mirror_scale_link"]
    print(f"hd_crf26: link {link['source']} {link['ratio']:.4f} (ratio error {100 * ratio_error:+.2f} %), RMS "
          f"{s['rms_mm']:.3f} mm, {100 * s['seen_reported_fraction']:.1f} % reported")
    assert link["source"].startswith("head motion") and link["shared_markers_link"]["relative_spread"] > LINK_MAX_SPREAD
    assert abs(ratio_error) < 0.004 and s["rms_mm"] < 0.8 and s["identity_switches"] == 0
    assert report["mirror_agreement"]["scattered"] is True and report["mirror_agreement"]["consistent"] is False
    assert "warning: the markers seen in both mirrors do not agree" in text
    # ... and says that those markers were set aside: the scales came from the head's motion (stop 45)
    assert "the mirrors' scales were linked through the head's motion instead" in text
    s, report, ratio_error, text = runs["hd_crf29"]
    assert report["mirror_scale_link"]["source"] == "markers tracked in both mirrors"
    warned = [w for w in report["warnings"] if w.startswith("the two mirrors' scales rest on only 1 marker")]
    assert len(warned) == 1 and "warning: the two mirrors' scales rest on" in text


def test_detect_records_the_videos_compression(tmp_path, capsys):
    """#18, stop 41: `mirrorcap detect` records the video's bits per second and per pixel of a frame in DETECTIONS.json
    (``video``; REPORT.json has the same): hd at H.264 CRF 26 (`make compressed-clips`) holds 0.067 bits per pixel of
    a frame, 4.15 Mbit/s; hd as rendered (CRF 17) 0.27. No warning rests on it: the normal-light clips re-encoded at
    CRF 20 lost dots at 0.17-0.27 bits (four576 94.0 -> 73.0 %) while the dark clip at CRF 23 kept them at 0.11."""
    reports = {}
    for name in ("hd_crf26", "hd"):
        clip = ROOT / "sample_scenes" / "normal" / name
        code, _, err = _run(["detect", clip / "clip.mp4", "--light", "normal", "--rig", clip / "rig.json",
                             "--frames", "0:5", "-q", "-o", tmp_path / f"{name}.csv"], capsys)
        assert code == 0, err
        reports[name] = json.loads((tmp_path / f"{name}.json").read_text())
    assert abs(reports["hd_crf26"]["video"]["bits_per_pixel"] - 0.0667) < 0.001
    assert abs(reports["hd_crf26"]["video"]["mbit_per_s"] - 4.15) < 0.01
    assert abs(reports["hd"]["video"]["bits_per_pixel"] - 0.268) < 0.002


def test_a_take_whose_dots_colours_are_washed_out_says_so(tmp_path, capsys):
    """#18, stop 41: compression washes a small dot's colour out until its hue falls between the colour classes and
    the detector drops it. light_crf26 (the light clip at H.264 CRF 26) tracks 92.3 % of its seen marker-frames where
    the light clip tracks 99.6 %, and nothing said so. Blobs that pass every test but the hue's, far from the skin's
    hue, are now counted (``between_classes``): 3.6 % as many as the dots found on light_crf26, 0.1 % on light (the
    rendered normal-light clips: 0.0-1.1 %); over 2 % is a warning from `track` and `detect`. Held out (rendered
    after the limit was set, not in the repository): rose720 (4.1 px mirror dots) 0.3 % as rendered, 3.3 / 7.9 /
    13.4 % at CRF 20 / 23 / 26, where its take lost 11 / 42 / 80 points -- warned each time."""
    from mirrorcap.core.capture.detect import BETWEEN_CLASSES_MAX_SHARE, between_classes_warning

    reports, printed = {}, {}
    for name in ("light_crf26", "light"):
        printed[name] = _tracked(name, tmp_path, capsys)
        reports[name] = json.loads((tmp_path / f"{name}.json").read_text())
    washed, clean = reports["light_crf26"]["between_classes"], reports["light"]["between_classes"]
    assert washed["share"] > 1.5 * BETWEEN_CLASSES_MAX_SHARE and washed["blobs"] > 20000
    assert clean["share"] < 0.2 * BETWEEN_CLASSES_MAX_SHARE and clean["blobs"] > 20000
    assert "colour between the colour classes" in printed["light_crf26"]
    assert "colour between the colour classes" not in printed["light"]
    assert between_classes_warning("uv", washed) is None
    clip = ROOT / "sample_scenes" / "normal" / "light_crf26"
    code, out, err = _run(["detect", clip / "clip.mp4", "--light", "normal", "--rig", clip / "rig.json",
                           "-o", tmp_path / "d.csv"], capsys)
    assert code == 0 and "warning: 3.6 % as many blobs as the dots found had a colour between" in out + err
    # stop 42: DETECTIONS.csv holds what a take would use -- the washed-out dots too, where they are kept
    for setting, kept in (("auto", True), ("drop", False)):
        csv = tmp_path / f"d_{setting}.csv"
        code, _, err = _run(["detect", clip / "clip.mp4", "--light", "normal", "--rig", clip / "rig.json", "-q",
                             "--washed-out", setting, "-o", csv], capsys)
        figures = json.loads(csv.with_suffix(".json").read_text())
        rows = len(csv.read_text().splitlines()) - 1
        assert code == 0 and figures["between_classes"]["kept"] is kept, err
        assert rows == figures["between_classes"]["blobs"] + kept * figures["between_classes"]["between_classes"]


def test_washed_out_dots_are_classed_by_their_colour_less_the_skins():
    """#18, stop 42: a dot blended with the skin around it -- video compression, a small image -- has a chromaticity
    ``a * paint + (1 - a) * skin``. Its own hue drifts towards the skin's as ``a`` falls, out of its class's 35 deg,
    but its colour less the skin's, ``a * (paint - skin)``, keeps one direction: the paint's as seen from the skin
    (:func:`colordots.difference_hue`). For the four default paints on three skins, down to a fifth of the paint,
    that direction names the right class every time where the blob's own hue, at a fifth, misses for some."""
    from mirrorcap.core.capture.colordots import difference_hue, hue_apart, hue_saturation

    classes = ColorClasses.default("normal")
    centres = classes.hue_centres()
    paints = {"blue": (30, 70, 230), "green": (30, 175, 60), "yellow": (245, 215, 20), "magenta": (215, 30, 175)}
    own_missed = 0
    for skin in ((235, 190, 165), (200, 150, 120), (120, 80, 60)):
        skin_c = np.asarray(skin, float) / sum(skin)
        for name, paint in paints.items():
            paint_c = np.asarray(paint, float) / sum(paint)
            for a in (1.0, 0.6, 0.35, 0.2):
                blob = a * paint_c + (1.0 - a) * skin_c
                by_difference = np.argmin(hue_apart(difference_hue(blob, skin_c)[:, None], centres[None]), axis=1)[0]
                assert classes.names[by_difference] == name, (skin, name, a)
                own = np.degrees(hue_apart(hue_saturation(blob)[0][:, None], centres[None]))[0]
                own_missed += a == 0.2 and (own.min() > 35.0 or classes.names[int(np.argmin(own))] != name)
    assert own_missed >= 6        # what the blob's own hue does with them: out of every class, or another's


def test_the_per_pixel_hue_is_the_colours_hue_to_the_bit():
    """Stop 43: the extractor's per-pixel hue (step 2) is computed from three channel columns
    (:func:`colordots.hue_of_channels`) instead of an ``(n, 3)`` array: the same angles to the bit as
    :func:`colordots.hue_saturation`, black pixels and float32 pixels included, so a pixel on the edge of the
    15 deg test falls on the same side."""
    from mirrorcap.core.capture.colordots import hue_of_channels, hue_saturation

    rng = np.random.default_rng(7)
    bgr = np.r_[rng.integers(0, 256, (20000, 3)), [[0, 0, 0], [0, 0, 255], [7, 7, 7]]].astype(np.float32)
    rgb = bgr[:, ::-1]
    assert np.array_equal(hue_of_channels(bgr[:, 2], bgr[:, 1], bgr[:, 0]), hue_saturation(rgb)[0])


@pytest.mark.parametrize("setting, share, kept", [("auto", 0.021, True), ("auto", 0.019, False), ("keep", 0.0, True),
                                                  ("drop", 0.5, False)])
def test_which_takes_keep_the_washed_out_dots(setting, share, kept):
    """``ExtractionSettings.washed_out``: "auto" keeps the dots between the colour classes when the first frames hold
    more than BETWEEN_CLASSES_MAX_SHARE (2 %) as many as the other dots; "keep" and "drop" always do as they say."""
    from mirrorcap.core.capture.detect import BETWEEN_CLASSES_MAX_SHARE, keeps_between

    assert BETWEEN_CLASSES_MAX_SHARE == 0.02
    assert keeps_between(setting, int(round(share * 10000)), 10000) is kept
    with pytest.raises(InputError, match="washed_out must be one of"):
        ExtractionSettings(light="normal", washed_out="sometimes")


def test_a_washed_out_take_keeps_its_dots_between_the_classes(tmp_path, capsys):
    """#18, stop 42: blobs of a hue between the colour classes, kept and classed by their colour less the skin's
    when the first 30 frames hold more than 2 % of them. light_crf26 (3.6 %) tracks 94.8 % of its seen
    marker-frames against 92.3 % with them dropped (``--washed-out drop``, the take of stop 41); hd_crf29 (2.4 %),
    whose mirrors' scales had rested on one marker (3.8 mm RMS), links them through the head's motion: 0.59 mm.
    The light clip as rendered (0.13 %) keeps nothing and tracks as before, 99.6 %. Held out (rendered at the stop
    after the rule was set, not in the repository: sand720 and umber600 re-encoded at CRF 20-26), the five takes
    over 2 % went from 16-83 to 34-89 % of their seen marker-frames, their identity switches 1,222 -> 33."""
    scores = {}
    for name, options, out_name in (("light_crf26", (), "kept"), ("light_crf26", ("--washed-out", "drop"), "dropped"),
                                    ("hd_crf29", (), "hd_crf29"), ("light", (), "light")):
        text = _tracked(name, tmp_path, capsys, *options, out_name=out_name)
        clip = ROOT / "sample_scenes" / "normal" / name
        scores[out_name] = (*scored_take(clip, tmp_path / f"{out_name}.c3d", tmp_path / f"{out_name}.json"), text)
    kept, dropped = scores["kept"][0], scores["dropped"][0]
    print({k: (round(100 * v[0]["seen_reported_fraction"], 2), round(v[0]["rms_mm"], 3)) for k, v in scores.items()})
    assert scores["kept"][1]["between_classes"]["kept"] is True
    assert scores["dropped"][1]["between_classes"]["kept"] is False
    assert kept["seen_reported_fraction"] > 0.945 and dropped["seen_reported_fraction"] < 0.93
    assert kept["identity_switches"] == 0 and kept["rms_mm"] < 0.55
    assert "They were kept, each classed by its colour less the skin's" in scores["kept"][3]
    assert "and they were dropped" in scores["dropped"][3]
    hd, report = scores["hd_crf29"][0], scores["hd_crf29"][1]
    assert report["between_classes"]["kept"] is True and report["mirror_scale_link"]["source"].startswith("head motion")
    assert hd["rms_mm"] < 1.0 and hd["identity_switches"] == 0 and hd["seen_reported_fraction"] > 0.87
    light, report = scores["light"][0], scores["light"][1]
    assert report["between_classes"]["kept"] is False and light["seen_reported_fraction"] > 0.995


def test_a_take_that_opens_without_a_face_decides_on_the_frames_that_show_it(tmp_path, capsys):
    """#18, stop 42: a take decides its view layout and whether it keeps its washed-out dots from its first frames,
    and self-calibrates its mirrors and finds its markers on its first frames too. One that opens on 35 frames with
    no face (a slate, the performer stepping in) had nothing to decide from: with no rig file `detect` and `track`
    refused it ("no markers found in the first 30 frames"), with one `track` refused it at self-calibration.
    Now the first 30 frames that show the face are pooled (at most 300 frames): 35 black frames before 40 frames of
    light_crf26 (3.6 % washed out) keep them, the views split as on light_crf26 alone, and `track` leaves the 35
    frames out with a warning and tracks the rest as light_crf26's own first 40 frames."""
    from mirrorcap.core.capture.detect import DetectionStream
    from mirrorcap.core.capture.rig import load_rig_views

    clip = ROOT / "sample_scenes" / "normal" / "light_crf26"
    frames = [frame for _, frame in open_source(clip / "clip.mp4").frames(0, 40, 1)]
    folder = tmp_path / "take"
    folder.mkdir()
    for i, frame in enumerate([np.zeros_like(frames[0])] * 35 + frames):
        cv2.imwrite(str(folder / f"f{i:03d}.png"), frame)
    colours, settings = ColorClasses.default("normal"), ExtractionSettings(light="normal")
    for layout in (load_rig_views(clip / "rig.json"), None):
        stream = DetectionStream(open_source(folder), colours, settings, layout)
        got = list(stream)
        assert len(got) == 75 and stream.keep_between is True
        assert sum(len(det) for _, det, _ in got[:35]) == 0 and all(len(det) > 100 for _, det, _ in got[35:])
    alone = DetectionStream(open_source(clip / "clip.mp4"), colours, settings, None, 0, 40)
    list(alone)
    assert np.allclose(stream.layout.boundaries, alone.layout.boundaries, atol=3.0)
    scores = {}
    for name, video in (("slate", folder), ("alone", clip / "clip.mp4")):
        code, out, err = _run(["track", video, "--light", "normal", "--camera", clip / "camera.json", "--frames",
                               "0:75" if name == "slate" else "0:40", "-o", tmp_path / f"{name}.c3d", "--report",
                               tmp_path / f"{name}.json"], capsys)
        assert code == 0, err
        scores[name] = (*scored_take(clip, tmp_path / f"{name}.c3d", tmp_path / f"{name}.json"), out + err)
    s, report, _, text = scores["slate"]
    assert "warning: the first 35 frames (0 to 34) show no face" in text
    assert report["frames"]["first"] == 35 and report["frames"]["count"] == 40
    assert s["identity_switches"] == 0 and s["seen_reported_fraction"] > 0.9
    assert s["seen_reported_fraction"] == scores["alone"][0]["seen_reported_fraction"]


def test_a_held_out_washed_out_take_keeps_its_labels(tmp_path, capsys):
    """#18, stop 42, held out: umber600 (960x600, a deep skin of sRGB 125,85,65, 180 dots of 3 mm 680 mm away,
    mirrors at 42 deg; rendered after the rule for washed-out dots was set) re-encoded at H.264 CRF 23 holds 7 %
    as many blobs between the colour classes as dots in its first 30 frames. With them dropped its take reported
    57.4 % of the seen marker-frames with 60 identity switches, 2.09 mm RMS; kept, 76.8 %, 7 switches, 0.75 mm."""
    text = _tracked("umber600_crf23", tmp_path, capsys)
    clip = ROOT / "sample_scenes" / "normal" / "umber600_crf23"
    s, report, _ = scored_take(clip, tmp_path / "umber600_crf23.c3d", tmp_path / "umber600_crf23.json")
    print(f"umber600_crf23: {100 * s['seen_reported_fraction']:.2f} %, {s['identity_switches']} switches, "
          f"{s['rms_mm']:.3f} mm RMS")
    assert report["between_classes"]["kept"] is True and "They were kept" in text
    assert s["seen_reported_fraction"] > 0.74 and s["identity_switches"] <= 10 and s["rms_mm"] < 1.0


def test_a_take_that_measures_few_of_the_dots_it_shows_says_so(tmp_path, capsys):
    """#18, stop 40: small540 (normal light, 960x540, 240 dots of 2.2 mm 700 mm away: 3.2 px across in the direct
    view, 2.8 and 2.5 px in the mirrors; rendered at the stop and held out from the threshold's choice). Video's
    halved colour resolution blends dots that small into the skin, and the mirrors show 36 and 19 of ~70 visible
    images a frame. The command ran to its end, exit 0, and wrote a take of 5 markers of 240 -- 1 % of the seen
    marker-frames -- with nothing but the count of undecided markers to say so. REPORT.json's ``coverage`` now
    says a typical frame measures 1 of the 146 dots its direct view shows, and one warning line says so with the
    dots' sizes; the light clip (99 %) has no such line. (Stop 42: its dots' colours wash out between the classes --
    16.8 % as many as the dots found -- and kept, they lift the typical frame's share from 0.7 % to 10 %: still far
    short of the 30 % the warning asks for.)"""
    runs = {}
    for name in ("small540", "light"):
        text = _tracked(name, tmp_path, capsys)
        runs[name] = (json.loads((tmp_path / f"{name}.json").read_text()), text)
    report, text = runs["small540"]
    coverage = report["coverage"]
    assert coverage["enough"] is False and coverage["measured_share"] < 0.15 and coverage["direct_dots"] > 100
    assert max(coverage["dot_px"][1:]) < 3.0 and coverage["dot_px"][0] > max(coverage["dot_px"][1:])
    warned = [w for w in report["warnings"] if w.startswith("in a typical frame the take measures")]
    assert len(warned) == 1 and "px in the mirrors" in warned[0]
    assert "warning: in a typical frame the take measures" in text  # on the command line
    report, text = runs["light"]
    assert report["coverage"]["enough"] is True and report["coverage"]["measured_share"] > 0.9
    assert "typical frame the take measures" not in text


def test_detect_says_when_the_mirrors_dots_are_too_small_for_normal_light(tmp_path, capsys):
    """#18, stop 40: `mirrorcap detect` reports each view's typical dot (DETECTIONS.json ``dot_px``, the median
    blob's diameter) and, under normal light, warns when a mirror's dots measure under
    detect.NORMAL_LIGHT_MIN_DOT_PX -- before a track that would measure 1 % of them (small540: 2.8 and 2.5 px in
    the mirrors). The light clip's mirrors (5.5 px) get no warning; nor did the seven other normal-light clips
    (3.6-7.0 px) when the limit was chosen, while held-out pale600 (3.0 px, its mirrors' scales not linkable) did."""
    runs = {}
    for name in ("small540", "light"):
        clip = ROOT / "sample_scenes" / "normal" / name
        code, out, err = _run(["detect", clip / "clip.mp4", "--light", "normal", "--frames", "0:20", "--rig",
                               clip / "rig.json", "-o", tmp_path / f"{name}.csv"], capsys)
        assert code == 0, err
        runs[name] = (json.loads((tmp_path / f"{name}.json").read_text())["dot_px"], out)
    px, out = runs["small540"]
    assert px["direct"] > px["mirror0"] > 2.0 and max(px["mirror0"], px["mirror1"]) < 3.0
    assert "warning: the mirrors' dots measure" in out and "px across" in out
    px, out = runs["light"]
    assert min(px.values()) > 5.0 and "dots measure" not in out


def test_two_touching_dots_of_two_colours_are_two_dots():
    """#18, stop 38: two dots of two colours touching in the image (at a mirror's grazing angle, or neighbours
    foreshortened into each other) were one connected blob whose mean hue is neither's, which the hue test
    dropped: both dots lost (tan720: 162 of its 308 unreported seen marker-frames had no mirror blob within
    6 px). colordots.split_by_colour splits a blob where two classes' pixels sit SPLIT_APART_PX apart; a lone
    dot, whose rim blended with the skin drifts towards the skin's hue all round, stays whole."""
    green, magenta = (60, 175, 30), (160, 30, 215)
    img = np.zeros((200, 200, 3), np.uint8)
    img[:] = (110, 140, 190)                                            # a tanned skin (BGR)
    yy, xx = np.mgrid[:200, :200]
    img[(xx - 100) ** 2 + (yy - 100) ** 2 <= 12] = green               # two dots of ~3.5 px radius, touching
    img[(xx - 106) ** 2 + (yy - 100) ** 2 <= 12] = magenta
    img[(xx - 60) ** 2 + (yy - 60) ** 2 <= 12] = green                 # and one alone
    img = cv2.GaussianBlur(img, (3, 3), 0.8)
    classes = ColorClasses.default("normal")
    det = marker_extractor(classes, ExtractionSettings(light="normal"))(img)
    found = {(round(float(x)), round(float(y))): classes.names[c] for x, y, c in zip(det.x, det.y, det.color)}
    assert found == {(60, 60): "green", (100, 100): "green", (106, 100): "magenta"}
    pair = np.hypot(det.x - 100.0, det.y - 100.0) < 1.0
    assert np.hypot(det.x[pair] - 100.0, det.y[pair] - 100.0).max() < 0.5
    alone = np.hypot(det.x - 60.0, det.y - 60.0) < 1.0
    assert det.area[alone][0] >= 50                                    # its whole rim (57 px), not split off

def test_a_shadow_of_the_skins_hue_beside_a_dot_does_not_move_it():
    """#18, stop 36, the full-HD clip: a blue dot at the jaw line touched the jaw's shadow -- darker and
    more saturated than the skin, so unlike it in chromaticity, but of the skin's hue -- and the two were
    one blob, its centre 8 px off the dot: never paired, never tracked. A candidate pixel (brighter than
    twice min_value) must differ from the skin around it in hue by FROM_SKIN_DEG, so the shadow is not
    part of the dot. A dark pixel's hue is noise, so the test leaves those alone."""
    skin_bgr, shadow_bgr, blue_bgr = (150, 170, 210), (70, 100, 160), (230, 70, 30)
    img = np.zeros((200, 200, 3), np.uint8)
    img[:] = skin_bgr
    img[105:113, 80:121] = shadow_bgr                                  # the shadow, touching the dot's bottom
    yy, xx = np.mgrid[:200, :200]
    img[(xx - 100) ** 2 + (yy - 100) ** 2 <= 25] = blue_bgr            # a dot of 5 px radius at (100, 100)
    det = marker_extractor(ColorClasses.default("normal"), ExtractionSettings(light="normal"))(img)
    near = np.hypot(det.x - 100.0, det.y - 100.0)
    # within a pixel (the seam where blue meets the shadow blends to a hue of neither); joined, 3.2 px off
    # and 408 px in area, the dot 81 px alone
    assert near.min() < 1.2 and det.color[int(np.argmin(near))] == ColorClasses.default("normal").names.index("blue")
    assert det.area[int(np.argmin(near))] < 200 and len(det.x) == 1   # and the shadow is no dot


def test_hv2_dots_paired_with_other_dots_images_at_a_mirrors_silhouette(tmp_path, capsys):
    """#18, stop 53: hv2 (held out, tuned on by nothing: the dark skin, 1152x648, 240 dots of 2.8 mm, mirrors at 45
    and 41 deg, the head 5 mm off the axis, +-15 deg yaw), tracked as a user runs it with no --light (the first frame
    says ordinary light). Two brow dots at one image height, each hidden from the mirror across, took each the
    other's image (the band cannot tell: both lie on one line of each mirror), 8-9 mm off along their rays from the
    first frames: 169 points over 2 mm, one split label. Stop 54: a crossing against the face's convexity is
    swapped (``initial._settle_crossed_pairs``): both brow dots within 2 mm in every frame; 24 identity switches and
    86 points over 2 mm were left. Stop 55: a chin dot (114), seen directly at a grazing angle and hidden from mirror
    0, was a late marker paired there with the image of a like dot the direct view does not see, 6-11 mm off along
    its ray for 45 frames; its own pairing with mirror 1, a rival on its direct track, lay no nearer the face (3.4 mm
    against 3.1) but holds over more chained frames (78 against 62), and now replaces it
    (``late._replaces_rival``): no identity switch, 41 points over 2 mm (a dot drifting 4 mm at a mirror's
    silhouette is left: README, "Known failures")."""
    out = _tracked("hv2", tmp_path, capsys)
    assert "light: ordinary (coloured dots), as frame 0 shows it" in out
    s, _, _ = scored_take(ROOT / "sample_scenes" / "normal" / "hv2", tmp_path / "hv2.c3d", tmp_path / "hv2.json")
    brow_and_chin = s["error_mm"][:, np.isin(s["ids"], [52, 53, 114])]
    assert brow_and_chin.shape[1] == 3 and np.nanmax(brow_and_chin) < 2.0
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    # stop 56: 41 -> 1 point over 2 mm, 0.34 -> 0.28 mm (late.LATE_OFF_FACE_CAMERA_MM)
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 2
    assert s["seen_reported_fraction"] > 0.97 and s["rms_mm"] < 0.3


def test_hx4_a_dot_found_again_on_its_direct_track_under_a_second_label_merges_back(tmp_path, capsys):
    """#18, stop 55: hx4 (held out until then: a dark skin of sRGB 110, 75, 58, 1152x648, 280 dots of 2.6 mm,
    mirrors at 44 and 42 deg tilted -3 and 4 deg, the head pitched 6 deg and swinging +-16 deg in pitch), tracked
    as a user runs it: no rig file, no --light. A chin dot lost through mirror 0 at frame 35 was found again at
    frame 60 on the same direct-view 2D track with a new mirror track, under a second label; over the 30 frames of a
    fast expression the first label's conjecture lay 1.07 mm (median) from the second's points, just over the
    1 mm that merges two labels. Two labels that are the only ones measured on one direct track merge within
    2 mm (``splits.SOLE_TRACK_MERGE_MM``): 2 split labels -> 1. Left (README, known failures): a dot measured in 12
    scattered frames before frame 29 and again from frame 58, too little for its learned relations to follow."""
    clip = ROOT / "sample_scenes" / "normal" / "hx4"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "-o", tmp_path / "hx4.c3d",
                           "--report", tmp_path / "hx4.json"], capsys)
    assert code == 0, err
    assert "light: ordinary (coloured dots), as frame 0 shows it" in out + err
    s, _, _ = scored_take(clip, tmp_path / "hx4.c3d", tmp_path / "hx4.json")
    assert np.count_nonzero(s["ids"] == 242) == 1                  # the chin dot: one label
    assert s["split_markers"] <= 1 and s["identity_switches"] == 0
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    # stop 56: 38 -> 4 points over 2 mm, 0.33 -> 0.30 mm (late.LATE_OFF_FACE_CAMERA_MM)
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 4
    assert s["seen_reported_fraction"] > 0.97 and s["rms_mm"] < 0.31


def test_a_late_chain_replaces_its_rival_on_a_direct_track_when_nearer_the_face_or_else_better_paired():
    """#18, stop 55: of two late chains on one direct 2D track at two depths (``late._rival``), the later one
    replaces the kept one when 2 mm nearer the face along its ray; where neither is that much nearer (at a grazing
    angle the face around a dot says little: hv2's chin dot), when its pairing of 2D tracks is the better supported.
    A chain clearly farther from the face never replaces its rival, nor one whose distance is unknown."""
    from mirrorcap.core.track.late import RIVAL_NEARER_MM, _replaces_rival

    clear = RIVAL_NEARER_MM + 0.5
    assert _replaces_rival(clear, better_paired=False)
    assert not _replaces_rival(-clear, better_paired=True)
    assert _replaces_rival(-0.3, better_paired=True) and _replaces_rival(0.3, better_paired=True)
    assert not _replaces_rival(0.3, better_paired=False) and not _replaces_rival(-0.3, better_paired=False)
    assert not _replaces_rival(float("nan"), better_paired=True)


def test_where_the_face_fits_loosely_a_late_chains_band_and_pairing_decide_against_its_rival():
    """#18, stop 56, held-out hy6: where the plane through a dot's neighbours fits them loosely (the face curving
    away at the silhouette), a chain's distance from it decides only beyond RIVAL_MISFIT_FACTOR times that misfit;
    within it, where the band residual and the pairing support agree on one chain, that chain stays; where they
    disagree, the rule of stop 55 holds. A plane that fits closely keeps the 2 mm margin."""
    from mirrorcap.core.track.late import RIVAL_MISFIT_FACTOR, RIVAL_NEARER_MM, _replaces_rival

    loose = 5.0                                                        # hy6: the plane 5 mm off its markers
    nearer = 4.0                                                       # hy6: the wrong pairing 4 mm nearer
    assert nearer > RIVAL_NEARER_MM and nearer < RIVAL_MISFIT_FACTOR * loose
    assert not _replaces_rival(nearer, better_paired=False, better_fit=False, misfit_mm=loose)
    assert _replaces_rival(-nearer, better_paired=True, better_fit=True, misfit_mm=loose)
    assert _replaces_rival(nearer, better_paired=False, better_fit=True, misfit_mm=loose)      # split: stop 55's
    assert not _replaces_rival(-nearer, better_paired=True, better_fit=False, misfit_mm=loose)
    assert _replaces_rival(RIVAL_MISFIT_FACTOR * loose + 0.5, better_paired=False, better_fit=False, misfit_mm=loose)
    assert _replaces_rival(nearer, better_paired=False, better_fit=False, misfit_mm=0.3)        # a close fit
    assert not _replaces_rival(float("nan"), better_paired=True, better_fit=True, misfit_mm=loose)


def test_hy2_a_silhouette_dot_keeps_its_own_mirror_image_over_a_like_dots(tmp_path, capsys):
    """#18, stop 56: hy2 (held out until then: a light skin of sRGB 200, 160, 140, 1024x576 at a 1400 px focal
    length, 240 dots of 2.4 mm, mirrors at 42 and 40 deg, the head turned 5 deg and swinging +-14 deg in yaw; the
    direct view touches mirror 1's), tracked as a user runs it. A cheek dot at the silhouette had two like images on
    its line in mirror 0: its own and that of a dot the direct view does not see, 10.7 mm deeper. Its late chain on
    its own image was kept first; then an earlier stretch of it, read at frame 0 where the plane through its
    neighbours misses the face curving away (9.1 mm off it), gave the marker its distance from the face, and the chain
    on the wrong image (2.1 mm off) replaced it: 30 frames 10.7 mm off, 14 identity switches. A late marker's distance
    from the face is now the nearest any of its stretches came (2.97 mm), and the better supported pairing (74 chained
    frames against 25) stays."""
    clip = ROOT / "sample_scenes" / "normal" / "hy2"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "-o", tmp_path / "hy2.c3d",
                           "--report", tmp_path / "hy2.json"], capsys)
    assert code == 0, err
    s, _, _ = scored_take(clip, tmp_path / "hy2.c3d", tmp_path / "hy2.json")
    cheek = np.flatnonzero(s["ids"] == 140)
    assert cheek.size == 1 and np.nanmax(s["error_mm"][:, cheek]) < 1.0
    assert np.isfinite(s["error_mm"][:30, cheek]).all()                # reported from the first frame
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    # stop 57: the mirrors' scales, linked through the head's motion, rest on the markers that move rigidly with it
    # (core.track.mirrorscale.RIGID_SHARE): 4 -> 0 points over 2 mm, 0.41 -> 0.27 mm RMS
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 1
    assert s["seen_reported_fraction"] > 0.99 and s["rms_mm"] < 0.31


def test_hy6_two_like_silhouette_dots_keep_their_own_images(tmp_path, capsys):
    """#18, stop 56: hy6 (held out until then: a skin of sRGB 90, 60, 45, 960x540, 220 dots of 2.6 mm, mirrors at
    45 deg, the head turned), tracked as a user runs it. Two like dots at the silhouette 12.7 mm apart (47 and 180)
    lie each on the other's line in mirror 1. Dot 180, a late marker, was kept on dot 47's image (its chain 2.2 mm off
    the plane through its neighbours against its own pairing's 6.2 mm, the plane 5 mm off its markers), and dot 47's
    label took dot 180's direct blob where the two claimed one image: 12 identity switches, points 8-9 mm off, dot 180
    never tracked. Where the plane fits that loosely the band and the pairing decide (``late._replaces_rival``)."""
    clip = ROOT / "sample_scenes" / "normal" / "hy6"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "-o", tmp_path / "hy6.c3d",
                           "--report", tmp_path / "hy6.json"], capsys)
    assert code == 0, err
    s, _, _ = scored_take(clip, tmp_path / "hy6.c3d", tmp_path / "hy6.json")
    for dot in (47, 180):
        label = np.flatnonzero(s["ids"] == dot)
        assert label.size == 1 and np.nanmax(s["error_mm"][:, label]) < 2.5
        assert np.isfinite(s["error_mm"][:, label]).sum() >= 70
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 24
    assert s["seen_reported_fraction"] > 0.945 and s["rms_mm"] < 0.45
