"""The scalar receiver's epochs as measurements of the loose and tight couplings.

In loose and tight mode the scalar receiver keeps tracking after the hand-over; no filter
output reaches its loops (no NCO feedback), so it runs over the whole file first and
:class:`GnssEpochRecorder` keeps, at every measurement epoch (``gnss_rate_hz``), what the
couplings need: the observables, the satellite states and ionosphere model in force, and
the WLS fix (position, velocity and their formal covariances). :class:`ScalarEpochSource`
then hands them to the integration loop (:class:`~sdr_di.integration.loop.IntegrationLoop`)
interval by interval, in time order; its subclasses form ``z`` and ``R`` (loose:
:mod:`~sdr_di.integration.loose_fixes`, tight: :mod:`~sdr_di.integration.tight_ranges`).

Time: an epoch is taken at IF sample ``k`` (receiver clock). Its BDT is receiver time minus
clock bias / c (loose: the fix's own bias; tight: the filter's clock state); the IMU samples
are on BDT (``imu_epoch``: BDT of IMU ``t = 0``). An epoch belongs to the filter interval
whose IMU times ``(t[i0], t[i1]]`` hold its BDT; the INS is interpolated linearly to that
instant (over 20 ms, 0.2 mm of position and well below 1 mm/s of velocity at 3 m/s^2) and
the measurement is applied at the interval's end, where the filter's error state is (it
changes by far less than the measurement noise in 20 ms).

Rates under dynamics (issue 25): a scalar channel's Doppler is its 3rd-order PLL's
frequency integrator, carried to the observation's sample with the loop's rate
(:meth:`~sdr_di.receiver.channel.Channel.observation_at`); under a line-of-sight jerk it
misses the loop's settled phase error times its proportional gain, ``f - k f''`` with
``k = b3 / w0^2`` (6.6e-3 s^2 at 15 Hz, :func:`~sdr_di.receiver.loops.
pll_rate_dynamic_error`; 1.5 cm/s at the circling's 2.5 m/s^3). The same on every channel
apart from the line of sight, so the filter cannot see it in its innovations; it made the
velocity NEES 7 (tight) and 6.5 (loose) at 40 dB-Hz. Both sources compare the rates (tight)
or the fix's velocity (loose) with the INS velocity modelled through the loop,
``v_n - k j_n`` (:meth:`ScalarEpochSource.loop_velocity`), the jerk from the INS's own
accelerations over the last 0.2 s (the per-interval velocity change, which the filter's
feedback does not step).

Screening and innovation gate (loose and tight; deep has its own, in its pre-filters): the
scalar receiver keeps a channel in its observables until its lock detector declares the
loss, a few hundred ms after the signal is gone; over those epochs the channel's Doppler,
hence its pseudorange rate, is noise (measured at a tunnel entry: rate innovations of 7-20
sigma against R, C/N0 reported NaN or 10-15 dB-Hz, the lock flags still set). One such epoch
let through moved the velocity by 0.45 m/s and the accelerometer-bias estimate by ~10 mg,
and the INS then coasted 10 s on them (docs/coupling.md, *Tunnel and 3 satellites*). So:

* screen: a channel counts only with a finite C/N0 at or above ``min_cn0_dbhz`` (default
  20 dB-Hz, below which the scalar loops do not hold lock) and in carrier lock (a finite
  carrier phase in the observables); a loose fix counts only if every satellite in it does;
* gate: each remaining measurement is tested against its innovation covariance
  ``S = H P H^T + R`` (``P``: the filter's covariance at the start of the interval, one
  20 ms prediction earlier than the update's, which changes ``S`` by far less than ``R``):
  tight, per channel, ``y_i^2 / S_ii`` of its pseudorange and of its rate against the
  chi-square 1-dof quantile at ``1 - gate_alpha`` (default 1e-4: 15.1, about 3.9 sigma), a
  channel failing either is dropped; loose, the fix's NIS ``y^T S^-1 y`` against the 6-dof
  quantile (27.9). With a consistent ``S`` a good measurement is rejected once in 10^4.
* recovery: if the gate has left no measurement for ``gate_reset_epochs`` (5: 1 s at 5 Hz)
  epochs in a row while the screen passed some, the next such epoch is taken ungated (an
  INS that has drifted beyond its own ``P`` would otherwise reject every fix for good).

Channel columns (``used``, ``cn0``): the PRNs the scalar receiver handed over, then any it
acquired later, in that order. A row shows the latest measurement epoch's channels (loose:
the satellites of the fix; tight: those in ``z``), also on the filter intervals between two
epochs, when ``z`` is None and the filter only predicts.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import math
import threading
import time

import numpy as np

from ..constants import C_LIGHT, SECONDS_PER_WEEK
from ..coupling.interval import LoopState
from ..errors import SdrDiError
from ..orbits.ephemeris import Klobuchar
from ..receiver.loops import pll_rate_dynamic_error
from ..receiver.observables import Observables
from ..receiver.pvt import PvtEngine, PvtSolution, SatelliteStates, satellite_states
from .loop import Interval, Measurements

__all__ = ["GnssEpoch", "GnssEpochRecorder", "ScalarEpochSource"]

#: Window [s] and length [intervals] of the INS acceleration history for the loops' rate model.
LOOP_ACC_WINDOW_S = 0.2
LOOP_ACC_INTERVALS = 16


@functools.lru_cache(maxsize=64)
def _chi2_quantile(p: float, dof: int) -> float:
    """Chi-square quantile ``F^-1(p)`` with ``dof`` degrees of freedom: ``2 P^-1(dof/2, p)``
    (inverse regularized lower incomplete gamma), the formula ``scipy.stats.chi2.ppf``
    evaluates, so the same value, without importing ``scipy.stats`` (about 0.6 s of every
    loose/tight run's start, a sixth of its integration loop on a 25 s file)."""
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(dof / 2.0, p))


