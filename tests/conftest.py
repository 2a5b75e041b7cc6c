"""Shared fixtures: synthetic scenes with exact truth."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from mirrorcap.synthetic import simulate as sim  # noqa: E402
from mirrorcap.core.geometry.camera import Camera  # noqa: E402

SAMPLE = ROOT / "sample_scenes" / "mirror_demo"


@pytest.fixture(autouse=True, scope="session")
def ctrl_c_as_a_terminal_delivers_it():
    """The tests of Ctrl-C need SIGINT to reach Python as a terminal delivers it. Started in a shell's background
    job (``nohup``, ``make test &``: a CI runner may) the tests get SIGINT ignored -- which the command rightly
    keeps -- and three of them saw exit 0 where an interrupted command gives 130. The test process takes Python's
    own handler, as a command started at a terminal has; the commands it starts then begin with the default."""
    import signal

    previous = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture
def paper_camera():
    """The simulated CCD of section 6.2: 720 x 720 px, f = 1500 px."""
    return Camera.ideal(1500.0, (720, 720))


@pytest.fixture
def cube_scene(paper_camera):
    """60 random points of the section 6.2 protocol and a mirror at (45 deg, 0 deg)."""
    rng = np.random.default_rng(11)
    pts = sim.random_cube_points(60, rng)
    normal, d = sim.mirror_plane_from_angles(45.0, 0.0, [0, 0, 40000.0], 12000.0)
    return pts, normal, d


@pytest.fixture
def distorted_camera():
    K = np.array([[1400.0, 0.0, 652.3], [0.0, 1395.0, 355.8], [0.0, 0.0, 1.0]])
    return Camera(K=K, dist=np.array([-0.08, 0.03, 0.0005, -0.0003, 0.0]), image_size=(1280, 720))


@pytest.fixture
def face():
    return sim.face_rig(n_markers=300, seed=3)


def write_rig_clip(root: Path, n_frames: int, name: str = "{:03d}.png", mp4=None):
    """Render a 300-marker rig clip (2 grey levels of noise, gentle head turn) into
    ``root/png`` (file names from ``name``), optionally also as an MP4 at 25 frames/s,
    and write ``root/camera.json``. Returns ``(rig, per-frame truth)``."""
    import json

    import cv2

    from mirrorcap.synthetic.render import RenderSettings, rig_clip_frames

    rig = sim.face_rig(n_markers=300, seed=3, layout="even")
    (root / "png").mkdir()
    writer = cv2.VideoWriter(str(mp4), cv2.VideoWriter_fourcc(*"mp4v"), 25, rig.camera.image_size) if mp4 else None
    truths = []
    for f, img, truth in rig_clip_frames(rig, n_frames, RenderSettings(noise_sigma=2.0), seed=1):
        cv2.imwrite(str(root / "png" / name.format(f)), img)
        if writer is not None:
            writer.write(img)
        truths.append(truth)
    if writer is not None:
        writer.release()
    (root / "camera.json").write_text(json.dumps(rig.camera.to_dict()))
    return rig, truths


def scored_take(clip: Path, take_path: Path, report_path: Path | None = None):
    """A take tracked from a rendered clip (``clip``: camera.json, truth.npz), scored against the
    clip's truth after one similarity (:func:`synthetic.evaluate.score_take`, with the marker-frames
    seen in the direct view and a mirror). Returns the scores, the report (or None) and the error
    of the mirrors' distance ratio against the truth (or None)."""
    import json

    from mirrorcap.core.take.c3d import read_c3d
    from mirrorcap.synthetic.evaluate import score_take

    truth = np.load(clip / "truth.npz")
    take = read_c3d(take_path)
    F = take["points"].shape[0]
    vis = truth["visible"][:F]
    scores = score_take(take["points"], truth["points"][:F], Camera.load(clip / "camera.json"),
                        conjectured=take["conjectured"], seen=vis[:, 0] & (vis[:, 1] | vis[:, 2]))
    if report_path is None:
        return scores, None, None
    report = json.loads(Path(report_path).read_text())
    ds = [m["d"] for m in report["mirrors"]]
    return scores, report, ds[1] / ds[0] / (truth["mirror_d"][1] / truth["mirror_d"][0]) - 1.0
