"""``sdr-di lc`` end to end: table, CSV, file input and every bad input (exit status 2)."""

import json

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.integration.loose import load_lc_scenario
from sdr_di.sim.lc_inputs import make_inputs
from sdr_di.io.imu_files import write_imu, write_truth
from sdr_di.scenario import DEFAULT_SCENARIO


def run(args, capsys):
    rc = main(["lc", *args])
    return rc, capsys.readouterr()


def one_line_error(err):
    lines = [ln for ln in err.strip().splitlines() if ln]
    assert len(lines) == 1, err
    assert lines[0].startswith("sdr-di: error: ")
    return lines[0]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("lcfiles")
    sc, st = load_lc_scenario(DEFAULT_SCENARIO)
    sc = sc.with_overrides(duration_s=5.0)
    truth, imu, _ = make_inputs(sc, st)
    write_imu(d / "imu.csv", imu, week=sc.week, sow=sc.sow)
    write_truth(d / "truth.csv", truth, week=sc.week, sow=sc.sow)
    return d


def test_lc_prints_table_and_writes_csv(tmp_path, capsys):
    rc, out = run(["--filter", "ukf", "--duration", "20", "--out", str(tmp_path),
                   "--r-window", "5", "10", "16"], capsys)
    assert rc == 0, out.err
    lines = out.out.strip().splitlines()
    assert lines[0].split()[:3] == ["filter", "span_s", "att_rmse_deg"]
    row = lines[1].split()
    assert row[0] == "ukf" and row[1] == "all" and float(row[6]) < 5.0
    assert lines[2].split()[1] == "5-10"
    csv = tmp_path / "default_lc_ukf.csv"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["default_lc_ukf.csv",
                                                          "default_lc_ukf_summary.json"]
    summary = json.loads((tmp_path / "default_lc_ukf_summary.json").read_text())
    assert summary["truth"]["gnss_noise"]["windows"] == [[5.0, 10.0, 16.0]]
    assert summary["assumptions"]["imu"]["accel_bias_mg"] == 4.0  # truth = belief here
    assert summary["assumptions"]["given"] is None
    data = np.loadtxt(csv, delimiter=",", skiprows=2)
    assert data.shape == (20, 32)              # 23 + the formal 1-sigma columns
    r_true = data[:, 17:23]
    win = (data[:, 0] >= 5) & (data[:, 0] <= 10)
    assert np.allclose(r_true[win], 16 * r_true[~win][0])
    assert np.allclose(data[:, 11:17], data[0, 11:17])     # the filter keeps nominal R


def test_lc_from_imu_and_truth_files(files, tmp_path, capsys):
    rc, out = run(["--imu", str(files / "imu.csv"), "--truth", str(files / "truth.csv"),
                   "--filter", "ckf", "--out", str(tmp_path)], capsys)
    assert rc == 0, out.err
    assert out.out.splitlines()[1].split()[0] == "ckf"
    assert np.loadtxt(tmp_path / "default_lc_ckf.csv", delimiter=",", skiprows=2).shape[0] == 5


def _corrupt(src, dst, how):
    lines = src.read_text().splitlines(keepends=True)
    first = next(i for i, ln in enumerate(lines) if ln.startswith("t,")) + 1
    k = first + 100
    if how == "nan":
        parts = lines[k].split(",")
        parts[4] = "nan"
        lines[k] = ",".join(parts)
    elif how == "gap":
        del lines[k:k + 3]
    elif how == "order":
        lines[k], lines[k + 1] = lines[k + 1], lines[k]
    dst.write_text("".join(lines))


@pytest.mark.parametrize("how, word", [("nan", "nan"), ("gap", "gap"),
                                       ("order", "not increasing")])
def test_lc_bad_imu_file(files, tmp_path, capsys, how, word):
    bad = tmp_path / "bad_imu.csv"
    _corrupt(files / "imu.csv", bad, how)
    rc, out = run(["--imu", str(bad), "--truth", str(files / "truth.csv"),
                   "--out", str(tmp_path / "o")], capsys)
    assert rc == 2
    line = one_line_error(out.err)
    assert "bad_imu.csv" in line and word in line.lower()
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_lc_imu_without_truth(files, capsys):
    rc, out = run(["--imu", str(files / "imu.csv")], capsys)
    assert rc == 2 and "--truth" in one_line_error(out.err)


def test_lc_unknown_filter(tmp_path, capsys):
    rc, out = run(["--filter", "kalman9000", "--out", str(tmp_path)], capsys)
    assert rc == 2
    line = one_line_error(out.err)
    assert "kalman9000" in line and "ml-r-ckf" in line


def test_lc_non_positive_definite_p0(tmp_path, capsys):
    sc = tmp_path / "bad.toml"
    text = DEFAULT_SCENARIO.read_text().replace('"../ephemeris/',
                                                f'"{DEFAULT_SCENARIO.parent}/../ephemeris/')
    sc.write_text(text + "\n[lc]\np0_sigma_vel_mps = [0.0, 0.0, 0.0]\n")
    rc, out = run(["--scenario", str(sc), "--duration", "3", "--out", str(tmp_path / "o")],
                  capsys)
    assert rc == 2
    assert "not positive definite" in one_line_error(out.err)


@pytest.mark.parametrize("extra, word", [("q_scale = -1.0", "q_scale"),
                                         ("colour = 3", "unknown key"),
                                         ("r_windows = [[7.0, 3.0, 16.0]]", "t0 < t1"),
                                         ("bias_noise = 1", "bias_noise"),
                                         ("[lc.options.kalman]\nx = 1", "unknown filter")])
def test_lc_bad_lc_table(tmp_path, capsys, extra, word):
    sc = tmp_path / "bad.toml"
    text = DEFAULT_SCENARIO.read_text().replace('"../ephemeris/',
                                                f'"{DEFAULT_SCENARIO.parent}/../ephemeris/')
    sc.write_text(text + f"\n[lc]\n{extra}\n")
    rc, out = run(["--scenario", str(sc), "--duration", "3"], capsys)
    assert rc == 2
    assert word in one_line_error(out.err)


def test_lc_bad_r_window_option(capsys):
    rc, out = run(["--r-window", "10", "5", "16", "--duration", "3"], capsys)
    assert rc == 2 and "--r-window" in one_line_error(out.err)
