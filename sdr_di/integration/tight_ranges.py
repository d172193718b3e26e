"""Tight coupling on the scalar receiver's pseudoranges and rates (``sdr-di run --mode
tight``).

Measurement (paper 004 eq 6-12, :class:`~sdr_di.integration.measurements.
RangeRateMeasurementModel`): for every usable channel of the epoch ``z = [P^_i - P_i,
D^_i - D_i]``, with ``P_i``, ``D_i`` the scalar receiver's pseudorange [m] and pseudorange
rate [m/s] and ``P^_i``, ``D^_i`` the same quantities predicted from the INS (interpolated
to the epoch's BDT, receiver time minus the filter's clock bias / c) and the filter's clock
states by the PVT's own models (:func:`~sdr_di.receiver.pvt.modelled_observables`:
satellite clock and its drift with the relativistic term, Sagnac rotation, Saastamoinen and
B3I Klobuchar delays and their rates, the ephemerides and ionosphere model in force at the
epoch). ``H`` (eq 10-12) from the lines of sight at the INS position; its clock columns make
the filter estimate the receiver clock (output columns ``clock_bias_m``,
``clock_drift_mps``: the filter's clock states, as in deep mode).

Usable channel: in the scalar receiver's observables (code lock, transmit time known), an
ephemeris in force, a finite pseudorange rate, elevation at or above the PVT's mask (10
deg), through the screen (C/N0 >= 20 dB-Hz and carrier lock) and the per-channel innovation
gate of :mod:`~sdr_di.integration.gnss_epochs`. Channels join and leave ``z`` as the scalar loops gain and lose them; with fewer
than 4 the filter still updates (the INS carries the missing geometry).

``R = diag(sigma_P^2, sigma_D^2)`` from the PVT's weight model
(:func:`~sdr_di.receiver.pvt.measurement_variances`: 1 m and 0.05 m/s at 45 dB-Hz, scaled by
1/sin(el) and C/N0), the same sigmas the WLS fix of loose mode is weighted with: loose and
tight see the same noise information.
"""

from __future__ import annotations

import numpy as np

from ..frames import C_e_n, llh_to_ecef
from ..receiver.pvt import PvtConfig, measurement_variances, modelled_observables
from .gnss_epochs import GnssEpoch, ScalarEpochSource
from .loop import IntegrationLoop, Interval, Measurements

__all__ = ["TightRangeSource"]


class TightRangeSource(ScalarEpochSource):
    """Pseudoranges and rates of every usable channel as measurements (module notes).

    Parameters
    ----------
    *args
        As :class:`~sdr_di.integration.gnss_epochs.ScalarEpochSource`.
    pvt_config : PvtConfig, optional
        Models, elevation mask and weight model (default: the PVT's).
    """

    def __init__(self, *args, pvt_config: PvtConfig | None = None, **kw) -> None:
        super().__init__(*args, **kw)
        self.pvt_config = pvt_config or PvtConfig()

    def measurement(self, loop: IntegrationLoop, iv: Interval, ep: GnssEpoch) -> Measurements:
        obs, sat, cfg = ep.obs, ep.sat, self.pvt_config
        none = Measurements(z=None, R=None, geometry=(), used=np.zeros(self.n_channels, bool))
        if sat is None:
            return none
        ok = sat.ok & np.isfinite(obs.pseudorange_m) & np.isfinite(obs.pseudorange_rate_mps)
        screen = self.screened(ep)
        self.n_screened += int((ok & ~screen).sum())
        idx = np.flatnonzero(ok & screen)
        if idx.size == 0:
            return none
        b = self.epoch_clock_bias(loop, iv, ep)
        d = loop.clock_drift_mps
        week, sow = self.bdt_of(ep, b)
        llh, v_n = self.ins_at(iv, self.imu_time(week, sow))
        r = llh_to_ecef(*llh)
        v = C_e_n(llh[0], llh[1]).T @ v_n
        P, D, U, el = modelled_observables(sat, idx, r, v, b, d, sow, ep.iono, cfg)
        keep = el >= np.radians(cfg.elevation_mask_deg)
        if not keep.any():
            return none
        idx, P, D, U, el = idx[keep], P[keep], D[keep], U[keep], el[keep]
        var_p, var_d = measurement_variances(el, obs.cn0_dbhz[idx], cfg)
        z = np.r_[P - obs.pseudorange_m[idx], D - obs.pseudorange_rate_mps[idx]]
        return Measurements(z=z, R=np.diag(np.r_[var_p, var_d]), geometry=(iv.nav1.llh, U),
                            used=self.used_mask(obs.prn[idx]), channels=obs.prn[idx])

    def gate(self, loop: IntegrationLoop, iv: Interval, ep: GnssEpoch,
             m: Measurements) -> Measurements:
        """Drop each channel whose pseudorange or rate innovation fails the 1-dof test
        (module notes of :mod:`~sdr_di.integration.gnss_epochs`)."""
        S = self.innovation_covariance(loop, m)
        n = m.z.size // 2
        r = m.z ** 2 / np.diag(S)
        keep = (r[:n] <= self.gate_limit(1)) & (r[n:] <= self.gate_limit(1))
        self.n_gated += int((~keep).sum())
        if keep.all():
            return m
        rows = np.r_[keep, keep]
        llh, U = m.geometry
        prns = np.asarray(m.channels)[keep]
        if not keep.any():
            return Measurements(z=None, R=None, geometry=(),
                                used=np.zeros(self.n_channels, bool))
        return Measurements(z=m.z[rows], R=m.R[np.ix_(rows, rows)], geometry=(llh, U[keep]),
                            used=self.used_mask(prns), channels=prns)
