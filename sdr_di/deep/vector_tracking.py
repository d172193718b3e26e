"""Deep mode's measurement source: vector tracking of every handed-over channel.

:class:`VectorTracking` is the :class:`~sdr_di.integration.loop.MeasurementSource` of the
deep receiver (:class:`~sdr_di.integration.receiver.IntegratedReceiver`) in the mode-independent
:class:`~sdr_di.integration.loop.IntegrationLoop`. Per filter interval it commands every
channel's code and carrier NCOs from the propagated INS and clock, correlates, runs the
pre-filters and the channel management, and forms ``z`` and ``R`` (paper 004 eq 7-9, 34);
after the filter update it takes its share of the closed-loop feedback (NCO ranges and
pre-filters) and takes up navigation data decoded meanwhile (a new ephemeris or ionosphere
model moves the state, the NCOs and the pre-filters together).

The decisions it implements (coherent pre-filter blocks, channel management and its
thresholds, navigation data) are the notes of :mod:`sdr_di.integration.receiver`, called
*module notes* below.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numba
import numpy as np

from ..constants import C_LIGHT, CHIP_RATE_B3I, CODE_LENGTH_B3I, LAMBDA_B3I
from ..coupling.config import IntegrationConfig
from ..coupling.interval import Interval, LoopState, Measurements
from ..coupling.measurements import RangeRateMeasurementModel
from ..errors import SdrDiError
from ..filters.state import CLOCK_BIAS, POS, layout_of_options
from ..frames import llh_to_ecef
from ..receiver.correlator import (  # the kernel: receiver._numba_correlate_bits
    CODE_PAD,
    bit_windows,
    carrier_rotation,
    correlate_epl_bits,
    padded_replicas,
    reduce_code_phase,
)
from ..receiver.ifreader import IfSource
from ..receiver.lock import noise_code_phases, noise_samples
from ..receiver.navdata import NavDataInForce
from ..receiver.observables import ReceiverTime
from ..receiver.scalar import ScalarReceiver
from ..receiver.threads import KernelThreads, RowsCall
from ..signal.codes import NH20, b3i_code
from ._numba_epoch_rows import epoch_rows
from .channel_tests import FAST_MS, ChannelTests
from .navdecode import ChannelNavDecoder
from .nco import nco_commands, predict_ranges
from .pass_epochs import PassEpochs, pass_epochs
from .architectures import block_ms, make_measurement_bank

__all__ = ["SampleClock", "VectorChannel", "VectorTracking"]

_SIGMA_F_MIN = 0.5   # floor of a restarted pre-filter's frequency sigma [Hz]
_SIGMA_TAU_MIN = 0.01  # floor of a reset pre-filter's code prior sigma [chips] (0.3 m)


@dataclasses.dataclass
class VectorChannel:
    """Vector-loop state of one handed-over channel."""

    prn: int
    idx: int
    is_d1: bool
    eph: object
    next_start: int          # first sample of the next code epoch
    epoch: int               # its number (ms since S0)
    phase: float             # carrier NCO phase at next_start [cycles]
    bit_ms: int = 20         # data bit [ms]: D1 20, D2 2
    cn0_dbhz: float = math.nan
    used: bool = True
    f_scalar: float = 0.0    # scalar loop Doppler at the hand-over [Hz]
    rejoining: bool = False  # lost: waits for a whole window of fresh prompts
    fast_fail: int = 0       # last tests: 0 pass, 1 fast test failed, 2 loss test too
    nav: ChannelNavDecoder | None = None   # navigation message after the hand-over


@dataclasses.dataclass(frozen=True)
class SampleClock:
    """Receiver time of IF samples: ``sow(k) = S0 + t_rel(k)`` [s of BDT week ``week``].

    ``S0`` is the whole second before the receiver time of the reference sample ``k0`` (kept
    apart so that ``t_rel``, a few hundred seconds, keeps its sub-nanosecond resolution).
    """

    week: int
    S0: float
    base_rel: float
    k0: float
    fs: float

    @classmethod
    def of(cls, rt: ReceiverTime, fs: float) -> SampleClock:
        S0 = math.floor(rt.sow0) - 1.0
        return cls(week=int(rt.week0), S0=S0, base_rel=rt.sow0 - S0, k0=rt.k0, fs=fs)

    def t_rel(self, k) -> float:
        """Receiver time of sample ``k`` minus ``S0`` [s]."""
        return self.base_rel + (k - self.k0) / self.fs

    def sow(self, k) -> float:
        """Receiver time of sample ``k`` [s of week]."""
        return self.S0 + self.t_rel(k)


@dataclasses.dataclass
class _EpochRows:
    """Correlator rows of one interval, all channels (one row per code epoch)."""

    reps: list               # rows of each channel
    starts: np.ndarray       # first sample of each epoch
    nsamp: np.ndarray        # samples of each epoch
    theta: np.ndarray        # code NCO phase at the start [chips]
    phi: np.ndarray          # carrier NCO phase at the start [cycles]
    dphi: np.ndarray         # carrier NCO frequency [cycles/sample]
    nh: np.ndarray           # NH20 sign (D1) or 1
    epoch: np.ndarray        # epoch number (ms since S0 on the satellite clock)
    dchip: np.ndarray        # code NCO rate of each channel [chips/sample]
    n_noise: np.ndarray | None = None   # samples of each noise row (set by correlate)


class VectorTracking:
    """Deep mode's measurement source of the :class:`~sdr_di.integration.loop.
    IntegrationLoop`: the vector tracking loop of every handed-over channel.

    One interval, :meth:`measure`::

        command_ncos       predicted ranges at k1 from the propagated INS and clock, code and
                           carrier NCO commands, correlator rows of every channel's epochs
        load_samples       the IF samples the rows need (False: the file ends)
        correlate          E/P/L of every epoch of every channel (one numba kernel call);
                           meanwhile, on this thread, the filter's predict and the
                           channels the kernel's leading part has correlated
        prefilter          the channels in their order (:class:`_ChannelPass`): NH
                           wipe-off, noise sums, C/N0 tests (one kernel call for the
                           pass's channels, :class:`~sdr_di.deep.channel_tests.
                           ChannelTests`), navigation decoding, pre-filters (one kernel
                           call), measurement-vector gate (:meth:`_usable`) -> z, R
                           (eq 7-9, 34)

    then :meth:`feed_back` (NCO ranges and pre-filters moved by the filter's correction,
    lost or inconsistent pre-filters restarted) and :meth:`take_up_navigation_data`.

    Parameters
    ----------
    cfg : IntegrationConfig
    source : IfSource
    chans : list of VectorChannel
        Handed-over channels (:func:`~sdr_di.integration.handover.handover_channels`).
    navdata : NavDataInForce
    clock : SampleClock
    stop : int
        IF sample at which the data ends.
    profile : dict
        Seconds per stage (``nco``, ``read``, ``correlate``, ``prefilter``; the navigation
        take-up is charged to ``ins`` with the feedback).
    handover : (t_s, week, sow)
        Hand-over time [s since file start] and BDT of the fix.
    spacing_chips : float
        Early-late spacing of the scalar receiver's correlators [chips].
    """

    def __init__(self, cfg: IntegrationConfig, source: IfSource, chans: list,
                 navdata: NavDataInForce, clock: SampleClock, stop: int, profile: dict, *,
                 handover: tuple, spacing_chips: float) -> None:
        self.cfg, self.source, self.chans, self.clock = cfg, source, chans, clock
        self.fs = source.sampling_rate_hz
        #: Samples of each epoch's noise correlator (:func:`~sdr_di.receiver.lock.
        #: noise_samples`, as the scalar channels').
        self.n_noise = noise_samples(self.fs)
        self.stop, self.profile = stop, profile
        self.n_channels = len(chans)
        self.iono = navdata.klobuchar
        self.ephs = [c.eph for c in chans]
        self.nav_log = _NavLog(navdata, chans, self.iono, *handover)
        self.pre = make_measurement_bank(cfg.deep_measurements, self.n_channels,
                                         spacing_chips, source.carrier_hz, cfg.imu,
                                         cfg.prefilter)
        # fusions: every fusion_every-th interval's outputs go to the filter (then the
        # pre-filters are decorrelated or, "reset", restarted); fusing: this interval's
        self.fusion_every = cfg.fusion_intervals
        self.block_ms = block_ms(cfg.deep_measurements, cfg.coherent_ms, cfg.filter_rate_hz,
                                 self.fusion_every)
        self.n_measured = 0
        self.fusing = True
        # the channels' bit sums, noise rings and tests (the state of the C/N0 tests as
        # arrays over the channels: channel_tests notes); the C/N0, rejoining and last test
        # of each channel are kept here for the kernel and copied to its VectorChannel
        # after each of its passes (prefilter), which the gate and the outputs read
        self.bit_ms = [c.bit_ms for c in chans]
        self.tests = ChannelTests(self.bit_ms, cfg.cn0_window_ms, self.fs,
                                  cfg.cn0_min_dbhz - cfg.fast_margin_db,
                                  cfg.cn0_min_dbhz - cfg.loss_margin_db)
        self.nav_ms0 = [c.nav.ms0 if c.nav is not None else 0 for c in chans]
        self.cn0 = np.array([c.cn0_dbhz for c in chans], np.float64)
        self.rejoining = np.array([c.rejoining for c in chans], bool)
        self.fast_fail = np.array([c.fast_fail for c in chans], np.int64)
        self.bits = bit_windows(np.stack([padded_replicas(np.asarray(b3i_code(c.prn)))[0]
                                          for c in chans]))
        self.chan_idx = np.arange(self.n_channels, dtype=np.int64)
        self.chan_order = np.array([c.idx for c in chans], np.int64)
        self.is_d1 = np.array([c.is_d1 for c in chans], bool)
        self.nh20 = NH20.astype(np.float64)
        self.kthreads = KernelThreads()
        self.threads_before = numba.get_num_threads()
        # every channel: the feedback's H (as many columns as the filter's states)
        self.meas_all = RangeRateMeasurementModel(
            n_states=layout_of_options(cfg.filter_options).n)
        # sample buffer
        self.x_buf = np.empty(0, dtype=np.int8)
        self.n_comp = 2
        self.buf0 = self.buf1 = 0
        self.npow = 1.0
        self.chunk = max(4 * round(self.fs * 1e-3), round(cfg.chunk_ms * 1e-3 * self.fs))
        # NCO state: predicted ranges at k0 after the feedback, last carrier NCO step
        self.P_k0 = self.Pc_k0 = self.tau_prev = None
        self.dp_prev = None
        self._first = True
        self._pred = self._P1 = self._Pc1 = None
        # NCOs one interval ahead (launch): the launched interval, and the pre-filter step
        # (code [chips], frequency [Hz] per channel) to take after its correlations
        self._launched: tuple | None = None
        self._shift_end: tuple | None = None

    # ------------------------------------------------------------------------------------
    def start(self, rx: ScalarReceiver, ins, clock_bias_m: float, k_start: int) -> None:
        """Predicted ranges at the loop's first sample ``k_start`` and every pre-filter from
        its scalar loop: code offset of the scalar loop from the INS prediction, 3 Hz
        frequency sigma (its Doppler is taken against the first NCO command)."""
        clock, ephs, iono, pre = self.clock, self.ephs, self.iono, self.pre
        week = clock.week
        r0 = llh_to_ecef(*ins.llh)
        pred0 = predict_ranges(ephs, week, [clock.sow(k_start)], [r0], [clock_bias_m], iono)
        self.P_k0, self.Pc_k0 = pred0.P[:, 0].copy(), pred0.Pc[:, 0].copy()
        for c in self.chans:
            sc = rx.channels[c.prn]
            s = c.next_start
            pr = predict_ranges([c.eph], week, [clock.sow(s)], [r0], [clock_bias_m], iono)
            chips_deep = CHIP_RATE_B3I * (clock.t_rel(s) - pr.P[0, 0] / C_LIGHT)
            dtau = c.epoch * CODE_LENGTH_B3I + float(sc.theta) - chips_deep
            pre.reset(c.idx, dtau=dtau, df=0.0, sigma_tau=0.1, sigma_phi=0.3, sigma_f=3.0)
            c.f_scalar = float(sc.fd)
            self.tests.take_noise(c.idx, sc.noise)
        self.tau_prev = pred0.tau

    def close(self) -> None:
        """Give numba back the thread count it had before the loop."""
        numba.set_num_threads(self.threads_before)

    # ------------------------------------------------------------------------------------
    def measure(self, loop: LoopState, iv: Interval) -> Measurements | None:
        """NCO commands, correlation and pre-filters of interval ``iv`` (class notes)."""
        rows = self.command_ncos(iv)
        if not self.load_samples(rows):
            return None
        self.n_measured += 1
        self.fusing = self.n_measured % self.fusion_every == 0
        pf = _ChannelPass(self, iv, rows, self._pred)

        def before(epochs_done: int, epl: np.ndarray) -> None:
            # the filter's predict does not need this interval's correlations, and a channel
            # needs only its own: both run on this thread while the kernel's worker thread
            # correlates the rest (receiver.threads notes)
            loop.predict_filter(iv)
            pf.run(epochs_done, epl)
        epl, _ = self.correlate(rows, before=before)
        pf.run(rows.starts.size, epl)
        return pf.measurements()

    def launch(self, loop: LoopState, iv: Interval, work=None) -> bool:
        """NCO commands and correlation of interval ``iv`` with the NCOs one interval ahead
        (``nco_latency = 1``, :meth:`~sdr_di.integration.loop.IntegrationLoop.run_ahead`):
        ``work()``, the previous interval's pre-filters, filter update and feedback, runs on
        this thread while the kernel's worker correlates (it needs none of these rows).
        The rows and their outputs wait for :meth:`measure_launched`. False (``work`` not
        run) when the IF data ends inside the interval."""
        rows = self.command_ncos(iv)
        if not self.load_samples(rows):
            return False
        pred = self._pred
        epl, pending = self.correlate(
            rows, before=None if work is None else (lambda done, epl: work()), detach=True)
        self._launched = (iv, rows, pred, epl, pending)
        return True

    def measure_launched(self, loop: LoopState, iv: Interval) -> Measurements:
        """Pre-filters and measurements of the launched interval ``iv`` (:meth:`launch`).
        Each pre-filter is first moved by the NCO step at the interval's end, which the
        feedback of the filter's prediction to ``k1`` made while the interval was being
        correlated (:meth:`feed_back_ahead`), so that ``z`` refers to the corrected INS."""
        iv_l, rows, pred, epl, pending = self._launched
        if iv_l is not iv:
            raise RuntimeError("measure_launched: interval was not the one launched")
        tw = time.perf_counter()
        pending.wait()               # the kernel worker's part of the rows (correlate)
        self.profile["correlate"] += time.perf_counter() - tw
        pf = _ChannelPass(self, iv, rows, pred)
        pf.run(rows.starts.size, epl)
        self._shift_end = None
        return pf.measurements()

    def command_ncos(self, iv: Interval) -> _EpochRows:
        """Code and carrier NCO commands over ``[k0, k1)`` and the correlator rows.

        Ranges at ``k1`` are predicted from the propagated INS and clock (``iv.nav1``,
        ``iv.clock_bias_m``; :func:`~sdr_di.deep.nco.predict_ranges`); at ``k0`` they are the
        previous interval's, moved by its feedback (``pred_new = pred_old - H x``). On the
        first interval each pre-filter's frequency starts at the scalar loop's Doppler minus
        the INS prediction.
        """
        tb = time.perf_counter()
        clock, fs, k0, k1 = self.clock, self.fs, iv.k0, iv.k1
        r_b = llh_to_ecef(*iv.nav1.llh)
        pred = predict_ranges(self.ephs, clock.week, [clock.sow(k1)], [r_b],
                              [iv.clock_bias_m], self.iono, tau0=self.tau_prev, passes=1)
        self.tau_prev = pred.tau
        P1, Pc1 = pred.P[:, 0], pred.Pc[:, 0]
        cmd = nco_commands(self.P_k0, self.Pc_k0, P1, Pc1, k0, k1, fs, clock.t_rel(k0),
                           clock.t_rel(k1), self.source.carrier_hz)
        dchip = cmd.code_rate_cps / fs
        if self._first:
            for c in self.chans:
                # initial frequency error: scalar loop Doppler minus the INS prediction
                self.pre.set_frequency(c.idx, c.f_scalar - float(cmd.doppler_hz[c.idx]))
            self._first = False
        dp1 = (self.source.if_hz + cmd.doppler_hz) / fs
        if self.dp_prev is None:
            self.dp_prev = dp1
        dp_prev = self.dp_prev
        # every channel's rows in one kernel call (_epoch_rows is its plain form)
        chans, idx = self.chans, self.chan_order
        nxt = np.array([c.next_start for c in chans], np.int64)
        ep = np.array([c.epoch for c in chans], np.int64)
        ph = np.array([c.phase for c in chans], np.float64)
        reps, *cols = epoch_rows(nxt, ep, ph, cmd.chips0[idx], dchip[idx], dp_prev[idx],
                                 dp1[idx], self.is_d1, self.nh20, CODE_LENGTH_B3I, k0, k1)
        for c, s, e, p in zip(chans, nxt.tolist(), ep.tolist(), ph.tolist()):
            c.next_start, c.epoch, c.phase = s, e, p
        self.dp_prev = dp1
        self._pred, self._P1, self._Pc1 = pred, P1, Pc1
        rows = _EpochRows(reps=reps.tolist(), starts=cols[0], nsamp=cols[1], theta=cols[2],
                          phi=cols[3], dphi=cols[4], nh=cols[5], epoch=cols[6], dchip=dchip)
        self.profile["nco"] += time.perf_counter() - tb
        return rows

    def load_samples(self, rows: _EpochRows) -> bool:
        """Read the stored IF samples the rows need (a chunk at a time); False when they run
        past the end of the data."""
        tc = time.perf_counter()
        need0 = int(rows.starts.min())
        need1 = int((rows.starts + rows.nsamp).max())
        if need1 > self.stop:
            return False
        if need0 < self.buf0 or need1 > self.buf1:
            n_read = min(max(self.chunk, need1 - need0), self.stop - need0)
            self.x_buf, self.n_comp, self.npow = self.source.read_stored_power(need0, n_read)
            self.buf0, self.buf1 = need0, need0 + n_read
        self.profile["read"] += time.perf_counter() - tc
        return True

    def correlate(self, rows: _EpochRows, before=None,
                  detach: bool = False) -> tuple[np.ndarray, RowsCall]:
        """Early, prompt, late of every epoch of every channel: one call of the receiver's
        kernel on the stored samples (bit-window replicas, one rotation row per epoch).
        The same call runs each epoch's noise correlator (its first :attr:`n_noise`
        samples, far from the prompt's code phase: :mod:`~sdr_di.receiver.lock` notes).
        Returns ``(epl, pending)``: ``epl`` complex (2 n_epochs, 3), E, P, L of epoch ``e``
        in row ``2 e``, of its noise correlator in row ``2 e + 1`` (NH code not wiped off:
        :class:`_ChannelPass` does), and the kernel call (its rows final on return unless
        ``detach``). ``before(epochs_done, epl)``: work for this thread while the kernel's
        worker ends its part, when the rows of the first ``epochs_done`` epochs are final
        (:meth:`~sdr_di.receiver.threads.KernelThreads.run_rows`; its time is not counted
        here). ``detach``: return as soon as this thread's part and ``before`` are done,
        the kernel worker's part left running until ``pending.wait()``
        (:meth:`~sdr_di.receiver.threads.KernelThreads.start_rows`: the NCOs one interval
        ahead, :meth:`launch`)."""
        td = time.perf_counter()
        t_before = [0.0]

        def timed_before(rows_done: int) -> None:
            tb = time.perf_counter()
            before(rows_done // 2, epl)
            t_before[0] += time.perf_counter() - tb
        n_rows = rows.starts.size
        th = reduce_code_phase(rows.theta, CODE_LENGTH_B3I)
        n_noise = rows.n_noise = np.minimum(rows.nsamp, self.n_noise)
        th_noise = noise_code_phases(th, rows.epoch)

        def pair(a, b=None):
            # each epoch's noise row right after it: the kernel's threads take contiguous
            # parts of the rows, which then hold equal work
            out = np.empty(2 * a.size, a.dtype)
            out[0::2] = a
            out[1::2] = a if b is None else b
            return out

        nsamp = pair(rows.nsamp, n_noise)
        out = np.empty((2 * n_rows, 3, 2))
        epl = out.view(np.complex128)[..., 0]    # (re, im) pairs: complex E, P, L rows
        x, n_comp, bits, spacing = self.x_buf, self.n_comp, self.bits, self.pre.spacing
        tab, start = pair(np.repeat(self.chan_idx, rows.reps)), pair(rows.starts - self.buf0)
        theta, dchip = pair(th, th_noise), pair(np.repeat(rows.dchip, rows.reps))
        phi, dphi = pair(rows.phi), pair(rows.dphi)
        rot_idx = pair(np.arange(n_rows, dtype=np.int64))

        def rows_ab(a, b):
            # one task per row (n_sub = 1): a row's sums are the same on any thread; the
            # carrier rotation tables of the part's epochs are made here, on its thread
            # (elementwise: the same values as made all at once)
            e0 = a // 2
            rot_re, rot_im = carrier_rotation(rows.dphi[e0:(b + 1) // 2])
            correlate_epl_bits(x, n_comp, bits, tab[a:b], CODE_PAD, CODE_LENGTH_B3I,
                               start[a:b], nsamp[a:b], theta[a:b], dchip[a:b], phi[a:b],
                               dphi[a:b], rot_re, rot_im, rot_idx[a:b] - e0, spacing, 1,
                               out[a:b])

        pending = self.kthreads.start_rows(rows_ab, nsamp,
                                           None if before is None else timed_before,
                                           detach=detach)
        if not detach:
            pending.wait()
        self.profile["correlate"] += time.perf_counter() - td - t_before[0]
        return epl, pending

    def prefilter(self, iv: Interval, ch0: int, counts: list, pe: PassEpochs,
                  nsamp: np.ndarray) -> list[bool]:
        """Channels ``ch0, ch0 + 1, ...`` of a pass, with ``counts[k]`` epochs each,
        consecutive in the arrays (``pe``: their outputs, :func:`~sdr_di.deep.pass_epochs.
        pass_epochs`; ``nsamp`` their sample counts): channel management (module notes; C/N0
        tests of every channel in one call, :meth:`~sdr_di.deep.channel_tests.ChannelTests.
        run`), navigation decoding, then the pre-filters over the coherent blocks (one
        call). Returns each channel's measurement-vector gate (:meth:`_usable`)."""
        self.tests.run(ch0, counts, pe.P, nsamp, pe.bit_start, pe.noise, pe.ok, self.npow,
                       self.cn0, self.rejoining, self.fast_fail)
        t_s = iv.k1 / self.fs
        new, tested = self.tests.new, self.tests.count_tested
        chans = self.chans[ch0:ch0 + len(counts)]
        nav_bits, nav_sums = pe.nav_bits.tolist(), pe.nav_sums.tolist()
        nb = pe.nav_bounds.tolist()
        cn0_lin = []
        for k, (c, cnt) in enumerate(zip(chans, counts)):
            i = c.idx
            cn0 = float(self.cn0[i])
            if cnt:
                c.cn0_dbhz = cn0
                c.fast_fail, c.rejoining = int(self.fast_fail[i]), bool(self.rejoining[i])
                self.nav_log.demodulate(c, nav_bits[nb[k]:nb[k + 1]], nav_sums[nb[k]:nb[k + 1]])
                if new[i] and c.nav is not None:
                    if c.fast_fail:
                        c.nav.interrupt()  # no subframe from bits of a failing interval
                    elif tested[i] >= FAST_MS // c.bit_ms:
                        self.nav_log.confirm(c, FAST_MS // c.bit_ms, t_s)  # subframes before it
            cn0_lin.append(10.0 ** (cn0 / 10.0) if math.isfinite(cn0) else 100.0)
        self.pre.process_channels(ch0, counts, pe.blocks[4], *pe.blocks[:4], cn0_lin)
        good = []
        for c, cnt in zip(chans, counts):
            if self._shift_end is not None:
                # NCOs one interval ahead: the step of the feedback made during the interval
                self._shift_prefilters(*self._shift_end, (c.idx,))
            c.used = self._usable(c, cnt)
            good.append(c.used)
        return good

    def _usable(self, c: VectorChannel, n_epochs: int) -> bool:
        """Measurement-vector gate of channel ``c`` (module notes): C/N0 at least the gate
        (less the hysteresis while in the vector), epochs this interval, fast test passed,
        pre-filter NIS consistent."""
        cfg = self.cfg
        gate = cfg.cn0_min_dbhz - (cfg.cn0_hysteresis_db if c.used else 0.0)
        return (math.isfinite(c.cn0_dbhz) and c.cn0_dbhz >= gate
                and n_epochs > 0 and c.fast_fail == 0
                and not self.pre.nis_p[c.idx] < cfg.nis_p_min)

    # ------------------------------------------------------------------------------------
    def feed_back(self, loop: LoopState, iv: Interval, x: np.ndarray) -> None:
        """The correction ``x`` on the NCOs and the pre-filters: ranges at the next ``k0``
        are ``P1 - H x``, each pre-filter shifted by the projection of ``x`` on its line
        of sight (its NCOs move by it), then decorrelated, or restarted from the NCO when
        lost or inconsistent (frequency prior: the filter's rate sigma on that line of
        sight, at least ``_SIGMA_F_MIN``)."""
        self._shift_prefilters(*self._move_ncos(iv.nav1.llh, self._pred, x))
        self.restart_prefilters(loop)

    def _move_ncos(self, llh, pred, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """NCO ranges at the next ``k0``: the last command's ranges at ``k1`` moved by the
        correction ``x`` (``P1 - H x``, geometry of ``pred`` at ``llh``). Returns the
        pre-filters' step, what their NCOs move (:meth:`_shift_prefilters`)."""
        n_ch = self.n_channels
        self.meas_all.set_geometry(llh, pred.U[:, 0])
        Hx = self.meas_all.matrix @ x
        self.P_k0 = self._P1 - Hx[:n_ch]
        self.Pc_k0 = self._Pc1 - Hx[:n_ch]
        return CHIP_RATE_B3I / C_LIGHT * Hx[:n_ch], Hx[n_ch:] / LAMBDA_B3I

    def _shift_prefilters(self, d_tau: np.ndarray, d_f: np.ndarray, channels=None) -> None:
        """Move pre-filters (default all) by their NCOs' step: ``d_tau`` [chips], ``d_f``
        [Hz] per channel (:meth:`~sdr_di.deep.prefilter.PreFilterBank.shift`)."""
        for i in range(self.n_channels) if channels is None else channels:
            self.pre.shift(i, d_tau[i], d_f[i])

    def restart_prefilters(self, loop: LoopState) -> None:
        """Each pre-filter after the filter update: restarted from its NCO when lost or
        inconsistent (frequency prior: the filter's rate sigma on that line of sight, at
        least ``_SIGMA_F_MIN``; geometry of the last :meth:`_move_ncos` or
        :meth:`geometry_of`), else decorrelated."""
        n_ch, pre, cfg = self.n_channels, self.pre, self.cfg
        Hr = self.meas_all.matrix[n_ch:]
        sig_f = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Hr, loop.kf.P, Hr), 0.0)) / LAMBDA_B3I
        sig_tau = None
        if pre.takes_prior and self.fusing:
            # information reset: the filter's range and rate sigmas as the window's prior
            Hc = self.meas_all.matrix[:n_ch]
            sig_tau = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Hc, loop.kf.P, Hc),
                                         0.0)) * CHIP_RATE_B3I / C_LIGHT
        for c in self.chans:
            i = c.idx
            if c.fast_fail >= 2 or pre.nis_p[i] < cfg.nis_p_min:
                # lost, or inconsistent: restart from the NCO (INS) with the integration
                # filter's rate uncertainty as the frequency prior
                pre.reset(i, sigma_phi=1.0, sigma_f=max(float(sig_f[i]), _SIGMA_F_MIN))
            elif self.fusing:
                pre.decorrelate(i) if sig_tau is None else pre.decorrelate(
                    i, prior=(max(float(sig_tau[i]), _SIGMA_TAU_MIN),
                              max(float(sig_f[i]), _SIGMA_F_MIN)))

    def geometry_of(self, iv: Interval) -> None:
        """Lines of sight of launched interval ``iv`` for :meth:`restart_prefilters`."""
        iv_l, _, pred, _, _ = self._launched
        self.meas_all.set_geometry(iv.nav1.llh, pred.U[:, 0])

    def feed_back_ahead(self, loop: LoopState, iv: Interval, x: np.ndarray) -> None:
        """NCOs one interval ahead: the correction ``x`` the loop fed back at the end of
        the launched interval ``iv`` (the filter's prediction to ``iv.k1``) moves the NCO
        ranges of the next command (``P1 - H x``); the pre-filters take the same step after
        the launched interval's correlations (:meth:`measure_launched`)."""
        self._shift_end = self._move_ncos(iv.nav1.llh, self._pred, x)

    def take_up_navigation_data(self, loop: LoopState, iv: Interval) -> None:
        """Navigation data decoded so far, taken up at the interval's end
        (:func:`_take_up_model_change`): INS position, clock, NCO ranges and pre-filters
        move with the range model."""
        tg = time.perf_counter()
        clock, chans, k1 = self.clock, self.chans, iv.k1
        new_ephs, new_iono = self.nav_log.changes(
            chans, clock.week, clock.sow(k1) - loop.clock_bias_m / C_LIGHT)
        if new_ephs is not None or new_iono is not self.iono:
            step = _take_up_model_change(
                self.ephs, new_ephs or self.ephs, self.iono, new_iono, clock.week,
                clock.sow(k1), loop.ins, loop.clock_bias_m, self.tau_prev,
                np.array([c.used for c in chans]), self.meas_all, loop.kf)
            if self._launched is None:
                self._shift_prefilters(step.d_tau, step.d_f)
            else:
                # NCOs one interval ahead: the launched interval's NCOs ran on the old model;
                # its pre-filters take the step after its correlations (measure_launched)
                self._shift_end = (self._shift_end[0] + step.d_tau,
                                   self._shift_end[1] + step.d_f)
            self.P_k0 = self.P_k0 + step.dP - step.Hx_rho
            self.Pc_k0 = self.Pc_k0 + step.dPc - step.Hx_rho
            loop.clock_bias_m = step.clock_bias_m
            self.nav_log.taken_up(k1 / self.fs, chans, new_ephs, self.iono, new_iono, step)
            self.ephs = [c.eph for c in chans]
            self.iono = new_iono
        self.profile["ins"] += time.perf_counter() - tg

    def row(self) -> dict:
        """Channel columns of a solution row: C/N0 [dB-Hz] and the navigation data taken up
        since the previous row (``IntegrationResult.nav_change``)."""
        out = {"cn0": [c.cn0_dbhz for c in self.chans], "nav": self.nav_log.flag}
        self.nav_log.flag = 0
        return out


