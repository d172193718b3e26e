"""Scalar tracking: configuration, channel states, observations and per-millisecond logs.

This module holds the plain data the tracking stage exchanges with the rest of the receiver;
the channel logic is in :mod:`~sdr_di.receiver.channel`, the file-level driver in
:mod:`~sdr_di.receiver.scalar`, the discriminators/loop filters in
:mod:`~sdr_di.receiver.loops` and C/N0 / lock detection in :mod:`~sdr_di.receiver.lock`.

Integration intervals
---------------------
Every correlation interval is one code epoch (1 ms of satellite time, 10230 chips) starting at
the first sample at or after the epoch's leading edge, so NH and data transitions (which fall
on code-epoch edges) never fall inside a correlation. All channels' current epochs are
correlated in one call of the numba kernel. The loops are updated

* every epoch (1 ms) until the channel is bit synchronized (pull-in, and tracking before NH /
  bit sync);
* then every ``coherent_ms_d1`` (default 10) epochs for D1 or ``coherent_ms_d2`` (default 2)
  for D2, on the sum of the NH-wiped 1 ms correlations of an interval aligned with the bit
  edges (the NCO rates are held over the interval, the phases run on). ``1`` keeps 1 ms
  updates throughout.

Transmit time
-------------
The code NCO is piecewise linear (one rate per epoch). At a sample ``s`` in epoch ``e``
(code phase ``theta(s)`` chips into that epoch), once frame-synchronized on a subframe whose
first bit left the satellite at epoch ``e_sf``::

    t_tx(s) = t_sf + (e - e_sf) * 1 ms + theta(s) / 10.23e6

with ``t_sf`` the subframe's start time from :func:`sdr_di.signal.navmsg.decode_subframe`
(``t_start``: the SOW field for D1; SOW + 0.6 (FraID - 1) s for D2, whose SOW is that of the
frame's first subframe). The week comes from the broadcast WN once decoded, before that from
the IF file's start time (when known), else it is unknown (``None``).

Carrier phase
-------------
``carrier_phase_cycles`` is the carrier NCO phase accumulated since the channel (re)started
tracking, *without* the IF: the integral of the NCO Doppler (whose smoothed value is
``doppler_hz``). It increases with positive
Doppler, i.e. it decreases as the range grows (a RINEX-style phase observable is
``-carrier_phase_cycles`` up to an integer). The Costas loop's half-cycle ambiguity is
resolved by the preamble polarity once frame-synchronized: 0.5 cycle is added, for the rest of
the arc (a loss of the frame alone keeps it), when the data came out inverted. Every
discontinuity of the reported phase increments ``ChannelObservation.slip_count``:
re-acquisition, return to pull-in, and a change of the half-cycle correction (the first
resolution of an inverted arc, which moves the phase reported so far by 0.5 cycle, or a
later preamble of the other polarity: a half-cycle slip of the Costas loop). A D2 satellite
(a preamble every 0.6 s) is resolved within about a second of tracking, a D1 one (every 6 s)
only after several seconds: phases of one ``slip_count`` belong to one continuous arc.
"""

from __future__ import annotations

import dataclasses
import enum
import math

import numpy as np

from ..constants import CODE_LENGTH_B3I

__all__ = ["LOG_FIELDS", "PLL_BT_MAX", "ChannelObservation", "ChannelState", "TrackingConfig",
           "TrackingLog", "pll_stability_problem"]

#: Largest product of the PLL noise bandwidth [Hz] and the coherent time [s] for which the
#: third-order loop stays stable (the one limit of ``TrackingConfig``, ``sdr-di run
#: --pll-bw`` and ``sdr_di.run(pll_bw_hz=)``).
PLL_BT_MAX = 0.25


