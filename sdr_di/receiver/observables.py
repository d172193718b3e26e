"""Raw observables from tracking channels: pseudorange, pseudorange rate, carrier phase.

Input: one :class:`~sdr_di.receiver.tracking.ChannelObservation` per channel, all taken at the
same receive sample index ``k`` (any object with the same attributes will do, see
:class:`ChannelObservationLike`). Output: an :class:`Observables` record at the common
receiver-clock time of sample ``k``.

Receiver time
-------------
The receiver has no time before its first fix. :class:`ReceiverTime` keeps it:

* **initialization** ("the usual trick"): the first time observables are formed, the
  receiver-clock time of sample ``k0`` is set to ``max(t_tx) + nominal_travel_s`` (default
  75 ms: the satellite with the latest transmit time is the nearest one, a MEO near zenith is
  about 72 ms away). The error of this guess (a few ms, up to ~1000 km in range) is common to
  all pseudoranges and is absorbed by the clock bias of the first PVT solution.
  Alternatively :meth:`ReceiverTime.from_sample_zero` uses the time tag of the IF file (sample
  0 at receiver-clock time ``start.week, start.sow`` in the sidecar); the solved bias is then
  the front end's own clock error (the scenario's ``receiver_clock`` in simulation).
* **afterwards** receiver time advances with the sample count only,
  ``t_rx(k) = t_rx0 + (k - k0) / fs``: the clock is *not steered*. The PVT solves the clock
  bias ``b`` [m] (receiver clock minus BDT, times c) and drift [m/s] every epoch and reports
  them; the BDT time of a fix is ``t_rx - b / c``. The bias therefore grows with the
  oscillator drift (e.g. 1e-7 s/s = 30 m/s); that is harmless for the solution. A caller that
  wants a steered clock can apply :meth:`ReceiverTime.shift`.

Observable definitions and signs
--------------------------------
* Pseudorange [m]: ``rho = c (t_rx - t_tx)`` with ``t_tx`` the satellite-clock transmit time
  (BDT week/sow) of the code received at sample ``k``. It contains
  ``range + c b - c dt_sv + T + I`` (receiver bias ``b``, satellite clock ``dt_sv``,
  troposphere ``T`` and ionospheric group delay ``I``).
* Pseudorange rate [m/s]: ``rho_dot = -lambda_B3I * doppler`` with ``lambda_B3I = c / 1268.52
  MHz`` and the Doppler positive for an approaching satellite (range decreasing). Strictly it
  is the *carrier-phase* range rate (the ionosphere enters with a minus sign), per second of
  receiver clock.
* Carrier phase [m] (accumulated delta range): ``phi = -lambda_B3I * carrier_phase_cycles``,
  assuming the channel's ``carrier_phase_cycles`` is the integral of its Doppler (positive
  for an approaching satellite), so ``d phi / dt = rho_dot``. It has an arbitrary constant
  (integer ambiguity, plus a half cycle before the data polarity is resolved) and is only
  given (not NaN) for channels in carrier lock.

A channel contributes a pseudorange when it is in code lock with a valid transmit time; a
pseudorange rate when, in addition, its Doppler is finite (an FLL Doppler without carrier
lock is accepted unless ``require_carrier_lock_for_rate``).

Transmit-time week: a channel may not know its week yet (``t_tx_week`` None until the
broadcast week number is decoded). It is then taken as the week that puts ``t_tx`` nearest
to a reference time: the receiver time once initialized, else the transmit time of a channel
that knows its week, else :attr:`ReceiverTime.time_hint` (e.g. an ephemeris' (week, toe) or
the IF file's start time; it only has to be within +-3.5 days). Without any reference the
channel is left out (listed in :attr:`Observables.unknown_week`).

Precision note: ``t_tx`` arrives as a float seconds of week; near sow = 3.6e5 s its unit in
the last place is 5.8e-11 s, i.e. the pseudorange is quantized to about 1.7 cm. That is far
below tracking noise, but it bounds "exact" end-to-end tests at the centimetre level.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Sequence

import numpy as np

from ..constants import C_LIGHT, LAMBDA_B3I, SECONDS_PER_WEEK
from .tracking import ChannelObservation

__all__ = [
    "NOMINAL_TRAVEL_TIME_S",
    "ChannelObservationLike",
    "ObservableBuilder",
    "Observables",
    "ReceiverTime",
    "form_observables",
]

#: Nominal signal travel time used to initialise the receiver clock [s].
NOMINAL_TRAVEL_TIME_S = 0.075


#: What the observables are formed from (one channel at one sample).
ChannelObservationLike = ChannelObservation


def _normalize(week: int, sow: float) -> tuple[int, float]:
    """Bring ``sow`` into [0, 604800) adjusting ``week``."""
    if 0.0 <= sow < SECONDS_PER_WEEK:
        return int(week), float(sow)
    n = math.floor(sow / SECONDS_PER_WEEK)
    return int(week) + n, float(sow - n * SECONDS_PER_WEEK)


class ReceiverTime:
    """Receiver-clock time of IF samples (BDT scale, not steered).

    Parameters
    ----------
    fs : float
        IF sampling rate [Hz] (samples per second of receiver clock).
    nominal_travel_s : float, optional
        Travel time assumed for the latest transmit time at initialization [s].
    time_hint : (int, float), optional
        Approximate BDT (week, sow [s]), within +-3.5 days, to resolve unknown transmit weeks
        before the clock is initialized (see the module docstring).

    Notes
    -----
    ``t_rx(k) = t_rx0 + (k - k0) / fs`` once initialized (see the module docstring). Times
    are (BDT week, seconds of week).
    """

    def __init__(self, fs: float, nominal_travel_s: float = NOMINAL_TRAVEL_TIME_S,
                 time_hint: tuple[int, float] | None = None):
        if not (fs > 0 and math.isfinite(fs)):
            raise ValueError(f"sampling rate must be positive, got {fs!r}")
        self.fs = float(fs)
        self.nominal_travel_s = float(nominal_travel_s)
        self.time_hint = None if time_hint is None else (int(time_hint[0]), float(time_hint[1]))
        self.k0: int | None = None
        self.week0: int | None = None
        self.sow0: float | None = None

    @classmethod
    def from_sample_zero(cls, fs: float, week: int, sow: float) -> ReceiverTime:
        """Receiver time from the IF file's time tag: sample 0 at (``week``, ``sow``)."""
        rt = cls(fs)
        rt.set(0, week, sow)
        return rt

    @property
    def initialized(self) -> bool:
        """True once the clock has been set."""
        return self.k0 is not None

    def set(self, sample_index: int, week: int, sow: float) -> None:
        """Set the receiver-clock time of sample ``sample_index`` to (``week``, ``sow``)."""
        self.k0 = int(sample_index)
        self.week0, self.sow0 = _normalize(week, sow)

    def initialize(self, sample_index: int, t_tx_week: Sequence[int],
                   t_tx_sow: Sequence[float]) -> None:
        """First-fix initialization: t_rx(sample_index) = max(t_tx) + nominal travel time.

        Parameters
        ----------
        sample_index : int
            Sample at which the transmit times were observed.
        t_tx_week, t_tx_sow : sequence
            Satellite-clock transmit times (BDT week, sow [s]) of the valid channels.
        """
        wk = np.asarray(t_tx_week, np.int64)
        sw = np.asarray(t_tx_sow, float)
        if wk.size == 0:
            raise ValueError("cannot initialise the receiver time without a transmit time")
        ref = int(wk.min())
        rel = (wk - ref) * SECONDS_PER_WEEK + sw
        i = int(np.argmax(rel))
        self.set(sample_index, int(wk[i]), float(sw[i]) + self.nominal_travel_s)

    def shift(self, dt_s: float) -> None:
        """Step the clock by ``dt_s`` [s] (steering; the reported bias changes by -c dt_s)."""
        if not self.initialized:
            raise RuntimeError("receiver time not initialised")
        self.week0, self.sow0 = _normalize(self.week0, self.sow0 + float(dt_s))

    def time_at(self, sample_index: int) -> tuple[int, float]:
        """Receiver-clock time (BDT week, sow [s]) of sample ``sample_index``."""
        if not self.initialized:
            raise RuntimeError("receiver time not initialised")
        return _normalize(self.week0, self.sow0 + (int(sample_index) - self.k0) / self.fs)


