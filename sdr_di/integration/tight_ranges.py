"""Tight coupling on the scalar receiver's pseudoranges and rates (``sdr-di run --mode
tight``).

Measurement (paper 004 eq 6-12, :class:`~sdr_di.coupling.measurements.
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

``R = diag(sigma_P^2, sigma_D^2)`` from the thermal noise of the scalar receiver's own
loops at each channel's C/N0 (:func:`tracking_variances`), with ``T`` the channel's coherent
time (D1 10 ms, D2 2 ms), ``d`` its early/late offset (0.5 chip)::

    sigma_P = (c / f_code) sigma_tau,   sigma_tau^2 = w0 T sigma_d^2 / (2 - w0 T),
              sigma_d^2 = d / (2 T C/N0) (1 + 1 / (T C/N0)),  w0 = 4 B_DLL   (1st-order DLL)
    sigma_D = lambda sigma_f,   sigma_f^2 = Lyapunov variance of the 3rd-order PLL's
              frequency integrator driven by sigma_phi^2 = (1 + 1 / (2 T C/N0)) / (2 T C/N0)

(:func:`~sdr_di.receiver.loops.dll_code_noise_chips`, :func:`~sdr_di.receiver.loops.
pll_doppler_noise_hz`; ``B_DLL`` 1 Hz, ``B_PLL`` 15 Hz). The PVT's weight model (1 m and
0.05 m/s at 45 dB-Hz, scaled by 1/sin(el) and C/N0) it replaced was 8.5 (pseudorange,
0.12 m) and 4 (rate, 0.012 m/s) times the thermal sigma at 45 dB-Hz and zenith; the
simulation has no multipath and its range models match the generator's, so thermal noise is
the measurement error. It is not
white: the DLL error is correlated over ``1 / (4 B_DLL)`` = 0.25 s (lag-1 correlation
about 0.45 at 5 Hz); ``R`` states its variance (NIS), and the filter sees it as white.

Time correlation, the stated rule: ``R`` keeps the variance, and only the innovation gate
allows for the correlation. A first-order DLL's error sampled every ``dt`` (the measurement
interval) has the lag-1 correlation ``rho = (1 - w0 T)^(dt / T)``; a filter that takes such
samples as white becomes overconfident by up to ``(1 + rho) / (1 - rho)`` (the variance
ratio of the mean of correlated and of white samples; 2.6 at 5 Hz), so the gate tests each
pseudorange innovation against ``S + ((1 + rho) / (1 - rho) - 1) R`` rather than ``S``.
Measured with the gate on the filter's ``S``: 1 good channel-epoch of 150 rejected in a
3-satellite blockage (``tests/test_coupling.py``); the chi-square tail at 1e-4 expects 0.03.
The rates (15 Hz PLL: correlated over tens of ms) are white at 5 Hz.
"""

from __future__ import annotations

import numpy as np

import math

from ..constants import C_LIGHT, CHIP_RATE_B3I, LAMBDA_B3I, is_geo
from ..coupling.interval import LoopState
from ..frames import C_e_n, llh_to_ecef
from ..receiver.loops import dll_code_noise_chips, pll_doppler_noise_hz
from ..receiver.pvt import PvtConfig, modelled_observables
from ..receiver.tracking import TrackingConfig
from .gnss_epochs import GnssEpoch, ScalarEpochSource
from .loop import Interval, Measurements

__all__ = ["TightRangeSource", "range_correlation_factor", "tracking_variances"]


def range_correlation_factor(prns, dt_s: float, config: TrackingConfig | None = None
                             ) -> np.ndarray:
    """``(1 + rho) / (1 - rho)`` per channel, ``rho = (1 - 4 B_DLL T)^(dt / T)`` the lag-1
    correlation of the DLL error sampled every ``dt_s`` [s] (module notes)."""
    cfg = config or TrackingConfig()
    out = []
    for prn in np.asarray(prns).tolist():
        t = 1e-3 * (cfg.coherent_ms_d2 if is_geo(prn) else cfg.coherent_ms_d1)
        rho = abs(1.0 - 4.0 * cfg.track_dll_bw_hz * t) ** (float(dt_s) / t)
        out.append((1.0 + rho) / (1.0 - rho))
    return np.array(out)


