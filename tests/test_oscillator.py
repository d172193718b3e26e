"""Receiver oscillator: the truth clock process (sim/oscillator.py) against its Allan
variance, the flicker mapping of the filter's two-state clock, the presets table."""

import math

import numpy as np
import pytest
from scipy.stats import chi2

from sdr_di.errors import ScenarioError
from sdr_di.ins.error_model import ClockModel
from sdr_di.oscillator import (
    CLOCK_PRESETS,
    G0,
    OscillatorSpec,
    allan_variance,
    oscillator_from_table,
    overlapping_allan_variance,
    two_state_coefficients,
)
from sdr_di.sim.oscillator import power_law_phase, simulate_clock

N_PHASE = 10_001      # 1e4 s at tau0 = 1 s
TAU0 = 1.0


def _edf(kind: str, n: int, m: int) -> float:
    """Equivalent degrees of freedom of the overlapping Allan variance (Howe, Allan and
    Barnes 1981; NIST SP 1065 table 5) for ``n`` phase points, ``tau = m tau0``."""
    if kind == "white":
        return (3 * (n - 1) / (2 * m) - 2 * (n - 2) / n) * 4 * m**2 / (4 * m**2 + 5)
    if kind == "flicker":
        return 2 * (n - 2) ** 2 / (2.3 * n - 4.9) if m == 1 else 5 * n**2 / (4 * m * (n + 3 * m))
    return (n - 2) / m * ((n - 1) ** 2 - 3 * m * (n - 1) + 4 * m**2) / (n - 3) ** 2


# one parameter set per dominant term (TCXO magnitudes), the averaging factors tested
CASES = [("white", OscillatorSpec(h0=2e-19), (1, 10, 100)),
         ("flicker", OscillatorSpec(h_1=7e-21), (10, 100)),
         ("random-walk", OscillatorSpec(h_2=2e-20), (10, 100))]


@pytest.mark.parametrize(("kind", "spec", "ms"), CASES, ids=[c[0] for c in CASES])
def test_allan_deviation_within_chi_square_bounds(kind, spec, ms):
    x, y = power_law_phase(spec, N_PHASE - 1, TAU0, np.random.default_rng(14))
    assert x.size == N_PHASE and x[0] == 0.0
    np.testing.assert_allclose(np.diff(x), y * TAU0, rtol=0, atol=1e-12 * np.abs(x).max())
    for m in ms:
        avar = overlapping_allan_variance(x, TAU0, m)
        edf = _edf(kind, N_PHASE, m)
        lo = edf * avar / chi2.ppf(0.9995, edf)
        hi = edf * avar / chi2.ppf(0.0005, edf)
        theory = float(spec.allan_variance(m * TAU0))
        assert lo <= theory <= hi, (kind, m, math.sqrt(avar), math.sqrt(theory), edf)


def test_wrong_level_is_outside_the_bounds():
    """The bounds are tight enough to see a factor of 2 in a coefficient."""
    spec = OscillatorSpec(h_1=7e-21)
    x, _ = power_law_phase(spec, N_PHASE - 1, TAU0, np.random.default_rng(14))
    avar = overlapping_allan_variance(x, TAU0, 10)
    edf = _edf("flicker", N_PHASE, 10)
    hi = edf * avar / chi2.ppf(0.0005, edf)
    assert 2 * float(spec.allan_variance(10.0)) > hi


def test_terms_are_independent_paths():
    """Turning one term off leaves the others' draws unchanged (fixed draw order)."""
    a, _ = power_law_phase(OscillatorSpec(h0=1e-19, h_2=1e-20), 500, 0.1,
                           np.random.default_rng(3))
    b, _ = power_law_phase(OscillatorSpec(h0=1e-19), 500, 0.1, np.random.default_rng(3))
    c, _ = power_law_phase(OscillatorSpec(h_2=1e-20), 500, 0.1, np.random.default_rng(3))
    np.testing.assert_allclose(a, b + c, rtol=1e-12, atol=1e-25)


@pytest.mark.parametrize("name", ["tcxo", "ocxo"])
def test_two_state_envelope_bounds_the_power_law(name):
    s = CLOCK_PRESETS[name]
    h0, h_2 = two_state_coefficients(s.h0, s.h_1, s.h_2)
    tau = np.logspace(-3, 5, 400)
    true = s.allan_variance(tau)
    env = allan_variance(h0, 0.0, h_2, tau)
    assert np.all(env >= true * (1 - 1e-12))
    assert env.min() / true[np.argmin(env - true)] < 1.0 + 1e-3  # touches at tau_m
    cm = ClockModel.from_oscillator(s)
    assert (cm.h0, cm.h_2) == (h0, h_2)
    assert two_state_coefficients(2e-19, 0.0, 2e-20) == (2e-19, 2e-20)


def test_g_sensitivity_integrates_the_specific_force():
    t = np.arange(0.0, 10.0001, 0.005)
    f_b = np.tile([0.0, 0.0, G0], (t.size, 1))
    f_b[t > 5.0, 1] = 2 * G0                      # 2 g forward after 5 s
    spec = OscillatorSpec(g_sensitivity_per_g=(0.0, 1e-9, 2e-9))
    ck = simulate_clock(spec, t, np.random.default_rng(0), bias_s=1e-4, drift_s_s=1e-7,
                        f_b=f_b)
    line = 1e-4 + 1e-7 * t
    expect = 2e-9 * t + 2e-9 * np.clip(t - 5.0, 0.0, None)
    np.testing.assert_allclose(ck.bias_s - line, expect, atol=1e-18)
    np.testing.assert_allclose(ck.drift_s_s[-1], 1e-7 + 4e-9, rtol=1e-9)
    np.testing.assert_allclose(ck.noise_at(np.array([7.5])), 2e-9 * 7.5 + 2e-9 * 2.5,
                               rtol=1e-9)


def test_oscillator_table_errors_name_the_key():
    with pytest.raises(ScenarioError, match=r"\[oscillator\]\.preset: unknown oscillator "
                                            r"preset 'rubidium'"):
        oscillator_from_table({"preset": "rubidium"}, "[oscillator]", ScenarioError)
    with pytest.raises(ScenarioError, match=r"\[oscillator\]\.h_1: h-parameters must be >= 0"):
        oscillator_from_table({"preset": "tcxo", "h_1": -1e-21}, "[oscillator]", ScenarioError)
    with pytest.raises(ScenarioError, match=r"unknown key\(s\) 'h_3'"):
        oscillator_from_table({"h_3": 1.0}, "[oscillator]", ScenarioError)
    with pytest.raises(ScenarioError, match="g_sensitivity_per_g"):
        oscillator_from_table({"g_sensitivity_per_g": [1e-9, 1e-9]}, "[oscillator]",
                              ScenarioError)
    with pytest.raises(ScenarioError, match="unknown key"):
        oscillator_from_table({"g_sensitivity_per_g": [0, 0, 0]}, "[assume.oscillator]",
                              ScenarioError, allow_g=False)
    s = oscillator_from_table({"preset": "tcxo", "h0": 1e-19}, "x", ScenarioError)
    assert (s.h0, s.h_1, s.h_2, s.preset) == (1e-19, 7e-21, 2e-20, "tcxo (modified)")
    assert oscillator_from_table({}, "x", ScenarioError).is_ideal
