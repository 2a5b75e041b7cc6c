"""Issue #18: tracking that holds on rigs it was not tuned to, checked on Cycles-rendered clips
(``sample_scenes/make_rig_clip.py``) through the command line, as a user runs it."""

from __future__ import annotations

import contextlib
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import scored_take
from mirrorcap.cli import parser as cli

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "sample_scenes" / "rig_clip"


def _run(args, capsys):
    code = cli.main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _mirrors_json(path: Path, normals, ds) -> Path:
    path.write_text(json.dumps({"mirrors": [{"mirror": k, "normal": list(map(float, n)), "d": float(d)}
                                            for k, (n, d) in enumerate(zip(normals, ds))], "units": "mm"}))
    return path


def test_a_take_whose_mirror_scales_disagree_is_flagged(tmp_path, capsys):
    """The true planes agree; the same planes with one mirror's d 2 % too large put every marker
    seen in both mirrors ~13 mm apart along its ray: REPORT.json says so, and so does the CLI."""
    truth = np.load(SAMPLE / "truth.npz")
    normals, ds = truth["mirror_normals"], truth["mirror_d"]
    runs = {}
    for name, scale in (("true", 1.0), ("scaled", 1.02)):
        mirrors = _mirrors_json(tmp_path / f"{name}.json", normals, ds * np.array([1.0, scale]))
        code, out, err = _run(["track", SAMPLE / "clip.mp4", "--camera", SAMPLE / "camera.json", "--rig",
                               SAMPLE / "rig.json", "--mirrors", mirrors, "-o", tmp_path / f"{name}.c3d",
                               "--report", tmp_path / f"{name}.json"], capsys)
        assert code == 0, err
        runs[name] = (json.loads((tmp_path / f"{name}.json").read_text()), out + err)
    good, text = runs["true"]
    agree = good["mirror_agreement"]
    assert agree["consistent"] is True and agree["markers"] >= 30
    assert abs(agree["median_difference"]) < agree["expected_sd"]
    assert "mirrors disagree" not in text and not any("disagree" in w for w in good["warnings"])
    assert good["mirror_scale_link"] is None  # planes from the file: nothing linked
    assert good["coverage"]["enough"] is True and good["coverage"]["measured_share"] > 0.9
    bad, text = runs["scaled"]
    agree = bad["mirror_agreement"]
    assert agree["consistent"] is False
    assert agree["relative_difference"] == pytest.approx(-0.02, abs=0.004)  # mirror 1 2 % too far: its depths 2 % long
    assert abs(agree["median_difference"]) > 5 * agree["expected_sd"]
    assert any("two mirrors disagree" in w for w in bad["warnings"])
    assert "warning: the two mirrors disagree" in text  # one line on the command line


def test_dense_rig_at_the_papers_resolution_self_calibrated(tmp_path, capsys):
    """The dense stress clip (`make stress-clips`: 720x480, 290 markers of 2.2 mm, mirror planes
    at 40 deg to the axis), its first 60 frames, mirrors self-calibrated: the two mirrors' scales
    linked through markers tracked in both within 0.5 % (the issue's rig was 2 % off), the take
    within the issue's 0.5 mm RMS after one similarity, no identity switch, no point over 2 mm.
    The dots are ~4 px across here: fragments merge within the frame's typical dot (4.1 px), not a
    fixed 6 px, which merged neighbouring dots of one colour (measured with 6 px: 90.4 % of the seen
    marker-frames reported, 0.26 mm RMS, 14 points over 2 mm; now 92.2 %, 0.22 mm, none)."""
    from mirrorcap.core.geometry.camera import Camera
    from mirrorcap.core.take.c3d import read_c3d
    from mirrorcap.synthetic.evaluate import score_take

    clip = ROOT / "sample_scenes" / "stress" / "dense"
    code, out, err = _run(["track", clip / "clip.mp4", "--frames", "0:60", "--camera", clip / "camera.json",
                           "--rig", clip / "rig.json", "-o", tmp_path / "take.c3d", "--report",
                           tmp_path / "take.json"], capsys)
    assert code == 0, err
    report = json.loads((tmp_path / "take.json").read_text())
    truth = np.load(clip / "truth.npz")
    ds = [m["d"] for m in report["mirrors"]]
    assert ds[1] / ds[0] == pytest.approx(truth["mirror_d"][1] / truth["mirror_d"][0], rel=0.005)
    assert report["mirror_scale_link"]["markers"] >= 10 and report["mirror_agreement"]["consistent"] is True
    take = read_c3d(tmp_path / "take.c3d")
    vis = truth["visible"][:60]
    s = score_take(take["points"], truth["points"][:60], Camera.from_dict(json.loads((clip / "camera.json")
                                                                                      .read_text())),
                   conjectured=take["conjectured"], seen=vis[:, 0] & (vis[:, 1] | vis[:, 2]))
    assert s["markers_tracked"] >= 200 and s["markers_matched"] == s["markers_tracked"]
    assert s["identity_switches"] == 0
    assert s["rms_mm"] < 0.25
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.nanmax(err_mm) < 2.0
    assert s["seen_reported_fraction"] > 0.915


def test_later_chains_of_a_marker_merge_back_into_it(tmp_path, capsys):
    """#18: on the head-motion stress clip (300 frames, +-15 deg yaw, fast expressions) four markers were
    each picked up again later as a second label. Three are no longer lost: their dots are followed on
    their 2D tracks through motion faster than the gate (core.track.tracker, ``follow_2d_max_mm``). A later
    chain that lies within 1 mm of the earlier marker's conjecture (its learned neighbour relations)
    at every frame it is measured merges back into it, and so does one whose dot the earlier label's
    followed dots reach: no split left, no identity switch, the take as accurate."""
    from mirrorcap.core.geometry.camera import Camera
    from mirrorcap.core.take.c3d import read_c3d
    from mirrorcap.synthetic.evaluate import score_take

    clip = ROOT / "sample_scenes" / "stress" / "motion"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--rig", clip / "rig.json",
                           "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json"], capsys)
    assert code == 0, err
    report = json.loads((tmp_path / "take.json").read_text())
    truth = np.load(clip / "truth.npz")
    take = read_c3d(tmp_path / "take.c3d")
    seen = truth["visible"][:, 0] & (truth["visible"][:, 1] | truth["visible"][:, 2])
    s = score_take(take["points"], truth["points"], Camera.load(clip / "camera.json"),
                   conjectured=take["conjectured"], seen=seen)
    print(f"motion clip: {report['per_frame']['merged_labels'][0]} labels merged, {s['split_markers']} split left, "
          f"{s['identity_switches']} switches, {100 * s['seen_reported_fraction']:.2f} % reported")
    # merged by their conjectures (core.track.splits.merge_split_labels) or when a followed dot reaches the
    # later label's measurement (core.track.singleview.follow_dots_through_gaps): none left
    assert report["per_frame"]["merged_labels"][0] >= 1 and s["split_markers"] == 0
    # 98.9 % reported with the dots followed through gaps (core.track.singleview; 94.9 % before) and past
    # the gate on their 2D tracks (98.5 % before); stop 35: 99.6 % with the clip's 2D tracks linked within 0.8 of
    # the blob spacing (pairing.clip_link_gate_px; 99.0 % at 8 px)
    assert s["identity_switches"] == 0 and s["rms_mm"] < 0.2 and s["seen_reported_fraction"] > 0.993


