"""Loose coupling on the scalar receiver's WLS fixes (``sdr-di run --mode loose``).

Measurement (papers 000/003 eq 13, :class:`~sdr_di.coupling.measurements.
LooseMeasurementModel`): ``z = [v_INS - v_GNSS (E, N, U) [m/s], position INS - GNSS (N, E,
U) [m]]`` at the fix's BDT (receiver time minus the fix's clock bias / c), the INS
interpolated to it (:mod:`~sdr_di.integration.gnss_epochs`). Only valid fixes with a valid
velocity are used, and only if every satellite of the fix passes the channel screen and the
fix its 6-dof innovation gate (:mod:`~sdr_di.integration.gnss_epochs`); an epoch with fewer
than 4 satellites gives no fix, and the INS coasts.

``R``: the error covariance of the fix's WLS estimate under the receiver's thermal noise
(:func:`thermal_fix_covariance`), not its formal covariance. The WLS weights the
pseudoranges and rates with the PVT's weight model (sigma 1 m / 0.05 m/s at 45 dB-Hz,
scaled by 1/sin(el) and C/N0); its formal covariance ``(H^T W H)^-1`` takes those sigmas as
the noise, but they are 8.5 and 4 times the scalar loops' thermal sigmas at 45 dB-Hz
(:mod:`~sdr_di.integration.tight_ranges`), hence the 4-12 times pessimistic fix covariance
(NIS 0.03). With ``Sigma`` the thermal variances of the used channels
(:func:`~sdr_di.integration.tight_ranges.tracking_variances`) and ``H = [-e_ENU, 1]`` from
the fix's elevations and azimuths::

    A = (H^T W H)^-1 H^T W,     cov = A Sigma A^T           (position / clock; ENU)

and the same for the velocity with the rate weights and variances; the position block is
reordered to N, E, U (``Pm``). Clock blocks and position-velocity cross terms are left out
(the filter has no clock rows in this mode; the two solutions come from separate
measurements).

Time correlation, the stated rule: the position errors are the DLL errors' combination,
correlated from one fix to the next with ``rho = (1 - 4 B_DLL T)^(dt / T)`` (0.44 at 5 Hz,
:func:`~sdr_di.integration.tight_ranges.range_correlation_factor`); a filter that takes
them as white is overconfident by up to ``(1 + rho) / (1 - rho)`` (2.6 at 5 Hz), so the
position block is multiplied by the mean of that factor over the fix's satellites. The
velocity errors (15 Hz PLL) are white at 5 Hz and keep their variance. :func:`fix_covariance`
is the formal covariance (for comparison).

Clock columns of the output: the loose filter does not estimate the receiver clock (no
row of ``H`` reaches states 15-16), so after each fix the loop's clock is set to the fix's
bias and drift (moved to the interval's end with the drift): the ``clock_bias_m`` /
``clock_drift_mps`` columns hold the latest WLS clock, and the ``bdt_sow`` column is
receiver time minus that bias / c.
"""

from __future__ import annotations

import numpy as np

from ..frames import C_e_n
from ..receiver.pvt import PvtConfig, measurement_variances
from ..receiver.tracking import TrackingConfig
from .gnss_epochs import GnssEpoch, ScalarEpochSource
from .loop import Interval, Measurements
from ..coupling.interval import LoopState
from ..coupling.measurements import loose_measurement
from .tight_ranges import range_correlation_factor, tracking_variances

__all__ = ["LooseFixSource", "fix_covariance", "thermal_fix_covariance"]

_NEU = [1, 0, 2]


def fix_covariance(sol) -> np.ndarray:
    """``R`` (6, 6) of a fix (module notes): ENU velocity [(m/s)^2], then N, E, U position
    [m^2]."""
    C = C_e_n(sol.llh[0], sol.llh[1])
    Rv = C @ np.asarray(sol.cov_v, float)[:3, :3] @ C.T
    Rp = (C @ np.asarray(sol.cov, float)[:3, :3] @ C.T)[np.ix_(_NEU, _NEU)]
    R = np.zeros((6, 6))
    R[:3, :3] = 0.5 * (Rv + Rv.T)
    R[3:, 3:] = 0.5 * (Rp + Rp.T)
    return R


