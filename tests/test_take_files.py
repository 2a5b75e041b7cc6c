"""Any vendor's C3D in (ezc3d), `mirrorcap info` / `export` on each, and bad files refused."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import ezc3d
import numpy as np
import pytest

from mirrorcap.cli.parser import main
from mirrorcap.core.common.errors import InputError
from mirrorcap.core.take.c3d import read_c3d, write_c3d

from c3d_variants import convert, to_integer


def _ezc3d_file(path, labels, pts_mm, rate, units="mm", analog=None, first_frame=0, zero_gaps=False):
    """A C3D written by ezc3d as another system would: ``pts_mm (F, M, 3)`` with NaN gaps,
    in ``units``; ``analog`` ``(channels, F * per_frame)`` samples; gaps as residual -1 or,
    with ``zero_gaps``, as all-zero coordinates with a valid residual."""
    factor = {"mm": 1.0, "m": 1000.0, "cm": 10.0}[units]
    F, M = pts_mm.shape[:2]
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(labels)
    gap = ~np.all(np.isfinite(pts_mm), axis=2)
    data = np.ones((4, M, F))
    data[:3] = np.where(gap[..., None], 0.0, pts_mm / factor).transpose(2, 1, 0)
    c["data"]["points"] = data
    res = np.where(gap, 0.5 if zero_gaps else -1.0, 0.5).T[None]
    c["data"]["meta_points"]["residuals"] = res
    c["data"]["meta_points"]["camera_masks"] = np.ones((7, M, F), bool) & ~gap.T[None]
    if analog is not None:
        per_frame = analog.shape[1] // F
        c["parameters"]["ANALOG"]["RATE"]["value"] = [rate * per_frame]
        c["parameters"]["ANALOG"]["LABELS"]["value"] = [f"Force.Fz{i}" for i in range(analog.shape[0])]
        c["parameters"]["ANALOG"]["UNITS"]["value"] = ["N"] * analog.shape[0]
        c["data"]["analogs"] = analog[None]
    c["header"]["points"]["first_frame"] = first_frame
    c.write(str(path))
    return path


def _take(seed=0, F=30, M=12):
    rng = np.random.default_rng(seed)
    pts = rng.normal(0, 80, (F, M, 3)) + [100.0, 1400.0, 900.0]
    pts[4, 2] = np.nan
    pts[10:14, 5] = np.nan
    return pts


VARIANTS = ["vicon_analog_m", "qualisys_labels", "zero_gaps", "dec", "integer", "first_frame_cm"]


@pytest.fixture(scope="module")
def vendor_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("vendors")
    pts = _take()
    F, M = pts.shape[:2]
    labels = [f"LFHD{i}" for i in range(M)]
    rng = np.random.default_rng(1)
    files = {}
    files["vicon_analog_m"] = (_ezc3d_file(d / "vicon.c3d", labels, pts, 100.0, units="m",
                                           analog=rng.normal(size=(6, F * 10))), labels, pts, 1)
    q_labels = ["head front", "head front", " ", "chin"] + labels[4:]
    files["qualisys_labels"] = (_ezc3d_file(d / "qualisys.c3d", q_labels, pts, 120.0), q_labels, pts, 1)
    files["zero_gaps"] = (_ezc3d_file(d / "zero.c3d", labels, pts, 60.0, zero_gaps=True), labels, pts, 1)
    base = _ezc3d_file(d / "intel.c3d", labels, pts, 60.0, analog=rng.normal(size=(2, F * 4)))
    for fmt in ("dec", "mips"):
        (d / f"{fmt}.c3d").write_bytes(convert(base.read_bytes(), fmt))
        files[fmt] = (d / f"{fmt}.c3d", labels, pts, 1)
    plain = _ezc3d_file(d / "plain.c3d", labels, pts, 60.0)
    (d / "integer.c3d").write_bytes(to_integer(plain.read_bytes(), 0.1))
    files["integer"] = (d / "integer.c3d", labels, pts, 1)
    files["first_frame_cm"] = (_ezc3d_file(d / "ff.c3d", labels, pts, 250.0, units="cm", first_frame=1199),
                               labels, pts, 1200)
    return files


@pytest.mark.parametrize("variant", VARIANTS)
def test_every_vendor_form_reads_as_ezc3d_does(vendor_files, variant):
    path, labels, pts, first = vendor_files[variant]
    c = ezc3d.c3d(str(path))
    factor = {"mm": 1.0, "m": 1000.0, "cm": 10.0}[c["parameters"]["POINT"]["UNITS"]["value"][0]] \
        if c["parameters"]["POINT"]["UNITS"]["value"] else 1.0
    theirs = np.transpose(c["data"]["points"][:3], (2, 1, 0)) * factor
    take = read_c3d(path)
    gap = ~np.all(np.isfinite(pts), axis=2)
    # gaps in the same places as written (-1 residual, or all-zero coordinates)
    assert np.array_equal(take["gaps"], gap)
    assert np.all(np.isnan(take["points"][gap]))
    # the same point values as ezc3d, in mm, within 1e-3 mm (and the truth within the format's precision)
    assert np.max(np.abs(take["points"][~gap] - theirs[~gap])) < 1e-3
    tol = 0.05 + 1e-3 if variant == "integer" else 2e-3 * np.abs(pts[~gap]).max() / 1000
    assert np.max(np.abs(take["points"][~gap] - pts[~gap])) < tol
    assert take["units"] == "mm" and take["first_frame"] == first
    assert len(take["labels"]) == len(set(take["labels"])) == len(labels)
    assert take["processor"] == {"dec": "DEC"}.get(variant, "Intel")
    if variant == "vicon_analog_m":
        assert take["analog"]["channels"] == 6 and take["analog"]["rate"] == 1000.0
        assert take["analog"]["labels"][0] == "Force.Fz0" and take["source_units"] == "m"
    if variant == "qualisys_labels":
        assert take["labels"][:4] == ["head front", "head front_2", "marker002", "chin"]
        assert [r["index"] for r in take["renamed"]] == [1, 2]


@pytest.mark.parametrize("variant", VARIANTS)
def test_info_and_export_on_every_vendor_form(vendor_files, variant, tmp_path, capsys):
    path, labels, pts, first = vendor_files[variant]
    assert main(["info", str(path), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    gap = ~np.all(np.isfinite(pts), axis=2)
    assert rep["frames"] == len(pts) and rep["first_frame"] == first and rep["last_frame"] == first + len(pts) - 1
    assert list(rep["gaps_per_label"].values()) == gap.sum(0).tolist()
    assert main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert f"{len(pts)} frames" in text and "gap frames" in text
    out = tmp_path / "points.csv"
    assert main(["export", str(path), "-o", str(out), "-q"]) == 0
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == pts.shape[0] * pts.shape[1]
    take = read_c3d(path)
    for row in rows[::37] + [rows[4 * pts.shape[1] + 2], rows[11 * pts.shape[1] + 5]]:
        f = int(row["frame"]) - first
        m = take["labels"].index(row["label"])
        if gap[f, m]:
            assert row["x"] == row["y"] == row["z"] == ""
        else:
            assert np.allclose([float(row[k]) for k in "xyz"], take["points"][f, m], atol=1e-4)


def test_a_mips_file_is_refused_by_name(vendor_files, capsys):
    """ezc3d 1.7 does not read the MIPS (big-endian) format: one message that says so."""
    path = vendor_files["mips"][0]
    with pytest.raises(InputError, match="MIPS"):
        read_c3d(path)
    assert main(["info", str(path)]) == 2
    assert "MIPS" in capsys.readouterr().err


def test_a_mirrorcap_take_round_trips(tmp_path):
    pts = _take(seed=3, F=20, M=300)
    conj = np.zeros(pts.shape[:2], bool)
    conj[6, 7] = True
    labels = [f"m{i:03d}" for i in range(300)]
    write_c3d(tmp_path / "t.c3d", labels, pts, 120.0, conjectured=conj, first_frame=9)
    take = read_c3d(tmp_path / "t.c3d")
    ok = np.all(np.isfinite(pts), axis=2)
    assert take["labels"] == labels and take["first_frame"] == 10 and take["rate"] == 120.0
    assert np.max(np.abs(take["points"][ok] - pts[ok])) < 1e-3
    assert take["conjectured"].sum() == 1 and take["conjectured"][6, 7]


def test_bad_files_are_refused_with_one_message(vendor_files, tmp_path, capsys):
    good = vendor_files["vicon_analog_m"][0].read_bytes()
    cases = {"not.c3d": b"hello, not a c3d file" * 40, "empty.c3d": b"",
             "cut_params.c3d": good[:700], "cut_data.c3d": good[:len(good) // 2],
             "random.c3d": np.random.default_rng(0).bytes(5000)}
    for name, data in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(InputError):
            read_c3d(tmp_path / name)
        out = tmp_path / f"{name}.csv"
        assert main(["export", str(tmp_path / name), "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("mirrorcap: error: ") and err.count("\n") == 1, err
        assert not out.exists()
    with pytest.raises(InputError, match="does not exist"):
        read_c3d(tmp_path / "missing.c3d")


def test_a_truncated_file_does_not_hang_the_reader(vendor_files, tmp_path):
    """ezc3d can loop on a file cut inside its parameter section: the reader checks first."""
    good = vendor_files["dec"][0].read_bytes()
    (tmp_path / "cut.c3d").write_bytes(good[:700])
    res = subprocess.run([sys.executable, "-m", "mirrorcap", "info", str(tmp_path / "cut.c3d")],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and "truncated" in res.stderr


def test_a_reader_that_goes_away_ends_the_command_quietly(tmp_path):
    """``mirrorcap info TAKE.c3d | head``: a pipe its reader closed ends the command with status 141 (as a
    shell reports SIGPIPE) and nothing on stderr, not a BrokenPipeError traceback."""
    path = tmp_path / "take.c3d"
    write_c3d(path, [f"m{i:03d}" for i in range(40)], np.zeros((30, 40, 3)), 30.0)
    proc = subprocess.Popen([sys.executable, "-m", "mirrorcap", "info", str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()                       # the reader goes away before the first line is written
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141, err
    assert err == ""


def test_takes_of_no_markers_or_no_measured_point(tmp_path, capsys):
    """Another system's C3D of no markers exports as the CSV header alone, and one whose every marker-frame is a
    gap is refused by `stabilize` with one message (were: an IndexError and numpy's "SVD did not converge")."""
    empty = tmp_path / "no_markers.c3d"
    _ezc3d_file(empty, [], np.zeros((10, 0, 3)), 100.0)
    assert main(["export", str(empty), "-o", str(tmp_path / "e.csv"), "-q"]) == 0
    assert (tmp_path / "e.csv").read_text() == "frame,label,x,y,z\n"
    gaps = tmp_path / "all_gaps.c3d"
    _ezc3d_file(gaps, [f"P{i}" for i in range(6)], np.full((10, 6, 3), np.nan), 100.0)
    assert main(["stabilize", str(gaps), "-o", str(tmp_path / "s.c3d")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no measured point" in err, err
    assert not (tmp_path / "s.c3d").exists()
