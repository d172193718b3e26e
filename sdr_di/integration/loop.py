"""One integration loop for every coupling mode: INS, filter, feedback, solution rows.

DESIGN section 7, "three couplings, one loop": loose (WLS fixes), tight (pseudoranges and
rates) and deep (pre-filter outputs, with the feedback also driving the NCOs) share this
loop; a mode differs only in its :class:`MeasurementSource`. One filter interval ``T`` (IMU
samples ``(i0, i1]``, IF samples ``[k0, k1)``) of :meth:`IntegrationLoop.run`::

    next_interval          the interval's IMU and IF sample bounds (None: end of the data)
    propagate_ins          strapdown INS over the interval at the IMU rate; clock bias
                           predicted to k1 with the drift
    source.measure         the mode's measurements z, R and their geometry
                           (deep: NCO commands from the propagated INS, correlators,
                           pre-filters, channel management; None: the IF data ran out)
    filter_step            process model over the interval (INS at both ends, compensated
                           IMU average), predict, update (paper 004 eq 13-25)
    feed_back              closed-loop correction of the INS and the clock, then the
                           source's own feedback (deep: NCO ranges and pre-filters), error
                           state reset to zero
    source.take_up_navigation_data
                           ephemeris / ionosphere decoded in the interval taken up at its end
    write_row              solution row at the output rate (after the feedback)

NCOs one interval ahead (deep, ``nco_latency = 1``: :meth:`IntegrationLoop.run_ahead`, the
reasons in :mod:`sdr_di.integration.receiver`'s notes): the same stages in another order, so
that the source's correlation of interval ``j + 1`` runs while this thread closes ``j``::

    propagate_ins(j + 1)   from the INS corrected at j.k1 by the error predicted there
    source.launch(j + 1)   NCO commands of j + 1 and its correlation, split between the
                           kernel's worker and this thread; after this thread's part (while
                           the worker still correlates), _close_ahead(j):
        source.measure_launched(j)   pre-filters of j, each first moved by the feedback
                                     made at j.k1 while j was correlated
        filter_step(j)               update (predict too on the first interval)
        source.restart_prefilters    lost or inconsistent pre-filters restarted
        write_row(j)                 INS and clock at j.k1, corrected by the update
        predict_filter(j + 1), then the predicted error at (j + 1).k1 fed back (INS, clock,
        source.feed_back_ahead: NCO ranges of the next command, the pre-filter step after
        j + 1), error state reset; source.take_up_navigation_data at (j + 1).k1

Tried and not kept: the correlation of ``j + 1`` started on the worker as soon as it is
commanded, so that it also overlaps the INS propagation and NCO commands of ``j + 2``
(outputs the same bytes). It took 12-13 s against 9-10 s for the run above (40 s file,
2 cores): with this thread in Python almost all the time, the worker waited for the GIL at
each Python step around its kernels (thread start, the rotation tables' and the kernel's
dispatch), and its part took 5.9 ms per interval against about 3.3 ms of kernel CPU.

State layout (paper 004 Table 1): attitude error 0-2, velocity error 3-5, position error
(lat, lon, h) 6-8, gyro bias 9-11, accelerometer bias 12-14, clock bias 15 [m], clock drift
16 [m/s]; with ``error_states=sf`` gyro and accelerometer scale factors 17-22, fed back into
the INS's IMU compensation as the biases are (the layout is ``process.layout``,
:mod:`sdr_di.filters.state`). The clock is carried here as ``clock_bias_m`` /
``clock_drift_mps`` (receiver clock minus BDT, times c) beside the INS.
"""

from __future__ import annotations

import copy
import math
import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from ..constants import C_LIGHT
from ..coupling.interval import Interval, MeasurementSource, Measurements
from ..filters.state import StateLayout
from ..ins.error_model import NavState, correct_ins
from .consistency import block_nis, enu_blocks, formal_sd, nees_per_dof
from .metrics import nav_errors

# Interval, Measurements and MeasurementSource live in sdr_di.coupling.interval
__all__ = ["BackgroundLoop", "IntegrationLoop", "Interval", "MeasurementSource",
           "Measurements", "channel_innovations"]