def test_the_clips_visibility_truth_matches_what_the_detector_finds(tmp_path, capsys):
    """truth.npz's ``visible`` (skin within 73 deg of facing the view, in the view's rectangle,
    on the mirror panel, the light path clear of the head) is what completeness is measured
    against: on the sample clip nearly every marker it calls seen in a view is detected there."""
    from scipy.spatial import cKDTree

    from mirrorcap.core.capture.detect import read_detections
    from mirrorcap.core.geometry.camera import Camera
    from mirrorcap.core.geometry.mirror import reflect_points

    code, _, err = _run(["detect", SAMPLE / "clip.mp4", "--frames", "0:40", "--camera", SAMPLE / "camera.json",
                         "--rig", SAMPLE / "rig.json", "-o", tmp_path / "det.csv", "-q"], capsys)
    assert code == 0, err
    det = read_detections(tmp_path / "det.csv")
    truth = np.load(SAMPLE / "truth.npz")
    camera = Camera.from_dict(json.loads((SAMPLE / "camera.json").read_text()))
    found, seen = np.zeros(3), np.zeros(3)
    for f in range(40):
        P = truth["points"][f]
        for v in range(3):
            P_v = reflect_points(P, truth["mirror_normals"][v - 1], truth["mirror_d"][v - 1]) if v else P
            vis = truth["visible"][f, v]
            pick = (det["frame"] == f) & (det["view"] == v)
            dist = cKDTree(np.c_[det["x"][pick], det["y"][pick]]).query(camera.project(P_v[vis]))[0]
            found[v] += np.count_nonzero(dist <= 1.5)
            seen[v] += vis.sum()
    assert seen.min() > 1000
    assert (found / seen > 0.98).all(), found / seen  # measured 0.9996, 0.991, 0.9988 over the clip


def test_the_sample_clip_reports_its_seen_markers(tmp_path, capsys):
    """#18's completeness target on the sparse 1280x720 clip, as a user runs `mirrorcap track`: >= 99 %
    of the marker-frames seen in the direct view and a mirror reported (99.4 % measured; 97.5 % before
    dots were followed through gaps and conjectures measured where seen, core.track.singleview), no
    identity switch, no point over 2 mm. Stop 33: dot 40 took dot 0's image grazing in mirror 1 by
    its hidden one, 2.9 mm off; a marker now keeps the pairing of the mirror track it has held
    (``tracker.HELD_FRAMES``) over a nearer pairing of its direct blob: max 1.3 mm."""
    from mirrorcap.core.geometry.camera import Camera
    from mirrorcap.core.take.c3d import read_c3d
    from mirrorcap.synthetic.evaluate import score_take

    code, out, err = _run(["track", SAMPLE / "clip.mp4", "--camera", SAMPLE / "camera.json", "--rig",
                           SAMPLE / "rig.json", "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json"],
                          capsys)
    assert code == 0, err
    report = json.loads((tmp_path / "take.json").read_text())
    assert not report["view_layout"]["crowded"] and "runs through dots" not in out + err  # the views' gaps are clear
    assert report["mirror_agreement"]["consistent"] is True
    truth = np.load(SAMPLE / "truth.npz")
    take = read_c3d(tmp_path / "take.c3d")
    seen = truth["visible"][:, 0] & (truth["visible"][:, 1] | truth["visible"][:, 2])
    s = score_take(take["points"], truth["points"], Camera.load(SAMPLE / "camera.json"),
                   conjectured=take["conjectured"], seen=seen)
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    print(f"sample clip: {100 * s['seen_reported_fraction']:.2f} % reported, never tracked {s['never_tracked']}, "
          f"{s['identity_switches']} switches, max {np.nanmax(err_mm):.2f} mm")
    assert s["seen_reported_fraction"] >= 0.99
    assert s["identity_switches"] == 0 and np.nanmax(err_mm) < 2.0
    # its one split label (a lower-lip marker behind the upper lip for 8 frames while the mouth moved
    # 8 mm sideways; mirror 1 kept the dot) merges along that mirror's 2D track (splits.merge_along_2d_tracks)
    assert s["split_markers"] == 0


def test_views_that_cut_through_the_face_are_flagged_and_the_clips_own_views_hold(tmp_path, capsys):
    """#18, the held-out mirror45 clip (mirrors at 45 deg, 200 markers of 3 mm): the clip maker had
    split the views at the mirror panels' edges, but the cheeks pass in front of mirrors turned this
    far, so the line ran through the face (~30 % of the mirror views' blobs were direct-view dots).
    With those views the take was silently wrong (mirror 1 0.41 deg off, 50 switches); now REPORT.json
    and the command line say the boundaries run through dots. With the views split where the fewest dots cross
    (the clip maker's rig.json now), self-calibration holds: 0 switches, 0.22 mm RMS, scales 0.02 % apart."""

    clip = ROOT / "sample_scenes" / "stress" / "mirror45"
    panel_edges = tmp_path / "panel_edges.json"
    panel_edges.write_text(json.dumps({"views": {"mirror0": [0, 0, 529, 720], "direct": [529, 0, 750, 720],
                                                 "mirror1": [750, 0, 1280, 720]}}))
    runs = {}
    for name, rig in (("panel edges", panel_edges), ("clip", clip / "rig.json")):
        code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--rig", rig,
                               "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json"], capsys)
        assert code == 0, err
        s, report, ratio_error = scored_take(clip, tmp_path / "take.c3d", tmp_path / "take.json")
        runs[name] = (report, out + err, s, ratio_error)
    code, out, err = _run(["detect", clip / "clip.mp4", "--frames", "0:30", "--rig", panel_edges,
                           "-o", tmp_path / "det.csv", "-q"], capsys)
    assert code == 0, err
    checked = json.loads((tmp_path / "det.json").read_text())["view_layout"]
    assert checked["crowded"] and all(b["crowded"] for b in checked["boundaries"])
    report, text, s, ratio_error = runs["panel edges"]
    assert all(b["crowded"] and b["crowding"] > 1.0 for b in report["view_layout"]["boundaries"])
    assert [b["x"] for b in report["view_layout"]["boundaries"]] == [529, 750]
    assert text.count("runs through dots") == 2
    # what the user gets from such views: the warnings are earned. Stop 32: 45 identity switches, 1.55 mm RMS;
    # since stop 33 (the touching-dot cut, the held mirror track) no switch, but 97 markers and 42 % of the seen
    # marker-frames, against 149 and 98 % with the clip's own views
    assert s["seen_reported_fraction"] < 0.6 and s["markers_tracked"] < 110
    report, text, s, ratio_error = runs["clip"]
    assert report["mirror_agreement"]["consistent"] is True
    assert abs(ratio_error) < 0.001
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert s["markers_tracked"] >= 135 and s["markers_matched"] == s["markers_tracked"]
    assert s["rms_mm"] < 0.3
    # stop 32: a marker paired in the first frames, lost by the final pass at frame 14 though its dot
    # is detected in both views throughout, is followed on (94.3 % -> 95.7 %); stop 33: 98.4 %; stop 35: a dot at
    # the face's silhouette, off the plane through its neighbours but on the face as the mirror sees it, is a late
    # marker (onface.off_in_mirrors): 99.1 %
    assert s["seen_reported_fraction"] > 0.985