def thermal_fix_covariance(sol, cn0_dbhz, tracking_config: TrackingConfig | None = None,
                           pvt_config: PvtConfig | None = None,
                           interval_s: float = 0.2) -> np.ndarray:
    """``R`` (6, 6) of a fix (module notes): the WLS estimate's covariance under the
    thermal noise of its channels (C/N0 ``cn0_dbhz`` [dB-Hz] of ``sol.prns``), the position
    block with the time-correlation factor for fixes every ``interval_s`` [s]. ENU velocity
    [(m/s)^2], then N, E, U position [m^2]."""
    el = np.asarray(sol.elevation, float)
    az = np.asarray(sol.azimuth, float)
    e = np.column_stack([np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)])
    H = np.hstack([-e, np.ones((el.size, 1))])
    w_p, w_d = (1.0 / v for v in measurement_variances(el, cn0_dbhz, pvt_config))
    s_p, s_d = tracking_variances(sol.prns, cn0_dbhz, tracking_config)

    def sandwich(w, sigma2):
        A = np.linalg.solve(H.T @ (H * w[:, None]), (H * w[:, None]).T)
        return (A * sigma2) @ A.T

    Rv = sandwich(w_d, s_d)[:3, :3]
    f = float(np.mean(range_correlation_factor(sol.prns, interval_s, tracking_config)))
    Rp = f * sandwich(w_p, s_p)[:3, :3][np.ix_(_NEU, _NEU)]
    R = np.zeros((6, 6))
    R[:3, :3] = 0.5 * (Rv + Rv.T)
    R[3:, 3:] = 0.5 * (Rp + Rp.T)
    return R


class LooseFixSource(ScalarEpochSource):
    """WLS position and velocity fixes as measurements (module notes).

    Parameters
    ----------
    *args
        As :class:`~sdr_di.integration.gnss_epochs.ScalarEpochSource`.
    tracking_config : TrackingConfig, optional
        The scalar receiver's loops, for ``R`` (default: its defaults).
    interval_s : float
        Fix interval [s] (the time-correlation factor, module notes).
    """

    def __init__(self, *args, tracking_config: TrackingConfig | None = None,
                 interval_s: float = 0.2, **kw) -> None:
        super().__init__(*args, **kw)
        self.tracking_config = tracking_config or TrackingConfig()
        self.interval_s = float(interval_s)

    def bdt_of(self, ep: GnssEpoch, clock_bias_m: float) -> tuple[int, float]:
        """The fix's own BDT (receiver time minus its clock bias / c)."""
        if ep.sol.valid:
            return ep.sol.week, ep.sol.sow
        return super().bdt_of(ep, clock_bias_m)

    def measurement(self, loop: LoopState, iv: Interval, ep: GnssEpoch) -> Measurements:
        sol = ep.sol
        if not (sol.valid and sol.velocity_valid and np.all(np.isfinite(sol.cov_v))):
            return Measurements(z=None, R=None, geometry=(),
                                used=np.zeros(self.n_channels, bool))
        screen = self.screened(ep)
        bad = {int(p) for p, ok in zip(ep.obs.prn, screen) if not ok}
        if bad & {int(p) for p in sol.prns}:
            self.n_screened += 1
            return Measurements(z=None, R=None, geometry=(),
                                used=np.zeros(self.n_channels, bool))
        t_imu = self.imu_time(sol.week, sol.sow)
        llh, v_n = self.ins_at(iv, t_imu)
        v_n = self.loop_velocity(v_n, t_imu, self.tracking_config.track_pll_bw_hz)
        z = loose_measurement(llh, v_n, sol.llh, sol.v_n)
        col = {int(p): i for i, p in enumerate(ep.obs.prn)}
        cn0 = np.array([ep.obs.cn0_dbhz[col[int(p)]] for p in sol.prns], float)
        R = thermal_fix_covariance(sol, cn0, self.tracking_config, None, self.interval_s)
        assert iv.nav1 is not None              # set by the loop's propagate_ins
        return Measurements(z=z, R=R, geometry=(iv.nav1.llh,),
                            used=self.used_mask(sol.prns))

    def gate(self, loop: LoopState, iv: Interval, ep: GnssEpoch,
             m: Measurements) -> Measurements:
        """The whole fix out when its NIS ``y^T S^-1 y`` exceeds the 6-dof quantile."""
        assert m.z is not None                  # _gated calls it only with a measurement
        S = self.innovation_covariance(loop, m)
        if float(m.z @ np.linalg.solve(S, m.z)) <= self.gate_limit(m.z.size):
            return m
        self.n_gated += 1
        return Measurements(z=None, R=None, geometry=(), used=np.zeros(self.n_channels, bool))

    def feed_back(self, loop: LoopState, iv: Interval, x: np.ndarray) -> None:
        """The loop's clock follows the latest fix (module notes, clock columns)."""
        ep = self.last
        if ep is not None and ep.sol.valid and np.isfinite(ep.sol.clock_drift_mps):
            d = float(ep.sol.clock_drift_mps)
            loop.clock_bias_m = float(ep.sol.clock_bias_m) + d * (iv.k1 - ep.sample) / self.fs
            loop.clock_drift_mps = d
