"""Scalar software receiver: acquisition, then all channels tracked over an IF file in chunks.

:class:`ScalarReceiver` drives :class:`~sdr_di.receiver.channel.Channel` objects over an
:class:`~sdr_di.receiver.ifreader.IfSource`:

1. **Acquisition** of the requested PRNs on the first ``noncoherent`` ms (default 40 x 1 ms)
   with :func:`~sdr_di.receiver.acquisition.acquire_source` (zero-stuffing below about 14 MHz,
   ``acq_upsample``, DC and line removal, and the +-500 Hz Doppler check are done there:
   module notes of :mod:`~sdr_di.receiver.acquisition`; a file shorter than the search is
   searched with what it holds). A cold search stays 1 ms coherent and non-coherent; with
   *assistance* (``run(assist=...)``: the satellites a sidecar lists with their start
   Doppler, or those visible from ephemeris and a time hint) only the expected PRNs are
   searched, each over ``+-assist_doppler_range_hz`` around its predicted Doppler (the bins
   of the cold grid that cover it: 7 instead of 21). PRNs of a list (assistance or explicit
   ``prns``) that the first search misses get the long search, ``long_noncoherent`` (400) x
   1 ms on a grid of half the step (250 Hz), at about 6 dB more sensitivity; a blind search
   of all 63 PRNs gets none (it would cost minutes).
2. **Tracking**: the samples are read from the file in chunks (``chunk_ms``, default
   100 ms; memory bounded by the chunk size whatever the file length) as stored
   (:meth:`~sdr_di.receiver.ifreader.IfSource.read_stored`: ``int8`` for the default 4-bit
   ``iq_int8`` files, no conversion to ``complex64``). At each step every tracking channel
   whose next *block* of epochs (one epoch before bit synchronization, one coherent interval
   after: 10 ms for D1, 2 ms for D2 by default) starts before the earliest block end is
   correlated: all epochs of all those channels in **one** call of the numba E/P/L kernel
   :func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_bits` (per-row NCO parameters
   and intervals; one bit-window replica row per channel, one carrier rotation table per
   channel, both named per row). Each channel then updates its loops and synchronization
   (:meth:`Channel.process_block`). The input noise power per sample (mean ``|x|^2`` of each
   chunk) is handed to the channels for their C/N0 estimators; each epoch row of a block is
   followed by the channel's noise-correlator row, which they use instead where the two
   disagree (interference: :class:`~sdr_di.receiver.lock.PostCorrelationNoise`). The reader
   reads the next chunk in a background thread while the kernel runs
   (:meth:`~sdr_di.receiver.ifreader.IfSource.read_stored`).
3. **Output epochs** every ``epoch_interval_s`` (sample ``start + round(k dt fs)``, k >= 1):
   once every tracking channel has passed the epoch's sample, ``on_epoch(sample,
   observations, ephemerides)`` is called with a
   :class:`~sdr_di.receiver.tracking.ChannelObservation` of each channel in
   ``PULL_IN``/``TRACK`` and the latest decoded ``{prn: Ephemeris}``.
4. **Loss and re-acquisition**: a channel that loses code lock goes ``LOST`` (its NCO coasts
   at the last Doppler); every ``reacq_interval_ms`` a narrow search runs on the samples at
   the current processing point (``REACQUIRE``) until the signal is found (``PULL_IN``). With
   a :attr:`ScalarReceiver.predictor` (``run_scalar`` sets one on the PVT's last fix:
   :mod:`~sdr_di.receiver.prediction`) the search is centred on the predicted Doppler and the
   channel's transmit time is rebuilt from the predicted range, so fixes resume without a
   new subframe; without a prediction (no fix yet, no decoded ephemeris) the search is
   centred on the last Doppler and the time carried by the coasting NCO. A **total
   blockage** (every channel lost) does not stop the run: output epochs keep coming with no
   observation (``on_epoch(sample, [], ephemerides)``; ``run_scalar`` writes a row with status
   ``too_few_satellites`` at the receiver time) until the signals return. PRNs not found by
   the initial acquisition are searched again (all together) every ``retry_acquisition_s``
   when that is set (default: never).

Processing cost (2-core development machine, AMD EPYC with AVX-512, shared with other
sessions, so wall times follow the machine's load; the CPU time is the load-independent
figure). ``python scripts/bench.py run --if-file F --repeat 3`` on a 40 s default-scenario
file (7 D1 channels, 25 MHz complex 4-bit ``iq_int8``, PVT and CSV/NMEA output at 5 Hz, whole
``run_scalar`` process including imports): at load average 1.1-1.5, 11.1-14.6 s wall
(2.7-3.6x real time; tracking loop alone 3.2-4.2x); at load 3.2-3.7, 18.5-19.4 s (2.1-2.2x);
at load 4-5, 24-30 s (1.3-1.6x). CPU time (user + system, both threads) 17.7-20.2 s, i.e.
about 2x real time even on a single free core; peak RSS 227 MiB for a 40 s file and 226 MiB
for a 10 s one (memory bounded by the chunk size). Shares of the wall time: correlation
56-63 % (kernel 1.35-1.6 ns per sample and channel, one thread), acquisition 7-12 % (~2 s of
CPU, mostly the FFT search of 7 PRNs x 21 Doppler bins x 40 ms), channels' Python work
8-11 %, reading 5-8 % (more when the file is not in the page cache), PVT/output 4-7 %, imports
and set-up 6-8 %. Side by side on the same file at the same load, the code before the
bit-window kernel (the former float-table kernel on ``complex64`` chunks, since deleted,
~3.1 ns per sample and channel, 2-thread calls explored 2 in every 64) took 27.4 s wall /
49.8 s CPU at load 1.5 (new: 15.0 s / 21.4 s) and 58-72 s / 40-49 s at load 3.5 (new: 27 s
/ 18-20 s). On a 20 MHz real ``int16`` file at 5 MHz IF
(``scripts/check_scalar.py --fs 20e6 --if 5e6 --format real_int16 --bits 12``) the receiver
ran 5.1x real time (before: 1.7x), same accuracy.
``ScalarReceiver.profile`` gives the breakdown of every run.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

import numba
import numpy as np

from ..constants import CODE_LENGTH_B3I
from ..orbits.ephemeris import Ephemeris
from ..settings import passive_kernel_workers
from ._numba_correlate_bits import correlate_epl_bits
from .acquisition import (
    LIKELY_CAUSES,
    AcquisitionResult,
    AcquisitionWarning,
    ImplausibleAcquisition,
    acquire_source,
    acquisition_upsampling,
    default_doppler_step_hz,
    implausible_detections,
)
from .channel import Channel
from .correlator import (
    CARRIER_BLOCK,
    CODE_PAD,
    bit_windows,
    carrier_rotation,
    check_prn,
    padded_replicas,
)
from .ifreader import IfSource
from .lock import noise_values
from .threads import KernelThreads
from .tracking import ChannelObservation, ChannelState, TrackingConfig, TrackingLog

if TYPE_CHECKING:
    from .prediction import SignalPrediction

__all__ = ["ScalarReceiver", "acquisition_upsampling"]

OnEpoch = Callable[[int, list[ChannelObservation], dict[int, Ephemeris]], bool | None]


class _Bank:
    """Replica and carrier-rotation tables of the channel slots, and the kernel call."""

    def __init__(self, n_slots: int, spacing: float, threads: int | None = None):
        self.spacing = float(spacing)
        # kernel thread count chosen by measured cost [s per sample-row]
        self.threads = KernelThreads(threads)
        self.tab = np.zeros((0, 1), np.uint64)
        self.rot_re = np.ones((n_slots, CARRIER_BLOCK), np.float32)
        self.rot_im = np.zeros((n_slots, CARRIER_BLOCK), np.float32)
        self.rot_dphi = [math.nan] * n_slots

    def set_prns(self, prns: list[int]) -> None:
        """Replica bit windows (:func:`~sdr_di.receiver.correlator.bit_windows`) of the slots'
        PRNs, one row per slot."""
        from ..signal.codes import b3i_code

        self.tab = np.ascontiguousarray(np.concatenate(
            [bit_windows(padded_replicas(np.asarray(b3i_code(p)))) for p in prns]))

    def _rot(self, slots: list[int], dphis: list[float]) -> None:
        """Carrier rotation tables ``exp(-j 2 pi m dphi)`` of the slots whose ``dphi`` changed."""
        new = [(s, d) for s, d in zip(slots, dphis) if self.rot_dphi[s] != d]
        if not new:
            return
        idx = [s for s, _ in new]
        self.rot_re[idx], self.rot_im[idx] = carrier_rotation([d for _, d in new])
        for s, d in new:
            self.rot_dphi[s] = d

    def correlate(self, x: np.ndarray, n_comp: int, buf0: int, slots: tuple[int, ...],
                  chans: list, ready: Callable[[int, list, np.ndarray | None], None]) -> None:
        """Correlate every row of the channels' blocks on the stored samples ``x``
        (:meth:`~sdr_di.receiver.ifreader.IfSource.read_stored`, first sample ``buf0``);
        ``ready(j, outs, noise)`` gets channel ``j``'s ``(E, P, L)`` sums (complex128, one row
        per row of its block) as soon as its rows are final, the channels in order: those of the kernel call's
        leading part while its worker correlates the rest (:meth:`~sdr_di.receiver.threads.
        KernelThreads.run_rows`), then the others. ``noise``: the values of its noise rows
        (every other row: :meth:`~sdr_di.receiver.channel.Channel.process_block`), made for
        the channels of a part in one numpy pass (:func:`~sdr_di.receiver.lock.
        noise_values`); None when a channel's block is not in pairs."""
        blocks = [c.block_rows for c in chans]
        reps = [len(b) for b in blocks]
        self._rot(list(slots), [b[0, 5].item() for b in blocks])
        par = np.concatenate(blocks).T.copy()
        n_rows = par.shape[1]
        start = par[0].astype(np.int64) - buf0
        nsamp = par[1].astype(np.int64)
        row_slot = np.repeat(np.array(slots, dtype=np.int64), reps)
        out = np.empty((n_rows, 3, 2))

        def rows_ab(a, b):    # rows [a, b), one task per row (receiver.threads notes)
            correlate_epl_bits(x, n_comp, self.tab, row_slot[a:b], CODE_PAD, CODE_LENGTH_B3I,
                               start[a:b], nsamp[a:b], par[2, a:b], par[3, a:b], par[4, a:b],
                               par[5, a:b], self.rot_re, self.rot_im, row_slot[a:b],
                               self.spacing, 1, out[a:b])

        ends = np.cumsum(reps).tolist()
        taken = [0]                       # channels given to `ready`
        paired = all(r % 2 == 0 for r in reps)     # (epoch row, noise row) pairs

        def take(rows_done: int) -> None:
            j0 = j1 = taken[0]
            while j1 < len(chans) and ends[j1] <= rows_done:
                j1 += 1
            if j1 == j0:
                return
            a0, a1 = (ends[j0 - 1] if j0 else 0), ends[j1 - 1]
            # (re, im) pairs are contiguous: a complex128 view of E, P, L
            seg = out[a0:a1].view(np.complex128).reshape(-1, 3)
            noise = None
            if paired:       # (every noise row holds at least one sample: Channel._plan)
                nz = seg[1::2]
                noise = noise_values(nz[:, 0], nz[:, 1], nz[:, 2], nsamp[a0 + 1:a1:2])
            for j in range(j0, j1):
                a = (ends[j - 1] if j else 0) - a0
                ready(j, seg[a:a + reps[j]],
                      None if noise is None else noise[a // 2:(a + reps[j]) // 2])
            taken[0] = j1

        self.threads.run_rows(rows_ab, nsamp, take)
        take(n_rows)


@dataclasses.dataclass
class _ScalarPass:
    """The state of one :meth:`ScalarReceiver.run` over a file, shared by its stages.

    Sample indices count from the file's first sample; ``[buf0, buf1)`` is the chunk read in
    ``x`` (``n_comp`` values per sample); ``t_now`` the earliest sample a tracking channel
    still needs; ``next_out`` the next output epoch (number ``k_out``).
    """

    source: IfSource
    on_epoch: OnEpoch | None
    epoch_interval_s: float
    fs: float
    start: int
    stop: int
    chans: list[Channel]
    slot_of: dict[int, int]
    bank: _Bank
    threads_before: int
    prof: dict
    n_acq: int
    reacq_step: int
    retry_step: int | None
    chunk: int
    n_comp: int
    buf0: int
    buf1: int
    next_out: int
    t_now: int
    k_out: int = 1
    x: np.ndarray = dataclasses.field(default_factory=lambda: np.empty(0, dtype=np.float32))


class ScalarReceiver:
    """Acquisition + scalar tracking of every channel over an IF file (module notes).

    Parameters
    ----------
    config : TrackingConfig, optional
        Loop and detector parameters of every channel.
    acquisition : dict, optional
        Keyword arguments for :func:`~sdr_di.receiver.acquisition.acquire` (defaults:
        ``noncoherent=40``, ``doppler_range_hz=5000``, ``pfa=1e-3``).
    chunk_ms : int, optional
        Samples read from the file per refill [ms]. Default 100.
    log : bool, optional
        Keep per-ms tracking logs (about 140 bytes per channel and ms). Default True.
    log_every_ms : int, optional
        Log one epoch in this many. Default 1.
    acq_upsample : int, optional
        Zero-stuffing factor of acquisition (default automatic: module notes of
        :mod:`~sdr_di.receiver.acquisition`).
    retry_acquisition_s : float, optional
        Search again for PRNs not found, this often [s]. Default None (never).
    long_noncoherent : int or None, optional
        K of the long search for listed PRNs the first search missed (default 400: 1 ms
        blocks, detection probability 0.9 at about 26 dB-Hz without losses, 29 dB-Hz with
        them). None: no long search.
    assist_doppler_range_hz : float, optional
        Half-width of the search around a predicted Doppler [Hz] (default 1000: the
        prediction's errors from an unknown receiver velocity, 100 m/s = 420 Hz, and about
        0.5 ppm of oscillator offset).
    threads : int, optional
        Threads of the tracking correlator kernel. Default None: chosen at run time between
        1 and numba's thread count by measured speed (see :mod:`~sdr_di.receiver.threads`: short
        parallel regions collapse when other processes load the cores).

    Attributes (after :meth:`run`)
    ------------------------------
    channels : dict
        ``{prn: Channel}`` of every requested PRN.
    acquisition_results : list of AcquisitionResult
        The initial acquisition.
    ephemerides : dict
        ``{prn: Ephemeris}`` decoded.
    klobuchar : Klobuchar or None
        Latest decoded ionosphere coefficients.
    profile : dict
        Seconds per stage (``acquisition``, ``read``, ``correlate``, ``channels``,
        ``callback``, ``tracking``, ``total``), ``steps`` (kernel calls), ``processed_s``
        (file seconds), ``realtime_factor`` (processed seconds per wall second of
        ``tracking``, which includes the re-acquisitions) and ``kernel_s_per_msample`` (kernel
        seconds per million sample-epochs, per thread setting, of the last call's size class:
        :attr:`~sdr_di.receiver.threads.KernelThreads.cost`).
    """

    def __init__(self, config: TrackingConfig | None = None, *, acquisition: dict | None = None,
                 chunk_ms: int = 100, log: bool = True, log_every_ms: int = 1,
                 acq_upsample: int | None = None, retry_acquisition_s: float | None = None,
                 threads: int | None = None, long_noncoherent: int | None = 400,
                 assist_doppler_range_hz: float = 1000.0):
        self.config = config or TrackingConfig()
        self.acq_kwargs = {"noncoherent": 40, "doppler_range_hz": 5000.0, "pfa": 1e-3}
        if acquisition:
            self.acq_kwargs.update(acquisition)
        if int(chunk_ms) < 2:
            raise ValueError(f"chunk_ms must be >= 2, got {chunk_ms}")
        self.chunk_ms = int(chunk_ms)
        self.log = bool(log)
        self.log_every_ms = int(log_every_ms)
        self.acq_upsample = acq_upsample
        self.retry_acquisition_s = retry_acquisition_s
        self.threads = threads
        self.long_noncoherent = None if not long_noncoherent else int(long_noncoherent)
        #: ``predictor(prn, sample) -> SignalPrediction | None`` (module notes, step 4), e.g.
        #: a :class:`~sdr_di.receiver.prediction.FixPredictor`; set by the caller.
        self.predictor: Callable[[int, int], SignalPrediction | None] | None = None
        self.assist_doppler_range_hz = float(assist_doppler_range_hz)
        self.channels: dict[int, Channel] = {}
        self.acquisition_results: list[AcquisitionResult] = []
        self.ephemerides: dict[int, Ephemeris] = {}
        self.klobuchar = None
        self.profile: dict[str, float] = {}

    # -- helpers -----------------------------------------------------------------------------
    def _acquire(self, source: IfSource, sample: int, prns: list[int],
                 **over) -> list[AcquisitionResult]:
        kw = dict(self.acq_kwargs)
        kw.update(over)
        return acquire_source(source, sample, prns=prns, upsample=self.acq_upsample, **kw)

    def _initial_search(self, source: IfSource, sample: int, prns: list[int],
                        assist: dict[int, float | None], listed: bool
                        ) -> list[AcquisitionResult]:
        """Step 1 of the module notes: one cold search shared by the PRNs without a predicted
        Doppler, a narrow search around each predicted Doppler, then, for the PRNs of a list
        (``listed``) still not found, the long non-coherent search."""
        fs = source.sampling_rate_hz
        res: dict[int, AcquisitionResult] = {}
        cold = [p for p in prns if assist.get(p) is None]
        if cold:
            res.update(zip(cold, self._acquire(source, sample, cold)))
        aided = [p for p in prns if p not in res]
        if aided:
            res.update(zip(aided, self._acquire(source, sample, aided,
                                                **self._assisted_windows(aided, assist, fs))))
        k_long = self.long_noncoherent
        missed = [p for p in prns if not res[p].detected]
        # whole coherent blocks the file holds from here: a short file gives no longer search
        n_block = round(int(self.acq_kwargs.get("coherent_ms", 1)) * fs * 1e-3)
        avail = (source.n_samples - sample) // max(1, n_block)
        if listed and k_long and missed and min(k_long, avail) > res[missed[0]].noncoherent:
            # half the Doppler step: the worst straddle loss drops from 0.9 to 0.2 dB, worth
            # the second FFT per bin at the sensitivity the long search is for
            fine = {"noncoherent": k_long,
                    "doppler_step_hz": 0.5 * self._doppler_step(fs)}
            cold = [p for p in missed if assist.get(p) is None]
            if cold:
                res.update(zip(cold, self._acquire(source, sample, cold, **fine)))
            aided = [p for p in missed if assist.get(p) is not None]
            if aided:
                res.update(zip(aided, self._acquire(source, sample, aided, **fine,
                                                    **self._assisted_windows(aided, assist,
                                                                             fs))))
        return [res[p] for p in prns]

    #: Refuse detections real signals cannot give (:meth:`_refuse_implausible`).
    refuse_implausible = True

    def _refuse_implausible(self, source: IfSource) -> None:
        """Stop, or leave channels out, on detections real signals cannot give
        (:func:`~sdr_di.receiver.acquisition.implausible_detections`).

        Many PRNs at zero Doppler, or more than can be in view: the samples are read wrongly
        and every channel would track noise, so the run stops here with the diagnosis
        (:class:`~sdr_di.receiver.acquisition.ImplausibleAcquisition`) instead of tracking
        for the whole file and ending without a fix. Many PRNs at one Doppler away from zero:
        a line or jammer artefact on otherwise good samples; those channels are not started
        (one :class:`~sdr_di.receiver.acquisition.AcquisitionWarning`), the others are.
        """
        if not self.refuse_implausible:
            return
        problem, prns = implausible_detections(self.acquisition_results)
        if problem is None:
            return
        if not prns:
            raise ImplausibleAcquisition(
                f"{source.path}: the acquisition found what real signals cannot give: "
                f"{problem}; the file is read wrongly: likely causes, most likely first: "
                f"{LIKELY_CAUSES}")
        import warnings

        warnings.warn(f"{source.path}: acquisition: {problem}: a line or artefact, not "
                      "satellites; those channels are not started", AcquisitionWarning,
                      stacklevel=2)
        for r in self.acquisition_results:
            if r.prn in prns:
                r.detected = False
                r.notes = (*r.notes, "refused: one Doppler shared with other PRNs")

    def _assisted_windows(self, prns: list[int], assist: dict[int, float | None],
                          fs: float) -> dict:
        """One search of several PRNs at ``fs`` [Hz], each over its :meth:`_assisted_window`
        (the widest half-width for all; the centres on the cold grid's lattice share their
        bins)."""
        wins = {p: self._assisted_window(assist[p], fs) for p in prns}
        return {"doppler_centers": {p: w["doppler_center_hz"] for p, w in wins.items()},
                "doppler_range_hz": max(w["doppler_range_hz"] for w in wins.values())}

    def _assisted_window(self, doppler_hz: float, fs: float) -> dict:
        """Doppler search around a predicted Doppler: the bins of the cold search's grid
        (multiples of its step) that cover ``+-assist_doppler_range_hz`` around it, so that an
        assisted search refines from the same bins as a cold one would."""
        step = self._doppler_step(fs)
        centre = round(doppler_hz / step) * step
        return {"doppler_center_hz": centre,
                "doppler_range_hz": self.assist_doppler_range_hz + abs(doppler_hz - centre)}

    def _pull_in_fll_bw(self, r: AcquisitionResult) -> float | None:
        """Pull-in FLL bandwidth for a channel started from ``r`` [Hz]: the minimum after a
        long search (its Doppler is refined over hundreds of ms of squared prompts, within a
        few Hz, and at the C/N0 it is for, below about 35 dB-Hz, a 10 Hz FLL on 1 ms prompts
        only adds noise: at 32 dB-Hz it walked well-acquired channels 20-50 Hz off until
        pull-in timed out); the configured schedule otherwise."""
        long = r.noncoherent > int(self.acq_kwargs.get("noncoherent", 40))
        return self.config.pull_in_fll_min_bw_hz if long and r.doppler_refined else None

    def _doppler_step(self, fs: float) -> float:
        """Doppler bin spacing of the searches at ``fs`` [Hz] (the acquisition default,
        :func:`~sdr_di.receiver.acquisition.default_doppler_step_hz`, unless configured)."""
        step = self.acq_kwargs.get("doppler_step_hz")
        return float(step) if step else \
            default_doppler_step_hz(int(self.acq_kwargs.get("coherent_ms", 1)), fs)

    def _acq_len(self, fs: float) -> int:
        return int(self.acq_kwargs.get("noncoherent", 20)) * \
            int(self.acq_kwargs.get("coherent_ms", 1)) * round(fs * 1e-3)

    def _collect_ephemerides(self) -> dict[int, Ephemeris]:
        for c in self.channels.values():
            if c.ephemeris is not None:
                self.ephemerides[c.prn] = c.ephemeris
                if c.klobuchar is not None:
                    self.klobuchar = c.klobuchar
        return dict(self.ephemerides)

    # -- main loop ---------------------------------------------------------------------------
    def run(self, source: IfSource, prns: Iterable[int] | None = None,
            on_epoch: OnEpoch | None = None, epoch_interval_s: float = 0.1, *,
            start_sample: int = 0, stop_sample: int | None = None,
            assist: dict[int, float | None] | None = None) -> dict[int, TrackingLog]:
        """Acquire and track ``prns`` over ``source``.

        The stages (module notes): :meth:`_begin` (channels, correlator bank, initial
        acquisition), then until the end of the samples: :meth:`_emit_epochs` (output
        epochs every channel has passed: ``on_epoch``), :meth:`_reacquire` (searches due),
        :meth:`_advance_idle` (nothing tracked: to the next search), :meth:`_next_batch`
        (the channels whose next block is read, reading a chunk when needed) and
        :meth:`_correlate` (their blocks); :meth:`_end` (profile, logs).

        Parameters
        ----------
        source : IfSource
            The IF file.
        prns : iterable of int, optional
            PRNs to search (default all 63).
        on_epoch : callable, optional
            ``on_epoch(sample_index, observations, ephemerides)`` at every output epoch. A
            return value of ``True`` stops the run there (the channels keep their NCO and
            loop states at their next epoch edge: the deep receiver takes over from them).
        epoch_interval_s : float, optional
            Output epoch interval [s]. Default 0.1.
        start_sample, stop_sample : int, optional
            Samples to process (default the whole file).
        assist : dict, optional
            ``{prn: predicted Doppler [Hz] at the start or None}``: the satellites expected
            in the file (a sidecar's list, or the visible ones from ephemeris and a time
            hint). Without ``prns`` they are the PRNs searched; a predicted Doppler narrows
            their search to ``+-assist_doppler_range_hz`` around it (module notes, step 1).

        Returns
        -------
        dict
            ``{prn: TrackingLog}`` of every PRN that was tracked at some point (an empty dict
            when ``log=False``).
        """
        t_total = time.perf_counter()
        passive_kernel_workers()       # before the first parallel kernel (sdr_di.settings)
        r = self._begin(source, prns, on_epoch, epoch_interval_s, start_sample, stop_sample,
                        assist)
        t_track = time.perf_counter()
        while True:
            act = [c for c in r.chans if c.tracking]
            if act:
                r.t_now = max(r.t_now, min(c.next_start for c in act))
            if self._emit_epochs(r, act):
                break
            if self._reacquire(r):
                continue
            if not act:
                if self._advance_idle(r):
                    continue
                break
            batch = self._next_batch(r, act)
            if batch is not None:
                self._correlate(r, batch)
        return self._end(r, t_total, t_track)

    def _begin(self, source: IfSource, prns, on_epoch, epoch_interval_s: float,
               start_sample: int, stop_sample: int | None, assist) -> _ScalarPass:
        """The channels of ``prns`` (default: the assisted ones, else all 63), the correlator
        bank, and the initial acquisition that starts the channels it detects."""
        fs = source.sampling_rate_hz
        assist = {check_prn(p): (None if d is None or not math.isfinite(d) else float(d))
                  for p, d in (assist or {}).items()}
        if prns is None and assist:
            prns = list(assist)
        prn_list = [check_prn(p) for p in (range(1, 64) if prns is None else prns)]
        prn_list = list(dict.fromkeys(prn_list))
        start = int(start_sample)
        stop = source.n_samples if stop_sample is None else min(int(stop_sample),
                                                                  source.n_samples)
        if not 0 <= start < stop:
            raise ValueError(f"empty sample range [{start}, {stop})")
        if not epoch_interval_s > 0:
            raise ValueError(f"epoch_interval_s must be > 0, got {epoch_interval_s}")
        rx_time = None
        if source.start_week is not None and source.start_sow is not None:
            rx_time = source.sample_time
        cfg = self.config
        chans = [Channel(p, fs, source.if_hz, cfg, carrier_hz=source.carrier_hz,
                         rx_time=rx_time, log=self.log, log_every_ms=self.log_every_ms)
                 for p in prn_list]
        self.channels = {c.prn: c for c in chans}
        self.ephemerides = {}
        self.klobuchar = None
        bank = _Bank(len(chans), cfg.spacing_chips, self.threads)
        bank.set_prns(prn_list)
        r = _ScalarPass(
            source=source, on_epoch=on_epoch, epoch_interval_s=epoch_interval_s, fs=fs,
            start=start, stop=stop, chans=chans,
            slot_of={id(c): i for i, c in enumerate(chans)}, bank=bank,
            threads_before=numba.get_num_threads(),
            prof={"acquisition": 0.0, "read": 0.0, "correlate": 0.0, "channels": 0.0,
                  "callback": 0.0, "steps": 0},
            n_acq=self._acq_len(fs),
            reacq_step=max(1, round(cfg.reacq_interval_ms * 1e-3 * fs)),
            retry_step=None if self.retry_acquisition_s is None else
            max(1, round(float(self.retry_acquisition_s) * fs)),
            chunk=max(2 * round(fs * 1e-3), round(self.chunk_ms * 1e-3 * fs)),
            n_comp=2 if source.is_complex else 1, buf0=start, buf1=start,
            next_out=start + round(epoch_interval_s * fs), t_now=start)
        t0 = time.perf_counter()
        self.acquisition_results = []
        if stop - start >= round(fs * 1e-3):  # a file shorter than its search: what it holds
            self.acquisition_results = self._initial_search(
                source, start, prn_list, assist, listed=prns is not None or bool(assist))
            self._refuse_implausible(source)
        for c, res in zip(chans, self.acquisition_results):
            if res.detected:
                c.start(start, res.code_phase_chips, res.doppler_hz, res.cn0_dbhz,
                        fll_bw_hz=self._pull_in_fll_bw(res))
            elif r.retry_step is not None:
                c.next_reacq_sample = start + r.retry_step
        r.prof["acquisition"] += time.perf_counter() - t0
        return r

    def _emit_epochs(self, r: _ScalarPass, act: list[Channel]) -> bool:
        """The output epochs every tracking channel has passed, each handed to ``on_epoch``;
        True when it asked to stop there."""
        while r.next_out < r.t_now and r.next_out < r.stop:
            t0 = time.perf_counter()
            stop_now = False
            if r.on_epoch is not None:
                obs = [c.observation_at(r.next_out) for c in act]
                stop_now = bool(r.on_epoch(r.next_out, obs, self._collect_ephemerides()))
            r.prof["callback"] += time.perf_counter() - t0
            r.k_out += 1
            r.next_out = r.start + round(r.k_out * r.epoch_interval_s * r.fs)
            if stop_now:
                return True
        return False

    def _reacquire(self, r: _ScalarPass) -> bool:
        """The (re-)acquisition searches due now: one full search for the PRNs never found
        (shared FFTs), a narrow one around each lost channel's predicted Doppler (from the
        last fix) or its last Doppler. True when a channel started tracking."""
        t_now, stop = r.t_now, r.stop
        due = [c for c in r.chans if not c.tracking and not c.finished
               and c.next_reacq_sample is not None and c.next_reacq_sample <= t_now]
        if not due:
            return False
        started = False
        t0 = time.perf_counter()
        if t_now + r.n_acq > stop:
            for c in due:
                c.next_reacq_sample = None
            due = []
        cold = [c for c in due if c.state == ChannelState.ACQUIRE]
        results = []
        if cold:
            results = list(zip(cold, self._acquire(r.source, t_now, [c.prn for c in cold])))
        preds = {}
        for c in due:
            if c.state == ChannelState.ACQUIRE:
                continue
            c.begin_reacquisition(t_now)
            centre, half = c.reacquire_search(t_now)
            pred = None if self.predictor is None else self.predictor(c.prn, t_now)
            if pred is not None:
                preds[c.prn] = pred
                centre, half = pred.doppler_hz, self.config.reacq_doppler_range_hz
            results.append((c, self._acquire(r.source, t_now, [c.prn],
                                             doppler_center_hz=centre,
                                             doppler_range_hz=half)[0]))
        for c, res in results:
            step = r.retry_step if c.state == ChannelState.ACQUIRE else r.reacq_step
            if res.detected:
                p = preds.get(c.prn)
                c.reacquired(t_now, res.code_phase_chips, res.doppler_hz, res.cn0_dbhz,
                             t_tx=None if p is None else (p.t_tx_week, p.t_tx_sow))
                started = True
            else:
                c.next_reacq_sample = None if step is None else t_now + step
        r.prof["acquisition"] += time.perf_counter() - t0
        return started

    def _advance_idle(self, r: _ScalarPass) -> bool:
        """Nothing tracked: on to the next search due; with none left, to the end of the
        samples (their output epochs still come). False when the run is over."""
        due = [c.next_reacq_sample for c in r.chans
               if not c.finished and c.next_reacq_sample is not None]
        if not due or min(due) + r.n_acq > r.stop:
            if r.t_now < r.stop:  # nothing more to search: the rest of the file's epochs
                r.t_now = r.stop
                return True
            return False
        r.t_now = max(r.t_now, min(due))
        return True

    def _next_batch(self, r: _ScalarPass, act: list[Channel]) -> list[Channel] | None:
        """The channels whose next block starts before every channel's block end, when the
        samples it needs are read; None after reading them (or after finishing the channels
        whose block runs past the end)."""
        horizon = min(c.block_end for c in act)
        batch = [c for c in act if c.next_start < horizon]
        need_end = max(c.block_end for c in batch)
        if need_end <= r.buf1:
            return batch
        if need_end > r.stop:
            for c in batch:
                if c.block_end > r.stop:
                    c.finished = True
            return None
        t0 = time.perf_counter()
        # read afresh from the earliest sample still needed: re-reading the short overlap
        # (< 2 coherent blocks) is cheaper than concatenating the new chunk
        n_read = min(max(r.chunk, need_end - r.t_now), r.stop - r.t_now)
        # with the input noise power per sample, for the channels' C/N0 estimators
        r.x, r.n_comp, npow = r.source.read_stored_power(r.t_now, n_read)
        r.buf0 = r.t_now
        r.buf1 = r.t_now + n_read
        for c in r.chans:
            c.noise_power_per_sample = npow
        r.prof["read"] += time.perf_counter() - t0
        return None

    def _correlate(self, r: _ScalarPass, batch: list[Channel]) -> None:
        """One kernel call over the batch's blocks; a channel's block needs only its own
        rows, so the channels of the kernel's leading part are processed while its worker
        correlates the others."""
        t0 = time.perf_counter()
        slots = tuple(r.slot_of[id(c)] for c in batch)
        t_ch = [0.0]

        def ready(j: int, outs: np.ndarray, noise, batch=batch, t_ch=t_ch) -> None:
            tc = time.perf_counter()
            batch[j].process_block(outs, noise)
            t_ch[0] += time.perf_counter() - tc

        r.bank.correlate(r.x, r.n_comp, r.buf0, slots, batch, ready)
        r.prof["correlate"] += time.perf_counter() - t0 - t_ch[0]
        r.prof["channels"] += t_ch[0]
        r.prof["steps"] += 1

    def _end(self, r: _ScalarPass, t_total: float, t_track: float) -> dict[int, TrackingLog]:
        """The run's profile and the channels' logs."""
        self._collect_ephemerides()
        numba.set_num_threads(r.threads_before)
        prof = r.prof
        prof["kernel_s_per_msample"] = {t: c * 1e6 for t, c in r.bank.threads.cost.items()}
        end = time.perf_counter()
        prof["tracking"] = end - t_track
        prof["total"] = end - t_total
        prof["processed_s"] = (min(r.t_now, r.stop) - r.start) / r.fs
        prof["realtime_factor"] = prof["processed_s"] / prof["tracking"] \
            if prof["tracking"] > 0 else math.inf
        self.profile = prof
        return {c.prn: c.log for c in r.chans if c.n_acquisitions > 0 and c.log is not None}
