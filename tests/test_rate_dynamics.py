"""The scalar loops' Doppler under dynamics (receiver.loops.pll_rate_dynamic_error) and the
loose/tight sources' model of it (ScalarEpochSource.loop_velocity)."""

import numpy as np
import pytest

from sdr_di.integration.gnss_epochs import ScalarEpochSource
from sdr_di.receiver.loops import CarrierLoop, pll_rate_dynamic_error


def _vel_error(f1: float, f2: float, t_end: float = 3.0, T: float = 0.01,
               bw: float = 15.0) -> float:
    """Noiseless 3rd-order PLL (no FLL) tracking f(t) = f1 t + f2 t^2 / 2 [Hz], coherent
    blocks of T: vel_hz after the last block minus f at that block's end [Hz]."""
    loop = CarrierLoop(bw, 0.0, 0.0, f1)
    th_nco = 0.0
    n = int(round(t_end / T))
    u = (np.arange(200) + 0.5) / 200 * T
    for k in range(n):
        t = k * T + u
        th_true = f1 * t ** 2 / 2 + f2 * t ** 3 / 6
        th_rep = th_nco + loop.freq_hz * u
        ep = float(np.mean(th_true - th_rep))  # block-mean phase error [cycles]
        th_nco += loop.freq_hz * T
        loop.update(ep, 0.0, T)
    t = n * T
    return loop.vel_hz - (f1 * t + f2 * t ** 2 / 2)


def test_frequency_integrator_error_follows_b3_over_w0_squared():
    # a constant frequency rate alone: a fixed lag; a frequency acceleration adds -k f''
    f1, f2 = 10.0, 20.0
    e0 = _vel_error(f1, 0.0)
    lag = -e0 / f1
    e1 = _vel_error(f1, f2)
    k_sim = (-e1 - lag * (f1 + f2 * 3.0)) / f2
    k = pll_rate_dynamic_error(15.0)
    assert k_sim == pytest.approx(k, rel=0.05)
    # vel_hz after a block stands for the middle of the next block (what the channel's
    # observations extrapolate from, receiver/channel.py)
    assert lag == pytest.approx(-0.005, abs=2e-4)


class _Iv:
    def __init__(self, i0, i1, v0, v1):
        self.i0, self.i1 = i0, i1
        self.nav0 = type("N", (), {"v_n": np.asarray(v0, float)})()
        self.nav1 = type("N", (), {"v_n": np.asarray(v1, float)})()


def test_loop_velocity_subtracts_k_times_jerk():
    dt = 0.02
    t = np.arange(0, 1.0 + 1e-9, dt)
    a0, j = np.array([1.0, -2.0, 0.5]), np.array([3.0, 0.0, -1.0])
    v = lambda s: a0 * s + j * s ** 2 / 2  # noqa: E731
    src = ScalarEpochSource([], [1], t, (900, 0.0), 1e6, {})
    for i in range(len(t) - 1):  # the loop's intervals, as measure() records them
        iv = _Iv(i, i + 1, v(t[i]), v(t[i + 1]))
        src._acc.append((0.5 * (t[i] + t[i + 1]),
                         (iv.nav1.v_n - iv.nav0.v_n) / dt))
    k = pll_rate_dynamic_error(15.0)
    out = src.loop_velocity(v(t[-1]), t[-1], 15.0)
    want = v(t[-1]) - k * j
    np.testing.assert_allclose(out, want, atol=1e-9)
    # without history: unchanged
    src2 = ScalarEpochSource([], [1], t, (900, 0.0), 1e6, {})
    np.testing.assert_array_equal(src2.loop_velocity(v(1.0), 1.0, 15.0), v(1.0))
