"""RINEX 3.05 output of the scalar receiver: B3I observations and decoded navigation data.

Two files per run (names and conventions in ``docs/solution_format.md``):

* an **observation file** (:class:`RinexObsWriter`): BDS only, time system BDT, one epoch per
  output epoch of the receiver, observables ``C6I L6I D6I S6I`` (RINEX 3.05 band 6 = B3,
  attribute I = the B3I signal);
* a **navigation file** (:class:`RinexNavWriter`): every distinct decoded clock/ephemeris
  record once, in the order decoded, and the decoded BDS Klobuchar coefficients as the
  ``BDSA``/``BDSB IONOSPHERIC CORR`` header lines. It reads back through
  :func:`sdr_di.orbits.rinex_nav.load_nav` and ``georinex.load`` to the same values.

Observables (RINEX 3.05 definitions, receiver conventions of
:mod:`sdr_di.receiver.observables`)
    ``C6I`` pseudorange [m] exactly as the PVT used it, ``c (t_rx - t_tx)``: it contains the
    receiver clock offset. ``L6I`` carrier phase [cycles] = minus the integrated Doppler
    (``-carrier_phase_cycles`` of the channel), so that it grows with the range like the
    pseudorange; written for channels in carrier lock only. ``D6I`` Doppler [Hz], positive
    for an approaching satellite. ``S6I`` C/N0 [dB-Hz] (``SIGNAL STRENGTH UNIT DBHZ``).
    The signal strength indicator (SSI, 1-9, RINEX's standardized S/N indicator) of ``C``, ``L`` and
    ``D`` is ``clip(floor(C/N0 / 6), 1, 9)``.

Loss of lock indicator of ``L6I``
    bit 1 (value 2): half-cycle ambiguity, set until the preamble polarity has resolved the
    Costas loop's half cycle (the channel's ``half_cycle_resolved``, else its frame
    synchronization ``time_valid``); bit 0 (value 1): lost lock since the previous epoch
    written, set on the first phase of every arc: a channel's first phase, after any epoch
    without phase, when its ``slip_count`` changed (re-acquisition, return to pull-in,
    half-cycle correction) and at the epoch its half cycle is resolved (the phase may have
    moved by 0.5 cycle then).

Epochs and the receiver clock
    The receiver clock is not steered (:class:`~sdr_di.receiver.observables.ReceiverTime`):
    an epoch is the *receiver-clock* time of the epoch's IF sample, so epochs do **not** fall
    on round seconds (the fraction of the first receive time stays). The epoch is written to
    the RINEX resolution of 1e-7 s (the pseudoranges are those of the exact sample: the
    rounding, below 50 ns, is common to all satellites and moves a satellite position by
    less than 0.2 mm). Pseudoranges and phases are as measured (``RCV CLOCK OFFS APPL 0``);
    where the PVT has a valid fix its clock bias ``b / c`` [s] goes into the epoch record's
    receiver clock offset field, so ``epoch - offset`` is the fix time in BDT, as in the
    solution CSV.

Streaming and atomicity
    Observation epochs are written as they come to ``<final>.body.part``. Some header values
    are known only later (``APPROX POSITION XYZ`` from the first valid fix, ``TIME OF LAST
    OBS``, ``# OF SATELLITES``, ``PRN / # / OBS``), so :meth:`RinexObsWriter.close` writes
    the header and the body to ``<final>.part`` and renames it; :meth:`~RinexObsWriter.abort`
    (or an exception inside a ``with`` block) removes the partial files. The navigation file
    needs the Klobuchar set, which arrives with the decoding, in its header; its records (a
    few per satellite and hour) are kept in memory and the file is written at
    :meth:`RinexNavWriter.close`.

Record formats (RINEX 3.05): observation epoch ``'>',1X,I4,4(1X,I2.2),F11.7,2X,I1,I3,6X,F15.12``
and satellite ``A1,I2.2,m(F14.3,I1,I1)``; BDS navigation record
``A1,I2.2,1X,I4,5(1X,I2.2),3D19.12`` then ``4X,4D19.12``; header lines ``A60`` + label
``A20``.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import os
import shutil
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from .. import __version__
from ..constants import C_LIGHT
from ..errors import OutputError
from ..orbits.ephemeris import Ephemeris, Klobuchar
from ..orbits.rinex_nav import URA_BOUNDS_M, toc_datetime  # the reader's own conventions
from ..timebase import bdt_to_datetime
from .atomic import FinalizingWriter, atomic_open

__all__ = [
    "LLI_HALF_CYCLE",
    "LLI_LOST_LOCK",
    "OBS_TYPES",
    "RINEX_VERSION",
    "RinexNavWriter",
    "RinexObsWriter",
    "RinexOutputs",
    "SatObservation",
    "format_nav_record",
    "rinex_names",
    "signal_strength_indicator",
]

#: RINEX version written.
RINEX_VERSION = "3.05"
#: Observation types of the B3I signal, in file order.
OBS_TYPES = ("C6I", "L6I", "D6I", "S6I")
#: Loss of lock indicator bits (phase only).
LLI_LOST_LOCK = 1
LLI_HALF_CYCLE = 2

_PROGRAM = f"sdr-di {__version__}"
_URA_NONE_M = 12288.0  # URA index 15: no accuracy prediction
_F14_MAX = 9_999_999_999.999


def rinex_names(stem: str) -> tuple[str, str]:
    """File names ``(STEM_obs.rnx, STEM_nav.rnx)`` of a run's RINEX outputs."""
    return f"{stem}_obs.rnx", f"{stem}_nav.rnx"