@dataclasses.dataclass(frozen=True)
class Observables:
    """Observables of all usable channels at one common receive instant.

    Attributes
    ----------
    sample_index : int
        IF sample index of the common receive instant.
    week : int
        BDT week of the receiver-clock time.
    sow : float
        Receiver-clock time, BDT seconds of week [s] (not corrected for the clock bias).
    prn : ndarray of int, shape (n,)
        PRNs.
    t_tx_week : ndarray of int, shape (n,)
        BDT week of the transmit time.
    t_tx_sow : ndarray, shape (n,)
        Transmit time, satellite clock, BDT seconds of week [s].
    pseudorange_m : ndarray, shape (n,)
        ``c (t_rx - t_tx)`` [m].
    pseudorange_rate_mps : ndarray, shape (n,)
        ``-lambda_B3I * doppler`` [m/s]; NaN where the Doppler is not usable.
    doppler_hz : ndarray, shape (n,)
        Carrier Doppler [Hz], positive for an approaching satellite.
    carrier_phase_m : ndarray, shape (n,)
        ``-lambda_B3I * carrier_phase_cycles`` [m] (ambiguous); NaN without carrier lock.
    cn0_dbhz : ndarray, shape (n,)
        C/N0 estimate [dB-Hz] (NaN if unknown).
    unknown_week : tuple of int
        PRNs left out because their transmit week could not be resolved.
    """

    sample_index: int
    week: int
    sow: float
    prn: np.ndarray
    t_tx_week: np.ndarray
    t_tx_sow: np.ndarray
    pseudorange_m: np.ndarray
    pseudorange_rate_mps: np.ndarray
    doppler_hz: np.ndarray
    carrier_phase_m: np.ndarray
    cn0_dbhz: np.ndarray
    unknown_week: tuple[int, ...] = ()

    @property
    def n(self) -> int:
        """Number of satellites."""
        return int(self.prn.size)

    def select(self, mask: np.ndarray) -> Observables:
        """Subset of satellites (boolean mask or index array)."""
        mask = np.asarray(mask)
        return dataclasses.replace(
            self, **{f: getattr(self, f)[mask] for f in _ARRAY_FIELDS})


