"""IMU error model: constants statistics, random-walk scaling with rate, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sdr_di.sim.imu import G_STANDARD, ImuData, ImuErrorModel

SPEC = ImuErrorModel()  # paper 004 Table 4


def _zeros(n: int, rate: float) -> ImuData:
    return ImuData(t=np.arange(n) / rate, f_b=np.zeros((n, 3)), w_ib_b=np.zeros((n, 3)), rate_hz=rate)


def _signal(n: int = 50, rate: float = 200.0) -> ImuData:
    rng = np.random.default_rng(99)
    return ImuData(t=np.arange(n) / rate, f_b=rng.normal(0, 5, (n, 3)) + [0, 0, 9.8],
                   w_ib_b=rng.normal(0, 0.5, (n, 3)), rate_hz=rate)


def test_defaults_are_paper_table4():
    assert (SPEC.accel_scale_factor_ppm, SPEC.gyro_scale_factor_ppm) == (100.0, 100.0)
    assert (SPEC.accel_bias_mg, SPEC.gyro_bias_deg_h) == (4.0, 8.0)
    assert (SPEC.accel_random_walk, SPEC.gyro_random_walk) == (0.05, 0.04)
    assert SPEC.accel_bias_si == pytest.approx(4e-3 * G_STANDARD)
    assert SPEC.gyro_bias_si == pytest.approx(math.radians(8) / 3600)
    assert SPEC.accel_random_walk_si == pytest.approx(0.05 / 60)
    assert SPEC.gyro_random_walk_si == pytest.approx(math.radians(0.04) / 60)


def test_determinism_and_seed_dependence():
    sig = _signal()
    a = SPEC.apply(sig, np.random.default_rng(7))
    b = SPEC.apply(sig, np.random.default_rng(7))
    c = SPEC.apply(sig, np.random.default_rng(8))
    for name in ("f_b", "w_ib_b", "accel_bias", "gyro_bias", "accel_scale", "gyro_scale"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert not np.array_equal(getattr(a, name), getattr(c, name))


def test_perfect_model_is_identity():
    sig = _signal()
    out = ImuErrorModel.perfect().apply(sig, None)
    np.testing.assert_array_equal(out.f_b, sig.f_b)
    np.testing.assert_array_equal(out.w_ib_b, sig.w_ib_b)
    assert out.f_b is not sig.f_b
    with pytest.raises(TypeError):
        SPEC.apply(sig, None)


def test_measurement_equation_without_noise():
    sig = _signal()
    model = ImuErrorModel(accel_random_walk=0.0, gyro_random_walk=0.0)
    out = model.apply(sig, np.random.default_rng(3))
    np.testing.assert_allclose(out.f_b, (1 + out.accel_scale) * sig.f_b + out.accel_bias, rtol=0, atol=1e-14)
    np.testing.assert_allclose(out.w_ib_b, (1 + out.gyro_scale) * sig.w_ib_b + out.gyro_bias, rtol=0, atol=1e-15)
    fixed = ImuErrorModel(draw="fixed").apply(sig, np.random.default_rng(3))
    np.testing.assert_allclose(fixed.accel_bias, [4e-3 * G_STANDARD] * 3)
    np.testing.assert_allclose(fixed.gyro_bias, [math.radians(8) / 3600] * 3)
    np.testing.assert_allclose(fixed.gyro_scale, [1e-4] * 3)


def test_bias_and_scale_statistics():
    """Gaussian draw: zero mean, 1-sigma = spec (600 seeds x 3 axes; 3.5-sigma tolerances)."""
    sig = _zeros(2, 200.0)
    draws = [SPEC.apply(sig, np.random.default_rng(s)) for s in range(600)]
    n = 600 * 3
    tol = 3.5 / math.sqrt(2 * n)  # relative std error of a std estimate
    for attr, spec in (("accel_bias", SPEC.accel_bias_si), ("gyro_bias", SPEC.gyro_bias_si),
                       ("accel_scale", 1e-4), ("gyro_scale", 1e-4)):
        x = np.concatenate([getattr(d, attr) for d in draws])
        assert abs(x.std() / spec - 1) < tol, attr
        assert abs(x.mean()) < 3.5 * spec / math.sqrt(n), attr


@pytest.mark.parametrize("rate, seeds", [(200.0, 40), (10.0, 300)])
def test_random_walk_scaling_over_one_hour(rate, seeds):
    """The integrated noise after 1 h has std = spec (0.05 m/s, 0.04 deg) at any rate."""
    n = int(3600 * rate)
    sig = _zeros(n, rate)
    model = ImuErrorModel(0, 0, 0, 0)  # noise only
    vel, ang, per_sample = [], [], []
    for s in range(seeds):
        out = model.apply(sig, np.random.default_rng(1000 + s))
        vel.append(out.f_b.sum(axis=0) / rate)      # m/s after 1 h
        ang.append(out.w_ib_b.sum(axis=0) / rate)   # rad after 1 h
        if s == 0:
            per_sample = (out.f_b.std(), out.w_ib_b.std())
    m = seeds * 3
    tol = 3.5 / math.sqrt(2 * m)
    assert abs(np.std(np.concatenate(vel)) / 0.05 - 1) < tol
    assert abs(np.degrees(np.std(np.concatenate(ang))) / 0.04 - 1) < tol
    # per-sample std = N / sqrt(dt)
    assert per_sample[0] == pytest.approx(0.05 / 60 * math.sqrt(rate), rel=0.02)
    assert per_sample[1] == pytest.approx(math.radians(0.04) / 60 * math.sqrt(rate), rel=0.02)


def test_invalid_spec():
    with pytest.raises(ValueError):
        ImuErrorModel(accel_bias_mg=-1.0)
    with pytest.raises(ValueError):
        ImuErrorModel(gyro_random_walk=float("nan"))
    with pytest.raises(ValueError):
        ImuErrorModel(draw="uniform")
