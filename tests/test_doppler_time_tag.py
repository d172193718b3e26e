"""The scalar Doppler's time tag (issue 25): the carrier loop's frequency integrator holds the
Doppler at the middle of the block it steers; observations carry it to their sample with the
loop's rate, and what is left under dynamics is the third-order loop's jerk error."""

import math

import numpy as np

from sdr_di.receiver.channel import Channel
from sdr_di.receiver.loops import PLL3_B3, CarrierLoop, pll_natural_frequency

FS = 2.5e6


def test_observation_doppler_is_carried_from_the_block_middle_with_the_loop_rate():
    ch = Channel(11, FS, 0.0, log=False)
    ch.start(0, 0.0, 1000.0, 45.0)
    ch.carrier.reset(1000.0, rate_hz_s=50.0)
    ch._plan()  # replan the first block with the rate
    s0, n = ch.block[0][0], ch.block_end - ch.block[0][0]
    mid = s0 + 0.5 * n
    d0 = ch.observation_at(s0).doppler_hz
    d1 = ch.observation_at(s0 + n - 1).doppler_hz
    assert math.isclose(d0, 1000.0 + 50.0 * (s0 - mid) / FS, abs_tol=2e-4)
    assert math.isclose(d1 - d0, 50.0 * (n - 1) / FS, rel_tol=1e-3)


def _circling_errors(extrapolate: bool):
    """Range-rate error [m/s] of the loop's Doppler against truth in a 26 m/s, 20 deg/s
    circle seen along the line of sight (ideal discriminator, 10 ms updates), with the
    truth's acceleration and jerk there."""
    lam = 299792458.0 / 1268.52e6
    V, Om, dt, sub = 26.0, math.radians(20.0), 0.01, 20
    f_true = lambda t: -V * np.cos(Om * t) / lam  # noqa: E731
    ph_true = lambda t: -V / Om * np.sin(Om * t) / lam  # noqa: E731
    loop = CarrierLoop(15.0, 0.0, f_true(0.0))
    ph, t, err, ts = ph_true(0.0), 0.0, [], []
    for _ in range(2000):
        tt = t + (np.arange(sub) + 0.5) * dt / sub
        ep = np.mean(ph_true(tt) - (ph + loop.freq_hz * (tt - t)))
        ph += loop.freq_hz * dt
        t += dt
        loop.update(ep, 0.0, dt)
        if t > 5.0:
            for s in t + np.arange(5) * dt / 5:
                f = loop.vel_hz + (loop.acc_hz_s * (s - t - dt / 2) if extrapolate else 0.0)
                err.append(-lam * (f - f_true(s)))
                ts.append(s)
    s = np.array(ts)
    A = np.c_[V * Om * np.sin(Om * s), V * Om ** 2 * np.cos(Om * s)]
    c = np.linalg.lstsq(A, np.array(err), rcond=None)[0]
    return np.array(err) - A @ c, c


def test_carried_doppler_leaves_only_the_loops_jerk_error():
    resid_held, _ = _circling_errors(False)
    resid, (lag_s, jerk_s2) = _circling_errors(True)
    assert np.std(resid_held) > 0.015  # held over the block: +-5 ms of a 9 m/s^2 change
    assert np.std(resid) < 0.002
    assert abs(lag_s) < 2e-4
    w0 = pll_natural_frequency(15.0)
    assert math.isclose(jerk_s2, PLL3_B3 / w0 ** 2, rel_tol=0.05)