def tracking_variances(prns, cn0_dbhz, config: TrackingConfig | None = None,
                       cn0_ref_dbhz: float = 45.0) -> tuple[np.ndarray, np.ndarray]:
    """Pseudorange [m^2] and pseudorange-rate [(m/s)^2] variances of the scalar receiver's
    tracked channels from its loops' thermal noise (module notes). ``prns`` pick the coherent
    time (GEO: D2, 2 ms; else D1, 10 ms); a NaN C/N0 counts as ``cn0_ref_dbhz``."""
    cfg = config or TrackingConfig()
    var_p, var_d = [], []
    for prn, cn0 in zip(np.asarray(prns).tolist(), np.asarray(cn0_dbhz, float).tolist()):
        t = 1e-3 * (cfg.coherent_ms_d2 if is_geo(prn) else cfg.coherent_ms_d1)
        c = cn0 if math.isfinite(cn0) else cn0_ref_dbhz
        s_tau = dll_code_noise_chips(c, t, cfg.track_dll_bw_hz, cfg.spacing_chips)
        var_p.append((C_LIGHT / CHIP_RATE_B3I * s_tau) ** 2)
        var_d.append((LAMBDA_B3I * pll_doppler_noise_hz(c, t, cfg.track_pll_bw_hz)) ** 2)
    return np.array(var_p), np.array(var_d)


class TightRangeSource(ScalarEpochSource):
    """Pseudoranges and rates of every usable channel as measurements (module notes).

    Parameters
    ----------
    *args
        As :class:`~sdr_di.integration.gnss_epochs.ScalarEpochSource`.
    pvt_config : PvtConfig, optional
        Models and elevation mask (default: the PVT's).
    tracking_config : TrackingConfig, optional
        The scalar receiver's loops, for ``R`` (default: its defaults).
    interval_s : float
        Measurement interval [s] (the gate's correlation allowance, module notes).
    """

    def __init__(self, *args, pvt_config: PvtConfig | None = None,
                 tracking_config: TrackingConfig | None = None, interval_s: float = 0.2,
                 **kw) -> None:
        super().__init__(*args, **kw)
        self.pvt_config = pvt_config or PvtConfig()
        self.tracking_config = tracking_config or TrackingConfig()
        self.interval_s = float(interval_s)

    def measurement(self, loop: LoopState, iv: Interval, ep: GnssEpoch) -> Measurements:
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
        # the rates are modelled with the velocity the loops' rates stand for (module
        # gnss_epochs, *Rates under dynamics*); P, U and el do not depend on the velocity
        v_loop = C_e_n(llh[0], llh[1]).T @ self.loop_velocity(
            v_n, self.imu_time(week, sow), self.tracking_config.track_pll_bw_hz)
        P, D, U, el = modelled_observables(sat, idx, r, v_loop, b, d, sow, ep.iono, cfg)
        keep = el >= np.radians(cfg.elevation_mask_deg)
        if not keep.any():
            return none
        idx, P, D, U, el = idx[keep], P[keep], D[keep], U[keep], el[keep]
        var_p, var_d = tracking_variances(obs.prn[idx], obs.cn0_dbhz[idx],
                                          self.tracking_config)
        z = np.r_[P - obs.pseudorange_m[idx], D - obs.pseudorange_rate_mps[idx]]
        assert iv.nav1 is not None              # set by the loop's propagate_ins
        return Measurements(z=z, R=np.diag(np.r_[var_p, var_d]), geometry=(iv.nav1.llh, U),
                            used=self.used_mask(obs.prn[idx]), channels=obs.prn[idx],
                            columns=self.columns_of(obs.prn[idx]))

    def gate(self, loop: LoopState, iv: Interval, ep: GnssEpoch,
             m: Measurements) -> Measurements:
        """Drop each channel whose pseudorange or rate innovation fails the 1-dof test
        (module notes of :mod:`~sdr_di.integration.gnss_epochs`; the pseudoranges' ``S``
        with the correlation allowance of this module's notes)."""
        # _gated calls it only with a measurement (z, and so R and channels, not None)
        assert m.z is not None and m.R is not None
        S = self.innovation_covariance(loop, m)
        n = m.z.size // 2
        s_gate = np.diag(S).copy()
        f = range_correlation_factor(m.channels, self.interval_s, self.tracking_config)
        s_gate[:n] += (f - 1.0) * np.diag(m.R)[:n]
        r = m.z ** 2 / s_gate
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
                            used=self.used_mask(prns), channels=prns,
                            columns=self.columns_of(prns))
