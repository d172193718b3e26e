"""One scalar tracking channel: NCOs, loops, lock detection, NH/bit/frame sync, decoding.

A :class:`Channel` does not read samples. Its driver (:class:`~sdr_di.receiver.scalar.
ScalarReceiver`) takes the next *block* of correlation intervals (:attr:`Channel.block_rows`:
one row of kernel parameters per code epoch and one per its noise correlator; one epoch
before bit synchronization, then the epochs of one coherent interval), correlates all channels' blocks in one kernel call and
hands each channel its per-epoch early/prompt/late sums (:meth:`Channel.process_block`).
The channel then

1. logs the epoch and keeps the 1 ms prompt in a ring buffer (C/N0, lock, synchronization);
2. updates its loops: every epoch before bit synchronization, then every ``coherent_ms``
   epochs on the NH-wiped sums of an interval aligned with the bit edges;
3. every ``lock_eval_ms``: C/N0 of the last ``cn0_window_ms`` 1 ms prompts (signal power
   ``M2 - P_n`` with the noise power ``P_n`` measured by the receiver on the input samples,
   :attr:`Channel.noise_power_per_sample`, or by the channel's noise correlator where the two
   disagree (interference: :class:`~sdr_di.receiver.lock.PostCorrelationNoise`); M2M4
   moments when neither is available), carrier-lock
   metric, state transitions (``PULL_IN`` -> ``TRACK``, ``TRACK`` -> ``PULL_IN`` or ``LOST``),
   FLL-assist narrowing during pull-in, NH synchronization (D1) or bit synchronization (D2);
4. demodulates bits (D1: sign of the NH-wiped 20 ms sum of prompt I; D2: 2 ms), finds the
   subframe preamble with :func:`~sdr_di.signal.navmsg.find_preamble`, decodes subframes with
   :func:`~sdr_di.signal.navmsg.decode_subframe` (polarity from the preamble) and feeds an
   :class:`~sdr_di.signal.navmsg.EphemerisAssembler` once the lock detector has confirmed
   the signal after the subframe's last bit (below);
5. commits the NCO for the next block (carrier-aided code rate: ``10.23e6 (1 + f_D /
   f_carrier)`` plus the DLL correction) and records every planned epoch (start sample, code
   phase, rates, accumulated phase) in a short history for :meth:`Channel.observation_at`.

NH synchronization (D1): the prompt I values since the carrier locked are cut into 20 ms
blocks at each of the 20 possible offsets and correlated with NH20; the sum over blocks of
``|sum_i I_i NH_i|`` (data-sign insensitive) peaks at the offset of the bit edges (accepted
when it beats the runner-up by ``sync_ratio``, after at least ``nh_sync_bits`` blocks). The NH
code is then wiped (sign of each 1 ms correlation), which also gives bit synchronization
(the NH code restarts at every bit edge). D2 (no NH, 2 ms bits): the sign changes of
prompt I between consecutive milliseconds are counted at the two parities; data transitions
only occur at the true bit edges.

Subframe confirmation: the bits are demodulated until the lock detector declares a loss,
``cn0_window_ms`` plus ``code_unlock_evals`` evaluations after the signal is gone, and D1/D2
words are BCH(15,11) coded, a perfect code that "corrects" every noise word to some
codeword. A subframe whose last bits came after a blockage began would decode cleanly with
wrong fields (count-change experiment: C10's argument of perigee 2.4e-5 rad off, 40 m of
modelled range, in force for the rest of the run). So a decoded subframe sets the time at
once but reaches the assembler (and :attr:`Channel.subframes`) only at the first lock
evaluation whose C/N0 window starts after its last bit and passes the code-lock test
(C/N0 >= ``cn0_lock_dbhz``: a 100 ms window of noise alone passes 28 dB-Hz with a
probability of about 1e-6, the mean of 100 exponential powers reaching 1.63 times the noise). Had the signal gone before that bit, every such evaluation fails until the
loss is declared, which drops the subframe; a weak signal whose estimate dips below the
threshold once only delays it. The ephemeris comes ``cn0_window_ms`` to
``cn0_window_ms + lock_eval_ms`` (0.10-0.12 s) after the subframe's end. At the deep
hand-over the subframes still held move to the vector loop's decoder, which confirms them
with its own test (:meth:`Channel.take_unconfirmed`).

Conventions and the transmit-time definition are in :mod:`~sdr_di.receiver.tracking`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..constants import CHIP_RATE_B3I, CODE_LENGTH_B3I, F_B3I, SECONDS_PER_WEEK
from ..errors import NavMessageError
from ..signal.codes import NH20, nav_type
from ..signal.navmsg import EphemerisAssembler, HeldSubframes, decode_subframe, find_preamble
from ..signal.words import PREAMBLE, SUBFRAME_BITS
from ._numba_channel import plain_epochs, plan_block, prompt_moments
from .correlator import check_prn
from .lock import (
    NOISE_MIN_LAG_CHIPS,
    LockCounter,
    PostCorrelationNoise,
    carrier_lock_metric,
    m2m4_powers,
    noise_code_phase,
    noise_samples,
    prompt_signal_power,
)
from .lock import _NOISE_LAG_STEP
from .loops import CarrierLoop, CodeLoop, costas_atan, dll_nelp, fll_atan
from .tracking import ChannelObservation, ChannelState, TrackingConfig, TrackingLog

__all__ = ["Channel"]

_L = CODE_LENGTH_B3I
_LF = float(CODE_LENGTH_B3I)
_RING = 2048  # prompts kept (>= cn0 window and sync windows)
_HIST = 64  # committed NCO epochs kept for observation_at
_MAX_BLOCK = 20  # epochs of the longest block (TrackingConfig.coherent_ms_d1 <= 20)
_NH = [float(v) for v in NH20]
_NH_ARR = np.asarray(NH20, dtype=np.float64)
_PREAMBLE = [int(b) for b in PREAMBLE]
_PREAMBLE_INV = [1 - b for b in _PREAMBLE]
_WEEK = SECONDS_PER_WEEK
_T_EPOCH = _LF / CHIP_RATE_B3I  # 1 ms


class Channel:
    """Scalar tracking channel of one PRN (module notes).

    Parameters
    ----------
    prn : int
        PRN 1..63 (D1 or D2 from :func:`sdr_di.signal.codes.nav_type`).
    sampling_rate_hz : float
        fs [Hz].
    if_hz : float
        IF of the (corrected) sample stream [Hz].
    config : TrackingConfig, optional
        Loop and detector parameters.
    carrier_hz : float, optional
        RF carrier [Hz] (code-Doppler scaling). Default B3I.
    rx_time : callable, optional
        ``sample -> (week, sow)`` receiver-clock time of a sample (the IF file's start time);
        enables the single-subframe time check and the week before WN is decoded.
    log : bool, optional
        Keep a :class:`~sdr_di.receiver.tracking.TrackingLog`. Default True.
    log_every_ms : int, optional
        Log one epoch in this many. Default 1.

    Attributes
    ----------
    state : ChannelState
    ephemeris, klobuchar
        Latest decoded broadcast record and ionosphere coefficients (None before).
    subframes : list of dict
        Decoded and confirmed subframes (module notes; ``decode_subframe`` dicts plus
        ``epoch``, the code epoch of the subframe start, and ``polarity``), the last 50.
    cn0_dbhz : float
        Latest C/N0 estimate.
    """

    #: Run the per-block and per-epoch bookkeeping in the numba kernels of
    #: :mod:`~sdr_di.receiver._numba_channel` (the same values bit for bit as the plain
    #: Python forms, :meth:`_plan_reference` and :meth:`_epoch`, which ``False`` runs; a
    #: channel with a tracking log always runs those).
    jit = True

    def __init__(self, prn: int, sampling_rate_hz: float, if_hz: float,
                 config: TrackingConfig | None = None, *, carrier_hz: float = F_B3I,
                 rx_time: Callable[[int], tuple[int, float]] | None = None,
                 log: bool = True, log_every_ms: int = 1):
        self.prn = check_prn(prn)
        self.nav = nav_type(self.prn)
        self.is_d1 = self.nav == "D1"
        self.fs = float(sampling_rate_hz)
        #: Samples of each epoch's noise-correlator row (:func:`~sdr_di.receiver.lock.
        #: noise_samples`).
        self.n_noise = noise_samples(self.fs)
        self.if_hz = float(if_hz)
        self.carrier_hz = float(carrier_hz)
        self.cfg = config or TrackingConfig()
        self.rx_time = rx_time
        self.log = TrackingLog(self.prn, self.fs) if log else None
        self.log_every = max(1, int(log_every_ms))
        self.bit_ms = 20 if self.is_d1 else 2
        self.coh_ms = self.cfg.coherent_ms_d1 if self.is_d1 else self.cfg.coherent_ms_d2
        self._state = ChannelState.ACQUIRE
        #: ``(sample, ChannelState)`` of every state change (sample: start of the epoch being
        #: processed, or of the acquisition block).
        self.transitions: list[tuple[int, ChannelState]] = []
        self.next_start = 0
        self.carrier = CarrierLoop(self.cfg.pull_in_pll_bw_hz, self.cfg.pull_in_fll_bw_hz, 0.0)
        self._fll_bw0 = self.cfg.pull_in_fll_bw_hz  # FLL bandwidth at the start of pull-in
        self.code = CodeLoop(self.cfg.pull_in_dll_bw_hz, self.cfg.dll_order)
        self.assembler = EphemerisAssembler(self.prn)
        self.ephemeris = None
        self.klobuchar = None
        self.subframes: list[dict] = []
        self.bit_runs: list[list] = []
        self.cn0_dbhz = math.nan
        self.lock_metric = 0.0
        self.code_lock = False
        self.carrier_lock = False
        self.slip_count = 0
        self.n_acquisitions = 0
        self.lost_at_sample: int | None = None
        self.next_reacq_sample: int | None = None
        self.finished = False
        #: Input noise power per sample (mean |x|^2 of the samples); when set (the receiver
        #: measures it on every chunk) C/N0 uses it, otherwise the M2M4 moments.
        self.noise_power_per_sample: float | None = None
        #: Noise-correlator values (:mod:`~sdr_di.receiver.lock` notes): the C/N0 takes its
        #: noise power from them where they disagree with the input power (interference).
        self.noise = PostCorrelationNoise()
        # NCO (valid once started)
        self.next_start = 0
        self.n_next = 0
        #: correlator rows of the next block (:meth:`_plan`), a view of ``_rows``
        self.block_rows = np.empty((0, 6))
        self._rows = np.zeros((2 * _MAX_BLOCK, 6))
        self._ends = np.zeros((_MAX_BLOCK, 4))  # (next_start, theta, phi, dphase) per epoch
        self.n_block_epochs = 0
        self.block_end = 0
        self.theta = 0.0
        self.code_rate = CHIP_RATE_B3I
        self.fd = 0.0
        self.phi = 0.0  # carrier NCO phase at next_start, in [0, 1)
        self.dphase = 0.0  # accumulated Doppler phase at next_start [cycles]
        self.epoch = 0
        # (start, theta, rate, dphase, fd, epoch, f_est, f_rate, f_mid) of the committed
        # epochs at row epoch % _HIST (epoch NaN: none yet)
        self._hist = np.full((_HIST, 9), np.nan)
        self._ring = np.zeros(_RING, np.complex128)
        self._time: tuple | None = None  # (sf_epoch, sf_sow, sf_week or None)
        self._reset_tracking_state()

    # -- life cycle ------------------------------------------------------------------------
    def _reset_tracking_state(self) -> None:
        self._prev_p: complex | None = None
        self._n_tracked = 0  # epochs since (re)start
        self._eval_count = 0
        self._pull_in_ms = 0
        self._track_since_epoch = 0
        self._pll_ctr = LockCounter(self.cfg.pull_in_lock_evals, self.cfg.carrier_unlock_evals)
        self._code_ctr = LockCounter(1, self.cfg.code_unlock_evals)
        self._bit_off: int | None = None  # epoch index (mod bit_ms) of bit edges
        self._coh = [0j, 0j, 0j, 0]  # E, P, L sums, epochs
        self._bit_acc = 0.0
        self._bit_n = 0
        self._bits: list[int] = []
        self._bits_epoch0 = 0
        self._search_from = 0
        self._frame: dict | None = None  # {'idx', 'pol', 'misses', 'expect'}
        self._candidate: dict | None = None
        self._unconfirmed = HeldSubframes()  # decoded subframes awaiting the lock (notes)
        self._frozen = False
        self.time_valid = False
        self._new_arc()

    def _new_arc(self) -> None:
        """A new carrier-phase arc (the counters are restarted by the caller): the Costas
        half cycle of the arc is unknown again."""
        self._half_cycle = 0.0  # [cycles] added to the reported phase: 0.5 if data inverted
        self._half_known = False

    def _note_polarity(self, pol: int) -> None:
        """A preamble came out with polarity ``pol`` (+1 upright, -1 inverted).

        The arc's half-cycle correction follows the polarity; when it changes the reported
        carrier phase moves by 0.5 cycle, a discontinuity counted in ``slip_count`` (the first
        resolution of an inverted arc, or a half-cycle slip of the Costas loop). The
        correction belongs to the arc, not to the frame synchronization: losing the frame
        (two missing preambles) keeps it.
        """
        corr = 0.5 if pol < 0 else 0.0
        if corr != self._half_cycle:
            self.slip_count += 1
        self._half_cycle = corr
        self._half_known = True

    @property
    def state(self) -> ChannelState:
        """Current :class:`~sdr_di.receiver.tracking.ChannelState`."""
        return self._state

    @state.setter
    def state(self, new: ChannelState) -> None:
        new = ChannelState(new)
        if new != self._state:
            self._state = new
            self.transitions.append((int(self.next_start), new))

    @property
    def tracking(self) -> bool:
        """True in ``PULL_IN`` and ``TRACK`` (the channel is correlated)."""
        return (self.state == ChannelState.PULL_IN or self.state == ChannelState.TRACK) \
            and not self.finished

    @property
    def bit_synced(self) -> bool:
        """NH (D1) / bit (D2) synchronization established."""
        return self._bit_off is not None

    def demodulated_bits(self) -> list[tuple[int, np.ndarray]]:
        """Every demodulated data bit so far, as runs of consecutive bits.

        Returns
        -------
        list of (int, numpy.ndarray)
            ``(epoch, bits)``: code epoch (channel counter) of the leading edge of the first
            bit of the run, and the uint8 0/1 hard decisions (polarity as demodulated: the
            Costas ambiguity is not removed).
        """
        return [(int(e), np.frombuffer(bytes(b), dtype=np.uint8)) for e, b in self.bit_runs]

    def start(self, sample: int, code_phase_chips: float, doppler_hz: float,
              cn0_dbhz: float = math.nan, fll_bw_hz: float | None = None) -> None:
        """Start tracking from an acquisition (code phase at ``sample``).

        The first correlation interval begins at the first code-epoch edge after ``sample``.
        ``fll_bw_hz`` is the pull-in FLL bandwidth to start from [Hz] (default
        ``pull_in_fll_bw_hz``; a long search's Doppler, refined over hundreds of ms, needs only
        the minimum: the receiver passes ``pull_in_fll_min_bw_hz`` then).
        """
        self._reset_tracking_state()
        self._time = None
        self._restart(sample, code_phase_chips, doppler_hz, cn0_dbhz, 0, fll_bw_hz)

    def _restart(self, sample: int, theta0: float, fd: float, cn0: float,
                 epoch_at_sample: int, fll_bw_hz: float | None = None) -> None:
        """Load the NCOs for pull-in. ``epoch_at_sample`` numbers the code epoch in progress
        at ``sample`` (the first correlated epoch is the next one unless ``sample`` is an
        epoch edge)."""
        self.n_acquisitions += 1
        self._fll_bw0 = self.cfg.pull_in_fll_bw_hz if fll_bw_hz is None else float(fll_bw_hz)
        self.carrier.set_bandwidths(self.cfg.pull_in_pll_bw_hz, self._fll_bw0)
        self.carrier.reset(fd)
        self.code.set_bandwidth(self.cfg.pull_in_dll_bw_hz)
        self.code.reset()
        self.cn0_dbhz = float(cn0)
        self.code_lock = True
        self._code_ctr.reset(locked=True)
        self.carrier_lock = False
        self.lost_at_sample = None
        self.next_reacq_sample = None
        self.fd = float(fd)
        self.code_rate = CHIP_RATE_B3I * (1.0 + self.fd / self.carrier_hz)
        dchip = self.code_rate / self.fs
        theta0 = float(theta0) % _LF
        k = 0 if theta0 == 0.0 else math.ceil((_LF - theta0) / dchip)
        self.next_start = int(sample) + k
        self.theta = max(theta0 + k * dchip - _LF, 0.0) if k else theta0
        self.phi = 0.0
        self.dphase = 0.0
        self.epoch = int(epoch_at_sample) + (1 if k else 0)
        self.state = ChannelState.PULL_IN
        self._plan()

    # -- NCO ---------------------------------------------------------------------------------
    def _plan(self) -> None:
        """Fix the NCO of the next block of epochs (one loop update) and record it.

        One epoch until bit synchronization; then up to the next coherent-interval edge
        (``coherent_ms`` epochs aligned with the bit edges; the first block after the sync is
        shorter). The rows of :attr:`block_rows` are the kernel parameters of each epoch:
        ``(start, n, theta, dchip, phi, dphi)``; ``block_end`` is one past the last sample.
        Each of the :attr:`n_block_epochs` epoch rows is followed by its noise-correlator row
        (its first :attr:`n_noise` samples, code phase far from the prompt's:
        :mod:`~sdr_di.receiver.lock` notes). The loop over the epochs is
        :func:`~sdr_di.receiver._numba_channel.plan_block` (:attr:`jit`), or its plain form
        :meth:`_plan_reference`.
        """
        m = 1
        if self._bit_off is not None and self.state == ChannelState.TRACK:
            k = (self.epoch - self._bit_off) % self.bit_ms
            m = self.coh_ms - k % self.coh_ms
        fs = self.fs
        rate = self.code_rate
        dchip = rate / fs
        fd = self.fd
        dphi = (self.if_hz + fd) / fs
        ddop = fd / fs
        f_est = self.carrier.vel_hz if self.state != ChannelState.LOST else fd
        f_rate = self.carrier.acc_hz_s if self.state != ChannelState.LOST else 0.0
        start = self.next_start
        # the loop's frequency integrator holds the Doppler at the middle of the block it
        # steers (module notes); the observations extrapolate from there with its rate
        f_mid = start + 0.5 * m * _LF * fs / rate
        args = (m, start, self.theta, self.phi, self.dphase, self.epoch, rate, dchip, dphi,
                ddop, fd, f_est, f_rate, f_mid)
        if self.jit:
            plan_block(*args, _L, self.n_noise, NOISE_MIN_LAG_CHIPS, _NOISE_LAG_STEP,
                       self._hist, self._rows, self._ends)
        else:
            self._plan_reference(*args)
        self.block_rows = self._rows[:2 * m]
        self.n_block_epochs = m
        end, n0 = self._ends[m - 1, 0], self._rows[0, 1]
        self.block_end = int(end)
        self.n_next = int(n0)

    def _plan_reference(self, m: int, start: int, th: float, ph: float, dph: float, ep: int,
                        rate: float, dchip: float, dphi: float, ddop: float, fd: float,
                        f_est: float, f_rate: float, f_mid: float) -> None:
        """:meth:`_plan`'s loop over the epochs in Python (the reference of
        :func:`~sdr_di.receiver._numba_channel.plan_block`, whose notes give the arguments):
        the rows, the NCO state after each epoch and the history rows."""
        rows, ends, hist = self._rows, self._ends, self._hist
        ceil, floor = math.ceil, math.floor
        for i in range(m):
            n = ceil((_LF - th) / dchip)
            if n < 1:
                n = 1
            # each epoch's noise row right after it: the kernel's threads take contiguous
            # halves of the rows, which then hold equal work
            rows[2 * i] = (start, n, th, dchip, ph, dphi)
            rows[2 * i + 1] = (start, n if n < self.n_noise else self.n_noise,
                               noise_code_phase(th, ep), dchip, ph, dphi)
            hist[ep % _HIST] = (start, th, rate, dph, fd, ep, f_est, f_rate, f_mid)
            th = th + n * dchip - _LF
            if th < 0.0:
                th = 0.0
            ph += n * dphi
            ph -= floor(ph)
            dph += n * ddop
            start += n
            ep += 1
            ends[i] = (start, th, ph, dph)

    @property
    def block(self) -> list[tuple]:
        """:attr:`block_rows` as tuples ``(start, n, theta, dchip, phi, dphi)`` (start and n
        as int)."""
        return [(int(r[0]), int(r[1]), *r[2:]) for r in self.block_rows.tolist()]

    def _consume(self, i: int) -> None:
        """NCO state after the ``i``-th epoch (0-based) of the current block."""
        start, self.theta, self.phi, self.dphase = self._ends[i].tolist()
        self.next_start = int(start)
        self.epoch += 1

    # -- per-epoch processing ---------------------------------------------------------------
    def process_block(self, outs, noise: np.ndarray | None = None) -> None:
        """Consume the E/P/L correlations of every epoch of :attr:`block_rows` and plan the
        next.

        Parameters
        ----------
        outs : numpy.ndarray or sequence
            One ``(E, P, L)`` (complex; complex128 rows from the scalar bank) per row of
            :attr:`block_rows`, or one per epoch (no noise-correlator values).
        noise : numpy.ndarray, optional
            With one triple per row: the noise rows' values, :func:`~sdr_di.receiver.lock.
            noise_values` of their sums and sample counts (the scalar bank makes them for
            several channels at once), instead of making them here from ``outs``.
        """
        m = self.n_block_epochs
        if len(outs) == 2 * m:
            if noise is not None:
                self.noise.add_values(noise)
            else:
                nz = outs[1::2]
                self.noise.add([o[0] for o in nz], [o[1] for o in nz], [o[2] for o in nz],
                               [r[1] for r in self.block[1::2]])
            outs = outs[0::2]
        self._frozen = False
        if self.jit and self.log is None and self._bit_off is not None and m > 1:
            self._epochs_jit(np.asarray(outs, np.complex128), m)
        else:
            if isinstance(outs, np.ndarray):
                outs = outs.tolist()
            for i in range(m):
                e, p, l = outs[i]
                self._epoch(e, p, l, i, m)
                self._consume(i)
        if self.state == ChannelState.LOST:
            # coast from here at the last Doppler
            self.fd = self.carrier.vel_hz
            self.code_rate = CHIP_RATE_B3I * (1.0 + self.fd / self.carrier_hz)
            self._plan()
            self.lost_at_sample = self.next_start
            self.next_reacq_sample = self.next_start
            return
        self.fd = self.carrier.freq_hz
        self.code_rate = CHIP_RATE_B3I * (1.0 + self.fd / self.carrier_hz) \
            + self.code.rate_corr_cps
        self._plan()

    def _epochs_jit(self, outs: np.ndarray, m: int) -> None:
        """:meth:`process_block`'s epochs of a bit-synchronized channel without a log: runs
        of plain epochs in :func:`~sdr_di.receiver._numba_channel.plain_epochs`, the others
        (a completed bit, a lock evaluation, the block's last epoch) in :meth:`_epoch`."""
        i = 0
        coh = self._coh
        while i < m:
            if self._bit_off is not None and i < m - 1:
                j, coh[0], coh[1], coh[2], self._bit_acc, self._bit_n, self._eval_count = \
                    plain_epochs(outs, i, m, self.epoch, self._bit_off, self.bit_ms,
                                 self.is_d1, _NH_ARR, self._ring, coh[0], coh[1], coh[2],
                                 self._bit_acc, self._bit_n, self._eval_count,
                                 self.cfg.lock_eval_ms, self._frozen)
                if j > i:
                    k = j - i
                    coh[3] += k
                    self._n_tracked += k
                    self.epoch += k - 1
                    self._consume(j - 1)
                    i = j
            e, p, l = outs[i].tolist()
            self._epoch(e, p, l, i, m)
            self._consume(i)
            i += 1

    def process_epoch(self, e: complex, p: complex, l: complex) -> None:
        """Single-epoch form of :meth:`process_block` (the block must be one epoch long; no
        noise-correlator values)."""
        if self.n_block_epochs != 1:
            raise ValueError("process_epoch needs a one-epoch block; use process_block")
        self.process_block(((e, p, l),))

    def _epoch(self, e: complex, p: complex, l: complex, i: int, m: int) -> None:
        """Epoch ``i`` of a block of ``m`` (NCO fixed over the block)."""
        cfg = self.cfg
        ep = self.epoch
        self._ring[ep % _RING] = p
        self._n_tracked += 1
        dt1 = self._rows[2 * i, 1].item() / self.fs
        frozen = self._frozen
        if self._bit_off is None:
            # 1 ms loops (pull-in, or tracking before bit sync)
            if not frozen:
                ephi = costas_atan(p.real, p.imag)
                ef = 0.0
                prev = self._prev_p
                if prev is not None and self.state == ChannelState.PULL_IN:
                    ef = fll_atan(prev.real, prev.imag, p.real, p.imag, dt1)
                self._prev_p = p
                self.carrier.update(ephi, ef, dt1)
                self.code.update(dll_nelp(abs(e), abs(l), cfg.spacing_chips), dt1)
        else:
            k = (ep - self._bit_off) % self.bit_ms
            if self.is_d1 and _NH[k] < 0.0:
                e, p, l = -e, -p, -l
            coh = self._coh
            coh[0] += e
            coh[1] += p
            coh[2] += l
            coh[3] += 1
            if i == m - 1:
                # end of the block = end of the coherent interval
                if not frozen:
                    pp = coh[1]
                    tc = coh[3] * dt1
                    self.carrier.update(costas_atan(pp.real, pp.imag), 0.0, tc)
                    self.code.update(dll_nelp(abs(coh[0]), abs(coh[2]), cfg.spacing_chips), tc)
                coh[0] = coh[1] = coh[2] = 0j
                coh[3] = 0
            # data bit
            if k == 0:
                self._bit_acc = 0.0
                self._bit_n = 0
            self._bit_acc += p.real
            self._bit_n += 1
            if k == self.bit_ms - 1:
                if self._bit_n == self.bit_ms:
                    self._on_bit(0 if self._bit_acc >= 0.0 else 1, ep - k)
                self._bit_n = 0
        self._eval_count += 1
        if self._eval_count >= cfg.lock_eval_ms and not frozen:
            self._eval_count = 0
            st = self.state
            synced = self._bit_off is not None
            self._evaluate()
            if self.state != st or (self._bit_off is not None) != synced:
                self._frozen = True  # the rest of the block was planned for the old mode
        if self.log is not None and ep % self.log_every == 0:
            st0 = self._hist[ep % _HIST].tolist()
            self.log.append((st0[0], ep, st0[1], st0[2], st0[6], st0[3], self.cn0_dbhz,
                             self.lock_metric, 1.0 if self.code_lock else 0.0,
                             1.0 if self.carrier_lock else 0.0, float(self.state),
                             p.real, p.imag, e.real, e.imag, l.real, l.imag))

    # -- lock detection and state machine ----------------------------------------------------
    def _recent(self, n: int) -> np.ndarray:
        """The last ``n`` 1 ms prompts (oldest first), ``n <= epochs tracked``."""
        end = (self.epoch + 1) % _RING
        start = end - n
        if start >= 0:
            return self._ring[start:end]
        return np.concatenate((self._ring[start:], self._ring[:end]))

    def _evaluate(self) -> None:
        cfg = self.cfg
        n = min(cfg.cn0_window_ms, self._n_tracked)
        if n < 10:
            return
        npow = self.noise.noise_power(self.noise_power_per_sample)
        pr = nbd = None
        if npow is not None and npow > 0.0:
            pn = npow * self.fs * _T_EPOCH
            if self.jit:
                # the window's means from the ring in one kernel call (the same values)
                m2, nbd = prompt_moments(self._ring, (self.epoch + 1) % _RING, n)
                pd = m2 - float(pn)
            else:
                pr = self._recent(n)
                pd = prompt_signal_power(pr, pn)
        else:
            pr = self._recent(n)
            pd, pn = m2m4_powers(pr)
        if pd > 0.0 and pn > 0.0:
            self.cn0_dbhz = 10.0 * math.log10(pd / (pn * _T_EPOCH))
        elif pd > 0.0:
            self.cn0_dbhz = 99.0
        else:
            self.cn0_dbhz = math.nan
        if nbd is not None and pd > 0.0:
            # carrier_lock_metric with the signal power pd: its numerator's mean, clipped
            self.lock_metric = max(-1.0, min(1.0, nbd / pd))
        else:
            self.lock_metric = carrier_lock_metric(self._recent(n) if pr is None else pr,
                                                   pd if pd > 0.0 else None)
        code_ok = self.cn0_dbhz >= cfg.cn0_lock_dbhz  # NaN -> False
        carrier_ok = code_ok and self.lock_metric >= cfg.pll_lock_threshold
        self.code_lock = self._code_ctr.update(code_ok)
        if self._unconfirmed and code_ok:
            self._confirm_subframes(self.epoch + 1 - n)
        self.carrier_lock = self._pll_ctr.update(carrier_ok)
        if self.state == ChannelState.PULL_IN:
            self._pull_in_ms += cfg.lock_eval_ms
            # FLL assist narrows as the frequency settles: halved every fll_halving_ms
            bf = max(min(cfg.pull_in_fll_min_bw_hz, self._fll_bw0), self._fll_bw0 *
                     0.5 ** (self._pull_in_ms // max(1, cfg.fll_halving_ms)))
            if bf != self.carrier.fll_bw_hz:
                self.carrier.set_bandwidths(cfg.pull_in_pll_bw_hz, bf)
            if self.carrier_lock:
                self._enter_track()
            elif not self.code_lock or self._pull_in_ms >= cfg.pull_in_timeout_ms:
                self._lose()
            return
        # TRACK
        if not self.code_lock:
            self._lose()
            return
        if not self.carrier_lock:
            self._back_to_pull_in()
            return
        if self._bit_off is None:
            self._try_bit_sync()

    def _enter_track(self) -> None:
        self.state = ChannelState.TRACK
        self.carrier.set_bandwidths(self.cfg.track_pll_bw_hz, self.cfg.track_fll_bw_hz)
        self.code.set_bandwidth(self.cfg.track_dll_bw_hz)
        self._pll_ctr.n_lock = self.cfg.pull_in_lock_evals
        self._track_since_epoch = self.epoch + 1

    def _back_to_pull_in(self) -> None:
        self.state = ChannelState.PULL_IN
        # the pull-in's own FLL start (a weak channel started narrow stays narrow)
        self.carrier.set_bandwidths(self.cfg.pull_in_pll_bw_hz, self._fll_bw0)
        self.code.set_bandwidth(self.cfg.pull_in_dll_bw_hz)
        self._pull_in_ms = 0
        self._prev_p = None
        self._drop_bit_sync()
        self._new_arc()
        self.slip_count += 1

    def _drop_bit_sync(self) -> None:
        self._bit_off = None
        self._coh = [0j, 0j, 0j, 0]
        self._bits = []
        self._search_from = 0
        self._frame = None
        self._candidate = None
        self._unconfirmed.drop()
        self.time_valid = False

    def _lose(self) -> None:
        """Declare the signal lost (the NCO coasts from the end of the current block)."""
        self.state = ChannelState.LOST
        self.code_lock = False
        self.carrier_lock = False
        self._drop_bit_sync()

    # -- re-acquisition ----------------------------------------------------------------------
    def begin_reacquisition(self, sample: int) -> None:
        """Mark the channel as searching (``REACQUIRE``) from ``sample``."""
        if self._state != ChannelState.REACQUIRE:
            self._state = ChannelState.REACQUIRE
            self.transitions.append((int(sample), ChannelState.REACQUIRE))

    def reacquire_search(self, sample: int) -> tuple[float, float]:
        """Doppler centre and half-range [Hz] of the narrow search at ``sample``."""
        out_s = 0.0 if self.lost_at_sample is None else (sample - self.lost_at_sample) / self.fs
        rng = self.cfg.reacq_doppler_range_hz + self.cfg.reacq_doppler_growth_hz_s * out_s
        return self.fd, min(rng, 10000.0)

    def reacquired(self, sample: int, code_phase_chips: float, doppler_hz: float,
                   cn0_dbhz: float = math.nan,
                   t_tx: tuple[int, float] | None = None) -> None:
        """Resume tracking after a successful (re-)acquisition at ``sample``.

        After a loss the channel's time is rebuilt, in this order of preference:

        1. ``t_tx`` given (BDT week, satellite-clock transmit time [s] of the code received
           at ``sample``, predicted from the last fix: :mod:`~sdr_di.receiver.prediction`):
           the re-acquired code phase gives the fraction of a millisecond, the prediction the
           whole milliseconds (it must be within +-0.5 ms: 150 km of range);
        2. the code-epoch count carried through the outage by the coasting NCO, when the
           re-acquired code phase agrees with the coasted one within ``coast_tol_chips`` (and
           the outage lasted at most ``coast_max_s``): the time established before the
           outage is kept.

        Either way the time is valid again (``time_valid``) as soon as the new bit
        synchronization falls on the bit edges that time puts them on (an independent check
        of the whole milliseconds modulo the bit length); without either the time is
        re-established from the next subframe.
        """
        cfg = self.cfg
        if self.lost_at_sample is None or self.state not in (ChannelState.LOST,
                                                             ChannelState.REACQUIRE):
            self.start(sample, code_phase_chips, doppler_hz, cn0_dbhz)
            return
        dur = (sample - self.lost_at_sample) / self.fs
        # coasted code phase at `sample`, from the last committed epoch
        chips = self.theta + (sample - self.next_start) * self.code_rate / self.fs
        wraps = math.floor(chips / _LF)
        th_pred = chips - wraps * _LF
        th0 = float(code_phase_chips) % _LF
        diff = (th0 - th_pred + _LF / 2) % _LF - _LF / 2
        ep_at = self.epoch + wraps + math.floor((th_pred + diff) / _LF)
        keep = dur <= cfg.coast_max_s and abs(diff) <= cfg.coast_tol_chips
        saved_time = self._time if keep else None
        if t_tx is not None and math.isfinite(t_tx[1]):
            saved_time = self._time_from_prediction(ep_at, th0, int(t_tx[0]), float(t_tx[1]))
        self._reset_tracking_state()
        self._restart(sample, th0, doppler_hz, cn0_dbhz, ep_at)
        self.slip_count += 1
        self._time = saved_time

    def _time_from_prediction(self, ep_at: int, theta0: float, week: int,
                              sow: float) -> tuple[int, float, int]:
        """``_time`` (subframe-start epoch, its time, week) for a predicted transmit time
        ``sow`` at the sample where code epoch ``ep_at`` is at phase ``theta0`` [chips]:
        the whole milliseconds of the epoch start are the prediction's (:meth:`reacquired`)."""
        ep_ms = round((sow - theta0 / CHIP_RATE_B3I) * 1000.0)  # epoch start [ms of week]
        sub_ms = SUBFRAME_BITS * self.bit_ms
        sf_ms = (ep_ms // sub_ms) * sub_ms
        return (ep_at - (ep_ms - sf_ms), sf_ms * 1e-3, week)

    # -- NH / bit synchronization ----------------------------------------------------------
    def _try_bit_sync(self) -> None:
        cfg = self.cfg
        avail = min(self.epoch + 1 - self._track_since_epoch, _RING - 40)
        if self.is_d1:
            need = 20 * cfg.nh_sync_bits + 19
            if avail < need:
                return
            nb = (avail - 19) // 20
            m = 20 * nb + 19
            i_vals = self._recent(m).real
            first = self.epoch + 1 - m
            scores = np.empty(20)
            for r in range(20):
                blk = i_vals[r:r + 20 * nb].reshape(nb, 20)
                scores[r] = np.sum(np.abs(blk @ _NH_ARR))
            order = np.argsort(scores)
            best, second = scores[order[-1]], scores[order[-2]]
            if not best >= cfg.sync_ratio * second:
                return
            self._bit_off = (first + int(order[-1])) % 20
        else:
            m = min(avail, cfg.d2_sync_ms)
            if m < 20:
                return
            i_vals = self._recent(m).real
            first = self.epoch + 1 - m
            flips = np.signbit(i_vals[1:]) != np.signbit(i_vals[:-1])
            # flip between prompt j and j+1 -> edge at epoch first + j + 1
            edge_par = (first + 1 + np.arange(m - 1)) % 2
            c = [int(np.count_nonzero(flips & (edge_par == q))) for q in (0, 1)]
            q = 0 if c[0] >= c[1] else 1
            if c[q] < cfg.d2_sync_min_transitions or 4 * c[1 - q] > c[q]:
                return
            self._bit_off = q
        self._coh = [0j, 0j, 0j, 0]
        self._bit_n = 0
        self._bit_acc = 0.0
        # demodulate the complete bits already in the ring
        bm = self.bit_ms
        e0 = self.epoch + 1 - min(avail, _RING - 40)
        e0 += (self._bit_off - e0) % bm
        n_bits = (self.epoch + 1 - e0) // bm
        if n_bits > 0:
            vals = self._recent(self.epoch + 1 - e0).real[:n_bits * bm].reshape(n_bits, bm)
            if self.is_d1:
                vals = vals * _NH_ARR
            soft = vals.sum(axis=1)
            for j in range(n_bits):
                self._on_bit(0 if soft[j] >= 0.0 else 1, e0 + j * bm)
        # partial bit in progress
        k_done = (self.epoch + 1 - self._bit_off) % bm
        if k_done:
            part = self._recent(k_done).real
            if self.is_d1:
                ks = (np.arange(self.epoch + 1 - k_done, self.epoch + 1) - self._bit_off) % 20
                part = part * _NH_ARR[ks]
            self._bit_acc = float(part.sum())
            self._bit_n = k_done
        self._check_time_after_resync()

    # -- frame synchronization and decoding ------------------------------------------------
    def _on_bit(self, bit: int, epoch: int) -> None:
        runs = self.bit_runs
        if runs and runs[-1][0] + len(runs[-1][1]) * self.bit_ms == epoch:
            runs[-1][1].append(bit)
        else:
            runs.append([epoch, bytearray([bit])])
        bits = self._bits
        if not bits:
            self._bits_epoch0 = epoch
        bits.append(bit)
        fr = self._frame
        if fr is not None:
            if len(bits) >= fr["idx"] + SUBFRAME_BITS:
                self._synced_subframe()
            return
        n = len(bits)
        if n - SUBFRAME_BITS < self._search_from:
            return
        arr = np.asarray(bits, dtype=np.uint8)
        res = find_preamble(arr, self._search_from)
        if res is None:
            self._search_from = max(self._search_from, n - SUBFRAME_BITS + 1)
            self._trim_bits(self._search_from)
            return
        off, pol = res
        seg = arr[off:off + SUBFRAME_BITS]
        try:
            d = decode_subframe(seg if pol == 1 else 1 - seg, prn=self.prn)
        except NavMessageError:
            self._search_from = off + 1
            return
        d["epoch"] = self._bits_epoch0 + off * self.bit_ms
        d["polarity"] = pol
        cand = self._candidate
        period = SUBFRAME_BITS * self.bit_ms * 1e-3
        if self._time_plausible(d) or (
                cand is not None and cand["offset_bits"] + SUBFRAME_BITS == off
                and cand["polarity"] == pol
                and abs(_wrap_week(d["t_start"] - cand["t_start"] - period)) < 1e-6):
            if cand is not None and cand["offset_bits"] + SUBFRAME_BITS == off:
                self._accept_subframe(cand)
            self._frame = {"idx": off + SUBFRAME_BITS, "pol": pol, "misses": 0,
                           "expect": d["t_start"] + period}
            self._note_polarity(pol)
            self._set_time(d)
            self._accept_subframe(d)
            self._trim_bits(off + SUBFRAME_BITS)
        else:
            d["offset_bits"] = off
            self._candidate = d
            self._search_from = off + 1

    def _trim_bits(self, keep_from: int) -> None:
        """Drop bits before index ``keep_from`` (indices shift; bookkeeping follows)."""
        if keep_from <= 0:
            return
        del self._bits[:keep_from]
        self._bits_epoch0 += keep_from * self.bit_ms
        self._search_from = max(0, self._search_from - keep_from)
        if self._frame is not None:
            self._frame["idx"] -= keep_from
        if self._candidate is not None:
            self._candidate["offset_bits"] -= keep_from

    def _time_plausible(self, d: dict) -> bool:
        if self.rx_time is None:
            return False
        start_sample = self._sample_of_epoch(d["epoch"])
        if start_sample is None:
            return False
        _, rx_sow = self.rx_time(start_sample)
        return abs(_wrap_week(rx_sow - d["t_start"])) < self.cfg.time_check_s

    def _sample_of_epoch(self, epoch: int) -> float | None:
        """Approximate sample at which code epoch ``epoch`` began (from the NCO history)."""
        h = self._hist[self.epoch % _HIST].tolist()
        if math.isnan(h[5]):
            return None
        start, th, rate, _, _, ep, *_ = h
        return int(start) + ((epoch - int(ep)) * _LF - th) * self.fs / rate

    def _synced_subframe(self) -> None:
        fr = self._frame
        idx = fr["idx"]
        seg = np.asarray(self._bits[idx:idx + SUBFRAME_BITS], dtype=np.uint8)
        head = [int(b) for b in seg[:len(_PREAMBLE)]]
        period = SUBFRAME_BITS * self.bit_ms * 1e-3
        found = 1 if head == _PREAMBLE else -1 if head == _PREAMBLE_INV else 0
        if found:
            fr["pol"] = found
            self._note_polarity(found)  # counts a half-cycle slip of the Costas loop
        d = None
        if found:
            try:
                d = decode_subframe(seg if found == 1 else 1 - seg, prn=self.prn)
            except NavMessageError:
                d = None
        if d is not None and abs(_wrap_week(d["t_start"] - fr["expect"])) < 1e-6:
            d["epoch"] = self._bits_epoch0 + idx * self.bit_ms
            d["polarity"] = found
            fr["misses"] = 0
            self._set_time(d)
            self._accept_subframe(d)
        else:
            fr["misses"] += 1
            if fr["misses"] >= 2:
                # lost the frame: search for a preamble again (time re-established there)
                self._frame = None
                self._candidate = None
                self.time_valid = False
                self._time = None
                self._search_from = max(0, idx - SUBFRAME_BITS)
                return
        fr["expect"] += period
        fr["idx"] = idx + SUBFRAME_BITS
        self._trim_bits(idx + SUBFRAME_BITS)

    def _set_time(self, d: dict) -> None:
        """Frame sync on decoded subframe ``d``: time and week of its first bit."""
        week = None
        if "WN" in d["raw"]:
            week = int(d["raw"]["WN"])
        elif self._time is not None and self._time[2] is not None:
            pred = self._time[1] + (d["epoch"] - self._time[0]) * 1e-3
            week = self._time[2] + round((pred - d["t_start"]) / _WEEK)
        elif self.rx_time is not None:
            s = self._sample_of_epoch(d["epoch"])
            if s is not None:
                rx_week, rx_sow = self.rx_time(int(s))
                dw = d["t_start"] - rx_sow
                week = rx_week - 1 if dw > _WEEK / 2 else rx_week + 1 if dw < -_WEEK / 2 \
                    else rx_week
        # (week kept apart from the SOW: float64 seconds since week 0 would quantize the
        # transmit time to 6e-8 s = 18 m)
        self._time = (d["epoch"], float(d["t_start"]), week)
        self.time_valid = True

    def _accept_subframe(self, d: dict) -> None:
        """Hold decoded subframe ``d`` until the lock detector confirms it (module notes)."""
        self._unconfirmed.hold(d, d["epoch"] + SUBFRAME_BITS * self.bit_ms)

    def _confirm_subframes(self, window_start: int) -> None:
        """Pass on the held subframes that ended before epoch ``window_start``, the start of
        the C/N0 window of a passed code-lock test (module notes)."""
        for d in self._unconfirmed.confirmed(window_start):
            self._use_subframe(d)

    def take_unconfirmed(self) -> list[tuple[int, dict]]:
        """The decoded subframes still awaiting the lock confirmation, handed over.

        At the deep hand-over this channel stops in lock; the vector loop's decoder, with its
        own C/N0 test and the same assembler, holds these until that test confirms them
        (:func:`~sdr_di.integration.handover.handover_decoder`). Passing them on unconfirmed
        would take a subframe whose last bits came after a blockage began; dropping them
        would lose a subframe that ended less than 0.12 s before the hand-over (its data
        set would wait a whole frame).

        Returns
        -------
        list of (int, dict)
            ``(end, subframe)`` oldest first: ``end`` is the code epoch (this channel's
            counter) after the subframe's last bit. None are held here after.
        """
        return self._unconfirmed.take()

    def _use_subframe(self, d: dict) -> None:
        self.subframes.append(d)
        if len(self.subframes) > 50:
            del self.subframes[:-50]
        try:
            res = self.assembler.add(d)
        except NavMessageError:
            res = None
        if res is not None:
            self.ephemeris, self.klobuchar = res

    def _check_time_after_resync(self) -> None:
        """After a new bit synchronization with a carried epoch count (re-acquisition, return
        from pull-in): the time is valid again when the bit edges fall where the carried time
        puts them; the subframe bookkeeping resumes at the next subframe edge."""
        if self._time is None or self._bit_off is None:
            return
        sf_ep, t_sf, _ = self._time
        if (sf_ep - self._bit_off) % self.bit_ms != 0 or not self._bits:
            self._time = None
            return
        self.time_valid = True
        sub_ep = SUBFRAME_BITS * self.bit_ms
        nxt = sf_ep + -(-(self._bits_epoch0 - sf_ep) // sub_ep) * sub_ep
        t_exp = t_sf + (nxt - sf_ep) * 1e-3
        self._frame = {"idx": (nxt - self._bits_epoch0) // self.bit_ms, "pol": 0,
                       "misses": 0, "expect": _sow_of(t_exp)}
        if len(self._bits) >= self._frame["idx"] + SUBFRAME_BITS:
            self._synced_subframe()

    # -- observations -----------------------------------------------------------------------
    def observation_at(self, sample_index: int) -> ChannelObservation:
        """Channel state at receiver sample ``sample_index`` (module notes of
        :mod:`~sdr_di.receiver.tracking`).

        The sample should lie within the last ~64 committed epochs (the receiver asks right
        after every channel has passed it); later samples are extrapolated with the current
        NCO, earlier ones raise ``ValueError``.
        """
        s = int(sample_index)
        h = None
        hist = self._hist
        for j in range(_HIST):
            row = (self.epoch - j) % _HIST
            if hist[row, 5] != self.epoch - j:     # (NaN: no epoch there yet)
                break
            if hist[row, 0] <= s:
                h = hist[row].tolist()
                break
        if h is None:
            raise ValueError(f"PRN {self.prn}: sample {s} is older than the NCO history")
        start, th, rate, dph, fd, ep, f_est, f_rate, f_mid = h
        start, ep = int(start), int(ep)
        f_est += f_rate * (s - f_mid) / self.fs
        chips = th + (s - start) * rate / self.fs
        wraps = math.floor(chips / _LF)
        code_phase = chips - wraps * _LF
        cphase = dph + (s - start) * fd / self.fs + self._half_cycle
        week = None
        sow = math.nan
        tv = bool(self.time_valid and self._time is not None)
        if tv:
            sf_ep, t_sf, sf_week = self._time
            t = t_sf + (ep - sf_ep) * 1e-3 + chips / CHIP_RATE_B3I
            w = math.floor(t / _WEEK)
            sow = t - w * _WEEK
            week = None if sf_week is None else int(sf_week + w)
        return ChannelObservation(
            prn=self.prn, sample_index=s, t_tx_week=week, t_tx_sow=sow, doppler_hz=f_est,
            carrier_phase_cycles=cphase, cn0_dbhz=self.cn0_dbhz, code_lock=self.code_lock,
            carrier_lock=self.carrier_lock, time_valid=tv, code_phase_chips=code_phase,
            state=self.state.name, slip_count=self.slip_count,
            half_cycle_resolved=self._half_known)

    def __repr__(self) -> str:
        return (f"Channel(prn={self.prn}, {self.nav}, state={self.state.name}, "
                f"doppler={self.fd:.1f} Hz, cn0={self.cn0_dbhz:.1f} dB-Hz, "
                f"time_valid={self.time_valid})")


def _wrap_week(dt: float) -> float:
    """Wrap a time difference to [-half week, half week)."""
    return (dt + _WEEK / 2) % _WEEK - _WEEK / 2


def _sow_of(t: float) -> float:
    return t - math.floor(t / _WEEK) * _WEEK