class _ChannelPass:
    """The per-channel work of one interval after the correlation
    (:meth:`VectorTracking.prefilter`), channel after channel in their order, and the
    measurements it gives: ``z = [c/f_code dtau_i, lambda df_i]`` and ``R`` from the
    pre-filter variances of the channels in the vector (paper 004 eq 7-9, 34).

    :meth:`run` takes the channels whose epochs are all correlated: first those of the
    kernel call's leading part, while its worker correlates the rest, then the others."""

    def __init__(self, vt: VectorTracking, iv: Interval, rows: _EpochRows, pred) -> None:
        self.vt, self.iv, self.rows, self.pred = vt, iv, rows, pred
        self.next = 0                     # next channel
        self.a = 0                        # its first epoch
        self.z_rho: list = []
        self.z_rate: list = []
        self.r_rho: list = []
        self.r_rate: list = []
        self.use: list = []

    def run(self, epochs_done: int, epl: np.ndarray) -> None:
        """The channels not yet taken whose epochs are all among the first
        ``epochs_done`` of ``epl`` (:meth:`VectorTracking.correlate`)."""
        te = time.perf_counter()
        vt, rows, reps = self.vt, self.rows, self.rows.reps
        j, a0, a1 = self.next, self.a, self.a
        while j < vt.n_channels and a1 + reps[j] <= epochs_done:
            a1 += reps[j]
            j += 1
        if j > self.next:
            # the outputs of these channels' epochs made ready at once (NH wiped off, noise
            # values, coherent blocks, bit sums: pass_epochs), then their tests, decoders
            # and pre-filters (prefilter)
            ch0 = self.next
            chans, counts = vt.chans[ch0:j], reps[ch0:j]
            pe = pass_epochs(epl, a0, a1, rows.nh, rows.n_noise, rows.nsamp, rows.epoch, vt.fs,
                             counts, vt.bit_ms[ch0:j], vt.block_ms, vt.nav_ms0[ch0:j])
            good = vt.prefilter(self.iv, ch0, counts, pe, rows.nsamp[a0:a1])
            self.use += good
            if vt.fusing:
                for c, g in zip(chans, good):
                    if g:
                        dtau, df, v_tau, v_f = vt.pre.outputs(c.idx)
                        self.z_rho.append(C_LIGHT / CHIP_RATE_B3I * dtau)
                        self.z_rate.append(LAMBDA_B3I * df)
                        self.r_rho.append((C_LIGHT / CHIP_RATE_B3I) ** 2 * v_tau)
                        self.r_rate.append(LAMBDA_B3I ** 2 * v_f)
            self.next, self.a = j, a1
        vt.profile["prefilter"] += time.perf_counter() - te

    def measurements(self) -> Measurements:
        """``z``, ``R`` and the geometry of the channels in the vector (all channels run)."""
        use = np.asarray(self.use, bool)
        z = R = None
        if self.z_rho:
            z = np.array(self.z_rho + self.z_rate)      # (lists: cheaper than np.r_)
            R = np.diag(np.array(self.r_rho + self.r_rate))
        return Measurements(z=z, R=R, geometry=(self.iv.nav1.llh, self.pred.U[use, 0]),
                            used=use)


