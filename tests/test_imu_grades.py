"""IMU grades (issue 46 item 1): draws per seed match the grade's 1-sigma values, the same
seed gives the same unit, the measurement model is the documented one, and the default
scenario's legacy IMU is untouched."""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from sdr_di.errors import AssumptionsError
from sdr_di.ins.grades import GRADE_PROVENANCE, GRADE_SOURCES, IMU_GRADES
from sdr_di.ins.imu import G_STANDARD, ImuData, ImuErrorModel
from sdr_di.integration.assumptions import parse_assumptions
from sdr_di.scenario.schema import ImuSpec, load_scenario, parse_scenario

REPO = Path(__file__).resolve().parents[1]
GRADES = ("navigation", "tactical", "industrial", "consumer")
N_DRAWS = 200


def _sd_in_band(x: np.ndarray, sigma: float, p: float = 1e-4) -> None:
    """Zero-mean draws ``x`` have standard deviation ``sigma``: ``sum x^2 / sigma^2`` is
    chi-square with ``x.size`` degrees of freedom (two-sided, total probability ``p`` of a
    false alarm), and the mean is within 4 standard errors of 0."""
    x = np.ravel(x)
    q = float(np.sum(x * x) / sigma**2)
    lo, hi = chi2.ppf([p / 2, 1 - p / 2], x.size)
    assert lo < q < hi, (q / x.size, lo / x.size, hi / x.size)
    assert abs(x.mean()) < 4 * sigma / math.sqrt(x.size)


@pytest.mark.parametrize("grade", GRADES)
def test_200_units_of_a_grade_have_its_1_sigma_values(grade):
    m = IMU_GRADES[grade]
    units = [m.draw_unit(np.random.default_rng([seed, 46])) for seed in range(N_DRAWS)]
    off = ~np.eye(3, dtype=bool)
    cases = [
        ([u.accel_scale for u in units], m.accel_scale_factor_ppm * 1e-6),
        ([u.gyro_scale for u in units], m.gyro_scale_factor_ppm * 1e-6),
        ([u.accel_bias for u in units], m.accel_bias_mg * 1e-3 * G_STANDARD),
        ([u.gyro_bias for u in units], math.radians(m.gyro_bias_deg_h) / 3600.0),
        ([u.M_a[off] for u in units], m.accel_misalignment_mrad * 1e-3),
        ([u.M_g[off] for u in units], m.gyro_misalignment_mrad * 1e-3),
        ([u.G_g for u in units],
         math.radians(m.gyro_g_sensitivity_deg_h_per_g) / 3600.0 / G_STANDARD),
    ]
    for draws, sigma in cases:
        x = np.asarray(draws)
        if sigma == 0:
            assert not x.any()
        else:
            _sd_in_band(x, sigma)
    assert all(np.all(np.diag(u.M_a) == 0) and np.all(np.diag(u.M_g) == 0) for u in units)


@pytest.mark.parametrize("grade", GRADES)
def test_in_run_bias_and_noise_of_a_grade(grade):
    """The Gauss-Markov in-run bias reaches its stationary 1-sigma (200 units, a short
    correlation time so that 1 s is many of them), and what is left after the unit's
    recorded errors is white noise of the random walks' density: the measurement model of
    the docstring, term for term (a wrong matrix or axis would leave a large residual)."""
    m = dataclasses.replace(IMU_GRADES[grade], accel_bias_tau_s=0.05, gyro_bias_tau_s=0.05)
    n, rate = 200, 200.0
    f_b = np.tile([0.7, -1.3, 9.9], (n, 1))
    w_ib_b = np.tile([0.2, -0.1, 0.5], (n, 1))
    truth = ImuData(t=np.arange(1, n + 1) / rate, f_b=f_b, w_ib_b=w_ib_b, rate_hz=rate)
    d_a, d_g, r_a, r_g = [], [], [], []
    for seed in range(N_DRAWS):
        imu = m.apply(truth, np.random.default_rng([seed, 460]))
        u = imu.unit
        d_a.append(u.d_a[-1])
        d_g.append(u.d_g[-1])
        K_a = np.eye(3) + np.diag(u.accel_scale) + u.M_a
        K_g = np.eye(3) + np.diag(u.gyro_scale) + u.M_g
        r_a.append(imu.f_b - f_b @ K_a.T - u.accel_bias - u.d_a)
        r_g.append(imu.w_ib_b - w_ib_b @ K_g.T - u.gyro_bias - u.d_g - f_b @ u.G_g.T)
    _sd_in_band(np.array(d_a), m.accel_bias_instability_si)
    _sd_in_band(np.array(d_g), m.gyro_bias_instability_si)
    _sd_in_band(np.array(r_a)[:, ::10], m.accel_random_walk_si * math.sqrt(rate))
    _sd_in_band(np.array(r_g)[:, ::10], m.gyro_random_walk_si * math.sqrt(rate))