def signal_strength_indicator(cn0_dbhz: float) -> int | None:
    """RINEX signal strength indicator 1..9 of a C/N0 [dB-Hz] (None when unknown).

    RINEX standardized S/N indicators: 1 below 12 dB-Hz, then one step per 6 dB (5 = 30-35
    dB-Hz), 9 at 54 dB-Hz and above.
    """
    c = float(cn0_dbhz)
    if not math.isfinite(c):
        return None
    return int(min(max(math.floor(c / 6.0), 1), 9))


# --- header helpers -------------------------------------------------------------------------
def _hline(content: str, label: str) -> str:
    """One header line: ``content`` in columns 1-60, ``label`` in 61-80."""
    if len(content) > 60:
        raise ValueError(f"RINEX header {label}: content longer than 60 columns: {content!r}")
    return f"{content:<60}{label:<20}\n"


def _text(value: str, width: int, what: str) -> str:
    """A character field: ASCII, no line break, cut to ``width``."""
    s = str(value)
    if not s.isascii() or any(c in s for c in "\r\n"):
        raise ValueError(f"RINEX {what} must be one line of ASCII text, got {value!r}")
    return f"{s[:width]:<{width}}"


def _pgm_line(program: str, run_by: str, created: _dt.datetime) -> str:
    date = f"{created:%Y%m%d %H%M%S} UTC"
    return _hline(_text(program, 20, "program") + _text(run_by, 20, "run by") + f"{date:<20}",
                  "PGM / RUN BY / DATE")


def _version_line(file_type: str) -> str:
    return _hline(f"{RINEX_VERSION:>9}{'':11}{file_type:<20}{'C: BDS':<20}",
                  "RINEX VERSION / TYPE")


def _now_utc() -> _dt.datetime:
    return _dt.datetime.now(_dt.timezone.utc).replace(tzinfo=None)


def _epoch_fields(week: int, sow: float) -> tuple[_dt.datetime, int]:
    """Calendar time (whole seconds, BDT) and the fraction in units of 1e-7 s of a time."""
    ticks = int(round(float(sow) * 1e7))
    sec, frac = divmod(ticks, 10_000_000)
    return bdt_to_datetime(int(week), 0.0) + _dt.timedelta(seconds=sec), frac


def _time_of_obs(week: int, sow: float, label: str) -> str:
    t, frac = _epoch_fields(week, sow)
    return _hline(f"{t.year:6d}{t.month:6d}{t.day:6d}{t.hour:6d}{t.minute:6d}"
                  f"{t.second:5d}.{frac:07d}{'':5}BDT", label)


# --- observation file -----------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class SatObservation:
    """One satellite's B3I observations at one epoch (NaN = not observed).

    Attributes
    ----------
    prn : int
        BDS PRN, 1..63.
    pseudorange_m : float
        ``C6I`` [m].
    phase_cycles : float
        ``L6I`` [cycles] (minus the integrated Doppler).
    doppler_hz : float
        ``D6I`` [Hz], positive for an approaching satellite.
    cn0_dbhz : float
        ``S6I`` [dB-Hz].
    lli : int
        Loss of lock indicator of ``L6I`` (bit 0 lost lock, bit 1 half-cycle ambiguity).
    """

    prn: int
    pseudorange_m: float = math.nan
    phase_cycles: float = math.nan
    doppler_hz: float = math.nan
    cn0_dbhz: float = math.nan
    lli: int = 0