def test_a_rig_whose_mirrors_share_no_marker_links_their_scales_through_head_motion(tmp_path, capsys):
    """#18, held-out mirror35 clip (960x540, 250 markers of 2.5 mm, mirrors at 35 deg, rendered after
    this stop's tracker changes): no marker is ever seen in both mirrors, so the two mirrors' scales
    cannot be linked through shared markers (`track` refused: "only 0 sightings"). The head's motion
    moves both halves of the face with one rotation, and each half's centroid then gives the
    translation in its own mirror's scale (core.track.mirrorscale.link_mirror_scales_by_motion):
    scales 0.07 % apart from the truth, 0 switches, 0.32 mm RMS (0.31 mm with the true planes).
    Self-calibration's least squares now runs to convergence: 6 rounds had left the normals 0.08 and
    0.13 deg off on this clip (30 switches, 1.04 mm RMS); converged, 0.02 deg. Since stop 57 the link rests on each
    mirror's more rigid half of its markers: here 0.14 % off and 0.28 mm RMS, the one committed clip it set back."""

    clip = ROOT / "sample_scenes" / "stress" / "mirror35"
    truth = np.load(clip / "truth.npz")
    assert not (truth["visible"][:, 1] & truth["visible"][:, 2]).any()  # no marker in both mirrors
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--rig", clip / "rig.json",
                           "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json"], capsys)
    assert code == 0, err
    s, report, ratio_error = scored_take(clip, tmp_path / "take.c3d", tmp_path / "take.json")
    link = report["mirror_scale_link"]
    assert link["source"].startswith("head motion") and min(link["markers_per_mirror"]) >= 30
    assert link["standard_error"] < 0.002
    assert abs(ratio_error) < 0.002
    normals = [np.array(m["normal"]) for m in report["mirrors"]]
    for n, n_true in zip(normals, truth["mirror_normals"]):
        assert np.degrees(np.arccos(min(1.0, abs(n @ n_true)))) < 0.05
    assert s["identity_switches"] == 0 and s["markers_matched"] == s["markers_tracked"] >= 100
    assert s["rms_mm"] < 0.4


def test_the_head_motion_link_matches_the_shared_marker_link_and_refuses_a_still_head(capsys):
    """On the sample clip, where 80 markers are seen in both mirrors, the head-motion link gives the
    same ratio within 0.15 % of the truth (measured 0.04 %; the shared-marker link 0.07 %). A head
    that does not move (one frame repeated) cannot fix the ratio: one clear error."""
    from mirrorcap.core.capture.views import ClipDetections
    from mirrorcap.core.common.errors import DegenerateError
    from mirrorcap.core.geometry.camera import Camera
    from mirrorcap.core.track.mirrorscale import link_mirror_scales_by_motion
    from mirrorcap.core.track.selfcal import self_calibrate_mirror

    camera = Camera.load(SAMPLE / "camera.json")
    truth = np.load(SAMPLE / "truth.npz")
    frames = _rig_clip_frames(SAMPLE)
    det = ClipDetections.of(frames, camera)
    cals = [self_calibrate_mirror(det.head(10), camera, k) for k in range(2)]
    normals, ds = np.stack([c.plane.normal for c in cals]), [c.plane.d for c in cals]
    out, figures = link_mirror_scales_by_motion(det, camera, normals, ds)
    assert out[1] / out[0] == pytest.approx(truth["mirror_d"][1] / truth["mirror_d"][0], rel=0.0015)
    assert figures["samples"] >= 50 and figures["standard_error"] < 0.002
    still = ClipDetections.of([frames[0]] * 40, camera)
    with pytest.raises(DegenerateError, match="moves too little"):
        link_mirror_scales_by_motion(still, camera, normals, ds)
    # a take too short for frame pairs 10 frames apart says so, not that too few markers are held (stop 58: dense41's
    # first 20 frames said "82 and 70 held ..., where 6 are needed")
    with pytest.raises(DegenerateError, match=r"a take of 20 frames is too short .* at least 26 frames"):
        link_mirror_scales_by_motion(det.window(0, 20), camera, normals, ds)
    # frames out of order: no 2D track lasts, and the error says how few are held and how large the dots are
    shuffled = ClipDetections.of([frames[i] for i in np.random.default_rng(0).permutation(len(frames))], camera)
    with pytest.raises(DegenerateError, match=r"tracked in each mirror at once .* where 6 are needed; the dots "
                                              r"measure [\d.]+ px across in the direct view"):
        link_mirror_scales_by_motion(shuffled, camera, normals, ds)


@pytest.mark.parametrize("name, before", [("stress/wide576", -0.27), ("normal/hy2", 0.19), ("stress/dense", -0.09)])
def test_the_head_motion_link_rests_on_the_markers_that_move_rigidly(name, before):
    """#18, stop 57. Between two frames each mirror's half of the face moves by the head's translation times its
    scale -- but a cheek marker moving with a smile moves its half's centroid too. Given the true normals, the link
    over all markers came out 0.11 % off the truth on average over 59 rendered clips, ``before`` % on these three,
    and hy11 (a held-out dense rig, 720x480, 280 dots, 2-3 markers in both mirrors at once) 0.27 %, its take 0.57 mm
    RMS. Each mirror's half of its markers that strayed least from the first fits now carries the link: 0.04 % on
    average (0.007, 0.021 and 0.023 % here; hy11 0.08 %, its take 0.34 mm)."""
    from mirrorcap.core.capture.views import ClipDetections
    from mirrorcap.core.geometry.camera import Camera
    from mirrorcap.core.track.mirrorscale import link_mirror_scales_by_motion

    clip = ROOT / "sample_scenes" / name
    camera = Camera.load(clip / "camera.json")
    truth = np.load(clip / "truth.npz")
    ds, figures = link_mirror_scales_by_motion(ClipDetections.of(_rig_clip_frames(clip), camera), camera,
                                               truth["mirror_normals"], [-1.0, -1.0])
    error = ds[1] / ds[0] / (truth["mirror_d"][1] / truth["mirror_d"][0]) - 1.0
    print(f"{name}: {100 * error:+.3f} % (all markers: {before:+.2f} %), rigid markers "
          f"{figures['rigid_markers_per_mirror']} of {figures['markers_per_mirror']}")
    assert abs(error) < 0.0005
    assert all(0 < r <= (m + 1) // 2
               for r, m in zip(figures["rigid_markers_per_mirror"], figures["markers_per_mirror"]))
    assert figures["relative_spread"] < figures["relative_spread_all_markers"]


def _rig_clip_frames(clip):
    """A rendered clip folder's per-frame detections (:class:`core.capture.views.FrameDets`), found as with its rig
    file's views, under the light its clip.json names (UV where it names none)."""
    from mirrorcap.core.capture.detect import DetectionStream
    from mirrorcap.core.capture.markers import ColorClasses, ExtractionSettings
    from mirrorcap.core.capture.rig import load_rig_views
    from mirrorcap.core.capture.video import open_source
    from mirrorcap.core.track.pipeline import collect_detections

    light = json.loads((clip / "clip.json").read_text()).get("light", "uv")
    stream = DetectionStream(open_source(clip / "clip.mp4"), ColorClasses.default(light),
                             ExtractionSettings(light=light), load_rig_views(clip / "rig.json"))
    return collect_detections(stream)[1]


@contextlib.contextmanager
def _sample_script(name):
    """The script ``sample_scenes/<name>.py`` loaded as a module (its functions under test), unloaded after."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "sample_scenes" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(name, None)


def test_the_clip_makers_view_split_puts_the_fewest_dots_in_the_wrong_view():
    """sample_scenes/make_rig_clip.py's view lines (the mirror45 and dense clips' views had been cut at
    the mirror panels' edges, through the face): each line is where the fewest of one view's dots land
    on the other's side, in the middle of the widest such stretch."""
    with _sample_script("make_rig_clip") as module:
        split = module._best_split
        assert split(np.array([1.0, 2, 3]), np.array([5.0, 6, 7])) == 4.0        # a clean gap: its middle
        assert split(np.array([1.0, 2, 5.5]), np.array([5.0, 6, 7])) == 3.5      # one dot astray either way:
        assert split(np.array([1.0, 2, 5.5, 5.6]), np.array([5.0, 6, 7])) == pytest.approx(5.8)  # fewest astray