#: Columns of :attr:`IntegrationLoop.rows` (one entry per solution row).
ROW_KEYS = ("t", "sow", "llh", "v", "att", "b", "d", "n", "ae", "ve", "pe", "used", "cn0",
            "nis", "nav", "sd", "nees", "innov")


def channel_innovations(m: Measurements, y: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Normalized innovation ``y_i / sqrt(S_ii)`` of each channel's two measurements,
    ``(2 n_ch,)``: the code (pseudorange) rows, then the rate rows, in channel order; NaN for
    a channel not in ``z``. ``z``'s channels are those of ``m.columns`` (tight), else the used
    ones in column order (deep); loose's ``z`` is a fix, not channels: NaN everywhere."""
    n_ch = m.used.size
    out = np.full(2 * n_ch, math.nan)
    n = y.size // 2
    if y.size != 2 * n or n != m.n_used or (m.channels is not None and m.columns is None):
        return out
    cols = np.flatnonzero(m.used) if m.columns is None else np.asarray(m.columns, int)
    if cols.size != n or (cols < 0).any():
        return out
    w = y / np.sqrt(np.diagonal(S))
    out[cols], out[n_ch + cols] = w[:n], w[n:]
    return out


def _per_channels(innov: np.ndarray | None, n_ch: int) -> np.ndarray:
    """:func:`channel_innovations` of an update (None: no update since the last row) for a
    row of ``n_ch`` channels: a source that acquires channels later (loose, tight) may have
    had fewer at the update, or more while its loop ran behind the receiver."""
    out = np.full(2 * n_ch, math.nan)
    if innov is not None:
        k = min(innov.size // 2, n_ch)
        out[:k], out[n_ch:n_ch + k] = innov[:k], innov[innov.size // 2:innov.size // 2 + k]
    return out


class IntegrationLoop:
    """Closed-loop INS integration at the filter rate (module notes).

    Parameters
    ----------
    imu : ImuData
        IMU record (``t``, ``f_b``, ``w_ib_b``).
    t_if : (n,) array
        IF-file time of every IMU sample [s].
    i_start, k_start : int
        IMU and IF sample of the loop's start (the hand-over grid point).
    n_per : int
        IMU samples per filter interval.
    fs : float
        IF sampling rate [Hz].
    stop : int
        IF sample at which the data ends.
    margin : int
        IF samples past ``k1`` an interval needs (the correlators' last code epochs).
    ins : StrapdownINS
        Aligned INS at ``i_start``.
    clock_bias_m, clock_drift_mps : float
        Receiver clock at ``i_start`` [m, m/s].
    kf : filter
        Integration filter (:func:`~sdr_di.filters.make_filter`, 17 states or the layout of
        ``process``).
    process : InsErrorModel
        Its process model (``layout``: the states fed back).
    set_geometry : callable
        ``set_geometry(*Measurements.geometry)`` sets the filter's measurement model for an
        update, after the predict (deep and tight:
        :meth:`~sdr_di.coupling.measurements.RangeRateMeasurementModel.set_geometry`;
        loose: :meth:`~sdr_di.coupling.measurements.LooseMeasurementModel.set_epoch`).
    sow_of_sample : callable
        ``sow_of_sample(k)``: receiver-clock seconds of week of IF sample ``k``.
    output_every : int
        Filter intervals per solution row.
    truth : Truth, optional
        Reference on the IMU time grid (error columns; NaN without it).
    progress : callable, optional
        ``progress(seconds, n_channels, n_used)`` about once per second.
    profile : dict
        Seconds per stage, added to (``ins``, ``filter``, ``output`` here; the source adds
        its own).
    """

    def __init__(self, *, imu, t_if: np.ndarray, i_start: int, k_start: int, n_per: int,
                 fs: float, stop: int, margin: int, ins, clock_bias_m: float,
                 clock_drift_mps: float, kf, process, set_geometry: Callable[..., None],
                 sow_of_sample: Callable[[int], float], output_every: int, truth=None,
                 progress: Callable[[float, int, int], None] | None = None,
                 profile: dict | None = None) -> None:
        self.imu, self.t_if, self.n_per, self.fs = imu, t_if, n_per, fs
        self.stop, self.margin = stop, margin
        self.T = n_per * (1.0 / imu.rate_hz)     # filter interval [s]
        self.ins = ins
        self.clock_bias_m, self.clock_drift_mps = clock_bias_m, clock_drift_mps
        self.kf, self.process, self.set_geometry = kf, process, set_geometry
        self.layout: StateLayout = getattr(process, "layout", None) or StateLayout()
        self.sow_of_sample = sow_of_sample
        self.output_every = output_every
        self.truth = truth if (truth is not None and len(truth.t) == len(imu.t)
                               and np.allclose(truth.t, imu.t, atol=1e-6)) else None
        self.progress = progress
        self.profile = profile if profile is not None else {}
        for k in ("ins", "filter", "output"):
            self.profile.setdefault(k, 0.0)
        self.i0, self.k0 = i_start, k_start
        self.n_intervals = 0
        self.rows: dict = {k: [] for k in ROW_KEYS}
        self._nis = [0.0, 0]
        self._innov: np.ndarray | None = None    # of the last update since the last row
        #: per update: time [s], NIS per degree of freedom of the two halves of ``z``
        #: (:func:`~sdr_di.integration.consistency.block_nis`) and the half's size
        self.updates: dict = {"t": [], "nis": [], "dof": []}
        self._next_progress = 0.0
        self.stop_requested = False      # set from another thread: end after this interval

    # ------------------------------------------------------------------------------------
    def run(self, source: MeasurementSource) -> None:
        """Run the loop until the IMU or the IF data ends (module notes), or until
        :attr:`stop_requested` is set."""
        while not self.stop_requested and (iv := self.next_interval()) is not None:
            self.propagate_ins(iv)
            m = source.measure(self, iv)
            if m is None:
                break
            self.filter_step(iv, m)
            self.feed_back(iv, source)
            source.take_up_navigation_data(self, iv)
            self.write_row(iv, m, source)
            self.i0, self.k0 = iv.i1, iv.k1

    def run_ahead(self, source) -> None:
        """:meth:`run` with the NCOs one interval ahead (deep, ``nco_latency = 1``; module
        notes, *NCOs one interval ahead*): the INS is propagated over interval ``j + 1``
        and its NCOs commanded before the update of interval ``j``, and that interval's
        correlation runs on the kernel's worker thread while this thread runs
        :meth:`_close_ahead` of ``j``. ``source``: :class:`~sdr_di.deep.vector_tracking.
        VectorTracking` (``launch``, ``measure_launched``, ``geometry_of``,
        ``restart_prefilters``, ``feed_back_ahead``)."""
        iv = self.next_interval()
        if iv is None:
            return
        self.propagate_ins(iv)
        if not source.launch(self, iv):
            return
        source.feed_back_ahead(self, iv, np.zeros(self.layout.n))  # nothing fed back yet
        while True:
            self.i0, self.k0 = iv.i1, iv.k1
            nxt = None if self.stop_requested else self.next_interval()
            # the INS and clock at iv.k1 (before the update of iv) for its solution row (a
            # shallow copy: StrapdownINS.correct and step replace their arrays)
            at_k1 = (copy.copy(self.ins), self.clock_bias_m, self.clock_drift_mps) \
                if (self.n_intervals + 1) % self.output_every == 0 else None
            if nxt is not None:
                self.propagate_ins(nxt)
                if source.launch(self, nxt, lambda: self._close_ahead(iv, nxt, at_k1, source)):
                    iv = nxt
                    continue
            self._close_ahead(iv, None, at_k1, source)
            return

    def _close_ahead(self, iv: Interval, nxt: Interval | None, at_k1: tuple | None,
                     source) -> None:
        """Interval ``iv`` of :meth:`run_ahead`, the INS already propagated over ``nxt``
        (None: the last interval): pre-filters and measurements, predict (on the first
        interval) and update, pre-filter restarts, the solution row at ``iv.k1`` (``at_k1``:
        the INS and clock there, corrected by the update), then the predict over ``nxt``
        and the feedback of the predicted error at ``nxt.k1`` (INS, clock, NCO ranges of
        the next command, pre-filter step after ``nxt``'s correlations) and the navigation
        data taken up there."""
        m = source.measure_launched(self, iv)
        self.filter_step(iv, m)
        source.geometry_of(iv)
        source.restart_prefilters(self)
        at = None
        if at_k1 is not None:
            ins, bias, drift = at_k1
            x, L = self.kf.x, self.layout
            correct_ins(ins, x, L)
            at = (ins, bias - x[L.clock_bias], drift - x[L.clock_drift])
        self.write_row(iv, m, source, at=at)
        if nxt is None:
            return
        self.predict_filter(nxt)
        self.feed_back(nxt, source, source.feed_back_ahead)
        source.take_up_navigation_data(self, nxt)

    # ------------------------------------------------------------------------------------
    def next_interval(self) -> Interval | None:
        """The next interval after ``(i0, k0)``; None when the IMU record or the IF data
        (``k1`` plus the correlators' ``margin``) ends."""
        i1 = self.i0 + self.n_per
        if i1 >= len(self.imu.t):
            return None
        k1 = round(self.t_if[i1] * self.fs)
        if k1 + self.margin > self.stop:
            return None
        return Interval(self.i0, i1, self.k0, k1)

    def propagate_ins(self, iv: Interval) -> None:
        """Strapdown INS over the interval's IMU samples; clock bias predicted to ``k1``.

        Sets ``iv.nav0``, ``iv.nav1`` (INS at both ends), ``iv.f_mean``, ``iv.w_mean`` (IMU
        averages compensated with the INS bias estimates, for the process model) and
        ``iv.clock_bias_m``.
        """
        ta = time.perf_counter()
        ins, imu, i0, i1 = self.ins, self.imu, iv.i0, iv.i1
        iv.nav0 = NavState.from_ins(ins)
        f_b = imu.f_b[i0 + 1:i1 + 1]
        w_ib_b = imu.w_ib_b[i0 + 1:i1 + 1]
        iv.f_mean, iv.w_mean = ins.compensate(f_b.mean(axis=0), w_ib_b.mean(axis=0))
        n = self.n_per
        ins.step_many(f_b[:n], w_ib_b[:n], np.diff(imu.t[i0:i0 + n + 1]))
        iv.nav1 = NavState.from_ins(ins)
        iv.clock_bias_m = self.clock_bias_m + self.clock_drift_mps * self.T
        self.profile["ins"] += time.perf_counter() - ta

    def predict_filter(self, iv: Interval) -> None:
        """Process model over the interval and the filter's predict, once per interval. It
        needs only the propagated INS, so a measurement source may call it while its
        correlators run (deep: :meth:`~sdr_di.deep.vector_tracking.VectorTracking.
        correlate`); :meth:`filter_step` calls it otherwise."""
        if iv.predicted:
            return
        ta = time.perf_counter()
        self.process.set_interval(iv.nav0, iv.nav1, iv.f_mean, iv.w_mean)
        self.kf.predict(self.T)
        iv.predicted = True
        self.profile["filter"] += time.perf_counter() - ta

    def filter_step(self, iv: Interval, m: Measurements) -> None:
        """Process model over the interval, predict, and update with ``m`` when it has a
        measurement ``z`` (paper 004 eq 13-25); accumulates the NIS per measurement and
        keeps the NIS per degree of freedom of each half of ``z`` (:attr:`updates`)."""
        self.predict_filter(iv)
        ta = time.perf_counter()
        kf = self.kf
        if m.z is not None:
            self.set_geometry(*m.geometry)
            kf.update(m.z, m.R)
            self._nis[0] += kf.nis / m.z.size
            self._nis[1] += 1
            self.updates["t"].append(iv.k1 / self.fs)
            self.updates["nis"].append(block_nis(kf.y, kf.S, 2))
            self.updates["dof"].append(m.z.size // 2)
            self._innov = channel_innovations(m, kf.y, kf.S)
        self.profile["filter"] += time.perf_counter() - ta

    def feed_back(self, iv: Interval, source: MeasurementSource,
                  share: Callable | None = None) -> np.ndarray:
        """Closed-loop feedback of the filter's error state ``x`` at ``iv.k1``: the INS
        (attitude, velocity, position, IMU biases) and the clock, then the source's own
        share (``share(loop, iv, x)``, default ``source.feed_back``; :meth:`run_ahead`: the
        predicted error with ``source.feed_back_ahead``); ``x`` reset to zero. Returns the
        ``x`` fed back (n,)."""
        ta = time.perf_counter()
        x, L = self.kf.x.copy(), self.layout
        correct_ins(self.ins, x, L)
        self.clock_bias_m = iv.clock_bias_m - x[L.clock_bias]
        self.clock_drift_mps = self.clock_drift_mps - x[L.clock_drift]
        (source.feed_back if share is None else share)(self, iv, x)
        self.kf.x = np.zeros(x.size)
        self.profile["ins"] += time.perf_counter() - ta
        return x

    def write_row(self, iv: Interval, m: Measurements, source: MeasurementSource,
                  at: tuple | None = None) -> None:
        """Solution row at ``k1`` every ``output_every`` intervals: time, BDT (receiver time
        minus clock bias / c), INS position/velocity/attitude after the feedback, clock,
        the source's channel columns, mean NIS since the last row, errors vs the truth,
        the formal 1-sigma of the corrected solution in ENU (``sd``) and its NEES per
        degree of freedom of position, velocity, attitude (``nees``). ``at``: ``(INS, clock
        bias [m], clock drift [m/s])`` at ``k1`` when the loop's own have moved on
        (:meth:`run_ahead`)."""
        ta = time.perf_counter()
        self.n_intervals += 1
        if self.n_intervals % self.output_every == 0:
            ins, bias, drift = (self.ins, self.clock_bias_m, self.clock_drift_mps) \
                if at is None else at
            rows, k1, fs = self.rows, iv.k1, self.fs
            rows["t"].append(k1 / fs)
            rows["sow"].append(self.sow_of_sample(k1) - bias / C_LIGHT)
            rows["llh"].append(ins.llh.copy())
            rows["v"].append(ins.v_n.copy())
            rows["att"].append(ins.att.copy())
            rows["b"].append(bias)
            rows["d"].append(drift)
            rows["n"].append(m.n_used)
            rows["used"].append(m.used.copy())
            for k, v in source.row().items():
                rows[k].append(v)
            rows["nis"].append(self._nis[0] / self._nis[1] if self._nis[1] else math.nan)
            self._nis = [0.0, 0]
            rows["innov"].append(_per_channels(self._innov, m.used.size))
            self._innov = None
            P = self.kf.P                  # of the corrected solution (x fed back)
            rows["sd"].append(formal_sd(P, ins.llh))
            if self.truth is not None:
                tr = self.truth
                ae, ve, pe = nav_errors(ins.llh, ins.v_n, ins.C_b_n, tr.llh[iv.i1],
                                        tr.v_n[iv.i1], tr.C_b_n[iv.i1])
                P_att, P_vel, P_pos = enu_blocks(P, ins.llh)
                rows["nees"].append(np.array([nees_per_dof(pe, P_pos),
                                              nees_per_dof(ve, P_vel),
                                              nees_per_dof(np.radians(ae), P_att)]))
            else:
                ae = ve = pe = np.full(3, math.nan)
                rows["nees"].append(np.full(3, math.nan))
            rows["ae"].append(ae)
            rows["ve"].append(ve)
            rows["pe"].append(pe)
            if self.progress is not None and k1 / fs >= self._next_progress:
                self.progress(k1 / fs, source.n_channels, m.n_used)
                self._next_progress = k1 / fs + 1.0
        self.profile["output"] += time.perf_counter() - ta

    def columns(self, n_ch: int) -> dict:
        """The rows as arrays: ``(n,)`` or ``(n, 3)`` floats, ``n`` and ``nav`` ints,
        ``used`` ``(n, n_ch)`` bool, ``cn0`` ``(n, n_ch)``, ``innov`` ``(n, 2 n_ch)``
        (:func:`channel_innovations` of the row's last update), ``sd`` ``(n, 9)``, ``nees``
        ``(n, 3)``; ``updates``: :attr:`updates` as arrays (``nis`` ``(k, 2)``)."""
        rows = self.rows

        def arr(key, width=None):
            a = np.asarray(rows[key], float)
            return a.reshape(-1, width) if width else a

        out = {k: arr(k) for k in ("t", "sow", "b", "d", "nis")}
        out.update({k: arr(k, 3) for k in ("llh", "v", "att", "ae", "ve", "pe")})
        out["n"] = np.asarray(rows["n"], int)
        out["nav"] = np.asarray(rows["nav"], int)
        out["used"] = np.asarray(rows["used"], bool).reshape(-1, n_ch)
        out["cn0"] = arr("cn0", n_ch)
        out["innov"] = arr("innov", 2 * n_ch)
        out["sd"] = arr("sd", 9)
        out["nees"] = arr("nees", 3)
        up = self.updates
        out["updates"] = {"t": np.asarray(up["t"], float),
                          "nis": np.asarray(up["nis"], float).reshape(-1, 2),
                          "dof": np.asarray(up["dof"], int)}
        return out



class BackgroundLoop:
    """:meth:`IntegrationLoop.run` on a second thread.

    Loose and tight mode run the loop behind the scalar receiver, which does not depend on
    the filter: the source waits for each GNSS epoch as the receiver records it
    (:class:`~sdr_di.integration.gnss_epochs.GnssEpochRecorder`), and the loop's Python
    work overlaps the receiver's correlation kernels, which release the GIL. The rows are
    the same as those of a loop run after the receiver: the loop sees the same epochs in
    the same order, whenever they arrive.

    GIL: while the loop thread runs, a receiver thread returning from a kernel waits for
    the GIL until the loop thread is made to drop it, after the interpreter's switch
    interval (5 ms by default: up to 5 ms after each of the receiver's ~100 kernel calls per
    second of file, which would put the loop's work back on the receiver's path). The
    switch interval is :attr:`switch_interval_s` while the thread runs, restored by
    :meth:`join` / :meth:`abort` when no other loop thread of the process is running (runs
    in threads of one process, e.g. a study's workers, share the interpreter's setting).

    Parameters
    ----------
    loop : IntegrationLoop
    source : MeasurementSource

    Attributes
    ----------
    cpu_s : float
        CPU time of the loop thread [s] (user + system), set when it ends.
    """

    #: Interpreter switch interval while the loop thread runs [s].
    switch_interval_s = 2e-4
    _lock = threading.Lock()
    _running = 0                 # loop threads of the process
    _saved_switch = 0.005        # the interval before the first of them

    def __init__(self, loop: IntegrationLoop, source: MeasurementSource) -> None:
        self.loop, self.source = loop, source
        self.error: BaseException | None = None
        self.cpu_s = 0.0
        self._restored = False
        with BackgroundLoop._lock:
            if BackgroundLoop._running == 0:
                BackgroundLoop._saved_switch = sys.getswitchinterval()
                sys.setswitchinterval(min(BackgroundLoop._saved_switch,
                                          self.switch_interval_s))
            BackgroundLoop._running += 1
        self._thread = threading.Thread(target=self._run, name="sdr-di integration loop",
                                        daemon=True)
        self._thread.start()

    def _restore_switch(self) -> None:
        with BackgroundLoop._lock:
            if self._restored:
                return
            self._restored = True
            BackgroundLoop._running -= 1
            if BackgroundLoop._running == 0:
                sys.setswitchinterval(BackgroundLoop._saved_switch)

    def _run(self) -> None:
        c0 = time.thread_time()
        try:
            self.loop.run(self.source)
        except BaseException as e:  # noqa: BLE001 - re-raised on the caller's thread
            self.error = e
        finally:
            self.cpu_s = time.thread_time() - c0

    def join(self) -> None:
        """Wait for the loop to end; re-raise its exception here."""
        self._thread.join()
        self._restore_switch()
        if self.error is not None:
            raise self.error

    def abort(self) -> None:
        """End the loop after its current interval and wait for it (the caller failed; the
        loop's own exception, if any, is dropped). The source must not be left waiting:
        close its epoch stream first."""
        self.loop.stop_requested = True
        self._thread.join()
        self._restore_switch()