def _f14(v: float) -> str:
    v = float(v)
    if not math.isfinite(v) or abs(v) > _F14_MAX:
        return " " * 14
    return f"{v:14.3f}"


def _sat_line(s: SatObservation) -> str:
    ssi = signal_strength_indicator(s.cn0_dbhz)
    ssi_c = " " if ssi is None else str(ssi)
    out = [f"C{int(s.prn):02d}"]
    for v, lli, with_ssi in ((s.pseudorange_m, 0, True), (s.phase_cycles, s.lli, True),
                             (s.doppler_hz, 0, True), (s.cn0_dbhz, 0, False)):
        f = _f14(v)
        if not f.strip():
            out.append(" " * 16)
            continue
        out.append(f + (str(lli) if lli else " ") + (ssi_c if with_ssi else " "))
    return "".join(out) + "\n"


class RinexObsWriter(FinalizingWriter):
    """Streaming RINEX 3.05 observation file writer (BDS B3I, BDT).

    Parameters
    ----------
    path : path
        Final file name (nothing carries it until :meth:`close`).
    marker_name : str
        ``MARKER NAME`` (e.g. the IF file's stem).
    interval_s : float, optional
        Nominal epoch interval [s] (``INTERVAL``); omitted when None.
    program, run_by, observer, agency : str
        ``PGM / RUN BY / DATE`` and ``OBSERVER / AGENCY`` fields.
    receiver_number, receiver_type, receiver_version : str
        ``REC # / TYPE / VERS``.
    antenna_number, antenna_type : str
        ``ANT # / TYPE``.
    antenna_delta_hen : (float, float, float)
        ``ANTENNA: DELTA H/E/N`` [m].
    marker_type : str
        ``MARKER TYPE`` (RINEX 3.05 keyword).
    comments : sequence of str
        Extra ``COMMENT`` lines (60 characters each at most).
    creation_time : datetime, optional
        File creation time (UTC) for ``PGM / RUN BY / DATE``; default now.
    """

    def __init__(self, path: str | Path, *, marker_name: str = "SDR-DI",
                 interval_s: float | None = None, program: str = _PROGRAM,
                 run_by: str = "sdr-di", observer: str = "sdr-di", agency: str = "",
                 receiver_number: str = "1", receiver_type: str = "SDR-DI SCALAR B3I",
                 receiver_version: str = __version__, antenna_number: str = "",
                 antenna_type: str = "",
                 antenna_delta_hen: Sequence[float] = (0.0, 0.0, 0.0),
                 marker_type: str = "NON_GEODETIC", comments: Sequence[str] = (),
                 creation_time: _dt.datetime | None = None):
        if interval_s is not None and not (interval_s > 0 and math.isfinite(interval_s)):
            raise ValueError(f"RINEX interval must be positive, got {interval_s!r}")
        self.path = Path(path)
        self.interval_s = interval_s
        self._fixed = {
            "marker_name": _text(marker_name, 60, "marker name"),
            "marker_type": _text(marker_type, 20, "marker type"),
            "pgm": _pgm_line(program, run_by, creation_time or _now_utc()),
            "observer": _text(observer, 20, "observer") + _text(agency, 40, "agency"),
            "receiver": (_text(receiver_number, 20, "receiver number")
                         + _text(receiver_type, 20, "receiver type")
                         + _text(receiver_version, 20, "receiver version")),
            "antenna": (_text(antenna_number, 20, "antenna number")
                        + _text(antenna_type, 20, "antenna type")),
        }
        self.antenna_delta_hen = tuple(float(x) for x in antenna_delta_hen)
        self.comments = [_text(c, 60, "comment") for c in comments]
        self.n_epochs = 0
        self.first: tuple[int, float] | None = None
        self.last: tuple[int, float] | None = None
        self.position_e: tuple[float, float, float] | None = None
        self.counts: dict[int, list[int]] = {}
        self._closed = False
        # receiver adapter state (write): per PRN (slip_count, half_cycle_resolved) of the
        # last epoch written with a phase
        self._arc: dict[int, tuple[int, bool]] = {}
        self._body_path = self.path.with_name(self.path.name + ".body.part")
        try:
            self._body = open(self._body_path, "w", encoding="ascii", newline="")
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot write ({exc.strerror or exc})") from None

    # -- plain-value API
    def write_epoch(self, week: int, sow: float, sats: Iterable[SatObservation],
                    clock_offset_s: float = math.nan,
                    position_e: Sequence[float] | None = None) -> bool:
        """Append one epoch.

        Parameters
        ----------
        week, sow : int, float
            Receiver-clock time of the epoch, BDT week and seconds of week [s].
        sats : iterable of SatObservation
            The satellites observed (written in PRN order; those without any value skipped).
        clock_offset_s : float, optional
            Receiver clock offset [s] (receiver clock minus BDT); blank when NaN.
        position_e : (3,) float, optional
            ECEF position [m] of a valid fix at this epoch: the first one given becomes
            ``APPROX POSITION XYZ``.

        Returns
        -------
        bool
            False (nothing written) for a non-finite time or no satellite.

        Raises
        ------
        OutputError
            The write failed (partial files removed; the writer is closed).
        """
        if self._closed:
            raise ValueError(f"{self.path}: writer is closed")
        if not math.isfinite(float(sow)):
            return False
        rows = sorted((s for s in sats if any(math.isfinite(float(v)) for v in (
            s.pseudorange_m, s.phase_cycles, s.doppler_hz, s.cn0_dbhz))),
            key=lambda s: int(s.prn))
        if not rows:
            return False
        prns = [int(s.prn) for s in rows]
        if len(set(prns)) != len(prns) or not all(1 <= p <= 63 for p in prns):
            raise ValueError(f"RINEX epoch: PRNs must be distinct and in 1..63, got {prns}")
        t, frac = _epoch_fields(week, sow)
        off = float(clock_offset_s)
        off_s = f"{off:15.12f}" if math.isfinite(off) and abs(off) < 1000.0 else ""
        head = (f"> {t.year:4d} {t.month:02d} {t.day:02d} {t.hour:02d} {t.minute:02d}"
                f"{t.second:3d}.{frac:07d}  0{len(rows):3d}{'':6}{off_s}").rstrip() + "\n"
        try:
            self._body.write(head + "".join(_sat_line(s) for s in rows))
        except OSError as exc:
            self.abort()
            raise OutputError(f"{self.path}: write failed ({exc.strerror or exc})") from None
        except BaseException:
            self.abort()
            raise
        for s in rows:
            c = self.counts.setdefault(int(s.prn), [0, 0, 0, 0])
            for i, v in enumerate((s.pseudorange_m, s.phase_cycles, s.doppler_hz, s.cn0_dbhz)):
                c[i] += bool(_f14(v).strip())
        if self.first is None:
            self.first = (int(week), float(sow))
        self.last = (int(week), float(sow))
        if self.position_e is None and position_e is not None:
            p = tuple(float(x) for x in position_e)
            if len(p) == 3 and all(math.isfinite(x) for x in p):
                self.position_e = p
        self.n_epochs += 1
        return True

    # -- receiver adapter
    def write(self, observables, channels: Iterable, solution=None) -> bool:
        """Append the epoch of the scalar receiver (duck-typed, see the module notes).

        Parameters
        ----------
        observables : Observables-like
            ``week``, ``sow`` (receiver clock), ``prn``, ``pseudorange_m``,
            ``pseudorange_rate_mps``, ``doppler_hz``, ``cn0_dbhz`` of the satellites with a
            pseudorange (:class:`~sdr_di.receiver.observables.Observables`).
        channels : iterable of ChannelObservation-like
            Every channel at the epoch's sample (``prn``, ``code_lock``, ``carrier_lock``,
            ``time_valid``, ``carrier_phase_cycles``, ``doppler_hz``, ``cn0_dbhz``,
            ``slip_count``, optionally ``half_cycle_resolved``): phases and LLI come from
            here, and channels in code lock without a pseudorange yet are written with their
            phase, Doppler and C/N0.
        solution : PvtSolution-like, optional
            ``valid``, ``clock_bias_m`` [m], ``r_e`` [m]: the epoch's fix (receiver clock
            offset field and ``APPROX POSITION XYZ``).
        """
        chans = {int(ch.prn): ch for ch in channels}
        rows: dict[int, dict] = {}
        for i, prn in enumerate(observables.prn):
            prn = int(prn)
            rate_ok = math.isfinite(float(observables.pseudorange_rate_mps[i]))
            rows[prn] = {"pseudorange_m": float(observables.pseudorange_m[i]),
                         "doppler_hz": float(observables.doppler_hz[i]) if rate_ok else math.nan,
                         "cn0_dbhz": float(observables.cn0_dbhz[i])}
        for prn, ch in chans.items():
            if prn not in rows and ch.code_lock:
                rows[prn] = {"doppler_hz": float(ch.doppler_hz), "cn0_dbhz": float(ch.cn0_dbhz)}
        sats = []
        arcs: dict[int, tuple[int, bool]] = {}
        for prn, r in rows.items():
            ch = chans.get(prn)
            lli = 0
            if ch is not None and ch.carrier_lock and math.isfinite(float(ch.carrier_phase_cycles)):
                r["phase_cycles"] = -float(ch.carrier_phase_cycles)
                resolved = bool(getattr(ch, "half_cycle_resolved", ch.time_valid))
                slips = int(getattr(ch, "slip_count", 0))
                prev = self._arc.get(prn)
                if prev is None or prev[0] != slips or (resolved and not prev[1]):
                    lli |= LLI_LOST_LOCK
                if not resolved:
                    lli |= LLI_HALF_CYCLE
                arcs[prn] = (slips, resolved)
            sats.append(SatObservation(prn=prn, lli=lli, **r))
        ok = solution is not None and bool(getattr(solution, "valid", False))
        offset = float(solution.clock_bias_m) / C_LIGHT if ok else math.nan
        written = self.write_epoch(observables.week, observables.sow, sats, offset,
                                   solution.r_e if ok else None)
        if written:
            self._arc = arcs
        return written

    # -- header and completion
    def _header(self) -> str:
        f = self._fixed
        lines = [_version_line("OBSERVATION DATA"), f["pgm"]]
        lines += [_hline(c, "COMMENT") for c in (
            "B3I observations of the sdr-di scalar receiver.",
            "Epochs: receiver clock (not steered, BDT scale), not round",
            "seconds. C6I/L6I as measured (include the receiver clock",
            "offset); epoch record clock offset = PVT clock bias / c [s]",
            "where the PVT has a fix: epoch - offset = BDT of the fix.",
            "L6I = -integrated Doppler; D6I > 0 approaching; LLI 2 until",
            "the preamble resolves the half cycle, LLI 1 at arc starts.",
            *self.comments)]
        lines.append(_hline(f["marker_name"], "MARKER NAME"))
        lines.append(_hline(f["marker_type"], "MARKER TYPE"))
        lines.append(_hline(f["observer"], "OBSERVER / AGENCY"))
        lines.append(_hline(f["receiver"], "REC # / TYPE / VERS"))
        lines.append(_hline(f["antenna"], "ANT # / TYPE"))
        pos = self.position_e or (0.0, 0.0, 0.0)
        lines.append(_hline("".join(f"{x:14.4f}" for x in pos), "APPROX POSITION XYZ"))
        lines.append(_hline("".join(f"{x:14.4f}" for x in self.antenna_delta_hen),
                            "ANTENNA: DELTA H/E/N"))
        lines.append(_hline(f"C  {len(OBS_TYPES):3d}" + "".join(f" {t}" for t in OBS_TYPES),
                            "SYS / # / OBS TYPES"))
        lines.append(_hline("DBHZ", "SIGNAL STRENGTH UNIT"))
        if self.interval_s is not None:
            lines.append(_hline(f"{self.interval_s:10.3f}", "INTERVAL"))
        if self.first is not None:
            lines.append(_time_of_obs(*self.first, "TIME OF FIRST OBS"))
            lines.append(_time_of_obs(*self.last, "TIME OF LAST OBS"))
        else:
            lines.append(_hline("no observation epoch (receiver time never set)", "COMMENT"))
        lines.append(_hline(f"{0:6d}", "RCV CLOCK OFFS APPL"))
        lines.append(_hline(f"C L6I {0.0:8.5f}", "SYS / PHASE SHIFT"))
        lines.append(_hline(f"{len(self.counts):6d}", "# OF SATELLITES"))
        for prn in sorted(self.counts):
            lines.append(_hline(f"   C{prn:02d}" + "".join(f"{n:6d}" for n in self.counts[prn]),
                                "PRN / # / OBS"))
        lines.append(_hline("", "END OF HEADER"))
        return "".join(lines)

    def close(self) -> Path:
        """Write the header and the epochs to the final name (atomically).

        Raises
        ------
        OutputError
            Writing or renaming failed (nothing under the final name).
        """
        if self._closed:
            return self.path
        try:
            self._body.close()
            with atomic_open(self.path, "w") as fh, \
                    open(self._body_path, encoding="ascii", newline="") as body:
                fh.write(self._header())
                shutil.copyfileobj(body, fh, 1 << 20)
        except OSError as exc:
            raise OutputError(f"{self.path}: write failed ({exc.strerror or exc})") from None
        finally:
            self._closed = True
            _unlink(self._body_path)
        return self.path

    def abort(self) -> None:
        """Discard everything written (removes the partial files)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._body.close()
        except OSError:
            pass
        _unlink(self._body_path)



def _unlink(path: Path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    except OSError:
        pass


# --- navigation file ------------------------------------------------------------------------
def _d19(v: float) -> str:
    """A ``D19.12`` field (written with an ``E`` exponent, as RINEX 3 allows)."""
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"non-finite navigation value {v!r}")
    if abs(v) < 1e-99:
        v = 0.0
    return f"{v:19.12E}"


def _d12(v: float) -> str:
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"non-finite Klobuchar coefficient {v!r}")
    if abs(v) < 1e-99:
        v = 0.0
    return f"{v:12.4E}"


def _accuracy_m(urai: int) -> float:
    """SV accuracy [m] written for a URA index (the upper bound of the index)."""
    i = int(urai)
    return URA_BOUNDS_M[i] if 0 <= i < len(URA_BOUNDS_M) else _URA_NONE_M


def format_nav_record(eph: Ephemeris, t_tx_sow: float | None = None) -> str:
    """The 8 lines of a RINEX 3.05 BDS navigation record.

    Parameters
    ----------
    eph : Ephemeris
        The record (angles in radians, times BDT).
    t_tx_sow : float, optional
        Transmission time of message [s of BDT week]; default the toe.
    """
    t = toc_datetime(eph)
    if t.microsecond:
        raise ValueError(f"C{eph.prn:02d} toc {eph.toc!r} s is not a whole second")
    tx = eph.toe if t_tx_sow is None or not math.isfinite(float(t_tx_sow)) else float(t_tx_sow)
    vals = (
        (eph.af0, eph.af1, eph.af2),
        (eph.AODE, eph.Crs, eph.Delta_n, eph.M0),
        (eph.Cuc, eph.e, eph.Cus, eph.sqrtA),
        (eph.toe, eph.Cic, eph.Omega0, eph.Cis),
        (eph.i0, eph.Crc, eph.omega, eph.Omega_dot),
        (eph.IDOT, 0.0, eph.week, 0.0),
        (_accuracy_m(eph.URAI), eph.SatH1, eph.TGD1, eph.TGD2),
        (tx, eph.AODC, 0.0, 0.0),
    )
    head = (f"C{int(eph.prn):02d} {t.year:4d} {t.month:02d} {t.day:02d} {t.hour:02d} "
            f"{t.minute:02d} {t.second:02d}")
    lines = [head + "".join(_d19(v) for v in vals[0])]
    lines += ["    " + "".join(_d19(v) for v in row) for row in vals[1:]]
    return "\n".join(lines) + "\n"


class RinexNavWriter(FinalizingWriter):
    """RINEX 3.05 BDS navigation file of the decoded ephemerides and Klobuchar set.

    Records are collected with :meth:`add` / :meth:`update` (each distinct record once, in
    the order first given) and written with the header at :meth:`close` (module notes).

    Parameters
    ----------
    path : path
        Final file name.
    program, run_by : str
        ``PGM / RUN BY / DATE`` fields.
    comments : sequence of str
        Extra ``COMMENT`` lines.
    creation_time : datetime, optional
        File creation time (UTC); default now.
    """

    def __init__(self, path: str | Path, *, program: str = _PROGRAM, run_by: str = "sdr-di",
                 comments: Sequence[str] = (), creation_time: _dt.datetime | None = None):
        self.path = Path(path)
        self._pgm = _pgm_line(program, run_by, creation_time or _now_utc())
        self.comments = [_text(c, 60, "comment") for c in comments]
        self.records: list[tuple[Ephemeris, float | None]] = []
        self._seen: set[Ephemeris] = set()
        self.klobuchar: Klobuchar | None = None
        self._closed = False

    def add(self, eph: Ephemeris, t_tx_sow: float | None = None) -> bool:
        """Keep ``eph`` unless an identical record was given before; True when new.

        ``t_tx_sow`` is the transmission time of message [s of BDT week] (e.g. the time the
        receiver completed its decoding); None writes the toe.
        """
        if self._closed:
            raise ValueError(f"{self.path}: writer is closed")
        # the frozen record is its own key (equal and hashed by its fields, as its
        # dataclasses.astuple would be, which deep-copies every field: 22-25 against 0.5 us
        # of thread CPU a call; docs/notes/speed.md, session 23)
        if eph in self._seen:
            return False
        if not eph.finite():
            raise ValueError(f"C{eph.prn:02d} record with a non-finite parameter")
        self._seen.add(eph)
        self.records.append((eph, t_tx_sow))
        return True

    def update(self, ephemerides: Mapping[int, Ephemeris] | Iterable[Ephemeris],
               klobuchar: Klobuchar | None = None, t_tx_sow: float | None = None) -> int:
        """Add the new records among ``ephemerides`` (in PRN order for a mapping) and keep
        ``klobuchar`` when given; returns how many records were new."""
        recs = ([ephemerides[k] for k in sorted(ephemerides)]
                if isinstance(ephemerides, Mapping) else list(ephemerides))
        if klobuchar is not None:
            self.klobuchar = klobuchar
        return sum(self.add(e, t_tx_sow) for e in recs)

    def _header(self) -> str:
        lines = [_version_line("N: GNSS NAV DATA"), self._pgm]
        lines += [_hline(c, "COMMENT") for c in (
            "Broadcast B3I clock/ephemeris records decoded by sdr-di,",
            "each distinct record once, in the order decoded; BDSA/BDSB",
            "= the last Klobuchar set decoded. Transmission time =",
            "time the receiver completed the record (toe if unknown).",
            *self.comments)]
        if self.klobuchar is not None:
            for name, coeffs in (("BDSA", self.klobuchar.alpha), ("BDSB", self.klobuchar.beta)):
                lines.append(_hline(f"{name} " + "".join(_d12(v) for v in coeffs),
                                    "IONOSPHERIC CORR"))
        lines.append(_hline("", "END OF HEADER"))
        return "".join(lines)

    def close(self) -> Path:
        """Write the file (header and records) atomically; returns its path.

        Raises
        ------
        OutputError
            Writing or renaming failed (nothing under the final name).
        """
        if self._closed:
            return self.path
        self._closed = True
        with atomic_open(self.path, "w") as fh:
            fh.write(self._header())
            for eph, tx in self.records:
                fh.write(format_nav_record(eph, tx))
        return self.path

    def abort(self) -> None:
        """Discard the records (nothing was written to disk)."""
        self._closed = True



# --- both files of a run --------------------------------------------------------------------
class RinexOutputs:
    """The observation and navigation writers of one receiver run.

    Parameters
    ----------
    obs_path, nav_path : path
        Final file names (see :func:`rinex_names`).
    marker_name : str
        ``MARKER NAME`` of the observation file.
    interval_s : float, optional
        Nominal epoch interval [s].
    """

    def __init__(self, obs_path: str | Path, nav_path: str | Path, *,
                 marker_name: str = "SDR-DI", interval_s: float | None = None):
        self.nav = RinexNavWriter(nav_path)
        self.obs = RinexObsWriter(obs_path, marker_name=marker_name, interval_s=interval_s)

    def write(self, observables, channels: Iterable, solution,
              ephemerides: Mapping[int, Ephemeris], klobuchar: Klobuchar | None) -> bool:
        """One receiver epoch: observations (:meth:`RinexObsWriter.write`) and any newly
        decoded record, stamped with the epoch's BDT time (the fix time, else the receiver
        time) as its transmission time."""
        sow = float(getattr(solution, "sow", math.nan)) if solution is not None else math.nan
        self.nav.update(ephemerides, klobuchar, sow if math.isfinite(sow) else None)
        return self.obs.write(observables, channels, solution)

    def close(self) -> tuple[Path, Path]:
        """Finish both files; returns (observation path, navigation path)."""
        try:
            return self.obs.close(), self.nav.close()
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Discard both files."""
        self.obs.abort()
        self.nav.abort()