@dataclasses.dataclass
class _ModelStep:
    """A change of the range model taken up at one epoch (:func:`_take_up_model_change`)."""

    dP: np.ndarray          # predicted code range change of every channel [m]
    dPc: np.ndarray         # predicted carrier phase-range change [m]
    Hx_rho: np.ndarray      # range change of the state step [m]
    x: np.ndarray           # state step (n,)
    clock_bias_m: float     # clock bias after the step [m]
    d_tau: np.ndarray       # pre-filter step (PreFilterBank.shift): code [chips]
    d_f: np.ndarray         # and frequency [Hz] of each channel


def _take_up_model_change(ephs_old, ephs_new, iono_old, iono_new, week: int, sow_nom: float,
                          ins, clock_bias_m: float, tau, used: np.ndarray, meas_all,
                          kf) -> _ModelStep:
    """Switch the range model (ephemerides, ionosphere) at a clean epoch (module notes).

    The predicted ranges at the epoch move by ``dP`` (new model minus old, same position and
    clock). A filter that ran on the old model has absorbed that step into its position and
    clock as far as the geometry lets it: its estimate sits at ``x_c``, the least-squares
    solution of ``H_rho x = dP`` over the channels in the measurement vector (position and
    clock columns). The INS and the clock are moved by ``x_c`` (the loop's feedback), the
    pre-filters by what the NCOs then move, ``dP - H x_c`` (which removes the misfit the old
    model left in the innovations; returned as ``d_tau``, ``d_f`` for the caller to take),
    and the position/clock covariance grows by ``(x_c / 2)^2`` for the error of that
    projection (the filter's weights are not equal).
    """
    r = llh_to_ecef(*ins.llh)
    old = predict_ranges(ephs_old, week, [sow_nom], [r], [clock_bias_m], iono_old, tau0=tau)
    new = predict_ranges(ephs_new, week, [sow_nom], [r], [clock_bias_m], iono_new, tau0=tau)
    dP = new.P[:, 0] - old.P[:, 0]
    dPc = new.Pc[:, 0] - old.Pc[:, 0]
    n = dP.size
    meas_all.set_geometry(ins.llh, new.U[:, 0])
    H = meas_all.matrix
    x = np.zeros(H.shape[1])
    cols = [POS.start, POS.start + 1, POS.start + 2, CLOCK_BIAS]
    if int(np.count_nonzero(used)) >= 4:
        x[cols] = np.linalg.lstsq(H[:n][used][:, cols], dP[used], rcond=None)[0]
        kf.P[cols, cols] += (0.5 * x[cols]) ** 2
    else:
        kf.P[CLOCK_BIAS, CLOCK_BIAS] += float(np.max(dP ** 2))
    Hx = H @ x
    z3 = np.zeros(3)
    ins.correct(z3, z3, x[POS], z3, z3)
    return _ModelStep(dP=dP, dPc=dPc, Hx_rho=Hx[:n], x=x,
                      clock_bias_m=clock_bias_m - x[CLOCK_BIAS],
                      d_tau=-CHIP_RATE_B3I / C_LIGHT * (dP - Hx[:n]),
                      d_f=Hx[n:] / LAMBDA_B3I)