def test_in_run_bias_starts_from_zero_at_switch_on():
    m = dataclasses.replace(IMU_GRADES["consumer"], gyro_bias_tau_s=100.0)
    w = np.random.default_rng(1).standard_normal((2000, 400))
    d = m.gauss_markov(w, 1.0, 100.0, 0.005)
    k = np.array([0, 99, 1999])
    expected = 1.0 - math.exp(-2 * 0.005 / 100.0) ** (k + 1)
    for j, v in zip(k, expected):
        lo, hi = chi2.ppf([5e-5, 1 - 5e-5], 400) / 400
        assert lo < np.mean(d[j] ** 2) / v < hi


def test_same_seed_same_unit_whatever_the_duration():
    m = IMU_GRADES["tactical"]

    def unit(seed, n):
        tr = ImuData(t=np.arange(1, n + 1) / 200.0, f_b=np.tile([0, 0, 9.8], (n, 1)),
                     w_ib_b=np.zeros((n, 3)), rate_hz=200.0)
        return m.apply(tr, np.random.default_rng(seed)).unit

    a, b, c = unit(7, 50), unit(7, 400), unit(8, 50)
    for name in ("accel_bias", "gyro_bias", "accel_scale", "gyro_scale", "M_a", "M_g", "G_g"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.d_g, b.d_g[:50]) and np.array_equal(a.d_a, b.d_a[:50])
    assert not np.array_equal(a.gyro_bias, c.gyro_bias)
    assert a.record() == unit(7, 50).record()


def test_grade_tables_are_documented_and_sourced():
    text = (REPO / "docs" / "assumptions.md").read_text()
    for g in GRADES:
        assert g in GRADE_SOURCES and g in GRADE_PROVENANCE
        assert set(GRADE_PROVENANCE[g].values()) <= {"D", "S", "R", "A"}
        doc = GRADE_SOURCES[g].split(" data sheet")[0].split(" IMU brochure")[0]
        assert doc.split()[-1] in text, doc
        assert IMU_GRADES[g].is_extended


def test_scenario_grade_fills_terms_and_explicit_values_override():
    raw_default = (REPO / "signals" / "default.toml").read_text()
    sc = load_scenario(REPO / "signals" / "default.toml")
    assert sc.imu.grade == "mems" and not sc.imu.is_extended
    assert list(sc.imu.as_dict()) == list(ImuSpec.LEGACY)
    assert not ImuErrorModel.from_spec(sc.imu).is_extended
    raw = tomllib.loads(raw_default)
    raw["satellites"]["ephemeris"] = str(REPO / "ephemeris" / Path(
        raw["satellites"]["ephemeris"]).name)
    raw["imu"] = {"grade": "industrial", "gyro_bias_deg_h": 50.0}
    spec = parse_scenario(raw).imu
    model = ImuErrorModel.from_spec(spec)
    assert model.gyro_bias_deg_h == 50.0
    assert model.gyro_bias_instability_deg_h == IMU_GRADES["industrial"].gyro_bias_instability_deg_h
    assert model.gyro_g_sensitivity_deg_h_per_g == 32.4 and spec.as_dict()["grade"] == "industrial"


def test_assumptions_take_a_grade_and_refuse_terms_without_states():
    a = parse_assumptions({"imu": {"grade": "tactical", "accel_bias_mg": 2.0}}, "a.toml")
    t = IMU_GRADES["tactical"]
    assert a.imu.gyro_bias_deg_h == t.gyro_bias_deg_h
    assert a.imu.gyro_random_walk == t.gyro_random_walk and a.imu.accel_bias_mg == 2.0
    with pytest.raises(AssumptionsError, match=r"gyro_misalignment_mrad: not an assumption"):
        parse_assumptions({"imu": {"grade": "consumer", "gyro_misalignment_mrad": 1.0}},
                          "a.toml")
