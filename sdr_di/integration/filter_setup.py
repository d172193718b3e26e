"""The integration filter of a run: its process noise ``Q``, initial covariance ``P0`` and
clock model from :class:`~sdr_di.coupling.config.IntegrationConfig` and the hand-over fix.

``make_integration_filter``  the configured filter over one interval (every mode)
``check_filter``             the same construction on dummy values, before the start-up, so
                             that a bad name or option fails before any work
``clock_model``              the filter's two-state clock for ``IntegrationConfig.clock``
"""

from __future__ import annotations

import math

import numpy as np

from ..filters import make_filter
from ..frames import radii_of_curvature
from ..ins.error_model import ClockModel, InsErrorModel, process_noise
from ..oscillator import CLOCK_PRESETS, OscillatorSpec
from ..coupling.config import IntegrationConfig
from ..coupling.measurements import RangeRateMeasurementModel

__all__ = ["check_filter", "clock_model", "make_integration_filter"]


def clock_model(clock: str | OscillatorSpec) -> ClockModel:
    """The filter's two-state clock for ``IntegrationConfig.clock``: a preset name of
    :data:`~sdr_di.oscillator.CLOCK_PRESETS` (the table the truth oscillator uses) or an
    :class:`~sdr_di.oscillator.OscillatorSpec` (flicker mapped:
    :meth:`ClockModel.from_oscillator`)."""
    return ClockModel.from_oscillator(CLOCK_PRESETS[clock] if isinstance(clock, str) else clock)


def check_filter(cfg: IntegrationConfig) -> None:
    """Build the configured filter on dummy values (17 states, identity ``P0`` and ``Q``).

    Raises
    ------
    FilterError
        Unknown filter name or option.
    """
    make_filter(cfg.filter, InsErrorModel(), RangeRateMeasurementModel(), np.zeros(17),
                np.eye(17), np.eye(17), None, dt=1.0 / cfg.filter_rate_hz,
                **cfg.filter_options)


def make_integration_filter(cfg: IntegrationConfig, T: float, sol, llh_fix, att_sig,
                            meas=None):
    """Integration filter of the configured name over interval ``T`` [s].

    ``Q`` from the IMU spec and the clock model (:func:`~sdr_di.ins.error_model.
    process_noise`); ``P0``: the attitude sigmas ``att_sig``, 0.1 m/s, the fix's
    position sigma (at least 1 m; 1.5x for height and clock bias), the bias specs and
    0.1 m/s of clock drift.

    ``meas``: the filter's measurement model (default
    :class:`~sdr_di.coupling.measurements.RangeRateMeasurementModel`; loose:
    :class:`~sdr_di.coupling.measurements.LooseMeasurementModel`).

    Returns
    -------
    kf, process (InsErrorModel), meas (the filter's measurement model)
    """
    gb, ab = cfg.imu.gyro_bias_si, cfg.imu.accel_bias_si
    Q0 = process_noise(T, gyro_random_walk_si=cfg.imu.gyro_random_walk_si,
                       accel_random_walk_si=cfg.imu.accel_random_walk_si,
                       gyro_bias_si=gb, accel_bias_si=ab, bias_time_s=cfg.bias_time_s,
                       clock=clock_model(cfg.clock))
    lat0, h0 = float(llh_fix[0]), float(llh_fix[2])
    R_M, R_N = (float(r) for r in radii_of_curvature(lat0))
    cov = np.asarray(sol.cov, float)
    s_pos = math.sqrt(max(np.trace(cov[:3, :3]) / 3.0, 0.25)) if np.all(
        np.isfinite(cov[:3, :3])) else 2.0
    s_pos = max(s_pos, 1.0)
    s_vel = np.full(3, 0.1) if cfg.p0_vel_mps is None else np.asarray(cfg.p0_vel_mps)
    s_enu = np.array([s_pos, s_pos, 1.5 * s_pos]) if cfg.p0_pos_m is None else np.maximum(
        np.asarray(cfg.p0_pos_m, float), [s_pos, s_pos, 1.5 * s_pos])
    s_clk = [1.5 * s_pos, 0.1]
    for i, v in enumerate(cfg.p0_clock or (None, None)):
        if v is not None:
            s_clk[i] = v
    p0 = np.r_[att_sig ** 2, s_vel ** 2,
               (s_enu[1] / (R_M + h0)) ** 2, (s_enu[0] / ((R_N + h0) * math.cos(lat0))) ** 2,
               s_enu[2] ** 2, [gb ** 2] * 3, [ab ** 2] * 3, s_clk[0] ** 2, s_clk[1] ** 2]
    process = InsErrorModel(clock_model(cfg.clock))
    meas = RangeRateMeasurementModel() if meas is None else meas
    kf = make_filter(cfg.filter, process, meas, np.zeros(17), np.diag(p0), Q0, None, dt=T,
                     **cfg.filter_options)
    return kf, process, meas