class _NavLog:
    """Navigation data of the vector loop's channels: decoding, changes, history."""

    def __init__(self, navdata: NavDataInForce, chans: list, iono, t_s: float, week: int,
                 sow: float) -> None:
        self.navdata = navdata
        self.flag = 0        # changes since the last output row (IntegrationResult.nav_change)
        self.ephemerides: dict = {f"C{c.prn:02d}": [] for c in chans}
        self.ionosphere: list = []
        self.steps: list = []
        self._new: list = []
        for c in chans:
            self._eph_entry(t_s, c.prn, c.eph, navdata.select_with_source(c.prn, week, sow)[1])
        self._iono_entry(t_s, iono)

    def demodulate(self, c: VectorChannel, bits: list, sums: list) -> None:
        """Feed channel ``c``'s prompt sums over its bits to its decoder (it holds what it
        decodes; :meth:`~sdr_di.deep.navdecode.ChannelNavDecoder.add_sums`)."""
        c.nav.add_sums(bits, sums)

    def confirm(self, c: VectorChannel, n_bits: int, t_s: float) -> None:
        """Channel ``c``'s test passed on its last ``n_bits`` bit sums: offer what the
        subframes its decoder held until then complete (deep.navdecode notes)."""
        for eph, klob in c.nav.confirm(n_bits):
            if eph is not None:
                self.navdata.offer_ephemeris(eph, t_s)
            self.navdata.offer_klobuchar(klob, t_s)

    def changes(self, chans: list, week: int, sow: float):
        """``(new ephemeris list or None, ionosphere in force)`` at BDT (``week``, ``sow``)."""
        self._new = []
        for c in chans:
            try:
                e, src = self.navdata.select_with_source(c.prn, week, sow)
            except SdrDiError:           # nothing valid any more: keep the last one
                e, src = c.eph, None
            self._new.append((e, src))
        changed = any(e is not c.eph and e != c.eph for c, (e, _) in zip(chans, self._new))
        return ([e for e, _ in self._new] if changed else None), self.navdata.klobuchar

    def taken_up(self, t_s: float, chans: list, new_ephs, iono_old, iono_new,
                 step: _ModelStep) -> None:
        """Record the change :func:`_take_up_model_change` just made; set the channels'
        records."""
        if new_ephs is not None:
            self.flag |= 1
            for c, (e, src) in zip(chans, self._new):
                if e is not c.eph and e != c.eph:
                    self._eph_entry(t_s, c.prn, e, src)
                    c.eph = e
        if iono_new is not iono_old:
            self.flag |= 2
            self._iono_entry(t_s, iono_new)
        self.steps.append({"t_s": round(t_s, 3),
                           "max_range_step_m": float(np.max(np.abs(step.dP))),
                           "clock_step_m": float(step.x[CLOCK_BIAS]),
                           "height_step_m": float(step.x[8])})

    def _eph_entry(self, t_s, prn, e, src) -> None:
        self.ephemerides[f"C{prn:02d}"].append(
            {"t_s": round(t_s, 3), "source": src,
             "week": int(e.week), "toe": float(e.toe), "aode": int(e.AODE)})

    def _iono_entry(self, t_s, iono) -> None:
        src = self.navdata.iono_source if iono is not None else None
        self.ionosphere.append({"t_s": round(t_s, 3), "model": "klobuchar" if src else "none",
                                "source": src})

    def summary(self, t_end_s: float) -> dict:
        """``navigation`` entry of the run summary."""
        models = self.navdata.models()
        return {
            "rule": "decoded broadcast data as it arrives (healthy, new data set, toe within "
                    "its age limit), the assistance (RINEX) record on the air before it",
            "ephemerides": self.ephemerides,
            "ionosphere": {**models["ionosphere"], "history": self.ionosphere},
            "troposphere": models["troposphere"],
            "model_steps": self.steps,
            "decoded_conflicts": self.navdata.n_conflicts,
            "decoded_rejected": self.navdata.n_rejected,
            "end_s": round(t_end_s, 3),
        }