def test_the_clip_maker_sets_up_rigs_by_hand():
    """sample_scenes/make_rig_clip.py's rigs as a user sets one up by hand: each mirror at its own angle
    and tilt (``--mirror-deg L0 L1``, ``--mirror-tilt``); each mirror panel lies in its plane and still
    spans the face's height where the plane touches the sphere around it; the default rig is the
    symmetric one of the committed clips."""
    with _sample_script("make_rig_clip") as module:
        (n0, d0), (n1, d1) = module.rig_planes(module.ClipSpec(mirror_longitude_deg=41.0))
        assert n0 == pytest.approx(n1 * np.array([-1.0, 1.0, 1.0])) and d0 == pytest.approx(d1)   # symmetric
        assert n0[1] == 0.0 and np.degrees(np.arctan2(n1[0], -n1[2])) == pytest.approx(-41.0)
        rig = module.ClipSpec(mirror_longitude_deg=38.0, mirror1_longitude_deg=50.0, mirror_tilt_deg=(10.0, -6.0))
        planes, panels = module.rig_planes(rig), module.mirror_panels(rig)
        for (n, d), panel, longitude, tilt in zip(planes, panels, (-38.0, 50.0), (10.0, -6.0)):
            # the normal faces the face: its horizontal direction at the mirror's angle, tilted as asked
            assert np.degrees(np.arctan2(-n[0], -n[2])) == pytest.approx(longitude)
            assert np.degrees(np.arcsin(-n[1])) == pytest.approx(tilt)
            assert panel @ n == pytest.approx(np.full(4, d))                     # the panel lies in its plane
            touch = np.asarray(rig.mirror_centre) - n * module.MIRROR_RADIUS_MM
            up = panel[3] - panel[0]
            height = (touch - panel[0]) @ up / (up @ up)
            assert 0.3 < height < 0.7                                            # the face's height on the panel


def test_the_clip_maker_blurs_motion_over_the_open_shutter():
    """``--shutter S``: each frame is the mean, in linear light, of ``--blur-steps`` moments of the same
    performance spread over the S of the frame interval around the frame's moment (a real camera's
    exposure). The moments between frames come from the same continuous head motion and expressions
    (``at``), and the default (no blur) is the clip of before."""
    from mirrorcap.core.face.headio import load_head_npz
    from mirrorcap.synthetic.headsim import performance

    with _sample_script("make_rig_clip") as module:
        rig = module.ClipSpec(head_deg=(10.0, 14.0, 5.0), head_turn_deg=(0.0, 8.0, 0.0), head_offset_mm=(10.0, 0.0))
        R, t = module.head_pose(rig, 90, 461)
        R_at, t_at = module.head_pose(rig, 90, 461, at=np.arange(90.0))
        assert np.array_equal(R, R_at) and np.array_equal(t, t_at)          # frames sampled as before
        # between frames 40 and 41, the motion passes between the two frames' poses
        R_half, t_half = module.head_pose(rig, 90, 461, at=[40.5])
        assert np.linalg.norm(t_half[0] - (t[40] + t[41]) / 2) < 0.05 * np.linalg.norm(t[41] - t[40]) + 1e-9
        assert np.linalg.norm(R_half[0] - (R[40] + R[41]) / 2) < 0.05 * np.linalg.norm(R[41] - R[40])
        head, keys = load_head_npz(ROOT / "sample_scenes" / "generic_head" / "head.npz", with_shape_keys=True)
        disp, _ = performance(head, keys, 90, 30.0, seed=461, tempo=3.0)
        disp_at, _ = performance(head, keys, 90, 30.0, seed=461, tempo=3.0, at=[39.0, 39.5, 40.0])
        assert np.array_equal(disp_at[[0, 2]], disp[[39, 40]])
        assert np.abs(disp[40] - disp[39]).max() > 0.5                     # the expression moves there ...
        twice, _ = performance(head, keys, 180, 60.0, seed=461, tempo=3.0)  # ... as a take at twice the rate has it
        assert np.array_equal(disp_at[1], twice[79])
        assert np.abs(disp_at[1] - disp[39]).max() > 0.1 and np.abs(disp_at[1] - disp[40]).max() > 0.1
        # a smear is light averaged, not sRGB values: a dot lit half the exposure is 188 of 255, not 128
        lit, dark = module.srgb_to_linear(np.array([1.0])), module.srgb_to_linear(np.array([0.0]))
        half = module.linear_to_srgb((lit + dark) / 2)
        assert round(float(half[0]) * 255) == 188
        assert module.paint_linear((255, 110, 200)) == pytest.approx([((c / 255 + 0.055) / 1.055) ** 2.4
                                                                      for c in (255, 110, 200)])


def test_an_object_passed_before_the_face_hides_the_dots_the_truth_says(tmp_path):
    """sample_scenes/occlude_clip.py (`make occluded-clips`): a dark sphere swept before the lower face.
    What the picture shows and what the truth says agree: every marker the truth newly hides in the
    direct view has the sphere over its dot in the frame, every marker it keeps has its dot still lit
    there, and outside the sphere's frames nothing changes."""
    import cv2

    from mirrorcap.core.geometry.camera import Camera

    source = ROOT / "sample_scenes" / "stress" / "webcam"
    with _sample_script("occlude_clip") as module:
        assert module.main([str(source), str(tmp_path / "hand"), "--frames", "30", "50", "--radius-mm", "30"]) == 0
    before, after = np.load(source / "truth.npz"), np.load(tmp_path / "hand" / "truth.npz")
    assert np.array_equal(before["points"], after["points"])
    assert np.array_equal(before["visible"][:30], after["visible"][:30])
    assert np.array_equal(before["visible"][51:], after["visible"][51:])
    assert not (after["visible"] & ~before["visible"]).any()
    camera = Camera.from_dict(json.loads((source / "camera.json").read_text()))
    video = cv2.VideoCapture(str(tmp_path / "hand" / "clip.mp4"))
    original = cv2.VideoCapture(str(source / "clip.mp4"))
    hidden_seen = kept_seen = 0
    for f in range(51):
        frame, was = video.read()[1], original.read()[1]
        if f < 36:
            continue
        px = np.round(camera.project(before["points"][f])).astype(int)
        inside = (px[:, 0] >= 0) & (px[:, 0] < frame.shape[1]) & (px[:, 1] >= 0) & (px[:, 1] < frame.shape[0])
        lit_before = np.zeros(len(px), bool)
        lit_before[inside] = was[px[inside, 1], px[inside, 0]].max(axis=1) > 80
        lit_after = np.zeros(len(px), bool)
        lit_after[inside] = frame[px[inside, 1], px[inside, 0]].max(axis=1) > 80
        hidden = before["visible"][f, 0] & ~after["visible"][f, 0] & lit_before
        kept = after["visible"][f, 0] & lit_before
        assert not lit_after[hidden].any()          # the sphere covers every dot the truth hides ...
        assert lit_after[kept].mean() > 0.97         # ... and no other (a dot at its rim may dim)
        hidden_seen += hidden.sum()
        kept_seen += kept.sum()
    assert hidden_seen > 50 and kept_seen > 500