@dataclasses.dataclass
class GnssEpoch:
    """One measurement epoch of the scalar receiver.

    Attributes
    ----------
    sample : int
        IF sample of the epoch.
    obs : Observables
        Observables of the usable channels (receiver time ``obs.week``, ``obs.sow``).
    sat : SatelliteStates or None
        Satellite states of ``obs`` with the ephemerides in force (None without observables).
    iono : Klobuchar or None
        Ionosphere coefficients in force.
    sol : PvtSolution
        The WLS fix of the epoch (``cov``, ``cov_v``: formal covariances).
    nav : dict
        ``{prn: (week, toe, aode, source)}`` of the ephemerides in force for ``obs``.
    """

    sample: int
    obs: Observables
    sat: SatelliteStates | None
    iono: Klobuchar | None
    sol: PvtSolution
    nav: dict


class GnssEpochRecorder:
    """Records the scalar receiver's epochs after the hand-over (module notes).

    The epochs are also a stream: the integration loop may consume them on another thread
    while the scalar receiver is still producing them (:meth:`wait_for`; the producer calls
    :meth:`close` when it has recorded its last epoch). A recorded epoch is never changed.

    Parameters
    ----------
    engine : PvtEngine
        The receiver's PVT (its ``ephemerides``/``iono`` set to the data in force by the
        caller before :meth:`record`).
    navdata : NavDataInForce
        Navigation data in force.
    """

    def __init__(self, engine: PvtEngine | None, navdata) -> None:
        # engine None: a replay's closed recorder (ScalarRecord.recorder), never recording
        self.engine, self.navdata = engine, navdata
        self.epochs: list[GnssEpoch] = []
        self.closed = False
        self._cond = threading.Condition()
        self._listeners: list[tuple] = []

    def add_listener(self, on_epoch, on_close) -> None:
        """Call ``on_epoch(ep)`` for every epoch, those recorded so far at once, and
        ``on_close()`` at :meth:`close` (on the recording thread; e.g. the feed of a loop
        in a child process, :mod:`~sdr_di.integration.loop_process`)."""
        with self._cond:
            for ep in self.epochs:
                on_epoch(ep)
            if self.closed:
                on_close()
            else:
                self._listeners.append((on_epoch, on_close))

    def close(self) -> None:
        """No more epochs: wakes a consumer waiting in :meth:`wait_for`."""
        with self._cond:
            if self.closed:
                return
            self.closed = True
            self._cond.notify_all()
            for _, on_close in self._listeners:
                on_close()

    def wait_for(self, i: int) -> bool:
        """Block until epoch ``i`` is recorded (True) or the recorder is closed without it
        (False)."""
        if i < len(self.epochs):
            return True
        with self._cond:
            while i >= len(self.epochs) and not self.closed:
                self._cond.wait()
            return i < len(self.epochs)

    def record(self, sample: int, channels: list) -> GnssEpoch:
        """PVT of the epoch at ``sample`` from the channel observations; kept and returned."""
        assert self.engine is not None          # only a replay's recorder has none
        sol = self.engine.process(channels, sample)
        obs = self.engine.last_observables
        assert obs is not None                  # set by process
        # the PVT's own satellite states (the engine's ephemerides are this navdata)
        sat = self.engine.last_satellites if self.engine.ephemerides is self.navdata else (
            satellite_states(obs, self.navdata) if obs.n else None)
        nav = {}
        for i, prn in enumerate(obs.prn):
            if sat is not None and sat.ok[i]:
                try:
                    e, src = self.navdata.select_with_source(int(prn), int(obs.t_tx_week[i]),
                                                             float(obs.t_tx_sow[i]))
                except SdrDiError:
                    continue
                nav[int(prn)] = (int(e.week), float(e.toe), int(e.AODE), src)
        return self.append(GnssEpoch(int(sample), obs, sat, self.navdata.klobuchar, sol, nav))

    def append(self, ep: GnssEpoch) -> GnssEpoch:
        """Keep ``ep`` (after the last one) and wake a waiting consumer; returns ``ep``."""
        with self._cond:
            self.epochs.append(ep)
            self._cond.notify_all()
            for on_epoch, _ in self._listeners:
                on_epoch(ep)
        return ep


