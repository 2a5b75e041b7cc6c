"""The camera: normalisation (the one undistortion point), projection, CAMERA.json."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from mirrorcap.core.geometry.camera import Camera, angle_deg
from mirrorcap.core.common.errors import InputError


def test_round_trip_without_and_with_distortion(distorted_camera):
    rng = np.random.default_rng(0)
    px = rng.uniform([0, 0], [1279, 719], size=(500, 2))
    for cam in (Camera(K=distorted_camera.K, image_size=(1280, 720)), distorted_camera):
        back = cam.denormalize(cam.normalize(px))
        assert np.max(np.abs(back - px)) < 1e-6


def test_project_matches_opencv(distorted_camera):
    rng = np.random.default_rng(1)
    pts = rng.uniform([-100, -60, 500], [100, 60, 700], size=(50, 3))
    ours = distorted_camera.project(pts)
    ref, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), distorted_camera.K, distorted_camera.dist)
    assert np.allclose(ours, ref.reshape(-1, 2), atol=1e-9)


def test_normalize_is_k_inverse_without_distortion():
    K = np.array([[1000.0, 2.0, 320.0], [0.0, 990.0, 240.0], [0.0, 0.0, 1.0]])
    cam = Camera(K=K, image_size=(640, 480))
    px = np.array([[10.0, 20.0], [600.0, 400.0]])
    expected = (np.linalg.inv(K) @ np.c_[px, np.ones(2)].T).T[:, :2]
    assert np.allclose(cam.normalize(px), expected, atol=1e-15)
    assert cam.normalize(px.reshape(1, 2, 2)).shape == (1, 2, 2)


def test_load_and_errors(tmp_path):
    good = {"K": [[1500, 0, 359.5], [0, 1500, 359.5], [0, 0, 1]], "dist": [], "image_size": [720, 720]}
    path = tmp_path / "camera.json"
    path.write_text(json.dumps(good))
    cam = Camera.load(path)
    assert cam.focal_px == 1500 and cam.image_size == (720, 720) and not cam.has_distortion
    assert Camera.from_dict(cam.to_dict()).to_dict() == cam.to_dict()
    cases = {
        "not json": "{",
        "missing K": json.dumps({"image_size": [1, 1]}),
        "K not 3x3": json.dumps({**good, "K": [[1, 0], [0, 1]]}),
        "negative focal": json.dumps({**good, "K": [[-5, 0, 1], [0, 5, 1], [0, 0, 1]]}),
        "dist length": json.dumps({**good, "dist": [0.1, 0.2, 0.3]}),
        "image size": json.dumps({**good, "image_size": [720]}),
        "non-integer size": json.dumps({**good, "image_size": [720.5, 720]}),
        "not an object": json.dumps([1, 2, 3]),
        "nan": json.dumps({**good, "dist": [float("nan"), 0, 0, 0]}),
    }
    for text in cases.values():
        path.write_text(text)
        with pytest.raises(InputError):
            Camera.load(path)
    with pytest.raises(InputError, match="cannot read"):
        Camera.load(tmp_path / "missing.json")


def test_contains_and_angle():
    cam = Camera.ideal(1000.0, (640, 480))
    assert cam.contains(np.array([[0, 0], [639, 479], [640.6, 10], [-1, 5]])).tolist() == [True, True, False, False]
    assert angle_deg(np.array([1.0, 0, 0]), np.array([0, 1.0, 0])) == pytest.approx(90.0)
    assert angle_deg(np.array([1.0, 0, 0]), np.array([1.0, 1e-9, 0])) == pytest.approx(np.degrees(1e-9))