def test_a_rig_set_up_by_hand_self_calibrates_and_tracks(tmp_path, capsys):
    """Stop 45: every earlier clip had two upright mirrors at one angle each side of a head centred
    between them. askew720 (`make stress-clips`) is a rig set up by hand: mirrors at 38 and 50 deg,
    one tilted 10 deg up and one 6 deg down, the head 15 mm off the rig's axis and turned 10 deg towards
    a mirror. Tracked as a new user would, with no rig file (the views split automatically) and the
    mirrors self-calibrated: the normals within 0.06 / 0.08 deg and the distances' ratio within 0.08 %
    of the truth; 97.8 % of the seen marker-frames reported, no identity switch, 0.26 mm RMS (measured:
    its 42 points over 2 mm are the grazing-mirror failure the README names -- a marker's own direct dot
    paired with another dot's image in the 38 deg mirror -- and conjectures)."""
    s, report, ratio_error, _ = _tracked_without_a_rig_file("askew720", tmp_path, capsys)
    truth = np.load(ROOT / "sample_scenes" / "stress" / "askew720" / "truth.npz")
    for plane, normal in zip(report["mirrors"], truth["mirror_normals"]):
        assert np.degrees(np.arccos(min(1.0, float(np.dot(plane["normal"], normal))))) < 0.2
    assert abs(ratio_error) < 0.003
    assert report["mirror_agreement"]["consistent"] is True
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert s["seen_reported_fraction"] >= 0.97 and s["rms_mm"] < 0.3


def test_views_that_touch_are_split_at_the_emptiest_lines(tmp_path, capsys):
    """Over all 90 frames of the mirror45 clip the views touch (the head turns the cheeks against the
    mirror images): no empty gap, where the automatic split used to refuse. It now takes the two
    emptiest lines, with a note for the user; tracked with views there the take holds (0 switches,
    0.22 mm RMS, 93.8 % reported, measured with the lines at 450 and 830). Evenly spread detections
    are still refused."""
    from mirrorcap.core.capture.detect import read_detections
    from mirrorcap.core.capture.rig import split_views_by_gaps
    from mirrorcap.core.common.errors import InputError

    clip = ROOT / "sample_scenes" / "stress" / "mirror45"
    code, _, err = _run(["detect", clip / "clip.mp4", "--rig", clip / "rig.json", "-o", tmp_path / "det.csv", "-q"],
                        capsys)
    assert code == 0, err
    x = read_detections(tmp_path / "det.csv")["x"]
    layout = split_views_by_gaps(x, 12.0)
    b0, b1 = layout.boundaries
    assert 440 <= b0 <= 466 and 805 <= b1 <= 835       # the clip maker's truth-based lines: 464.7, 810.3
    assert layout.note and "no empty gap" in layout.note
    with pytest.raises(InputError, match="no clear gap"):
        split_views_by_gaps(np.random.default_rng(0).uniform(0, 1280, 20000), 12.0)


def test_held_out_turning_head_without_a_rig_file(tmp_path, capsys):
    """The fourth held-out clip (`sample_scenes/stress/turn`: 1600x900, 220 markers of 2.5 mm, mirrors
    at 42 deg, the head turning +-18 deg and pitching +-12 deg, expressions twice as fast), tracked as a
    new user would, without a rig file: its views touch, so the automatic split takes the emptiest lines
    and says so; the take holds -- 0 switches, 0.31 mm RMS, 96.2 % of the seen marker-frames reported,
    the mirrors' scales 0.02 % apart. (Its one bad marker: a direct dot whose mirror images are both
    hidden, paired for 31 frames with another marker's image on its epipolar line, 7.9 mm off.)"""

    s, report, ratio_error, text = _tracked_without_a_rig_file("turn", tmp_path, capsys)
    assert "no empty gap between the views" in text and report["view_layout"]["note"]
    assert abs(ratio_error) < 0.002
    assert s["identity_switches"] == 0 and s["split_markers"] == 0 and s["markers_tracked"] >= 150
    assert s["rms_mm"] < 0.35
    assert s["seen_reported_fraction"] > 0.95


def test_a_close_face_without_a_rig_file(tmp_path, capsys):
    """Stop 45: the close clip (`sample_scenes/stress/close`: a face 480 mm from a wide lens, mirrors at
    55 deg) tracked as a new user would, without a rig file, was refused ("cannot split the direct and
    mirror views automatically"): its left valley between the face and the mirror image holds two empty
    lines 27 px apart with a few dots between, and the second counted as an empty column inside a view.
    They are one valley now: the views split at x = 452 and 815 (its rig file: 478 and 812), with the
    note, and the take holds -- 99.5 % of the seen marker-frames reported (99.7 % with the rig file), no
    switch, 0.17 mm RMS, the mirrors' scales 0.01 % apart."""
    s, report, ratio_error, text = _tracked_without_a_rig_file("close", tmp_path, capsys)
    assert "no empty gap between the views" in text and report["view_layout"]["note"]
    assert abs(ratio_error) < 0.002
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert s["seen_reported_fraction"] >= 0.99 and s["rms_mm"] < 0.25


def test_a_sparse_rig_the_product_cannot_measure_is_refused_not_guessed(tmp_path, capsys):
    """The fifth held-out clip (`sample_scenes/stress/sparse`: 80 dots of 4 mm, face 550 mm away, mirrors
    at 38 deg): no marker is in both mirrors, and the 20 markers each mirror sees move with the
    expressions, so the head-motion scale link came out 1.6 % off (standard error 0.25 %) and the take
    2.0 mm RMS, 1,073 points over 2 mm, silently. Its frame pairs disagree by 2.1 % (0.1-0.4 % on every
    clip that links), so it is now refused with one message and nothing written. Without a rig file the
    automatic split would have put its lines inside the views (x = 384 and 544: sparse dots leave empty
    columns); it is refused too."""
    clip = ROOT / "sample_scenes" / "stress" / "sparse"
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--rig", clip / "rig.json",
                           "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json"], capsys)
    assert code == 2 and "do not move together closely enough" in err and "MIRRORS.json" in err
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "-o", tmp_path / "take.c3d"],
                          capsys)
    assert code == 2 and "cannot split the direct and mirror views" in err
    assert not any(tmp_path.iterdir())  # nothing written, nothing half-written


def test_a_dense_rig_whose_mirrors_share_few_markers_without_a_rig_file(tmp_path, capsys):
    """#18, stop 57: dense41 (held-out hy11 of stop 56: 720x480 like the dense clip, 280 dots of 2.2 mm 650 mm away,
    mirrors at 41 and 39 deg, 4 render samples a pixel), tracked as a user runs it. The views touch and the mirrors
    see the sides of the face: two markers are found in both at once, so the mirrors' scales are linked through the
    head's motion. Over all the markers each mirror tracks, the cheeks moving with the expressions, that link came
    out 0.21 % off and the take 0.57 mm RMS, its median marker 0.45 mm off from the first frame; on the half of each
    mirror's markers that move most rigidly with the head, 0.003 % and 0.34 mm. (With the true planes: 0.30 mm.)
    Open: m186 is paired at frame 88, after a 4-frame gap, with a like dot's image in mirror 1 (5.8 mm off, one
    identity switch), and 20 points lie over 2 mm (15 of them one dot's)."""
    s, report, ratio_error, text = _tracked_without_a_rig_file("dense41", tmp_path, capsys)
    link = report["mirror_scale_link"]
    print(f"dense41: link {link['source']}, ratio error {100 * ratio_error:+.3f} %, RMS {s['rms_mm']:.3f} mm, "
          f"{100 * s['seen_reported_fraction']:.1f} % reported, {s['identity_switches']} switches")
    assert link["source"].startswith("head motion") and abs(ratio_error) < 0.001
    assert s["rms_mm"] < 0.4 and s["seen_reported_fraction"] > 0.965 and s["split_markers"] == 0
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 20 and s["identity_switches"] <= 1


