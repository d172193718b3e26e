"""Consistency statistics of a run (sdr_di.integration.consistency; issue 25 item 1).

The formulas are checked on a linear-Gaussian filter whose covariances are right by
construction (a constant-velocity model observed in position and velocity, with noise
correlated across the two blocks): the block NIS per degree of freedom and the NEES per
degree of freedom come out in their chi-square bands around 1, and leave them when the
filter's R is 4 times too large, or when the statistic is computed with the wrong matrix
or without the degree-of-freedom normalization. The ``lc`` command, whose simulated GNSS
noise is white and equal to the filter's R, writes the formal sigmas and a ``consistency``
entry with values near 1.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from filter_problems import cv2d

from sdr_di.filters import LinearMeasurementModel, LinearProcessModel, make_filter
from sdr_di.frames import radii_of_curvature
from sdr_di.integration.consistency import (
    BAND_RULE,
    SD_COLUMNS,
    block_nis,
    chi2_band,
    consistency_summary,
    effective_count,
    enu_blocks,
    formal_sd,
    nees_per_dof,
)

STEPS = 1500


def _toy(r_scale: float = 1.0, seed: int = 7):
    """Run a CV-2D KF with z = [x, y, vx, vy]; per step the block NIS, the NEES of the
    position and the whole-vector statistics for the wrong-formula checks."""
    F, Q = cv2d(1.0, 0.3)
    R = np.array([[4.0, 0.0, 0.6, 0.0], [0.0, 4.0, 0.0, 0.6],
                  [0.6, 0.0, 0.25, 0.0], [0.0, 0.6, 0.0, 0.25]])    # pos/vel correlated
    rng = np.random.default_rng(seed)
    P0 = np.diag([10.0, 10.0, 1.0, 1.0]) ** 2
    x = np.array([0.0, 0.0, 3.0, -1.0])
    kf = make_filter("ekf", LinearProcessModel(F), LinearMeasurementModel(np.eye(4)),
                     x + rng.multivariate_normal(np.zeros(4), P0), P0, Q, r_scale * R)
    Lq, Lr = np.linalg.cholesky(Q), np.linalg.cholesky(R)
    nis, nees, nis_nodof, nis_pzz = [], [], [], []
    for _ in range(STEPS):
        x = F @ x + Lq @ rng.normal(size=4)
        kf.predict()
        kf.update(x + Lr @ rng.normal(size=4))
        nis.append(block_nis(kf.y, kf.S, 2))
        b = slice(0, 2)
        nis_nodof.append(float(kf.y[b] @ np.linalg.solve(kf.S[b, b], kf.y[b])))
        Pzz = kf.S - kf.R_used
        nis_pzz.append(float(kf.y[b] @ np.linalg.solve(Pzz[b, b], kf.y[b])) / 2)
        nees.append(nees_per_dof((kf.x - x)[:2], kf.P[:2, :2]))
    return (np.array(nis), np.array(nees), np.array(nis_nodof), np.array(nis_pzz))


def _in_band(x: np.ndarray, dof: int) -> bool:
    lo, hi = chi2_band(effective_count(x), dof)
    return lo <= float(np.mean(x)) <= hi


def test_block_nis_and_nees_of_a_consistent_filter_are_in_their_bands():
    nis, nees, nis_nodof, nis_pzz = _toy()
    assert _in_band(nis[:, 0], 2) and _in_band(nis[:, 1], 2), nis.mean(axis=0)
    assert _in_band(nees, 2), nees.mean()
    # the wrong formulas leave the band: no division by the block size, P_zz for S
    assert not _in_band(nis_nodof, 2), nis_nodof.mean()
    assert not _in_band(nis_pzz, 2), nis_pzz.mean()


def test_a_pessimistic_r_leaves_the_band():
    nis, nees, *_ = _toy(r_scale=4.0)
    assert nis[:, 0].mean() < chi2_band(effective_count(nis[:, 0]), 2)[0]
    assert nis[:, 1].mean() < chi2_band(effective_count(nis[:, 1]), 2)[0]
    assert nees.mean() < chi2_band(effective_count(nees), 2)[0]


def test_block_nis_uses_each_blocks_own_part_of_s():
    S = np.array([[4.0, 1.0, 0.0, 0.0], [1.0, 2.0, 0.0, 0.0],
                  [0.0, 0.0, 9.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    y = np.array([2.0, 0.0, 3.0, 1.0])
    b = block_nis(y, S, 2)
    assert b[0] == pytest.approx(y[:2] @ np.linalg.solve(S[:2, :2], y[:2]) / 2)
    assert b[1] == pytest.approx((1.0 + 1.0) / 2)


def test_effective_count_of_an_ar1_series():
    rng = np.random.default_rng(3)
    rho, n = 0.8, 20000
    e = rng.normal(size=n)
    x = np.empty(n)
    x[0] = e[0]
    for k in range(1, n):
        x[k] = rho * x[k - 1] + e[k]
    expected = n * (1 - rho) / (1 + rho)                # N / (1 + 2 sum rho^k)
    assert effective_count(x) == pytest.approx(expected, rel=0.15)
    assert effective_count(rng.normal(size=n)) == pytest.approx(n, rel=0.05)


def test_enu_blocks_map_lat_lon_height_to_metres():
    lat, h = math.radians(40.0), 100.0
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    P = np.eye(17) * 1e-6
    P[6, 6] = (2.0 / (R_M + h)) ** 2                     # 2 m north
    P[7, 7] = (3.0 / ((R_N + h) * math.cos(lat))) ** 2   # 3 m east
    P[8, 8] = 5.0 ** 2
    P[0, 0] = math.radians(0.5) ** 2
    sd = formal_sd(P, [lat, 0.3, h])
    assert sd[:3] == pytest.approx([3.0, 2.0, 5.0])
    assert sd[3:6] == pytest.approx([1e-3] * 3)
    assert sd[6] == pytest.approx(0.5)
    _, _, P_pos = enu_blocks(P, [lat, 0.3, h])
    assert nees_per_dof(np.array([3.0, 2.0, 5.0]), P_pos) == pytest.approx(1.0)


def test_summary_entry_names_blocks_and_band():
    rng = np.random.default_rng(1)
    t = np.arange(200) * 0.1
    nis = rng.chisquare(3, size=(200, 2)) / 3
    nees = rng.chisquare(3, size=(200, 3)) / 3
    c = consistency_summary("tight", t, nis, np.full(200, 3), t, nees, t0=5.0)
    assert c["band_rule"] == BAND_RULE
    assert set(c) == {"band_rule", "nis_range", "nis_rate", "nees_pos", "nees_vel",
                      "nees_att"}
    e = c["nis_range"]
    assert e["expected"] == 1.0 and e["n"] == 150
    assert e["value"] == pytest.approx(nis[50:, 0].mean())
    assert e["band"][0] < 1.0 < e["band"][1]


def test_lc_writes_formal_sigmas_and_consistency(tmp_path, capsys):
    from sdr_di.cli import main

    assert main(["lc", "--filter", "ekf", "--duration", "60", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    lines = (tmp_path / "default_lc_ekf.csv").read_text().splitlines()
    cols = lines[1].split(",")
    assert tuple(cols[-9:]) == SD_COLUMNS
    data = np.loadtxt(tmp_path / "default_lc_ekf.csv", delimiter=",", skiprows=2)
    assert np.all(data[:, -9:] > 0)
    c = json.loads((tmp_path / "default_lc_ekf_summary.json").read_text())["consistency"]
    # the simulated fixes are white with the filter's R: the NIS is near 1 (measured 0.82
    # velocity, 0.91 position; NEES 0.73 position, 0.72 velocity over 60 s)
    for k in ("nis_vel", "nis_pos", "nees_pos", "nees_vel"):
        assert 0.5 < c[k]["value"] < 1.5, (k, c[k])


def test_check_consistency_script_table_means_over_seeds():
    """scripts/check_consistency.py's table: mean over the seeds that ran, failures counted
    apart, each mode's own block names (the grid runner itself is exercised by hand)."""
    import argparse
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scripts" / "check_consistency.py"
    spec = importlib.util.spec_from_file_location("check_consistency", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    args = argparse.Namespace(modes=["deep", "loose"], cn0=[30.0], filters=["ekf"],
                              filter_rates=[50.0, 10.0], duration=30.0, fs=2.5e6,
                              t_step=15.0, t0=17.0)
    recs = [{"mode": "deep", "cn0_dbhz": 30.0, "filter": "ekf", "filter_rate_hz": 50.0,
             "seed": s, "error": "", "nis_code": v, "nis_rate": 2 * v, "nees_pos": 1.0,
             "nees_vel": 1.0, "nees_att": 1.0} for s, v in ((0, 0.5), (1, 1.5))]
    recs.append({"mode": "deep", "cn0_dbhz": 30.0, "filter": "ekf", "filter_rate_hz": 50.0,
                 "seed": 2, "error": "HandoverError: x"})
    recs.append({"mode": "deep", "cn0_dbhz": 30.0, "filter": "ekf", "filter_rate_hz": 10.0,
                 "seed": 0, "error": "", "nis_code": 3.0, "nis_rate": 3.0, "nees_pos": 1.0,
                 "nees_vel": 1.0, "nees_att": 1.0})
    text = mod.table(recs, args)
    rows = [ln for ln in text.splitlines() if ln.startswith("| deep")]
    assert rows[0].split("|")[4:10] == [" 50 ", " - ", " 2 ", " 1 ", " code 1 ", " rate 2 "]
    assert rows[1].split("|")[4:10] == [" 10 ", " - ", " 1 ", " 0 ", " code 3 ", " rate 3 "]
    assert "| loose | 30 | ekf | 50 | - | 0 | 0 | vel - | pos - |" in text


@pytest.mark.parametrize(("n_runs", "dim"), [(1, 1), (8, 3), (24, 3), (50, 2), (200, 2)])
def test_ensemble_band_is_the_chi_square_quantiles(n_runs, dim):
    """ANEES band over N runs of dimension n (Bar-Shalom et al. 2001, 5.4.2):
    chi2.ppf([0.025, 0.975], N n) / N, and per degree of freedom / (N n)."""
    from scipy.stats import chi2

    from sdr_di.integration.consistency import ensemble_band

    ref = chi2.ppf([0.025, 0.975], n_runs * dim) / n_runs
    assert ensemble_band(n_runs, dim, per_dof=False) == pytest.approx(ref, rel=1e-10)
    assert ensemble_band(n_runs, dim) == pytest.approx(ref / dim, rel=1e-10)
    ref99 = chi2.ppf([0.005, 0.995], n_runs * dim) / (n_runs * dim)
    assert ensemble_band(n_runs, dim, 0.99) == pytest.approx(ref99, rel=1e-10)


def test_check_consistency_ensemble_averages_runs_on_a_shared_grid():
    """``--ensemble``: runs that hand over at different times (rows on grids offset by a
    fraction of the output period) are averaged epoch by epoch; consistent NEES (chi-square
    3 / 3 draws) give an ANEES inside the band of N runs (scipy's quantiles), 2x too large
    errors (NEES 4x) one above it, and the share of epochs inside follows."""
    import argparse
    import importlib.util
    from pathlib import Path

    from scipy.stats import chi2

    path = Path(__file__).resolve().parents[1] / "scripts" / "check_consistency.py"
    spec = importlib.util.spec_from_file_location("check_consistency", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rng = np.random.default_rng(0)
    n_runs, n_rows = 30, 200
    recs = []
    for arch, scale in (("reset", 1.0), ("prefilter", 4.0)):
        for k in range(n_runs):
            t0 = 12.0 + rng.uniform(0.0, 0.2)           # each run's own hand-over
            rows = {round(t0 + 0.2 * i, 3): (scale * rng.chisquare(3, 3) / 3, 0.0, 0.0, 0.0)
                    for i in range(n_rows)}
            ups = {round(t0 + 0.02 * i, 3): (rng.chisquare(7, 2) / 7, 7)
                   for i in range(10 * n_rows)}
            recs.append({"mode": "deep", "cn0_dbhz": 40.0, "filter": "ekf",
                         "filter_rate_hz": 50.0, "architecture": arch, "seed": k, "error": "",
                         "series": {"rows": rows, "updates": ups}})
    out = {r["architecture"]: r for r in mod.ensemble_rows(recs, argparse.Namespace())}
    lo, hi = (chi2.ppf(q, 3 * n_runs) / (3 * n_runs) for q in (0.025, 0.975))
    good, bad = out["reset"], out["prefilter"]
    assert good["n"] == n_runs and good["anees_pos_band"] == pytest.approx((lo, hi))
    assert lo < good["anees_pos"] < hi and good["anees_pos_inside"] > 0.85
    assert bad["anees_pos"] > 3.5 and bad["anees_pos_inside"] == 0.0
    lo7, hi7 = (chi2.ppf(q, 7 * n_runs) / (7 * n_runs) for q in (0.025, 0.975))
    assert good["anis_code_band"] == pytest.approx((lo7, hi7))
    assert lo7 < good["anis_code"] < hi7


def test_ensemble_band_book_example_and_bad_input():
    from sdr_di.integration.consistency import ensemble_band

    # the book's example: 50 runs of a 2-state NEES give the 95 % region [1.5, 2.6]
    lo, hi = ensemble_band(50, 2, per_dof=False)
    assert (round(lo, 1), round(hi, 1)) == (1.5, 2.6)
    for bad in ((0, 3), (5, 0), (2.5, 3), (True, 3)):
        with pytest.raises(ValueError, match="positive integer"):
            ensemble_band(*bad)
    with pytest.raises(ValueError, match="level"):
        ensemble_band(5, 3, 1.0)


@pytest.mark.parametrize("m, n_blocks", [(14, 2), (2, 2), (9, 2), (12, 3), (0, 2)])
def test_block_nis_kernel_equals_the_numpy_form(m, n_blocks, monkeypatch):
    """The kernel (``consistency.jit``) against the numpy form: random SPD covariances and
    innovations, the split and the whole-vector case (``m`` not a multiple), empty ``y``."""
    from sdr_di.integration import consistency

    rng = np.random.default_rng(m)
    for _ in range(20):
        A = rng.normal(size=(m, m))
        S = A @ A.T + 0.1 * np.eye(m) * rng.uniform(0.01, 100.0)
        y = rng.normal(size=m) * rng.uniform(0.1, 10.0)
        monkeypatch.setattr(consistency, "jit", True)
        fast = block_nis(y, S, n_blocks)
        monkeypatch.setattr(consistency, "jit", False)
        ref = block_nis(y, S, n_blocks)
        np.testing.assert_allclose(fast, ref, rtol=1e-12, atol=0.0)
        assert np.array_equal(np.isnan(fast), np.isnan(ref))
