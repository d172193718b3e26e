"""Truth atmosphere apart from the receiver's models and the drawn truth on record (issue 46
items 1 and 4): a short file with a grade and atmospheric residuals records its draws in the
sidecar and the truth file's header, and its delays differ from Klobuchar and Saastamoinen
by exactly the drawn amounts; ``truth = "model"`` gives the model's delays."""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from sdr_di.constants import CHIP_RATE_B3I
from sdr_di.errors import ScenarioError
from sdr_di.orbits.atmosphere import saastamoinen_zenith_wet
from sdr_di.scenario.schema import AtmosphereSpec, parse_scenario
from sdr_di.sim.atmosphere import AtmosphereTruth, chao_wet_mapping
from sdr_di.sim.generate import generate_files, make_generator

REPO = Path(__file__).resolve().parents[1]


def _scenario(imu: dict | None = None, atmosphere: dict | None = None, duration_s=0.1):
    raw = tomllib.loads((REPO / "signals" / "default.toml").read_text())
    raw["satellites"]["ephemeris"] = str(REPO / "ephemeris" / Path(
        raw["satellites"]["ephemeris"]).name)
    if imu is not None:
        raw["imu"] = imu
    if atmosphere is not None:
        raw["atmosphere"] = atmosphere
    raw["scenario"]["duration_s"] = duration_s
    raw["signal"]["sampling_rate_hz"] = 2.5e6
    return parse_scenario(raw)


@pytest.fixture(scope="module")
def graded(tmp_path_factory):
    sc = _scenario({"grade": "tactical"}, {"truth": "residuals"})
    out = tmp_path_factory.mktemp("graded")
    paths = generate_files(sc, out, name="g", progress=False)
    return sc, paths


def _header(path: Path) -> dict:
    meta = {}
    for line in path.read_text().splitlines():
        if not line.startswith("#"):
            break
        key, _, value = line[1:].partition(":")
        meta[key.strip()] = value.strip()
    return meta


def test_draws_recorded_in_sidecar_and_truth_header(graded):
    sc, paths = graded
    meta = json.loads(paths["metadata"].read_text())
    head = _header(paths["truth"])
    assert json.loads(head["imu_unit"]) == meta["imu_unit"]
    assert json.loads(head["atmosphere_truth"]) == meta["atmosphere_truth"]
    assert meta["imu"]["grade"] == "tactical" and meta["imu"]["gyro_bias_tau_s"] == 600.0
    # the IMU file's true constants are the unit's
    imu_head = _header(paths["imu"])
    assert np.allclose([float(v) for v in imu_head["true_gyro_bias_rads"].split()],
                       meta["imu_unit"]["gyro_bias"], rtol=1e-15)
    # reproducible from the seed
    again = make_generator(sc).atmosphere.record()
    assert again == meta["atmosphere_truth"]
    prns = sorted(s["prn"] for s in meta["satellites"])
    assert sorted(meta["atmosphere_truth"]["iono_scale"]) == [f"C{p:02d}" for p in prns]


def test_delays_differ_from_the_models_by_the_drawn_amounts(graded):
    """At t = 0 the slow variations are zero, so truth - model is the drawn constants alone:
    the ionosphere ``k_s I_Klobuchar`` (per satellite), the troposphere
    ``(ZWD_0 + dz) m_Chao(E) - ZWD_0 / sin E``; the IF generator's code phases move by those
    delays."""
    sc, paths = graded
    rec = json.loads(paths["metadata"].read_text())["atmosphere_truth"]
    gen = make_generator(sc)
    model = make_generator(sc)
    model.atmosphere = None
    st_true, st_model = gen.node_state(0, 1), model.node_state(0, 1)
    from sdr_di.sim.geometry import satellite_delays

    t = np.array([0.0])
    zwd0 = float(saastamoinen_zenith_wet(sc.height))
    assert rec["zwd_model_m"] == pytest.approx(zwd0, rel=1e-12)
    moved = 0
    for k, sat in enumerate(gen.sats):
        d_true = satellite_delays(sat.eph, gen.path, t, sc.sow, t, gen.iono, True,
                                  atmosphere=gen.atmosphere)
        d_model = satellite_delays(sat.eph, gen.path, t, sc.sow, t, gen.iono, True)
        k_s = rec["iono_scale"][f"C{sat.prn:02d}"]
        assert d_model.iono_m[0] > 1.0                      # daytime: metres of delay
        assert d_true.iono_m[0] - d_model.iono_m[0] == pytest.approx(
            max(k_s, -1.0) * d_model.iono_m[0], rel=1e-9, abs=1e-9)
        el = max(d_model.el[0], math.radians(0.1))
        dz = rec["zwd_offset_m"]
        expected = (zwd0 + dz) * chao_wet_mapping(el) - zwd0 / math.sin(el)
        assert d_true.tropo_m[0] - d_model.tropo_m[0] == pytest.approx(expected, abs=1e-9)
        # the IF: code phase later by the extra code delay (chips, modulo the code period)
        dd = (d_true.d_code[0] - d_model.d_code[0]) * CHIP_RATE_B3I
        dchip = (st_model["chip0"][k, 0] - st_true["chip0"][k, 0]) % 10230.0
        dchip = dchip - 10230.0 if dchip > 5115.0 else dchip
        assert dchip == pytest.approx(dd, abs=1e-5)
        moved += abs(dd) > 1e-3
    assert moved >= len(gen.sats) - 1


def test_truth_model_switch_gives_the_models():
    sc = _scenario(atmosphere={"truth": "model", "zwd_sigma_m": 0.2})
    assert make_generator(sc).atmosphere is None
    assert _scenario().atmosphere is None and AtmosphereSpec().truth == "model"


def test_atmosphere_draws_have_their_1_sigma_values():
    spec = AtmosphereSpec(truth="residuals", iono_variation_tau_s=2.0,
                          zwd_variation_tau_s=2.0)
    prns = (8, 10, 13, 27, 28, 30, 32)
    draws = [AtmosphereTruth(spec, prns, 20.0, seed, 100.0) for seed in range(200)]
    k = np.array([[a.iono_scale[p] for p in prns] for a in draws])
    dz = np.array([a.zwd_offset_m for a in draws])
    g_end = np.array([[a.iono_variation[p][-1] for p in prns] for a in draws])
    z_end = np.array([a.zwd_variation_m[-1] for a in draws])
    for x, sigma in ((k, spec.iono_scale_sigma), (dz, spec.zwd_sigma_m),
                     (g_end, spec.iono_variation_sigma), (z_end, spec.zwd_variation_sigma_m)):
        x = x.ravel()
        lo, hi = chi2.ppf([5e-5, 1 - 5e-5], x.size)
        assert lo < np.sum(x * x) / sigma**2 < hi
    a = draws[0]
    assert a.iono_variation[8][1] == 0.0 and a.zwd_variation_m[1] == 0.0  # 0 at t = 0
    assert a.iono_factor(8, 0.0) == pytest.approx(1.0 + a.iono_scale[8])


def test_bad_atmosphere_table():
    with pytest.raises(ScenarioError, match=r"\[atmosphere\]\.truth: 'klobuchar' is not one"):
        _scenario(atmosphere={"truth": "klobuchar"})
    with pytest.raises(ScenarioError, match=r"\[atmosphere\]\.iono_variation_tau_s: must be > 0"):
        _scenario(atmosphere={"truth": "residuals", "iono_variation_tau_s": 0.0})
    with pytest.raises(ScenarioError, match=r"\[atmosphere\]: unknown key\(s\) 'zwd_sigma'"):
        _scenario(atmosphere={"zwd_sigma": 0.1})
