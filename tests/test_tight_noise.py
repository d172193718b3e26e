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