class ScalarEpochSource:
    """Measurement source of the loose and tight couplings (module notes); subclasses
    implement :meth:`measurement`.

    Parameters
    ----------
    epochs : list of GnssEpoch or GnssEpochRecorder
        The recorded epochs, in time order; a recorder: its epochs, waited for as the
        scalar receiver records them (:meth:`GnssEpochRecorder.wait_for`).
    prns : sequence of int
        Channel columns (:meth:`keep_columns` narrows them after the run).
    imu_t : (n,) array
        IMU sample times [s].
    imu_epoch : (int, float)
        BDT (week, seconds of week) of IMU ``t = 0``.
    fs : float
        IF sampling rate [Hz].
    profile : dict
        Seconds per stage; this source adds ``measure`` and ``epoch_wait`` (behind the
        receiver: waiting for its next epoch, left out of ``measure``).
    min_cn0_dbhz : float or None, optional
        Screen: lowest C/N0 of a usable channel [dB-Hz] (module notes); None: no C/N0 test.
    gate_alpha : float, optional
        Innovation gate: probability of rejecting a good measurement (0 disables the gate).
    gate_reset_epochs : int, optional
        Epochs in a row with everything gated out before one is taken ungated.
    """

    def __init__(self, epochs: list[GnssEpoch], prns, imu_t: np.ndarray, imu_epoch,
                 fs: float, profile: dict, *, min_cn0_dbhz: float | None = 20.0,
                 gate_alpha: float = 1e-4, gate_reset_epochs: int = 5) -> None:
        self._wait = epochs.wait_for if isinstance(epochs, GnssEpochRecorder) else None
        self.epochs = epochs.epochs if isinstance(epochs, GnssEpochRecorder) else epochs
        self.prns = tuple(int(p) for p in prns)
        self.col = {p: i for i, p in enumerate(self.prns)}
        self.n_channels = len(self.prns)
        self.imu_t = imu_t
        self.imu_week, self.imu_sow = int(imu_epoch[0]), float(imu_epoch[1])
        self.fs = fs
        self.profile = profile
        profile.setdefault("measure", 0.0)
        if self._wait is not None:
            profile.setdefault("epoch_wait", 0.0)
        self._next = 0
        self._used = np.zeros(self.n_channels, bool)
        self._cn0 = np.full(self.n_channels, math.nan)
        self._nav_prev: dict = {}
        self._iono_prev: Klobuchar | None = None
        self._flag = 0
        self.last: GnssEpoch | None = None
        self.min_cn0_dbhz = None if min_cn0_dbhz is None else float(min_cn0_dbhz)
        self.gate_alpha = float(gate_alpha)
        self.gate_reset_epochs = int(gate_reset_epochs)
        self._gated_in_a_row = 0
        self.n_screened = 0              # channel-epochs (tight) / fixes (loose) screened out
        self.n_gated = 0                 # channel-epochs (tight) / fixes (loose) gated out
        self.navigation: dict = {"ephemerides": {}, "ionosphere": []}
        #: INS acceleration of the latest intervals: (mid time [s, IMU], a_n [m/s^2]).
        self._acc: collections.deque = collections.deque(maxlen=LOOP_ACC_INTERVALS)

    def detach_epochs(self) -> tuple:
        """Take the epoch list and its wait away (to pickle the source); returns them for
        :meth:`attach_epochs`."""
        saved = (self.epochs, self._wait)
        self.epochs, self._wait = [], None
        return saved

    def attach_epochs(self, epochs: list, wait=None) -> None:
        """Read ``epochs`` (``wait(i)``: blocks until epoch ``i`` exists or none will, as
        :meth:`GnssEpochRecorder.wait_for`; None: the list is complete)."""
        self.epochs, self._wait = epochs, wait
        if wait is not None:
            self.profile.setdefault("epoch_wait", 0.0)

    # ------------------------------------------------------------------------------------
    def imu_time(self, week: int, sow: float) -> float:
        """IMU time [s] of BDT (``week``, ``sow``)."""
        return (week - self.imu_week) * SECONDS_PER_WEEK + sow - self.imu_sow

    def bdt_of(self, ep: GnssEpoch, clock_bias_m: float) -> tuple[int, float]:
        """BDT of the epoch: receiver time minus ``clock_bias_m`` / c."""
        return ep.obs.week, ep.obs.sow - clock_bias_m / C_LIGHT

    def epoch_clock_bias(self, loop: LoopState, iv: Interval, ep: GnssEpoch) -> float:
        """The clock bias [m] used to time-tag ``ep`` (default: the filter's clock
        interpolated between the interval's ends)."""
        a = (ep.sample - iv.k0) / max(iv.k1 - iv.k0, 1)
        return loop.clock_bias_m + a * (iv.clock_bias_m - loop.clock_bias_m)

    def ins_at(self, iv: Interval, t_imu: float) -> tuple[np.ndarray, np.ndarray]:
        """INS position (rad, rad, m) and ENU velocity [m/s] at IMU time ``t_imu``, linear
        between the interval's ends."""
        t0, t1 = self.imu_t[iv.i0], self.imu_t[iv.i1]
        a = min(max((t_imu - t0) / (t1 - t0), 0.0), 1.0)
        n0, n1 = iv.nav0, iv.nav1
        assert n0 is not None and n1 is not None    # set by the loop's propagate_ins
        return n0.llh + a * (n1.llh - n0.llh), n0.v_n + a * (n1.v_n - n0.v_n)

    def loop_velocity(self, v_n: np.ndarray, t_imu: float, pll_bw_hz: float) -> np.ndarray:
        """The velocity [m/s, ENU] the scalar loops' rates stand for at IMU time ``t_imu``:
        ``v_n - k j_n`` (module notes, *Rates under dynamics*; ``k``:
        :func:`~sdr_di.receiver.loops.pll_rate_dynamic_error`), the jerk ``j_n`` the slope of
        a straight-line fit to the INS's interval accelerations over the last
        ``LOOP_ACC_WINDOW_S``; ``v_n`` unchanged with fewer than 3 intervals."""
        k = pll_rate_dynamic_error(pll_bw_hz)
        rows = [(t, a) for t, a in self._acc if t_imu - LOOP_ACC_WINDOW_S <= t <= t_imu + 0.05]
        if len(rows) < 3:
            return v_n
        dt = np.array([t for t, _ in rows]) - t_imu
        A = np.array([a for _, a in rows])
        X = np.c_[np.ones(dt.size), dt]
        (_, j), *_ = np.linalg.lstsq(X, A, rcond=None)
        return v_n - k * j

    def _take_epoch(self, loop: LoopState, iv: Interval) -> GnssEpoch | None:
        """The latest epoch whose BDT falls in the interval's IMU span; earlier ones are
        skipped (at most one per interval while ``gnss_rate_hz`` <= the filter rate)."""
        t1 = self.imu_t[iv.i1]
        found = None
        while self._have(self._next):
            ep = self.epochs[self._next]
            t = self.imu_time(*self.bdt_of(ep, self.epoch_clock_bias(loop, iv, ep)))
            if t > t1:
                break
            if t > self.imu_t[iv.i0]:
                found = ep
            self._next += 1
        return found

    def _have(self, i: int) -> bool:
        """Epoch ``i`` exists (behind the receiver: waiting for it, the wait timed)."""
        if i < len(self.epochs) or self._wait is None:
            return i < len(self.epochs)
        ta = time.perf_counter()
        ok = self._wait(i)
        self.profile["epoch_wait"] += time.perf_counter() - ta
        return ok

    def screened(self, ep: GnssEpoch) -> np.ndarray:
        """Mask over ``ep.obs`` of the channels passing the screen (module notes): C/N0
        finite and at least ``min_cn0_dbhz``, carrier lock (finite carrier phase)."""
        obs = ep.obs
        cn0 = np.asarray(obs.cn0_dbhz, float)
        ok = np.ones(cn0.shape, bool)
        if self.min_cn0_dbhz is not None:
            ok &= np.isfinite(cn0) & (np.nan_to_num(cn0, nan=-np.inf) >= self.min_cn0_dbhz)
        cph = getattr(obs, "carrier_phase_m", None)
        if cph is not None:
            ok &= np.isfinite(np.asarray(cph, float))
        return ok

    def gate_limit(self, dof: int) -> float:
        """Chi-square quantile at ``1 - gate_alpha`` with ``dof`` degrees of freedom."""
        return _chi2_quantile(1.0 - self.gate_alpha, int(dof))

    def innovation_covariance(self, loop: LoopState, m: Measurements) -> np.ndarray:
        """``S = H P H^T + R`` of ``m`` with the filter's current ``P`` (module notes)."""
        loop.set_geometry(*m.geometry)
        kf = loop.kf
        H = kf.measurement_model.H(kf.x)
        return H @ kf.P @ H.T + m.R

    def gate(self, loop: LoopState, iv: Interval, ep: GnssEpoch,
             m: Measurements) -> Measurements:
        """``m`` less the measurements failing the innovation gate (subclasses); returns
        ``m`` unchanged by default."""
        return m

    def _gated(self, loop: LoopState, iv: Interval, ep: GnssEpoch,
               m: Measurements) -> Measurements:
        """Innovation gate with the recovery rule (module notes)."""
        if m.z is None or not m.z.size or self.gate_alpha <= 0.0:
            return m
        g = self.gate(loop, iv, ep, m)
        if g.z is not None and g.z.size:
            self._gated_in_a_row = 0
            return g
        self._gated_in_a_row += 1
        if self._gated_in_a_row > self.gate_reset_epochs:
            self._gated_in_a_row = 0
            return m
        return g

    # ---- MeasurementSource ------------------------------------------------------------
    def measure(self, loop: LoopState, iv: Interval) -> Measurements:
        """The interval's measurement (None ``z`` between epochs)."""
        ta = time.perf_counter()
        wait0 = self.profile.get("epoch_wait", 0.0)
        if iv.nav0 is not None and iv.nav1 is not None:
            t0, t1 = self.imu_t[iv.i0], self.imu_t[iv.i1]
            if t1 > t0:
                self._acc.append((0.5 * (t0 + t1), (iv.nav1.v_n - iv.nav0.v_n) / (t1 - t0)))
        ep = self._take_epoch(loop, iv)
        m = None
        if ep is not None:
            self.last = ep
            self._note_navigation(ep, iv.k1 / self.fs)
            m = self._gated(loop, iv, ep, self.measurement(loop, iv, ep))
            self._used = m.used.copy()
            self._cn0 = np.full(self.n_channels, math.nan)
            for prn, c in zip(ep.obs.prn, ep.obs.cn0_dbhz):
                if int(prn) in self.col:
                    self._cn0[self.col[int(prn)]] = c
        if m is None:
            m = Measurements(z=None, R=None, geometry=(), used=self._used)
        self.profile["measure"] += (time.perf_counter() - ta
                                    - (self.profile.get("epoch_wait", 0.0) - wait0))
        return m

    def measurement(self, loop: LoopState, iv: Interval, ep: GnssEpoch) -> Measurements:
        """``z``, ``R``, geometry and channels of epoch ``ep`` (subclasses)."""
        raise NotImplementedError

    def keep_columns(self, prns, rows: dict) -> None:
        """Narrow the channel columns to ``prns`` (a subset of :attr:`prns`, any order), in
        the source and in the loop's ``rows`` (``used``, ``cn0``, ``innov``): a loop run behind the
        scalar receiver starts with a column for every channel of the receiver, since which
        of them will be acquired later is known only at the end."""
        idx = [self.col[int(p)] for p in prns]
        for key in ("used", "cn0"):
            rows[key] = [np.asarray(r)[idx] for r in rows[key]]
        half = self.n_channels                  # innov: code then rate, per channel
        rows["innov"] = [np.r_[np.asarray(r)[:half][idx], np.asarray(r)[half:][idx]]
                         for r in rows.get("innov", [])]
        self.prns = tuple(int(p) for p in prns)
        self.col = {p: i for i, p in enumerate(self.prns)}
        self.n_channels = len(self.prns)
        self._used, self._cn0 = self._used[idx], self._cn0[idx]

    def columns_of(self, prns) -> np.ndarray:
        """Channel column of each of ``prns``, in their order (-1: not a column)."""
        return np.array([self.col.get(int(p), -1) for p in prns], int)

    def used_mask(self, prns) -> np.ndarray:
        """Channel mask of ``prns``."""
        used = np.zeros(self.n_channels, bool)
        for p in prns:
            if int(p) in self.col:
                used[self.col[int(p)]] = True
        return used

    def feed_back(self, loop: LoopState, iv: Interval, x: np.ndarray) -> None:
        """No NCOs to drive: the scalar loops run on their own."""

    def take_up_navigation_data(self, loop: LoopState, iv: Interval) -> None:
        """Nothing to switch: each epoch carries the navigation data in force at it."""

    def row(self) -> dict:
        """``cn0`` of the latest epoch [dB-Hz] and the navigation-data flag since the last
        row (1 an ephemeris changed, 2 the ionosphere model)."""
        out = {"cn0": self._cn0.copy(), "nav": self._flag}
        self._flag = 0
        return out

    def _note_navigation(self, ep: GnssEpoch, t_s: float) -> None:
        for prn, rec in ep.nav.items():
            prev = self._nav_prev.get(prn)
            if prev != rec:
                if prev is not None:
                    self._flag |= 1
                self._nav_prev[prn] = rec
                self.navigation["ephemerides"].setdefault(f"C{prn:02d}", []).append(
                    {"t_s": round(t_s, 3), "source": rec[3], "week": rec[0], "toe": rec[1],
                     "aode": rec[2]})
        if ep.iono is not self._iono_prev or not self.navigation["ionosphere"]:
            if self.navigation["ionosphere"]:
                self._flag |= 2
            self._iono_prev = ep.iono
            self.navigation["ionosphere"].append(
                {"t_s": round(t_s, 3), "model": "klobuchar" if ep.iono is not None else "none"})
