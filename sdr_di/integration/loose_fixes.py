"""Loose coupling on the scalar receiver's WLS fixes (``sdr-di run --mode loose``).

Measurement (papers 000/003 eq 13, :class:`~sdr_di.integration.measurements.
LooseMeasurementModel`): ``z = [v_INS - v_GNSS (E, N, U) [m/s], position INS - GNSS (N, E,
U) [m]]`` at the fix's BDT (receiver time minus the fix's clock bias / c), the INS
interpolated to it (:mod:`~sdr_di.integration.gnss_epochs`). Only valid fixes with a valid
velocity are used, and only if every satellite of the fix passes the channel screen and the
fix its 6-dof innovation gate (:mod:`~sdr_di.integration.gnss_epochs`); an epoch with fewer
than 4 satellites gives no fix, and the INS coasts.

``R`` from the fix's formal covariances (:mod:`~sdr_di.receiver.pvt`)::

    R = blockdiag( C_e_n  cov_v[0:3, 0:3]  C_e_n^T,   Pm C_e_n cov[0:3, 0:3] C_e_n^T Pm^T )

``cov`` = (H^T W H)^-1 and ``cov_v`` = (J^T W J)^-1 are the WLS covariances of (x, y, z, b)
and (v_x, v_y, v_z, d) in ECEF with the PVT's weight model (sigma 1 m / 0.05 m/s at 45
dB-Hz, scaled by 1/sin(el) and C/N0); their position and velocity blocks are rotated to ENU
(``C_e_n``) and the position block reordered to N, E, U (``Pm``). The clock blocks and the
position-velocity cross terms are left out: the filter has no clock rows in this mode, and
the pseudoranges and rates behind the two solutions are separate measurements. The formal
covariance assumes white errors; the scalar DLL's are correlated over a fraction of a
second, hence the default ``gnss_rate_hz`` of 5 Hz.

Clock columns of the output: the loose filter does not estimate the receiver clock (no
row of ``H`` reaches states 15-16), so after each fix the loop's clock is set to the fix's
bias and drift (moved to the interval's end with the drift): the ``clock_bias_m`` /
``clock_drift_mps`` columns hold the latest WLS clock, and the ``bdt_sow`` column is
receiver time minus that bias / c.
"""

from __future__ import annotations

import numpy as np

from ..frames import C_e_n
from .gnss_epochs import GnssEpoch, ScalarEpochSource
from .loop import IntegrationLoop, Interval, Measurements
from .measurements import loose_measurement

__all__ = ["LooseFixSource", "fix_covariance"]

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


class LooseFixSource(ScalarEpochSource):
    """WLS position and velocity fixes as measurements (module notes)."""

    def bdt_of(self, ep: GnssEpoch, clock_bias_m: float) -> tuple[int, float]:
        """The fix's own BDT (receiver time minus its clock bias / c)."""
        if ep.sol.valid:
            return ep.sol.week, ep.sol.sow
        return super().bdt_of(ep, clock_bias_m)

    def measurement(self, loop: IntegrationLoop, iv: Interval, ep: GnssEpoch) -> Measurements:
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
        llh, v_n = self.ins_at(iv, self.imu_time(sol.week, sol.sow))
        z = loose_measurement(llh, v_n, sol.llh, sol.v_n)
        return Measurements(z=z, R=fix_covariance(sol), geometry=(iv.nav1.llh,),
                            used=self.used_mask(sol.prns))

    def gate(self, loop: IntegrationLoop, iv: Interval, ep: GnssEpoch,
             m: Measurements) -> Measurements:
        """The whole fix out when its NIS ``y^T S^-1 y`` exceeds the 6-dof quantile."""
        S = self.innovation_covariance(loop, m)
        if float(m.z @ np.linalg.solve(S, m.z)) <= self.gate_limit(m.z.size):
            return m
        self.n_gated += 1
        return Measurements(z=None, R=None, geometry=(), used=np.zeros(self.n_channels, bool))

    def feed_back(self, loop: IntegrationLoop, iv: Interval, x: np.ndarray) -> None:
        """The loop's clock follows the latest fix (module notes, clock columns)."""
        ep = self.last
        if ep is not None and ep.sol.valid and np.isfinite(ep.sol.clock_drift_mps):
            d = float(ep.sol.clock_drift_mps)
            loop.clock_bias_m = float(ep.sol.clock_bias_m) + d * (iv.k1 - ep.sample) / self.fs
            loop.clock_drift_mps = d