def pll_stability_problem(pll_bw_hz: float, coherent_s: float,
                          name: str = "track_pll_bw_hz") -> str | None:
    """What is wrong with a PLL noise bandwidth for a coherent time, or None if it is stable.

    Parameters
    ----------
    pll_bw_hz : float
        PLL noise bandwidth once locked [Hz].
    coherent_s : float
        Longest coherent integration time of the loop [s]
        (:attr:`TrackingConfig.max_coherent_s`).
    name : str
        How the message names the bandwidth (the CLI's ``--pll-bw``, the API's
        ``pll_bw_hz``).

    Returns
    -------
    str or None
        ``"NAME B Hz x T ms coherent time = BT > 0.25 (unstable loop): at most B_max Hz"``
        when ``B T`` exceeds :data:`PLL_BT_MAX`.
    """
    bt = pll_bw_hz * coherent_s
    if bt <= PLL_BT_MAX:
        return None
    return (f"{name} {pll_bw_hz:g} Hz x {coherent_s * 1e3:g} ms coherent time = {bt:g} > "
            f"{PLL_BT_MAX:g} (unstable loop): at most {PLL_BT_MAX / coherent_s:g} Hz")


class ChannelState(enum.IntEnum):
    """Channel state machine.

    ``ACQUIRE``: waiting for (or retrying) the initial acquisition; ``PULL_IN``: 1 ms loops with
    FLL assist and wide bandwidths until the carrier locks; ``TRACK``: PLL-only narrow loops, NH
    / bit / frame synchronization and decoding; ``LOST``: code lock lost (C/N0 below threshold,
    or no carrier lock within the pull-in time), the NCO coasts at the last Doppler;
    ``REACQUIRE``: narrow searches around the last Doppler until the signal is found again
    (then ``PULL_IN``).
    """

    ACQUIRE = 0
    PULL_IN = 1
    TRACK = 2
    LOST = 3
    REACQUIRE = 4


@dataclasses.dataclass(frozen=True)
class ChannelObservation:
    """State of one channel at a receiver sample (see the module notes).

    Attributes
    ----------
    prn : int
    sample_index : int
        Receiver sample the observation refers to (file sample index).
    t_tx_week : int or None
        BDT week of the transmit time (None when unknown).
    t_tx_sow : float
        Transmit time of the signal received at ``sample_index`` (satellite clock, BDT
        seconds of week) [s]; NaN unless ``time_valid``.
    doppler_hz : float
        Carrier Doppler estimate [Hz]: the carrier loop's frequency integrator (the NCO
        frequency minus the IF, without the proportional phase-correction term that makes
        the NCO frequency itself jitter by ~0.5 Hz at 40 dB-Hz), which holds the Doppler at
        the middle of the coherent block it steers, carried to ``sample_index`` with the
        loop's frequency-rate integrator (held as it was, it would be off by the rate times
        up to half a block: 0.045 m/s at 9 m/s^2 and 5 ms). Left in it: the third-order
        loop's dynamic-stress error ``B3 / w0^2`` times the line-of-sight jerk (0.0066 s^2
        at 15 Hz: 0.02 m/s in the default scenario's circling), docs/coupling.md.
    carrier_phase_cycles : float
        Accumulated carrier phase (integral of the Doppler) [cycles].
    cn0_dbhz : float
        C/N0 estimate [dB-Hz] (NaN before the first estimate).
    code_lock, carrier_lock : bool
        Lock detector outputs.
    time_valid : bool
        Frame synchronized: ``t_tx_sow`` is the transmit time.
    code_phase_chips : float
        Code NCO phase at ``sample_index`` [chips into the current epoch, 0..10230).
    state : str
        :class:`ChannelState` name.
    slip_count : int
        Carrier-phase discontinuities so far (module notes).
    half_cycle_resolved : bool
        A preamble's polarity has resolved the Costas loop's half-cycle ambiguity of
        ``carrier_phase_cycles`` in the current arc (False from every (re)start of tracking
        or return to pull-in until the next preamble; kept when only the frame is lost).
    """

    prn: int
    sample_index: int
    t_tx_week: int | None
    t_tx_sow: float
    doppler_hz: float
    carrier_phase_cycles: float
    cn0_dbhz: float
    code_lock: bool
    carrier_lock: bool
    time_valid: bool
    code_phase_chips: float = math.nan
    state: str = ""
    slip_count: int = 0
    half_cycle_resolved: bool = False


