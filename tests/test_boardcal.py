"""Mirror planes in millimetres from a ChArUco board seen directly and in both mirrors."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from mirrorcap.cli import parser as cli
from mirrorcap.core.capture.boardcal import calibrate_mirrors_from_board, load_mirrors
from mirrorcap.core.capture.calibrate import Board
from mirrorcap.core.geometry.camera import angle_deg
from mirrorcap.core.common.errors import DegenerateError, InputError
from mirrorcap.synthetic.render import render_board_in_rig
from mirrorcap.synthetic.simulate import face_rig

BOARD = "charuco:7x5:20:15"


@pytest.fixture(scope="module")
def board_clip(tmp_path_factory):
    root = tmp_path_factory.mktemp("board")
    rig = face_rig(n_markers=50, seed=3, layout="even")
    frames = render_board_in_rig(rig.camera, rig.planes, Board.parse(BOARD), 12, np.random.default_rng(0))
    for i, img in enumerate(frames):
        cv2.imwrite(str(root / f"f{i:02d}.png"), img)
    (root / "camera.json").write_text(json.dumps(rig.camera.to_dict()))
    return root, rig, frames


def test_board_gives_mirror_planes_in_mm(board_clip):
    _, rig, frames = board_clip
    result = calibrate_mirrors_from_board(frames, rig.camera, Board.parse(BOARD))
    for k, plane in enumerate(result.planes):
        true_n, true_d = rig.planes[k]
        assert angle_deg(plane.normal, true_n) < 0.1
        assert plane.d == pytest.approx(true_d, rel=0.005)  # metric, without a known length
        assert plane.n_inliers >= 100


def test_mirrors_cli_writes_a_loadable_file(board_clip, capsys, tmp_path):
    root, rig, _ = board_clip
    out = tmp_path / "mirrors.json"
    code = cli.main(["mirrors", str(root), "--camera", str(root / "camera.json"), "--board", BOARD, "-o", str(out),
                     "-q"])
    assert code == 0, capsys.readouterr().err
    planes = load_mirrors(out)
    assert len(planes) == 2 and json.loads(out.read_text())["units"] == "mm"
    assert angle_deg(planes[1].normal, rig.planes[1][0]) < 0.1


def test_board_errors(board_clip, capsys, tmp_path):
    root, rig, frames = board_clip
    blank_right = [f.copy() for f in frames]
    for f in blank_right:
        f[:, 2 * f.shape[1] // 3:] = 0  # mirror 1 shows nothing
    with pytest.raises(DegenerateError, match="mirror 1"):
        calibrate_mirrors_from_board(blank_right, rig.camera, Board.parse(BOARD))
    with pytest.raises(InputError, match="ChArUco"):
        calibrate_mirrors_from_board(frames, rig.camera, Board.parse("chessboard:7x5:20"))
    out = tmp_path / "m.json"
    other = json.loads((root / "camera.json").read_text())
    other["image_size"] = [640, 480]
    (tmp_path / "cam.json").write_text(json.dumps(other))
    code = cli.main(["mirrors", str(root), "--camera", str(tmp_path / "cam.json"), "--board", BOARD, "-o", str(out)])
    assert code == 2 and "640x480" in capsys.readouterr().err and not out.exists()
    for text in ('{"mirrors": [{"normal": [0, 0]}]}', '{"mirrors": [{"normal": [0, 0], "d": -1}]}',
                 '{"mirrors": [{"normal": [0, 0, 2], "d": -1}]}', '{"mirrors": []}', "[]"):
        (tmp_path / "bad.json").write_text(text)
        with pytest.raises(InputError, match="mirrors file"):
            load_mirrors(tmp_path / "bad.json")
