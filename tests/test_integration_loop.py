"""The mode-independent integration loop (sdr_di.integration.loop) with stand-in sources.

A source other than deep's vector tracking runs the loop unchanged: one that only counts the
stages, and a loose-like one (INS minus reference position/velocity, papers 000/003 eq 13,
no NCO feedback) that must pull a 20 m / 0.5 m/s initial error in.
"""

from __future__ import annotations

import math
import types

import numpy as np

from sdr_di.constants import OMEGA_E
from sdr_di.filters import make_filter
from sdr_di.ins.error_model import InsErrorModel, process_noise
from sdr_di.ins.gravity import normal_gravity
from sdr_di.ins.imu import ImuErrorModel
from sdr_di.ins.mechanization import StrapdownINS
from sdr_di.integration.loop import IntegrationLoop, Measurements
from sdr_di.coupling.measurements import LooseMeasurementModel, loose_measurement

LLH0 = np.array([math.radians(40.0), math.radians(116.0), 100.0])
RATE = 200.0
FS = 1000.0          # "IF" samples per second of the stand-in sources


def _static_imu(seconds: float):
    """Error-free IMU at rest, level, body Right-Front-Up along East-North-Up."""
    n = round(seconds * RATE) + 1
    lat = LLH0[0]
    f_b = np.tile([0.0, 0.0, float(normal_gravity(lat, LLH0[2]))], (n, 1))
    w_ib_b = np.tile([0.0, OMEGA_E * math.cos(lat), OMEGA_E * math.sin(lat)], (n, 1))
    return types.SimpleNamespace(t=np.arange(n) / RATE, f_b=f_b, w_ib_b=w_ib_b, rate_hz=RATE)


def _loop(imu, ins, model, set_geometry, *, n_per=4, output_every=5, p0_pos_m=30.0):
    T = n_per / RATE
    spec = ImuErrorModel()
    Q = process_noise(T, gyro_random_walk_si=spec.gyro_random_walk_si,
                      accel_random_walk_si=spec.accel_random_walk_si,
                      gyro_bias_si=spec.gyro_bias_si, accel_bias_si=spec.accel_bias_si)
    R_e = 6.4e6
    p0 = np.r_[[1e-3 ** 2] * 3, [1.0] * 3, (p0_pos_m / R_e) ** 2, (p0_pos_m / R_e) ** 2,
               p0_pos_m ** 2, [spec.gyro_bias_si ** 2] * 3, [spec.accel_bias_si ** 2] * 3,
               100.0, 1.0]
    process = InsErrorModel()
    kf = make_filter("ekf", process, model, np.zeros(17), np.diag(p0), Q, None, dt=T)
    return IntegrationLoop(
        imu=imu, t_if=imu.t, i_start=0, k_start=0, n_per=n_per, fs=FS, stop=10 ** 9,
        margin=0, ins=ins, clock_bias_m=0.0, clock_drift_mps=0.0, kf=kf, process=process,
        set_geometry=set_geometry, sow_of_sample=lambda k: 1000.0 + k / FS,
        output_every=output_every)


class _Counting:
    """Stand-in source: no measurement; records the stages; its data end in interval 13."""

    n_channels = 2

    def __init__(self):
        self.calls = []

    def measure(self, loop, iv):
        self.calls.append("measure")
        if loop.n_intervals == 12:
            return None
        return Measurements(z=None, R=None, geometry=(), used=np.array([False, False]))

    def feed_back(self, loop, iv, x):
        self.calls.append("feed_back")

    def take_up_navigation_data(self, loop, iv):
        self.calls.append("take_up")

    def row(self):
        self.calls.append("row")
        return {"cn0": [30.0, 40.0], "nav": 0}


def test_loop_runs_the_stages_in_order_and_stops_where_the_source_ends():
    imu = _static_imu(2.0)
    ins = StrapdownINS(LLH0, np.zeros(3), att=np.zeros(3))
    ins.set_previous_increments(imu.f_b[0], imu.w_ib_b[0], 1.0 / RATE)
    src = _Counting()
    loop = _loop(imu, ins, LooseMeasurementModel(), lambda: None)
    loop.run(src)
    # 12 whole intervals, then the source's data end inside the 13th
    assert loop.n_intervals == 12
    assert loop.k0 == round(imu.t[12 * 4] * FS)
    per = ["measure", "feed_back", "take_up"]
    expected = []
    for j in range(1, 13):
        expected += per + (["row"] if j % 5 == 0 else [])
    assert src.calls == expected + ["measure"]
    cols = loop.columns(2)
    np.testing.assert_array_equal(cols["t"], [imu.t[20], imu.t[40]])
    np.testing.assert_array_equal(cols["used"], [[False, False]] * 2)
    np.testing.assert_array_equal(cols["n"], [0, 0])
    np.testing.assert_array_equal(cols["cn0"], [[30.0, 40.0]] * 2)
    assert np.all(np.isnan(cols["nis"]))           # no update, no NIS