def _epoch_rows(c: VectorChannel, c0: float, dc: float, dp0: float, dp1: float, k0: int, k1: int):
    """Correlator rows of channel ``c``: its code epochs that start in ``[next_start, k1)``.

    The code NCO's chip count is ``c0 + (k - k0) dc`` over the interval; epoch ``e`` ends at
    the first sample where it reaches ``(e + 1) L``. The carrier NCO frequency of each epoch
    [cycles per sample] is ramped linearly in time between ``dp0`` (the previous interval's
    average, placed at its middle ``k0 - N/2``) and ``dp1`` (this interval's average, at
    ``k0 + N/2``), so it follows the Doppler rate of the dynamics (7 m/s^2 in the circling
    phases = 0.6 Hz over a 20 ms interval) while its integral over the interval still equals
    the predicted carrier-phase change; the phase stays continuous. Advances the channel's
    ``next_start``, ``epoch`` and ``phase``.

    Returns ``(starts, n, theta, phi, dphi, nh_sign, epoch)`` arrays (one row per epoch;
    ``epoch`` = ms since S0 on the satellite clock).
    """
    L = CODE_LENGTH_B3I
    s0, e0 = c.next_start, c.epoch
    if s0 >= k1:
        z = np.zeros(0)
        return np.zeros(0, np.int64), np.zeros(0, np.int64), z, z, z, z, np.zeros(0, np.int64)
    # epoch ends: ceil(k0 + ((e + 1) L - c0) / dc) until one reaches k1
    m_max = int((k1 - s0) * dc / L) + 3
    ends = np.ceil(k0 + ((e0 + 1 + np.arange(m_max)) * L - c0) / dc).astype(np.int64)
    starts = np.concatenate(([s0], ends[:-1]))
    ends = np.maximum(ends, starts + 1)
    keep = starts < k1
    starts, ends = starts[keep], ends[keep]
    m = starts.size
    n = ends - starts
    ep = e0 + np.arange(m)
    theta = c0 + (starts - k0) * dc - ep * L
    N = float(k1 - k0)
    dphi = dp0 + (dp1 - dp0) * ((starts + 0.5 * n - k0) / N + 0.5)
    adv = np.cumsum(n * dphi)
    phi = c.phase + np.concatenate(([0.0], adv[:-1]))
    phi -= np.floor(phi)
    end_phase = c.phase + float(adv[-1])
    c.next_start, c.epoch, c.phase = int(ends[-1]), e0 + m, end_phase - math.floor(end_phase)
    nh = NH20[ep % 20].astype(float) if c.is_d1 else np.ones(m)
    return starts, n, theta, phi, dphi, nh, ep