_ARRAY_FIELDS = ("prn", "t_tx_week", "t_tx_sow", "pseudorange_m", "pseudorange_rate_mps",
                 "doppler_hz", "carrier_phase_m", "cn0_dbhz")


def form_observables(channels: Iterable[ChannelObservationLike], rx_time: ReceiverTime,
                     *, require_carrier_lock_for_rate: bool = False,
                     sample_index: int | None = None) -> Observables:
    """Form observables from channel observations taken at one sample index.

    Initializes ``rx_time`` (first-fix trick) if it is not yet initialized and at least one
    channel is usable.

    Parameters
    ----------
    channels : iterable of ChannelObservation
        One per channel, all with the same ``sample_index``. Channels without code lock or a
        valid transmit time are skipped; a PRN may appear only once among the usable ones.
    rx_time : ReceiverTime
        The receiver clock (modified on first use).
    require_carrier_lock_for_rate : bool, optional
        Give a pseudorange rate only for channels in carrier lock.
    sample_index : int, optional
        The epoch's sample index. Needed when ``channels`` is empty (every channel lost:
        the epoch still has a receiver time, and zero satellites); checked against the
        channels' otherwise.

    Returns
    -------
    Observables
        Possibly with zero satellites (then ``week``/``sow`` are those of the clock, or
        ``(0, nan)`` if it could not be initialized).

    Raises
    ------
    ValueError
        Channels at different sample indices (or not at ``sample_index``), a PRN twice, or
        neither a channel nor ``sample_index``.
    """
    chans = list(channels)
    if not chans and sample_index is None:
        raise ValueError("no channel observations and no sample index given")
    k = int(chans[0].sample_index if sample_index is None else sample_index)
    for ch in chans:
        if int(ch.sample_index) != k:
            raise ValueError(
                f"channel observations at different samples: the epoch is at sample {k}, "
                f"C{int(ch.prn):02d} at {int(ch.sample_index)}")
    use = [ch for ch in chans
           if ch.code_lock and ch.time_valid and math.isfinite(float(ch.t_tx_sow))]
    prns = [int(ch.prn) for ch in use]
    if len(set(prns)) != len(prns):
        raise ValueError(f"a PRN appears in more than one locked channel: {sorted(prns)}")
    weeks = _resolve_weeks(use, rx_time, k)
    unknown = tuple(int(ch.prn) for ch, w in zip(use, weeks) if w is None)
    use = [ch for ch, w in zip(use, weeks) if w is not None]
    prn = np.array([int(ch.prn) for ch in use], np.int64)
    wk = np.array([w for w in weeks if w is not None], np.int64)
    sw = np.array([float(ch.t_tx_sow) for ch in use], float)
    if not rx_time.initialized and use:
        rx_time.initialize(k, wk, sw)
    if rx_time.initialized:
        week, sow = rx_time.time_at(k)
    else:
        week, sow = 0, float("nan")
    # c (t_rx - t_tx): whole weeks exactly, then the sow difference (exact subtraction)
    pr = C_LIGHT * ((week - wk) * SECONDS_PER_WEEK + (sow - sw))
    dop = np.array([float(ch.doppler_hz) for ch in use], float)
    if require_carrier_lock_for_rate:
        dop_ok = np.array([bool(ch.carrier_lock) for ch in use], bool)
    else:
        dop_ok = np.ones(len(use), bool)
    rate = np.where(dop_ok & np.isfinite(dop), -LAMBDA_B3I * dop, np.nan)
    cph = np.array([float(ch.carrier_phase_cycles) if ch.carrier_lock else np.nan
                    for ch in use], float)
    cn0 = np.array([float(ch.cn0_dbhz) for ch in use], float)
    return Observables(sample_index=k, week=int(week), sow=float(sow), prn=prn, t_tx_week=wk,
                       t_tx_sow=sw, pseudorange_m=pr, pseudorange_rate_mps=rate,
                       doppler_hz=dop, carrier_phase_m=-LAMBDA_B3I * cph, cn0_dbhz=cn0,
                       unknown_week=unknown)