@dataclasses.dataclass
class TrackingConfig:
    """Loop and detector parameters of the scalar channels (defaults are the documented ones).

    Loop bandwidths [Hz] (noise bandwidths of :class:`~sdr_di.receiver.loops.CarrierLoop` /
    :class:`~sdr_di.receiver.loops.CodeLoop`)
        Pull-in (1 ms updates): third-order PLL ``pull_in_pll_bw_hz`` 18 with second-order FLL
        assist starting at ``pull_in_fll_bw_hz`` 10 and halved every ``fll_halving_ms`` (200)
        down to ``pull_in_fll_min_bw_hz`` 2 (a 10 Hz FLL at 1 ms is too noisy to let the PLL
        lock below ~38 dB-Hz, a 2 Hz one too slow for > 50 Hz errors: the schedule pulls in
        200 Hz errors at 35 dB-Hz within ~1 s); DLL ``pull_in_dll_bw_hz`` 2.
        Track: PLL ``track_pll_bw_hz`` 15, ``track_fll_bw_hz`` 0 (no FLL once locked), DLL
        ``track_dll_bw_hz`` 1 (carrier aided, first order: ``dll_order`` 1).
    Coherent integration [ms] after bit synchronization
        ``coherent_ms_d1`` 10 (a divisor of 20; NH removed, aligned with bit edges),
        ``coherent_ms_d2`` 2 (1 or 2). ``track_pll_bw_hz * coherent_ms / 1000`` must stay
        <= 0.25 (third-order loop stability).
    Correlator
        ``spacing_chips`` 0.5 (early/late at +-0.5 chip).
    C/N0 and lock detection (evaluated every ``lock_eval_ms`` = 20 ms on the last
    ``cn0_window_ms`` = 100 1-ms prompts; C/N0 from ``mean |P|^2`` minus the noise power
    measured on the input samples, or M2M4 without it, see :mod:`~sdr_di.receiver.lock`)
        code lock: C/N0 >= ``cn0_lock_dbhz`` (28); declared lost (``LOST``) after
        ``code_unlock_evals`` (10, i.e. 200 ms) failing evaluations.
        carrier lock: cos 2 phi estimate >= ``pll_lock_threshold`` (0.6); ``pull_in_lock_evals``
        (3) successes move ``PULL_IN`` to ``TRACK``; ``carrier_unlock_evals`` (10) failures
        move ``TRACK`` back to ``PULL_IN``; no carrier lock within ``pull_in_timeout_ms``
        (1500) declares the channel lost.
    NH / bit synchronization
        D1: NH20 correlation over ``nh_sync_bits`` (10) bit periods (200 ms) of prompt I
        values, accepted when the best of the 20 offsets beats the second by ``sync_ratio``
        (2.0). D2: sign changes of prompt I between milliseconds counted at the two parities
        over up to ``d2_sync_ms`` (200), accepted with >= ``d2_sync_min_transitions`` (8) at
        one parity and at most a quarter of that at the other.
    Frame synchronization
        A decoded subframe establishes the time when its start agrees with the receiver clock
        of the IF file within ``time_check_s`` (60 s); without a known file start time two
        consecutive consistent subframes are required. Two consecutive missing preambles drop
        the frame sync.
    Re-acquisition
        every ``reacq_interval_ms`` (500) while lost, ``acquire`` over +-(``reacq_doppler_range_hz``
        (500) + ``reacq_doppler_growth_hz_s`` (10) x outage seconds) around the last Doppler;
        the code epoch count (hence the time) is carried through an outage of up to
        ``coast_max_s`` (300 s) when the re-acquired code phase is within ``coast_tol_chips``
        (1000) of the coasted NCO.
    """

    spacing_chips: float = 0.5
    pull_in_pll_bw_hz: float = 18.0
    pull_in_fll_bw_hz: float = 10.0
    pull_in_fll_min_bw_hz: float = 2.0
    fll_halving_ms: int = 200
    pull_in_dll_bw_hz: float = 2.0
    track_pll_bw_hz: float = 15.0
    track_fll_bw_hz: float = 0.0
    track_dll_bw_hz: float = 1.0
    dll_order: int = 1
    coherent_ms_d1: int = 10
    coherent_ms_d2: int = 2
    lock_eval_ms: int = 20
    cn0_window_ms: int = 100
    cn0_lock_dbhz: float = 28.0
    code_unlock_evals: int = 10
    pll_lock_threshold: float = 0.6
    pull_in_lock_evals: int = 3
    carrier_unlock_evals: int = 10
    pull_in_timeout_ms: int = 1500
    nh_sync_bits: int = 10
    sync_ratio: float = 2.0
    d2_sync_ms: int = 200
    d2_sync_min_transitions: int = 8
    time_check_s: float = 60.0
    reacq_interval_ms: int = 500
    reacq_doppler_range_hz: float = 500.0
    reacq_doppler_growth_hz_s: float = 10.0
    coast_max_s: float = 300.0
    coast_tol_chips: float = 1000.0

    @property
    def max_coherent_s(self) -> float:
        """Longest coherent time of the tracking loops [s]; ``track_pll_bw_hz`` times it
        must stay <= 0.25 (loop stability)."""
        return max(self.coherent_ms_d1, self.coherent_ms_d2) * 1e-3

    def __post_init__(self):
        if self.coherent_ms_d1 not in (1, 2, 4, 5, 10, 20):
            raise ValueError(f"coherent_ms_d1 must divide 20 ms, got {self.coherent_ms_d1}")
        if self.coherent_ms_d2 not in (1, 2):
            raise ValueError(f"coherent_ms_d2 must be 1 or 2, got {self.coherent_ms_d2}")
        for name in ("pull_in_pll_bw_hz", "pull_in_fll_bw_hz", "pull_in_dll_bw_hz",
                     "track_pll_bw_hz", "track_fll_bw_hz", "track_dll_bw_hz"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v}")
        problem = pll_stability_problem(self.track_pll_bw_hz, self.max_coherent_s)
        if problem is not None:
            raise ValueError(problem)
        if not 0.0 <= self.spacing_chips < 1.0:
            raise ValueError(f"spacing_chips must be in [0, 1), got {self.spacing_chips}")
        if self.cn0_window_ms < 10 or self.lock_eval_ms < 1:
            raise ValueError("cn0_window_ms must be >= 10 and lock_eval_ms >= 1")
        if self.cn0_window_ms > 1000:
            raise ValueError("cn0_window_ms must be <= 1000")


