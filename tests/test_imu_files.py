"""IMU and truth CSV files: round trip, atomic writing, validation errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sdr_di.errors import ImuDataError
from sdr_di.io.imu_files import read_imu, read_truth, write_imu, write_truth
from sdr_di.sim import motion as mo
from sdr_di.sim.imu import ImuErrorModel
from sdr_di.sim.trajectory import generate_trajectory


@pytest.fixture(scope="module")
def truth():
    return generate_trajectory(math.radians(40), math.radians(116), 100.0, (0, 20, 0), (0, 0, 0),
                               [mo.Accelerate(1.0, 1.0), mo.Turn(1.0, 10.0, "left")], rate_hz=200.0)


@pytest.fixture(scope="module")
def imu(truth):
    return ImuErrorModel().apply(truth, np.random.default_rng(5))


def test_imu_round_trip(tmp_path, imu):
    path = write_imu(tmp_path / "imu.csv", imu, week=762, sow=388800.5)
    assert path.exists() and not (tmp_path / "imu.csv.part").exists()
    text = path.read_text()
    assert "# bdt_week_t0: 762" in text and "gyro_x [rad/s]" not in text.splitlines()[-1]
    back = read_imu(path)
    np.testing.assert_array_equal(back.t, imu.t)
    np.testing.assert_array_equal(back.f_b, imu.f_b)
    np.testing.assert_array_equal(back.w_ib_b, imu.w_ib_b)
    np.testing.assert_array_equal(back.accel_bias, imu.accel_bias)
    np.testing.assert_array_equal(back.gyro_scale, imu.gyro_scale)
    assert (back.week, back.sow, back.rate_hz) == (762, 388800.5, 200.0)


def test_truth_round_trip(tmp_path, truth):
    path = write_truth(tmp_path / "truth.csv", truth, week=762, sow=10.0)
    back, week, sow = read_truth(path)
    assert (week, sow) == (762, 10.0)
    np.testing.assert_array_equal(back.t, truth.t)
    np.testing.assert_allclose(back.llh[:, :2], truth.llh[:, :2], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(back.llh[:, 2], truth.llh[:, 2])
    np.testing.assert_allclose(back.att, truth.att, rtol=0, atol=1e-15)
    np.testing.assert_allclose(back.C_b_n, truth.C_b_n, rtol=0, atol=1e-14)
    for name in ("v_n", "f_b", "w_ib_b", "r_e", "v_e", "a_e"):
        np.testing.assert_array_equal(getattr(back, name), getattr(truth, name))


def _lines(tmp_path, imu) -> tuple[Path, list[str]]:
    path = write_imu(tmp_path / "imu.csv", imu)
    return path, path.read_text().splitlines()


def _first_data(lines: list[str]) -> int:
    return next(i for i, ln in enumerate(lines) if ln.startswith("t,")) + 1


@pytest.mark.parametrize("case, match", [
    ("nan", "not a finite number"),
    ("gap", "deviates from the nominal"),
    ("nonmono", "time not increasing"),
    ("columns", "expected 7 columns"),
    ("names", "expected columns"),
    ("text", "unreadable number"),
    ("empty", "no column line"),
])
def test_bad_imu_files(tmp_path, imu, case, match):
    path, lines = _lines(tmp_path, imu)
    k = _first_data(lines) + 10
    if case == "nan":
        parts = lines[k].split(",")
        parts[4] = "nan"
        lines[k] = ",".join(parts)
    elif case == "gap":
        del lines[k]
    elif case == "nonmono":
        lines[k], lines[k + 1] = lines[k + 1], lines[k]
    elif case == "columns":
        lines[k] = lines[k].rsplit(",", 1)[0]
    elif case == "names":
        lines[k - 11] = lines[k - 11].replace("gyro_x", "gx")
    elif case == "text":
        lines[k] = lines[k].replace(",", ",abc,", 1).rsplit(",", 1)[0]
    elif case == "empty":
        lines = [ln for ln in lines if ln.startswith("#")]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ImuDataError, match=match) as info:
        read_imu(path)
    assert str(path) in str(info.value)
    if case in ("nan", "gap", "columns"):
        assert f"line {k + 1}" in str(info.value)
    if case == "nonmono":  # line k + 1 (1-based) now holds the later time; k + 2 goes back
        assert f"line {k + 2}" in str(info.value)


def test_bad_truth_file_and_missing_file(tmp_path, truth):
    path = write_truth(tmp_path / "truth.csv", truth)
    lines = path.read_text().splitlines()
    k = _first_data(lines) + 3
    lines[k] = lines[k].replace(lines[k].split(",")[1], "inf", 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ImuDataError, match="not a finite number"):
        read_truth(path)
    with pytest.raises(ImuDataError, match="cannot read"):
        read_imu(tmp_path / "nope.csv")


def test_rate_from_argument_overrides_header(tmp_path, imu):
    path, _ = _lines(tmp_path, imu)
    with pytest.raises(ImuDataError, match="nominal"):
        read_imu(path, rate_hz=100.0)


def test_failed_write_leaves_no_file(tmp_path, imu):
    bad = imu.__class__(t=imu.t, f_b=imu.f_b[:, :2], w_ib_b=imu.w_ib_b, rate_hz=imu.rate_hz)
    with pytest.raises(ValueError, match="shape"):
        write_imu(tmp_path / "x.csv", bad)
    assert list(tmp_path.iterdir()) == []


def test_unwritable_destination_raises_output_error(tmp_path, imu):
    from sdr_di.errors import OutputError

    with pytest.raises(OutputError):
        write_imu(tmp_path / "no_such_dir" / "imu.csv", imu)
