"""Tight mode's R: the scalar receiver's thermal code and Doppler noise (tight_ranges notes).

The DLL formula against a Monte Carlo of :class:`~sdr_di.receiver.loops.CodeLoop` fed the
normalized early-minus-late envelope of simulated correlator sums; the PLL formula is checked
the same way in ``tests/test_receiver_tracking.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sdr_di.constants import C_LIGHT, CHIP_RATE_B3I, LAMBDA_B3I
from sdr_di.integration.tight_ranges import tracking_variances
from sdr_di.receiver.loops import (
    CodeLoop,
    dll_code_noise_chips,
    dll_nelp,
    pll_doppler_noise_hz,
)
from sdr_di.receiver.tracking import TrackingConfig


def _dll_monte_carlo(cn0_dbhz, t, bw, d, n=6000, seed=2):
    """RMS code error [chips] of the first-order DLL on a static signal (carrier aided:
    the only code motion is the loop's own correction)."""
    rng = np.random.default_rng(seed)
    amp = math.sqrt(2.0 * 10 ** (cn0_dbhz / 10) * t)      # unit noise per component
    loop = CodeLoop(bw, 1)
    tau = 0.0
    err = []
    for k in range(n):
        e = abs(amp * max(1 - abs(tau - d), 0) + rng.normal() + 1j * rng.normal())
        late = abs(amp * max(1 - abs(tau + d), 0) + rng.normal() + 1j * rng.normal())
        tau -= loop.update(dll_nelp(e, late, d), t) * t
        if k > 500:
            err.append(tau)
    return float(np.sqrt(np.mean(np.square(err))))


@pytest.mark.parametrize("cn0_dbhz", [40.0, 30.0])
def test_dll_code_noise_matches_monte_carlo(cn0_dbhz):
    mc = _dll_monte_carlo(cn0_dbhz, 0.01, 1.0, 0.5)
    assert dll_code_noise_chips(cn0_dbhz, 0.01, 1.0, 0.5) == pytest.approx(mc, rel=0.12)


def test_tracking_variances_use_each_channels_coherent_time():
    cfg = TrackingConfig()
    vp, vd = tracking_variances([10, 1], [40.0, 40.0], cfg)       # MEO D1, GEO D2
    s10 = dll_code_noise_chips(40.0, 0.01, cfg.track_dll_bw_hz, cfg.spacing_chips)
    assert math.sqrt(vp[0]) == pytest.approx(C_LIGHT / CHIP_RATE_B3I * s10)
    s2 = dll_code_noise_chips(40.0, 0.002, cfg.track_dll_bw_hz, cfg.spacing_chips)
    assert math.sqrt(vp[1]) == pytest.approx(C_LIGHT / CHIP_RATE_B3I * s2)
    assert vd[1] == pytest.approx((LAMBDA_B3I * pll_doppler_noise_hz(40.0, 0.002, 15.0)) ** 2)
    vp30, vd30 = tracking_variances([10], [30.0], cfg)
    assert 8.0 < vp30[0] / vp[0] < 14.0 and 8.0 < vd30[0] / vd[0] < 14.0


def test_loose_fix_covariance_is_the_wls_error_covariance_under_thermal_noise():
    """Monte Carlo of the WLS position/velocity with the PVT's weights on the thermal noise:
    its error covariance equals :func:`thermal_fix_covariance` (position block without the
    time-correlation factor), where the formal covariance is many times larger."""
    import types

    from sdr_di.integration.loose_fixes import thermal_fix_covariance
    from sdr_di.integration.tight_ranges import range_correlation_factor
    from sdr_di.receiver.pvt import measurement_variances

    rng = np.random.default_rng(7)
    el = np.radians([75.0, 40.0, 30.0, 55.0, 20.0, 35.0])
    az = np.radians([10.0, 95.0, 200.0, 280.0, 45.0, 150.0])
    prns = np.array([19, 20, 21, 22, 1, 23])
    cn0 = np.array([42.0, 38.0, 35.0, 40.0, 33.0, 37.0])
    sol = types.SimpleNamespace(elevation=el, azimuth=az, prns=prns)
    R = thermal_fix_covariance(sol, cn0, interval_s=0.2)
    e = np.column_stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    H = np.hstack([-e, np.ones((6, 1))])
    w_p, w_d = (1.0 / v for v in measurement_variances(el, cn0))
    s_p, s_d = tracking_variances(prns, cn0)
    n = 20000
    out = []
    for w, s2 in ((w_d, s_d), (w_p, s_p)):
        A = np.linalg.solve(H.T @ (H * w[:, None]), (H * w[:, None]).T)
        x = (rng.normal(size=(n, 6)) * np.sqrt(s2)) @ A.T
        out.append(np.cov(x[:, :3].T))
        formal = np.linalg.inv(H.T @ (H * w[:, None]))[:3, :3]
        assert np.trace(formal) > 4.0 * np.trace(out[-1])
    f = float(np.mean(range_correlation_factor(prns, 0.2)))
    assert 2.0 < f < 3.0
    assert np.allclose(R[:3, :3], out[0], rtol=0.05, atol=0.03 * np.max(out[0]))
    neu = [1, 0, 2]
    assert np.allclose(R[3:, 3:] / f, out[1][np.ix_(neu, neu)], rtol=0.05,
                       atol=0.03 * np.max(out[1]))