def _tracked_without_a_rig_file(name, tmp_path, capsys):
    """``mirrorcap track`` on the stress clip ``name`` as a new user runs it, with no rig file (the views split
    automatically), mirrors self-calibrated: its scores against the truth (:func:`conftest.scored_take`), its
    report, the mirrors' ratio error and what the command printed."""
    clip = ROOT / "sample_scenes" / "stress" / name
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "-o", tmp_path / "take.c3d",
                           "--report", tmp_path / "take.json"], capsys)
    assert code == 0, err
    return (*scored_take(clip, tmp_path / "take.c3d", tmp_path / "take.json"), out + err)


def _tracked_stress_clip(name, tmp_path, capsys, folder="stress"):
    """``mirrorcap track`` on the stress clip ``name`` (in ``sample_scenes/<folder>``) as a user runs it (its rig
    file, mirrors self-calibrated), scored against its truth (:func:`conftest.scored_take`)."""
    clip = ROOT / "sample_scenes" / folder / name
    code, out, err = _run(["track", clip / "clip.mp4", "--camera", clip / "camera.json", "--rig", clip / "rig.json",
                           "-o", tmp_path / "take.c3d", "--report", tmp_path / "take.json"], capsys)
    assert code == 0, err
    per_frame = json.loads((tmp_path / "take.json").read_text())["per_frame"]
    repaired, doubted, merged = (sum(per_frame[k]) for k in ("repaired", "doubted", "merged_images"))
    line = f"disowned: {repaired} re-paired onto another mirror image, {doubted} left to the gap fill"
    assert (line in out) == bool(repaired or doubted)   # the command says what the gap fill re-paired or doubted
    assert (f"({merged} of them through one blob of two dots' images)" in out) == bool(merged)
    assert f"{np.mean(per_frame['bridged']):.1f} bridged along their 2D tracks" in out   # and what the bridge measured
    return scored_take(clip, tmp_path / "take.c3d", tmp_path / "take.json")


def test_a_marker_hidden_behind_a_hand_comes_back_as_itself(tmp_path, capsys):
    """Stop 46: fast720 with a dark sphere (a hand) swept before the mouth for frames 20-60 (`make
    occluded-clips`). Two markers of one colour 10 mm apart are hidden from the camera for 14 frames of a fast
    expression while the mirror still sees them; their conjectures drift further than the gate, and one came
    back on the other's dot, the other conjectured to the end: 31 identity switches, one label carrying two
    markers, 95.8 % of the seen marker-frames, 0.52 mm RMS. A marker whose direct dot vanished now comes back on
    the mirror track it held (measured: 0 switches, 97.8 %, 0.18 mm, 7 points over 2 mm)."""
    s, _, ratio_error = _tracked_stress_clip("fast720_hand", tmp_path, capsys, folder="occluded")
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert s["seen_reported_fraction"] >= 0.975 and s["rms_mm"] < 0.25
    assert abs(ratio_error) < 0.002


@pytest.mark.parametrize("name, reported", [("close", 0.96), ("jaw", 0.995)])
def test_a_dot_moving_faster_than_the_gate_is_followed_on_its_2d_tracks(tmp_path, capsys, name, reported):
    """#18, two held-out clips: close (a face 480 mm from a wide lens, mirrors at 55 deg) and jaw
    (expressions 2.5 times as fast, 30 frames/s), where chin and lip dots move 3.5-4.6 mm in a frame,
    more than the widest gate (3 mm). Such a marker was lost in the first fast frame and, its
    conjecture off, not taken back for tens of frames (close: one never tracked at all, 93.7 % of the
    seen marker-frames reported; jaw: 95.2 %, one identity switch, a point 12.8 mm off). Its
    candidate on the 2D tracks of its last measurement (the direct view and a mirror) is now taken
    beyond the gate, when the step lies mostly across the line of sight (which the direct view
    vouches for) and along it within the widest gate (a mirror's track can slip onto a like dot
    on the same epipolar line): close 96.8 %, jaw 95.8 %, no switch, no point off by more than 3.4 mm.
    One jaw marker was still split over two labels (a chin dot measured by turns under two labels in
    frames 55-81, moving 4-8 mm a frame mostly along the line of sight): two labels that are the only
    ones on one pair of 2D tracks (direct view and mirror) are now one marker -- jaw 96.2 %, no split.
    Stop 32: with touching dots cut in two (``split_touching``) a chin dot's later frames went to a new
    label and its first label (18 frames) was dropped as lost for good (95.8 %); a marker lost for good
    now stays when its dot is followed into a later label of it and its points lie on that label's
    path (``core.track.late.settle_lost_markers``): 96.1 %. Stop 35: a fast dot's gap bracketed by its 2D
    tracks is measured (``bridge.bridge_gaps_along_2d_tracks``): jaw 96.5 -> 97.0 %; with the clip's 2D tracks
    linked within 0.8 of the blob spacing (``pairing.clip_link_gate_px``) its two chin dots hold: 99.0 %.
    Stop 52: a marker's last measurement followed on along all its 2D tracks (``bridge``): jaw 99.9 %."""
    s, report, ratio_error = _tracked_stress_clip(name, tmp_path, capsys)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0 and s["markers_matched"] == s["markers_tracked"]
    assert s["seen_reported_fraction"] > reported
    assert s["rms_mm"] < 0.25 and s["max_mm"] < 3.5
    assert abs(ratio_error) < 0.002


def test_a_dot_the_final_pass_lost_at_a_fast_peak_is_followed_on(tmp_path, capsys):
    """#18, stop 52, hq1 (held out at stop 51: 1024x576, 210 dots of 2.6 mm, mirrors at 43 and 49 deg, the head
    8 mm off the axis, expressions twice as fast): a dot by the nose, seen directly and in mirror 1 in all 75
    frames, rose 10 mm and fell back in 5 frames; the final pass lost it at the peak, its conjecture stayed 5-11 mm
    off for the rest of the take, and the marker went with its 14 measured frames: 96.6 % of the seen
    marker-frames reported. After a marker's last measurement, the candidates on its direct track and on all the
    mirror tracks it was measured on, one a frame, are now its own (``bridge.bridge_gaps_along_2d_tracks``):
    99.0 %, no switch, no split, 9 points over 2 mm as before."""
    s, report, ratio_error = _tracked_stress_clip("hq1", tmp_path, capsys)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0
    assert s["seen_reported_fraction"] > 0.985
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 10 and s["rms_mm"] < 0.25
    assert sum(report["per_frame"]["bridged"]) > 0


def test_a_dot_hidden_from_a_mirror_keeps_no_grazing_image_of_a_like_dot(tmp_path, capsys):
    """#18, hr2 (rendered after stop 52's follow-on, the mirror images touching the face): two forehead dots
    seen only directly paired with like dots' grazing mirror-1 images from the first frames; the images' own dots
    took them in other frames. Stop 52: of two labels on one mirror track, the one off the face while the other lies
    on it is undone there (``onface.off_face_on_shared_tracks``): one of the two (22 mm off the face) went, and with
    it the split label (91 -> 63 identity switches, 99 -> 63 points over 2 mm). The other, 5 mm off the face along a
    grazing ray, stayed. Stop 53: an image whose pairing over the clip holds in the band less than a like dot's,
    paired nowhere in that mirror, goes to neither (``initial._doubt_near_rivals``; that dot's image: 75 of 90
    frames against its own dot's 85): no identity switch and no point over 2 mm left."""
    s, report, _ = _tracked_stress_clip("hr2", tmp_path, capsys)
    assert s["split_markers"] == 0 and s["identity_switches"] == 0
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 2 and s["rms_mm"] < 0.25
    assert s["seen_reported_fraction"] > 0.985