#: Columns of a tracking log row (see :class:`TrackingLog`).
LOG_FIELDS = ("sample", "epoch", "code_phase_chips", "code_rate_cps", "doppler_hz",
              "carrier_phase_cycles", "cn0_dbhz", "lock_metric", "code_lock", "carrier_lock",
              "state", "prompt_i", "prompt_q", "early_i", "early_q", "late_i", "late_q")


class TrackingLog:
    """Per-millisecond tracking history of one channel (one row per correlated code epoch).

    Attributes (numpy arrays, one element per logged epoch)
    ------------------------------------------------------
    sample : int64
        First sample of the epoch's correlation interval.
    time_s : float64
        ``sample / fs`` [s] (receiver time since the file start).
    epoch : int64
        Code-epoch counter of the channel.
    code_phase_chips : float64
        Code NCO phase at ``sample`` [chips into the epoch, in [0, code rate / fs)].
    code_rate_cps : float64
        Code NCO rate over the epoch [chips/s].
    doppler_hz : float64
        Carrier Doppler estimate during the epoch [Hz] (the loop's frequency integrator, as
        :attr:`ChannelObservation.doppler_hz`).
    carrier_phase_cycles : float64
        Accumulated carrier phase at ``sample`` [cycles].
    cn0_dbhz, lock_metric : float64
        Latest C/N0 estimate [dB-Hz] and carrier-lock metric (cos 2 phi estimate).
    code_lock, carrier_lock : bool
    state : int8
        :class:`ChannelState` value.
    prompt, early, late : complex128
        1 ms correlator outputs (input units x samples).
    """

    _BLOCK = 4096

    def __init__(self, prn: int, sampling_rate_hz: float):
        self.prn = int(prn)
        self.sampling_rate_hz = float(sampling_rate_hz)
        self._rows: list[tuple] = []
        self._blocks: list[np.ndarray] = []
        self._cache: np.ndarray | None = None

    def append(self, row: tuple) -> None:
        """Add one row (values in :data:`LOG_FIELDS` order)."""
        self._rows.append(row)
        if len(self._rows) >= self._BLOCK:
            self._flush()

    def _flush(self) -> None:
        if self._rows:
            self._blocks.append(np.array(self._rows, dtype=np.float64))
            self._rows = []
        self._cache = None

    def _table(self) -> np.ndarray:
        if self._cache is None or self._rows:
            self._flush()
            if self._blocks:
                self._cache = np.concatenate(self._blocks) if len(self._blocks) > 1 \
                    else self._blocks[0]
                self._blocks = [self._cache]
            else:
                self._cache = np.empty((0, len(LOG_FIELDS)))
        return self._cache

    def __len__(self) -> int:
        return sum(b.shape[0] for b in self._blocks) + len(self._rows)

    def _col(self, name: str) -> np.ndarray:
        return self._table()[:, LOG_FIELDS.index(name)]

    @property
    def sample(self) -> np.ndarray:
        return self._col("sample").astype(np.int64)

    @property
    def time_s(self) -> np.ndarray:
        return self._col("sample") / self.sampling_rate_hz

    @property
    def epoch(self) -> np.ndarray:
        return self._col("epoch").astype(np.int64)

    @property
    def code_phase_chips(self) -> np.ndarray:
        return self._col("code_phase_chips").copy()

    @property
    def code_rate_cps(self) -> np.ndarray:
        return self._col("code_rate_cps").copy()

    @property
    def doppler_hz(self) -> np.ndarray:
        return self._col("doppler_hz").copy()

    @property
    def carrier_phase_cycles(self) -> np.ndarray:
        return self._col("carrier_phase_cycles").copy()

    @property
    def cn0_dbhz(self) -> np.ndarray:
        return self._col("cn0_dbhz").copy()

    @property
    def lock_metric(self) -> np.ndarray:
        return self._col("lock_metric").copy()

    @property
    def code_lock(self) -> np.ndarray:
        return self._col("code_lock") > 0.5

    @property
    def carrier_lock(self) -> np.ndarray:
        return self._col("carrier_lock") > 0.5

    @property
    def state(self) -> np.ndarray:
        return self._col("state").astype(np.int8)

    @property
    def prompt(self) -> np.ndarray:
        return self._col("prompt_i") + 1j * self._col("prompt_q")

    @property
    def early(self) -> np.ndarray:
        return self._col("early_i") + 1j * self._col("early_q")

    @property
    def late(self) -> np.ndarray:
        return self._col("late_i") + 1j * self._col("late_q")

    def arrays(self) -> dict[str, np.ndarray]:
        """All columns as a dict of arrays (plus ``time_s``, ``prompt``, ``early``, ``late``)."""
        out = {name: getattr(self, name) for name in
               ("sample", "time_s", "epoch", "code_phase_chips", "code_rate_cps", "doppler_hz",
                "carrier_phase_cycles", "cn0_dbhz", "lock_metric", "code_lock",
                "carrier_lock", "state", "prompt", "early", "late")}
        return out

    def _locate(self, samples) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(samples, dtype=np.float64)
        starts = self._col("sample")
        if starts.size == 0:
            raise ValueError(f"PRN {self.prn}: empty tracking log")
        i = np.searchsorted(starts, s, side="right") - 1
        if np.any(i < 0):
            raise ValueError(f"PRN {self.prn}: sample before the first logged epoch")
        return s, i

    def code_phase_at(self, samples) -> np.ndarray:
        """Code NCO phase [chips, in [0, 10230)] at arbitrary samples (interpolated within the
        logged epoch containing each sample; exact when every epoch is logged)."""
        s, i = self._locate(samples)
        t = self._table()
        c = LOG_FIELDS.index
        th = t[i, c("code_phase_chips")] + (s - t[i, c("sample")]) * \
            t[i, c("code_rate_cps")] / self.sampling_rate_hz
        return np.mod(th, float(CODE_LENGTH_B3I))

    def doppler_at(self, samples) -> np.ndarray:
        """Carrier Doppler [Hz] of the epoch containing each sample."""
        _, i = self._locate(samples)
        return self._table()[i, LOG_FIELDS.index("doppler_hz")]

    def __repr__(self) -> str:
        return f"TrackingLog(prn={self.prn}, rows={len(self)})"
