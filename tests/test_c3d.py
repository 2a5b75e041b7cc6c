"""The C3D writer, read back with an independent reader (ezc3d)."""

from __future__ import annotations

import struct

import ezc3d
import numpy as np
import pytest

from mirrorcap.core.take.c3d import c3d_bytes, write_c3d
from mirrorcap.core.common.errors import InputError


def _take(n_frames=40, n_markers=300, seed=0):
    rng = np.random.default_rng(seed)
    pts = rng.normal(0, 60, (n_frames, n_markers, 3)) + [0, 0, 600]
    pts[3, 7] = np.nan  # a gap
    conj = np.zeros((n_frames, n_markers), bool)
    conj[5, 11] = True  # a conjectured marker
    mask = rng.integers(1, 8, (n_frames, n_markers))
    res = rng.uniform(0.01, 0.5, (n_frames, n_markers))
    return [f"m{i:03d}" for i in range(n_markers)], pts, mask, res, conj


def test_round_trip_through_ezc3d(tmp_path):
    labels, pts, mask, res, conj = _take()
    path = tmp_path / "take.c3d"
    write_c3d(path, labels, pts, 119.88, residual=res, camera_mask=mask, conjectured=conj)
    c = ezc3d.c3d(str(path))
    read = np.transpose(c["data"]["points"][:3], (2, 1, 0))  # (frames, markers, 3)
    ok = np.isfinite(pts).all(axis=2)
    assert read.shape == pts.shape
    assert np.max(np.abs(read[ok] - pts[ok])) < 1e-4  # float32
    assert np.all(np.isnan(read[3, 7]))  # the gap is a gap
    point = c["parameters"]["POINT"]
    assert point["LABELS"]["value"] + point["LABELS2"]["value"] == labels  # 300 labels: LABELS + LABELS2
    assert point["RATE"]["value"][0] == pytest.approx(119.88, rel=1e-6)
    assert point["UNITS"]["value"] == ["mm"]
    assert c["header"]["points"]["first_frame"] == 0 and c["header"]["points"]["last_frame"] == 39
    residual = c["data"]["meta_points"]["residuals"][0].T  # (frames, markers)
    cams = c["data"]["meta_points"]["camera_masks"].transpose(2, 1, 0)
    # conjectured: residual 0 and no camera, however a reader orders the two bytes
    assert residual[5, 11] == 0 and not cams[5, 11].any()
    measured = ok & ~conj
    assert np.all(residual[measured] > 0)
    assert residual[3, 7] < 0


def test_fourth_word_of_a_point(tmp_path):
    """ezc3d's writer: residual in |POINT:SCALE| units in the high byte, the camera mask in the
    low byte; -1 and coordinates 0 for a gap; 0 for a conjectured marker."""
    pts = np.array([[[100.0, -50.0, 640.0], [np.nan, np.nan, np.nan], [1.0, 2.0, 3.0]]])
    data = c3d_bytes(["a", "b", "c"], pts, 60.0, residual=np.array([[0.2, 0, 0]]),
                     camera_mask=np.array([[5, 1, 3]]), conjectured=np.array([[False, False, True]]))
    path = tmp_path / "w.c3d"
    path.write_bytes(data)
    scale = ezc3d.c3d(str(path))["parameters"]["POINT"]["SCALE"]["value"][0]
    assert scale == pytest.approx(-640.0 / 32000, rel=1e-6)
    start = struct.unpack("<H", data[16:18])[0]
    rec = np.frombuffer(data[(start - 1) * 512:(start - 1) * 512 + 48], "<f4")
    word = int(rec[3])
    assert (word & 0xFF) == 5 and word >> 8 == round(0.2 / abs(scale))
    assert np.allclose(rec[:3], [100.0, -50.0, 640.0])
    assert rec[7] == -1.0 and np.all(rec[4:7] == 0)
    assert rec[11] == 0.0 and np.allclose(rec[8:11], [1, 2, 3])


def test_bad_takes_are_refused(tmp_path):
    labels, pts, *_ = _take(n_frames=6, n_markers=12)
    labels, pts = labels[:4], pts[:3, :4]
    with pytest.raises(InputError, match="labels"):
        c3d_bytes(labels[:3], pts, 60.0)
    with pytest.raises(InputError, match="unique"):
        c3d_bytes(["a", "a", "b", "c"], pts, 60.0)
    with pytest.raises(InputError, match="frame rate"):
        c3d_bytes(labels, pts, 0.0)
    with pytest.raises(InputError, match="shape"):
        c3d_bytes(labels, pts[..., :2], 60.0)
    with pytest.raises(InputError, match="camera masks"):
        c3d_bytes(labels, pts, 60.0, camera_mask=np.full((3, 4), 200))
    path = tmp_path / "x.c3d"
    path.write_bytes(b"keep")
    with pytest.raises(InputError):
        write_c3d(path, labels[:2], pts, 60.0)
    assert path.read_bytes() == b"keep"  # nothing half-written