@pytest.mark.parametrize("name, reported, over_2mm, switches", [("fast540", 0.97, 5, 0), ("lip648", 0.985, 2, 0)])
def test_a_fast_dots_gap_bracketed_by_its_2d_tracks_is_measured(tmp_path, capsys, name, reported, over_2mm, switches):
    """#18, stop 35: on fast540 (held out, expressions 3x as fast: lips 3-7 mm a frame) eight lower-face
    markers were lost at one frame and left gaps of 4-12 frames though both views detected their dots;
    one view's 2D track ran through each gap. Such a gap is measured from the candidates on the marker's
    own tracks at either end (``bridge.bridge_gaps_along_2d_tracks``): fast540 96.1 -> 97.2 % of the seen
    marker-frames reported, points over 2 mm 5 -> 4; lip648 97.9 -> 98.2 %, its two identity switches
    gone (4 -> 1 point over 2 mm); with the clip's 2D tracks linked within 0.8 of the blob spacing
    (``pairing.clip_link_gate_px``) lip648 99.0 %, fast540 97.3 %."""
    s, report, ratio_error = _tracked_stress_clip(name, tmp_path, capsys)
    assert s["identity_switches"] == switches and s["split_markers"] == 0
    assert s["seen_reported_fraction"] > reported
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= over_2mm
    assert sum(report["per_frame"]["bridged"]) > 0
    assert abs(ratio_error) < 0.002


@pytest.mark.parametrize("name, over_2mm, reported", [("fast720", 20, 0.99), ("dense", 0, 0.99)])
def test_touching_dots_are_measured_apart(tmp_path, capsys, name, over_2mm, reported):
    """#18, stop 32: two touching dots made one blob, centred between them. On fast720 (held out,
    expressions 2.2x as fast) one label sat on such a blob of two dots at the silhouette, 3-4 mm off
    either: 10 identity switches, a split label, 0.50 mm RMS. On dense, one marker's mirror blob was
    two grazing images merged: most of the clip's 103 points over 2 mm. The detector now cuts such a
    blob in two across its long axis (``ExtractionSettings.split_touching``): fast720 0 switches, no
    split label, 0.23 mm RMS, 14 points over 2 mm (48), 94.9 % reported (94.4 %); dense 26 points over
    2 mm, 97.5 % reported (95.7 %). Since stop 34 dense's single-mirror measurements that their
    neighbours disown are re-paired onto the dot's own image or conjectured
    (``gapfill.doubt_outlying_measurements``): 8 -> 1 point over 2 mm. Stop 35: fast720 97.7 -> 99.6 % with the
    clip's 2D tracks linked within 0.8 of the blob spacing (``pairing.clip_link_gate_px``). Stop 37: a
    single-mirror measurement through a mirror blob of twice its typical dot's area is doubted
    (``capture.views.MERGED_SHARE``): dense's last point over 2 mm (2.003 mm, dot 192's grazing image run into
    its neighbour's) is gone, 1 -> 0."""
    s, report, ratio_error = _tracked_stress_clip(name, tmp_path, capsys)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0 and s["markers_matched"] == s["markers_tracked"]
    assert s["rms_mm"] < 0.3
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= over_2mm
    assert s["seen_reported_fraction"] > reported
    assert abs(ratio_error) < 0.002


def test_a_mirror_blob_of_two_dots_images_does_not_measure_a_marker(tmp_path, capsys):
    """#18, stop 37, webcam (640x360, 120 dots of 3.5 mm): two dots, 67 and 82, were measured through mirror
    0 for tens of frames in blobs that their grazing neighbours' images had run into, up to 4.5 mm off --
    57 points over 2 mm, too smoothly for their neighbours' relations to disown them. No marker is now
    measured through a mirror blob of twice its typical dot's area (``capture.views.MERGED_SHARE``): the
    gap fill doubts such a measurement and conjectures it, and neither the following of dots through gaps
    nor the single-view step takes such a blob. 21 points over 2 mm (26 with the doubt alone), 0.34 mm RMS
    (0.40); 97.2 % of the seen marker-frames reported (98.4 %: the conjectures of the longest such stretches
    are expected too far off and withheld)."""
    s, report, ratio_error = _tracked_stress_clip("webcam", tmp_path, capsys)
    assert sum(report["per_frame"]["merged_images"]) >= 20
    _holds_on_a_held_out_clip(s, report, ratio_error, 0.97, 24)
    assert s["rms_mm"] < 0.36


@pytest.mark.parametrize("held_frames", [5, 10 ** 9])
def test_a_dot_seen_only_directly_does_not_pair_with_another_dots_grazing_image(tmp_path, capsys, monkeypatch,
                                                                               held_frames):
    """#18, stop 33, wide576 (held out: 1024x576, 260 dots of 2.4 mm, mirrors at 44 deg): dot 89, seen
    only in the direct view, paired with dot 37's image grazing in mirror 1 on the same epipolar line
    into a point 15 mm off the face, in the frames where dot 37's own marker was measured without that
    mirror -- 3 identity switches, points 11 mm off, 92.3 % of the seen marker-frames reported. Two
    defences, each enough against the switches: in the pass, a marker keeps the pairing of the mirror
    track it has held ``tracker.HELD_FRAMES`` measurements over a nearer pairing of its direct blob;
    after it, a direct + one-mirror measurement is undone when its mirror blob lies within a pixel of
    another marker's reflected image on a mirror track that marker measures and the point is off the
    face (``late.release_other_markers_blobs``: 14 measurements released with the first defence off).
    Measured: no switch, no split, 0.22 mm RMS, max 2.8 mm, 96.0 % (with the first defence off: no
    switch either, the same max, but one marker split over two labels). Stop 38 added a third, earlier one:
    of two late chains on one direct 2D track at two depths along its ray, the one nearer the face is kept
    (late.RIVAL_ALONG_MM); with the first defence off it leaves the release nothing to do, so it is off too
    where the release is checked."""
    from mirrorcap.core.track import late, tracker

    monkeypatch.setattr(tracker, "HELD_FRAMES", held_frames)
    if held_frames > 5:   # stop 38's rivals on one direct track (late.RIVAL_ALONG_MM) off too: the release alone
        monkeypatch.setattr(late, "RIVAL_ALONG_MM", np.inf)
    s, report, ratio_error = _tracked_stress_clip("wide576", tmp_path, capsys)
    assert (report["per_frame"]["released_blobs"][0] >= 10) == (held_frames > 5)
    assert s["identity_switches"] == 0 and s["markers_matched"] == s["markers_tracked"]
    assert s["rms_mm"] < 0.25 and s["max_mm"] < 3.5
    assert s["seen_reported_fraction"] > 0.955
    assert abs(ratio_error) < 0.002
    if held_frames == 5:   # the product's default
        assert s["split_markers"] == 0
        # stop 35: dots 9 and 155, at the face's silhouette, are late markers where the mirror sees them on the
        # face (onface.off_in_mirrors): 96.0 -> 97.6 %, points over 2 mm 12 -> 8
        assert s["seen_reported_fraction"] > 0.97


def _holds_on_a_held_out_clip(s, report, ratio_error, reported, over_2mm):
    """No identity switch, no split label, every label a true marker, more than ``reported`` of the seen
    marker-frames reported, at most ``over_2mm`` points over 2 mm, the mirrors' scales linked within 0.3 %."""
    assert s["identity_switches"] == 0 and s["split_markers"] == 0 and s["markers_matched"] == s["markers_tracked"]
    assert s["seen_reported_fraction"] > reported
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= over_2mm
    assert abs(ratio_error) < 0.003