class _LooseLike:
    """Stand-in for a loose mode: INS minus the (known, static) reference position and
    velocity every interval; no NCOs, so no feedback of its own."""

    n_channels = 1

    def __init__(self):
        self.fed_back = 0

    def measure(self, loop, iv):
        z = loose_measurement(iv.nav1.llh, iv.nav1.v_n, LLH0, np.zeros(3))
        R = np.diag([0.05 ** 2] * 3 + [0.5 ** 2] * 3)
        return Measurements(z=z, R=R, geometry=(iv.nav1.llh,), used=np.array([True]))

    def feed_back(self, loop, iv, x):
        self.fed_back += 1

    def take_up_navigation_data(self, loop, iv):
        pass

    def row(self):
        return {"cn0": [math.nan], "nav": 0}


def test_a_loose_like_source_runs_the_same_loop_and_pulls_the_error_in():
    imu = _static_imu(10.0)
    # INS 20 m north and 0.5 m/s east of the reference at the start
    lat_err = 20.0 / 6.37e6
    ins = StrapdownINS(LLH0 + [lat_err, 0.0, 0.0], np.array([0.5, 0.0, 0.0]), att=np.zeros(3))
    ins.set_previous_increments(imu.f_b[0], imu.w_ib_b[0], 1.0 / RATE)
    model = LooseMeasurementModel()
    src = _LooseLike()
    loop = _loop(imu, ins, model, model.set_epoch, n_per=40)     # 5 Hz fixes
    loop.run(src)
    assert src.fed_back == loop.n_intervals == 50
    cols = loop.columns(1)
    north_m = (cols["llh"][:, 0] - LLH0[0]) * 6.37e6
    assert abs(north_m[-1]) < 1.0                   # after 10 s of 0.5 m fixes
    assert np.linalg.norm(cols["v"][-1]) < 0.05
    assert np.all(np.isfinite(cols["nis"]))


def test_background_loops_restore_the_switch_interval_after_the_last_one():
    """Loop threads lower the interpreter's switch interval while they run; with two at a
    time (a study's threads) it comes back to its value only after the last one ends, and
    an exception on the loop thread reaches the caller."""
    import sys
    import time

    import pytest

    from sdr_di.integration.loop import BackgroundLoop

    class Sleeper:
        stop_requested = False

        def __init__(self, t, fail=False):
            self.t, self.fail = t, fail

        def run(self, source):
            time.sleep(self.t)
            if self.fail:
                raise RuntimeError("loop failed")

    s0 = sys.getswitchinterval()
    a, b = BackgroundLoop(Sleeper(0.05), None), BackgroundLoop(Sleeper(0.2, fail=True), None)
    assert sys.getswitchinterval() < s0
    a.join()
    assert sys.getswitchinterval() < s0
    with pytest.raises(RuntimeError, match="loop failed"):
        b.join()
    assert sys.getswitchinterval() == s0


def test_channel_innovations_land_in_their_channel_columns():
    """``y_i / sqrt(S_ii)`` per channel: deep's ``z`` holds the used channels in column
    order, tight's in its own order with ``columns``; loose's fix maps to no channel."""
    from sdr_di.integration.loop import Measurements, channel_innovations

    y = np.array([1.0, -2.0, 0.5, 3.0])                 # 2 channels: codes, then rates
    S = np.diag([4.0, 1.0, 0.25, 9.0])
    used = np.array([False, True, False, True])
    deep = channel_innovations(Measurements(y, S, (), used), y, S)
    assert np.array_equal(deep, [np.nan, 0.5, np.nan, -2.0, np.nan, 1.0, np.nan, 1.0],
                          equal_nan=True)
    tight = channel_innovations(Measurements(y, S, (), used, channels=np.array([27, 8]),
                                             columns=np.array([3, 1])), y, S)
    assert np.array_equal(tight, [np.nan, -2.0, np.nan, 0.5, np.nan, 1.0, np.nan, 1.0],
                          equal_nan=True)
    fix = np.arange(6.0)
    loose = channel_innovations(Measurements(fix, np.eye(6), (), np.ones(5, bool)), fix,
                                np.eye(6))
    assert np.isnan(loose).all()
