"""The integration filter of a run: its process noise ``Q``, initial covariance ``P0`` and
clock model from :class:`~sdr_di.coupling.config.IntegrationConfig` and the hand-over fix.

``make_integration_filter``  the configured filter over one interval (every mode)
``check_filter``             the same construction on dummy values, before the start-up, so
                             that a bad name or option fails before any work
``clock_model``              the filter's two-state clock for ``IntegrationConfig.clock``
``error_state_model``        process model, ``Q`` and ``P0`` terms of the filter option
                             ``error_states`` (scale-factor states, Gauss-Markov biases)
                             from the assumed IMU, shared with ``lc``

The option ``error_states`` (``none``, ``sf``, ``gm``, ``sf+gm``; docs/filters.md, *Error
states*) is taken from the filter's options here: the models are built for its layout
(:func:`~sdr_di.filters.state.state_layout`) and the filter receives them.
"""

from __future__ import annotations

import math

import numpy as np

from ..filters import make_filter
from ..filters.state import StateLayout, layout_of_options
from ..frames import radii_of_curvature
from ..ins.error_model import ClockModel, InsErrorModel, process_noise
from ..ins.imu import ImuErrorModel
from ..oscillator import CLOCK_PRESETS, OscillatorSpec
from ..coupling.config import IntegrationConfig
from ..coupling.measurements import RangeRateMeasurementModel

__all__ = ["check_filter", "clock_model", "error_state_model", "make_integration_filter"]

#: Floor of the scale-factor sigma of ``P0`` [-] (1 ppm): an assumed perfect IMU still
#: gives a positive-definite ``P0``.
SCALE_SIGMA_FLOOR = 1e-6


def clock_model(clock: str | OscillatorSpec) -> ClockModel:
    """The filter's two-state clock for ``IntegrationConfig.clock``: a preset name of
    :data:`~sdr_di.oscillator.CLOCK_PRESETS` (the table the truth oscillator uses) or an
    :class:`~sdr_di.oscillator.OscillatorSpec` (flicker mapped:
    :meth:`ClockModel.from_oscillator`)."""
    return ClockModel.from_oscillator(CLOCK_PRESETS[clock] if isinstance(clock, str) else clock)


def error_state_model(imu: ImuErrorModel, layout: StateLayout, *,
                      clock: ClockModel | None = None, **noise) -> tuple[InsErrorModel, dict,
                                                                         np.ndarray]:
    """Process model and the ``error_states`` terms of ``Q`` and ``P0`` for an assumed IMU.

    Parameters
    ----------
    imu : ImuErrorModel
        The IMU the filter assumes (``IntegrationConfig.imu``; lc: its ``imu_model``).
    layout : StateLayout
        The filter's states.
    clock : ClockModel, optional
        The filter's clock (lc: the default, unobserved).
    **noise
        Passed to :func:`~sdr_di.ins.error_model.process_noise` with these terms.

    Returns
    -------
    process : InsErrorModel
        Of ``layout`` with the grade's bias correlation times (gyro, accel).
    q_terms : dict
        Keywords of :func:`~sdr_di.ins.error_model.process_noise`: ``layout``, the
        scale-factor sigmas [-], the correlation times [s] and the in-run instabilities (SI).
    p0_extra : ndarray
        Variances of ``P0`` appended after the clock: ``s_g^2`` (3) then ``s_a^2`` (3) with
        ``sf`` (the grade's 1-sigma, at least :data:`SCALE_SIGMA_FLOOR`), else empty.
    """
    tau = (imu.gyro_bias_tau_s, imu.accel_bias_tau_s)
    sg = imu.gyro_scale_factor_ppm * 1e-6
    sa = imu.accel_scale_factor_ppm * 1e-6
    q_terms = {"layout": layout, "gyro_scale": sg, "accel_scale": sa, "bias_tau_s": tau,
               "bias_instability_si": (imu.gyro_bias_instability_si,
                                       imu.accel_bias_instability_si), **noise}
    p0_extra = (np.r_[[max(sg, SCALE_SIGMA_FLOOR) ** 2] * 3, [max(sa, SCALE_SIGMA_FLOOR) ** 2] * 3]
                if layout.scale_factors else np.zeros(0))
    return InsErrorModel(clock, layout, tau), q_terms, p0_extra


def check_filter(cfg: IntegrationConfig) -> None:
    """Build the configured filter on dummy values (its layout, identity ``P0`` and ``Q``).

    Raises
    ------
    FilterError
        Unknown filter name or option, a bad ``error_states``.
    """
    layout = layout_of_options(cfg.filter_options)
    n = layout.n
    make_filter(cfg.filter, InsErrorModel(layout=layout),
                RangeRateMeasurementModel(n_states=n), np.zeros(n), np.eye(n), np.eye(n), None,
                dt=1.0 / cfg.filter_rate_hz, **cfg.filter_options)


def make_integration_filter(cfg: IntegrationConfig, T: float, sol, llh_fix, att_sig,
                            meas=None):
    """Integration filter of the configured name over interval ``T`` [s].

    ``Q`` from the IMU spec and the clock model (:func:`~sdr_di.ins.error_model.
    process_noise`); ``P0``: the attitude sigmas ``att_sig``, 0.1 m/s, the fix's
    position sigma (at least 1 m; 1.5x for height and clock bias), the bias specs and
    0.1 m/s of clock drift.

    ``meas``: the filter's measurement model (default
    :class:`~sdr_di.coupling.measurements.RangeRateMeasurementModel`; loose:
    :class:`~sdr_di.coupling.measurements.LooseMeasurementModel`), with as many columns as
    the layout of ``cfg.filter_options["error_states"]`` has states. That option adds the
    scale-factor states (``P0``: the assumed grade's 1-sigma) or makes the biases
    Gauss-Markov (:func:`error_state_model`).

    Returns
    -------
    kf, process (InsErrorModel), meas (the filter's measurement model)
    """
    gb, ab = cfg.imu.gyro_bias_si, cfg.imu.accel_bias_si
    layout = layout_of_options(cfg.filter_options)
    clock = clock_model(cfg.clock)
    process, q_terms, p0_extra = error_state_model(cfg.imu, layout, clock=clock)
    Q0 = process_noise(T, gyro_random_walk_si=cfg.imu.gyro_random_walk_si,
                       accel_random_walk_si=cfg.imu.accel_random_walk_si,
                       gyro_bias_si=gb, accel_bias_si=ab, bias_time_s=cfg.bias_time_s,
                       clock=clock, **q_terms)
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
               s_enu[2] ** 2, [gb ** 2] * 3, [ab ** 2] * 3, s_clk[0] ** 2, s_clk[1] ** 2,
               p0_extra]
    meas = RangeRateMeasurementModel(n_states=layout.n) if meas is None else meas
    if getattr(meas, "n_states", layout.n) != layout.n:
        raise ValueError(f"the measurement model has {meas.n_states} columns but "
                         f"error_states={layout.error_states} has {layout.n} states")
    kf = make_filter(cfg.filter, process, meas, np.zeros(layout.n), np.diag(p0), Q0, None,
                     dt=T, **cfg.filter_options)
    return kf, process, meas