def _resolve_weeks(use: list, rx_time: ReceiverTime, k: int) -> list[int | None]:
    """Transmit week of each channel; unknown ones from the nearest-week rule (module doc)."""
    ref: tuple[int, float] | None = None
    if rx_time.initialized:
        ref = rx_time.time_at(k)
    else:
        known = [ch for ch in use if ch.t_tx_week is not None]
        if known:
            ref = (int(known[0].t_tx_week), float(known[0].t_tx_sow))
        elif rx_time.time_hint is not None:
            ref = rx_time.time_hint
    out: list[int | None] = []
    for ch in use:
        if ch.t_tx_week is not None:
            out.append(int(ch.t_tx_week))
        elif ref is not None:
            out.append(ref[0] + round((ref[1] - float(ch.t_tx_sow)) / SECONDS_PER_WEEK))
        else:
            out.append(None)
    return out


class ObservableBuilder:
    """Stateful observable former: holds the :class:`ReceiverTime` across epochs.

    Parameters
    ----------
    fs : float
        IF sampling rate [Hz].
    rx_time : ReceiverTime, optional
        A preset clock (e.g. :meth:`ReceiverTime.from_sample_zero`); default: initialized at
        the first epoch with usable channels.
    require_carrier_lock_for_rate : bool, optional
        See :func:`form_observables`.
    time_hint : (int, float), optional
        Approximate BDT (week, sow) for a new :class:`ReceiverTime` (ignored with ``rx_time``).
    """

    def __init__(self, fs: float, rx_time: ReceiverTime | None = None, *,
                 require_carrier_lock_for_rate: bool = False,
                 time_hint: tuple[int, float] | None = None):
        self.rx_time = rx_time if rx_time is not None else ReceiverTime(fs, time_hint=time_hint)
        self.require_carrier_lock_for_rate = require_carrier_lock_for_rate

    def __call__(self, channels: Iterable[ChannelObservationLike],
                 sample_index: int | None = None) -> Observables:
        """Observables of one epoch (see :func:`form_observables`)."""
        return form_observables(channels, self.rx_time,
                                require_carrier_lock_for_rate=self.require_carrier_lock_for_rate,
                                sample_index=sample_index)