@pytest.mark.parametrize("name, reported, over_2mm", [("yaw540", 0.985, 2), ("dots720", 0.99, 40),
                                                     ("hold648", 0.975, 15), ("tempo720", 0.982, 22)])
def test_stop_34s_new_clips(tmp_path, capsys, name, reported, over_2mm):
    """#18, stop 34: yaw540 (960x540, 230 dots of 2.4 mm, mirrors at 44 deg, +-12 deg pitch; rendered at
    the stop's start, then used in choosing its variants) and dots720 (1280x720, 260 dots of 2.2 mm,
    mirrors at 38 deg; rendered once the stop's changes were chosen, tuned on by nothing). Measured: no
    switch, no split label, 98.9 % and 98.8 % of the seen marker-frames reported; yaw540 no point over
    2 mm (5 before the re-pairing and doubting of measurements their neighbours disown), dots720 35 (36):
    on dots720 a dot's grazing mirror image, partly hidden at the face's silhouette, drifts 1.5-3 mm off
    the dot for twenty frames, too smoothly for its relations to disown it (the failure the README
    lists as open). hold648 (1152x648, 250 dots of 2.3 mm, mirrors at 43 deg, +-13 deg yaw; rendered at
    the start of stop 35, before its one change): no switch, no split label, 98.0 %, 12 points over 2 mm.
    Stop 35: dots720's dot 9, at the face's silhouette, is a late marker where mirror 1 sees it on the face
    (onface.off_in_mirrors): 98.8 -> 99.6 %. tempo720 (1280x720, 230 dots of 2.5 mm, mirrors at 46 deg,
    expressions 2.8x as fast; rendered during stop 35 and held out from its choices): 98.2 % with the
    silhouette rule, 98.4 % with the gap bridge, 98.6 % with the clip's wider 2D links; no switch, no split
    label, 18 points over 2 mm."""
    _holds_on_a_held_out_clip(*_tracked_stress_clip(name, tmp_path, capsys), reported, over_2mm)


@pytest.mark.parametrize("name, reported, over_2mm", [("pitch800", 0.965, 30), ("vga480", 0.985, 12)])
def test_stop_36s_held_out_clips(tmp_path, capsys, name, reported, over_2mm):
    """#18, stop 36: two rigs rendered at the stop and tuned on by nothing. pitch800 (800x600, a 4:3
    sensor, 200 dots of 2.8 mm, mirrors at 40 deg, +-12 deg pitch): no switch, no split label, 96.9 % of
    the seen marker-frames reported, 60 points over 2 mm: 27 from dots whose mirror image grazes the face,
    merged with a neighbour's (the failure the README lists as open), and 33 low on the jaw's side, where the
    camera itself sees the dots at a grazing angle -- a dot's partly hidden direct image drifts 1.5-3.5 px
    (8 points), and a dot hidden from the camera had its direct 2D track slip onto that image, 17 mm behind
    it and a pixel away (25 points, up to 6.7 mm). vga480 (640x480,
    160 dots of 3 mm, mirrors at 48 deg, face 700 mm away, +-14 deg yaw): no switch, no split label, 98.9 %,
    11 points over 2 mm. With the direct view's 2D tracks cut where two like dots come apart
    (pairing.cut_at_splits) and the gap bridge refusing a dot the camera sees at a grazing angle:
    pitch800 35 points over 2 mm (60), vga480 10 (11), both at the same completeness; with late markers
    resting where their earliest stretch says (late.REST_AGREE_MM) pitch800 27. 60 and 11 fail these
    bounds (the done-when is 99 % and none)."""
    _holds_on_a_held_out_clip(*_tracked_stress_clip(name, tmp_path, capsys), reported, over_2mm)


def test_stop_37s_held_out_clip(tmp_path, capsys):
    """#18, stop 37: cam450 (800x450, 150 dots of 3.2 mm, mirrors at 46 deg, +-12 deg yaw, expressions 1.6x as
    fast), rendered to check the stop's change -- no marker measured through a mirror blob of two dots'
    images -- and tuned on by nothing: 42 points over 2 mm with it and without it, 96.9 % of the seen
    marker-frames reported (97.0 % without), no switch, no split label. Its worst label (38 points, up to
    6.8 mm) is a phantom: dot 54, seen only directly, paired with the images of dots 53 and 112, both grazing
    in mirror 0 and merged into a blob of a typical dot's area, 6-7 px from where dot 54's image would be.
    Stop 56: its late chain lay 6.0 mm along its ray from a plane 1.2 mm off its markers, and the camera's limit
    is 5 mm where the plane fits that closely (``late.LATE_OFF_FACE_CAMERA_MM``): 4 points over 2 mm, 0.28 mm RMS.
    The bounds hold what was measured (the done-when is 99 % and no point over 2 mm)."""
    s, report, ratio_error = _tracked_stress_clip("cam450", tmp_path, capsys)
    _holds_on_a_held_out_clip(s, report, ratio_error, 0.965, 4)
    assert s["rms_mm"] < 0.3


def test_a_coasting_marker_does_not_take_a_dot_its_neighbour_has_held(tmp_path, capsys):
    """#18, stop 38: side600 (1024x600, 220 dots of 2.4 mm, mirrors at 50 deg, +-14 deg yaw, +-6 deg roll), rendered
    at the stop and held out until its first run: 34 identity switches, one label split, 66 points over 2 mm
    (up to 11.7 mm), 0.55 mm RMS. Traced: two dots 11 mm apart at the face's silhouette, their direct images
    10 px apart; one moved 5 px in 3 frames and was lost, its marker's prediction coasted onto the other dot, whose
    own marker, its step along the line of sight, was lost in the same frames -- and the first marker took the
    other's dot and kept it. A candidate on the 2D tracks a marker has held HELD_FRAMES measurements is that
    marker's dot: a marker coasting through a gap of its own (measured before, not in the last frame) does not
    take it, and the tracks' owner does (tracker._continuing_owner). Measured: no switch, no split, 28 points over
    2 mm, 0.19 mm RMS, 99.3 % of the seen marker-frames reported."""
    s, report, ratio_error = _tracked_stress_clip("side600", tmp_path, capsys)
    _holds_on_a_held_out_clip(s, report, ratio_error, 0.99, 32)
    assert s["rms_mm"] < 0.23

def test_a_late_markers_rest_is_read_from_its_earliest_stretch(tmp_path, capsys):
    """#18, stop 36, tilt630 (1120x630, 210 dots, +-13 deg yaw, +-6 deg roll): dot 77, undecided in the
    first frames, became a late marker from two stretches of its dots (frames 0-10, and from frame 50). Its
    rest position came from the better supported later one (its position less its neighbours' motion then),
    1.1 mm off; with the face still at the start, the neighbour test (eq. 5.6) refused every measurement as
    false tracking until frame 25. The earliest stretch, where there is least motion to take off, now gives
    the rest position when the two agree within REST_AGREE_MM (a wrong pairing's lies 2.5-3.6 mm off):
    measured in frames 0-10, 97.5 -> 97.8 % of the seen marker-frames, 61 -> 56 points over 2 mm."""
    s, report, ratio_error = _tracked_stress_clip("tilt630", tmp_path, capsys)
    assert s["identity_switches"] == 0 and s["split_markers"] == 0 and s["markers_matched"] == s["markers_tracked"]
    label = int(np.flatnonzero(s["ids"] == 77)[0])
    assert np.isfinite(s["error_mm"][:11, label]).sum() >= 9
    assert s["seen_reported_fraction"] > 0.9765
    err_mm = s["error_mm"][:, s["ids"] >= 0]
    assert np.count_nonzero(err_mm[np.isfinite(err_mm)] > 2.0) <= 58
