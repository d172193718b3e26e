"""Navigation solution files: CSV epochs and NMEA 0183 GGA/RMC sentences.

Both writers stream: open once, :meth:`~SolutionCsvWriter.write` one
:class:`~sdr_di.receiver.pvt.PvtSolution` per epoch, :meth:`~SolutionCsvWriter.close` at the
end. Everything goes to ``<name>.part`` (:func:`sdr_di.io.atomic.atomic_open`) and is renamed
to ``<name>`` only by a successful ``close``; an exception inside a ``with`` block, a write
error (disk full) or :meth:`~SolutionCsvWriter.abort` removes the partial file, so nothing
ever carries the final name unless it is complete.

Output rate: with ``rate_hz`` given, the first epoch of each interval
``[k / rate_hz, (k + 1) / rate_hz)`` of BDT (fix time, 1 microsecond tolerance) is written
and the others are skipped; ``None`` writes every epoch. The receiver clock is not steered,
so the written instants carry the fraction of second of the receiver's epochs.

Times: the fix time is BDT ``(week, sow)`` = receiver time minus clock bias / c; UTC =
BDT - (BDT - UTC leap seconds) from :mod:`sdr_di.timebase` (4 s since 2017).

The CSV layout is documented in ``docs/solution_format.md``; :data:`CSV_COLUMNS` lists the
columns. NMEA conventions (also in the doc): talker ``GN`` by default (configurable, e.g.
``GB`` for NMEA 4.10 BeiDou or ``BD``); latitude ``ddmm.mmmmm`` and longitude
``dddmm.mmmmm`` with ``decimals`` (default 5) decimals of minutes; GGA altitude is the
*ellipsoidal* height with geoid separation 0.0 (no geoid model: altitude + separation = h);
GGA quality 1 for a valid fix else 0 with empty position fields; RMC status A/V and NMEA 2.3
mode indicator A/N, speed in knots and course over ground in degrees true from the ENU
velocity; sentences end with ``*hh`` (XOR of the characters between ``$`` and ``*``, two
upper-case hex digits) and CR LF.
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from ..constants import SECONDS_PER_WEEK
from ..errors import OutputError, SdrDiError, SolutionFileError  # noqa: F401
from ..frames import C_e_n
from ..timebase import bdt_minus_utc, bdt_to_datetime
from .atomic import FinalizingWriter, atomic_open

__all__ = [
    "CSV_COLUMNS",
    "CSV_MAGIC",
    "NmeaWriter",
    "SolutionCsvWriter",
    "SolutionFileError",
    "bdt_to_utc",
    "format_gga",
    "format_rmc",
    "nmea_checksum",
    "nmea_sentence",
    "read_solution_csv",
    "write_nmea",
    "write_solution_csv",
]

#: First line of a solution CSV file.
CSV_MAGIC = "# sdr-di solution v1"
#: CSV columns, in order (units in docs/solution_format.md).
CSV_COLUMNS = (
    "week", "sow", "utc", "rx_week", "rx_sow",
    "lat_deg", "lon_deg", "h_m", "x_m", "y_m", "z_m",
    "ve_mps", "vn_mps", "vu_mps", "clock_bias_m", "clock_drift_mps",
    "n_sats", "gdop", "pdop", "hdop", "vdop", "tdop", "status", "velocity_status",
    "pos_sd_e_m", "pos_sd_n_m", "pos_sd_u_m", "vel_sd_e", "vel_sd_n", "vel_sd_u",
)
#: Columns a file written before the formal sigmas were added ends with (read with the
#: sigma columns NaN).
_CSV_COLUMNS_V1_0 = CSV_COLUMNS[:-6]
_INT_COLS = ("week", "rx_week", "n_sats")
_STR_COLS = ("utc", "status", "velocity_status")
_FMT = {"sow": "%.9f", "rx_sow": "%.9f", "lat_deg": "%.10f", "lon_deg": "%.10f",
        "h_m": "%.4f", "x_m": "%.4f", "y_m": "%.4f", "z_m": "%.4f", "ve_mps": "%.5f",
        "vn_mps": "%.5f", "vu_mps": "%.5f", "clock_bias_m": "%.4f",
        "clock_drift_mps": "%.5f", "gdop": "%.3f", "pdop": "%.3f", "hdop": "%.3f",
        "vdop": "%.3f", "tdop": "%.3f", **dict.fromkeys(
            ("pos_sd_e_m", "pos_sd_n_m", "pos_sd_u_m"), "%.4f"),
        **dict.fromkeys(("vel_sd_e", "vel_sd_n", "vel_sd_u"), "%.5f")}
_KNOTS_PER_MPS = 3600.0 / 1852.0




class _Abort(Exception):
    """Thrown into the atomic writer to discard the partial file."""


# --- time -----------------------------------------------------------------------------------
def bdt_to_utc(week: int, sow: float) -> _dt.datetime:
    """UTC (naive datetime) of a BDT instant (week, sow [s]), leap seconds from timebase."""
    bdt = bdt_to_datetime(int(week), float(sow))
    utc = bdt - _dt.timedelta(seconds=bdt_minus_utc(bdt))
    return bdt - _dt.timedelta(seconds=bdt_minus_utc(utc))


def _utc_of(sol) -> _dt.datetime | None:
    if not math.isfinite(sol.sow):
        return None
    return bdt_to_utc(sol.week, sol.sow)


def _round_dt(t: _dt.datetime, us: int) -> _dt.datetime:
    """Round to a multiple of ``us`` microseconds (carrying into seconds, days...)."""
    base = t.replace(microsecond=0)
    q = int(round(t.microsecond / us)) * us
    return base + _dt.timedelta(microseconds=q)


# --- CSV ------------------------------------------------------------------------------------
def _f(x: float, fmt: str) -> str:
    x = float(x)
    return fmt % x if math.isfinite(x) else "nan"


def _week_sow(week: int, sow: float) -> tuple[str, str]:
    """The week and seconds-of-week fields of a time: both empty while it is unknown (the
    rows before the receiver clock is set by the first fix), not a week 0."""
    if not math.isfinite(float(sow)):
        return "", ""
    return str(int(week)), _FMT["sow"] % float(sow)


def _csv_row(sol) -> str:
    utc = _utc_of(sol)
    utc_s = "" if utc is None else utc.strftime("%Y-%m-%dT%H:%M:%S.%f") + "Z"
    llh = np.asarray(sol.llh, float)
    vals = {
        "week": _week_sow(sol.week, sol.sow)[0], "utc": utc_s,
        "rx_week": _week_sow(sol.rx_week, sol.rx_sow)[0],
        "sow": _week_sow(sol.week, sol.sow)[1], "rx_sow": _week_sow(sol.rx_week, sol.rx_sow)[1],
        "lat_deg": _f(math.degrees(llh[0]), _FMT["lat_deg"]),
        "lon_deg": _f(math.degrees(llh[1]), _FMT["lon_deg"]),
        "h_m": _f(llh[2], _FMT["h_m"]),
        "n_sats": str(int(sol.n_sats)),
        "clock_bias_m": _f(sol.clock_bias_m, _FMT["clock_bias_m"]),
        "clock_drift_mps": _f(sol.clock_drift_mps, _FMT["clock_drift_mps"]),
        "status": str(sol.status), "velocity_status": str(sol.velocity_status),
    }
    for name, v in zip(("x_m", "y_m", "z_m"), np.asarray(sol.r_e, float)):
        vals[name] = _f(v, _FMT[name])
    for name, v in zip(("ve_mps", "vn_mps", "vu_mps"), np.asarray(sol.v_n, float)):
        vals[name] = _f(v, _FMT[name])
    for name in ("gdop", "pdop", "hdop", "vdop", "tdop"):
        vals[name] = _f(getattr(sol.dops, name), _FMT[name])
    sd = _enu_sd(sol)
    for j, name in enumerate(CSV_COLUMNS[-6:]):
        vals[name] = _f(sd[j], _FMT[name])
    return ",".join(vals[c] for c in CSV_COLUMNS) + "\n"


def _enu_sd(sol) -> np.ndarray:
    """The fix's formal 1-sigma (6,): position E, N, U [m] from ``cov`` (x, y, z block) and
    velocity E, N, U [m/s] from ``cov_v``, rotated from ECEF to ENU at the fix; NaN without
    a valid fix (position) or velocity solution."""
    out = np.full(6, math.nan)
    llh = np.asarray(getattr(sol, "llh", np.full(3, math.nan)), float)
    if not getattr(sol, "valid", str(sol.status) == "fix") or not np.isfinite(llh[:2]).all():
        return out
    C = C_e_n(llh[0], llh[1])
    for k, cov in enumerate((getattr(sol, "cov", None), getattr(sol, "cov_v", None))):
        P = np.asarray(cov if cov is not None else np.full((4, 4), math.nan), float)[:3, :3]
        if np.isfinite(P).all():
            out[3 * k:3 * k + 3] = np.sqrt(np.clip(np.diagonal(C @ P @ C.T), 0.0, None))
    if str(sol.velocity_status) != "fix":
        out[3:] = math.nan
    return out


_CSV_HEADER = (
    CSV_MAGIC,
    ("# time: week, sow = BDT of the fix (receiver time - clock_bias_m / c) [s]; utc = ISO 8601 "
     "UTC (BDT - leap seconds); rx_week, rx_sow = receiver-clock time of the epoch [s]"),
    ("# position: lat_deg, lon_deg [deg] geodetic CGCS2000, h_m ellipsoidal height [m]; "
     "x_m, y_m, z_m ECEF CGCS2000 [m]"),
    "# velocity: ve_mps, vn_mps, vu_mps East-North-Up [m/s]",
    "# clock: clock_bias_m = c * (receiver clock - BDT) [m]; clock_drift_mps its rate [m/s]",
    "# geometry: n_sats used; gdop, pdop, hdop, vdop, tdop (unweighted, ENU)",
    ("# sigma: pos_sd_e_m, pos_sd_n_m, pos_sd_u_m [m], vel_sd_e, vel_sd_n, vel_sd_u [m/s]: the "
     "fix's formal 1-sigma, East-North-Up, from the weighted least squares' covariance"),
    ("# status: fix | too_few_satellites | bad_geometry | no_convergence | large_residuals "
     "(| not_computed for velocity_status); nan = no value"),
)


class _StreamWriter(FinalizingWriter):
    """Streaming text writer on top of :func:`atomic_open` with output-rate decimation."""

    def __init__(self, path: str | Path, rate_hz: float | None):
        if rate_hz is not None and not (rate_hz > 0 and math.isfinite(rate_hz)):
            raise ValueError(f"output rate must be positive, got {rate_hz!r}")
        self.path = Path(path)
        self.rate_hz = None if rate_hz is None else float(rate_hz)
        self.n_written = 0
        self._last_slot: int | None = None
        self._closed = False
        self._cm = atomic_open(self.path, "w")
        self._fh = self._cm.__enter__()
        try:
            self._fh.write(self._header())
        except OSError as exc:
            self._fail(exc)
        except BaseException:
            self.abort()
            raise

    # -- subclass hooks
    def _header(self) -> str:
        return ""

    def _format(self, sol) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- API
    def _due(self, sol) -> bool:
        if self.rate_hz is None:
            return True
        t = float(sol.week) * SECONDS_PER_WEEK + float(sol.sow)
        if not math.isfinite(t):
            t = float(sol.rx_week) * SECONDS_PER_WEEK + float(sol.rx_sow)
        if not math.isfinite(t):
            return False
        slot = math.floor((t + 1e-6) * self.rate_hz)
        if self._last_slot is not None and slot <= self._last_slot:
            return False
        self._last_slot = slot
        return True

    def write(self, sol) -> bool:
        """Append one epoch (a :class:`~sdr_di.receiver.pvt.PvtSolution`).

        Returns
        -------
        bool
            True if written, False if skipped by the output rate.

        Raises
        ------
        OutputError
            The write failed (the partial file is removed; the writer is closed).
        """
        if self._closed:
            raise ValueError(f"{self.path}: writer is closed")
        if not self._due(sol):
            return False
        try:
            self._fh.write(self._format(sol))
        except OSError as exc:
            self._fail(exc)
        except BaseException:
            self.abort()
            raise
        self.n_written += 1
        return True

    def write_all(self, solutions: Iterable) -> int:
        """Write many epochs; returns how many were written (not skipped)."""
        return sum(self.write(s) for s in solutions)

    def close(self) -> Path:
        """Finish: flush, close and rename ``.part`` to the final name.

        Raises
        ------
        OutputError
            The final flush or rename failed (nothing under the final name).
        """
        if self._closed:
            return self.path
        self._closed = True
        self._cm.__exit__(None, None, None)
        return self.path

    def abort(self) -> None:
        """Discard everything written (removes the ``.part`` file)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._cm.__exit__(_Abort, _Abort(), None)
        except OutputError:  # closing the partial file failed too: it is removed anyway
            pass

    def _fail(self, exc: OSError):
        self.abort()
        raise OutputError(f"{self.path}: write failed ({exc.strerror or exc})") from None



class SolutionCsvWriter(_StreamWriter):
    """Streaming CSV solution writer (columns :data:`CSV_COLUMNS`).

    Parameters
    ----------
    path : path
        Final file name (written as ``path.part`` until :meth:`close`).
    rate_hz : float, optional
        Output rate [Hz]; None writes every epoch.
    """

    def __init__(self, path: str | Path, rate_hz: float | None = None):
        super().__init__(path, rate_hz)

    def _header(self) -> str:
        lines = list(_CSV_HEADER)
        if self.rate_hz is not None:
            lines.append(f"# rate_hz: {self.rate_hz!r}")
        return "\n".join(lines) + "\n" + ",".join(CSV_COLUMNS) + "\n"

    def _format(self, sol) -> str:
        return _csv_row(sol)


def write_solution_csv(path: str | Path, solutions: Iterable, rate_hz: float | None = None
                       ) -> Path:
    """Write all ``solutions`` to a CSV file atomically; returns the path."""
    with SolutionCsvWriter(path, rate_hz) as w:
        w.write_all(solutions)
    return Path(path)


def read_solution_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Read a solution CSV file.

    Returns
    -------
    dict
        Column name -> array: ``week``, ``rx_week``, ``n_sats`` int64; ``utc``, ``status``,
        ``velocity_status`` str; everything else float64 (NaN where the file says ``nan``;
        the sigma columns NaN in a file written before they existed).

    Raises
    ------
    SolutionFileError
        Not a solution file, wrong columns, or an unparsable value (file and line named).
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise SolutionFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not lines or lines[0].strip() != CSV_MAGIC:
        raise SolutionFileError(f"{path}: not an sdr-di solution file (first line "
                                f"{lines[0][:40] if lines else ''!r})")
    i = 0
    while i < len(lines) and lines[i].startswith("#"):
        i += 1
    names = tuple(lines[i].split(",")) if i < len(lines) else ()
    if names not in (CSV_COLUMNS, _CSV_COLUMNS_V1_0):
        raise SolutionFileError(f"{path}: line {i + 1}: expected the column line "
                                f"{','.join(CSV_COLUMNS)}")
    cols: dict[str, list] = {c: [] for c in CSV_COLUMNS}
    for ln, line in enumerate(lines[i + 1:], start=i + 2):
        if not line.strip():
            continue
        parts = line.split(",")
        if len(parts) != len(names):
            raise SolutionFileError(f"{path}: line {ln}: {len(parts)} fields, expected "
                                    f"{len(names)}")
        parts += ["nan"] * (len(CSV_COLUMNS) - len(names))    # an older file: no sigmas
        for c, p in zip(CSV_COLUMNS, parts):
            try:
                # an empty week / seconds of week: the time is not known yet (0 and NaN)
                cols[c].append(p if c in _STR_COLS else (int(p) if p else 0) if c in _INT_COLS
                               else float(p) if p else math.nan)
            except ValueError:
                raise SolutionFileError(f"{path}: line {ln}: column {c}: bad value {p!r}") from None
    out: dict[str, np.ndarray] = {}
    for c in CSV_COLUMNS:
        if c in _STR_COLS:
            out[c] = np.array(cols[c], dtype=str)
        elif c in _INT_COLS:
            out[c] = np.array(cols[c], dtype=np.int64)
        else:
            out[c] = np.array(cols[c], dtype=float)
    return out


# --- NMEA -----------------------------------------------------------------------------------
def nmea_checksum(body: str) -> str:
    """NMEA checksum of the characters between ``$`` and ``*``: two upper-case hex digits."""
    x = 0
    for ch in body.encode("ascii"):
        x ^= ch
    return f"{x:02X}"


def nmea_sentence(body: str) -> str:
    """``$body*hh`` (no line terminator)."""
    if any(c in body for c in "$*\r\n"):
        raise ValueError(f"NMEA sentence body must not contain $, * or line breaks: {body!r}")
    return f"${body}*{nmea_checksum(body)}"


def _angle(deg: float, deg_digits: int, decimals: int) -> str:
    """|deg| as d..dmm.m..m (degrees zero-padded to ``deg_digits``), minutes rounded."""
    scale = 10 ** decimals
    total = int(round(abs(deg) * 60.0 * scale))
    d, m = divmod(total, 60 * scale)
    mi, mf = divmod(m, scale)
    frac = f".{mf:0{decimals}d}" if decimals > 0 else ""
    return f"{d:0{deg_digits}d}{mi:02d}{frac}"


def _latlon_fields(sol, decimals: int) -> list[str]:
    llh = np.asarray(sol.llh, float)
    if not sol.valid or not np.all(np.isfinite(llh[:2])):
        return ["", "", "", ""]
    lat, lon = math.degrees(llh[0]), math.degrees(llh[1])
    lon = (lon + 180.0) % 360.0 - 180.0
    return [_angle(lat, 2, decimals), "N" if lat >= 0 else "S",
            _angle(lon, 3, decimals), "E" if lon >= 0 else "W"]


def _time_fields(sol) -> tuple[str, str]:
    """(hhmmss.ss, ddmmyy) of the fix in UTC, or empty strings."""
    utc = _utc_of(sol)
    if utc is None:
        return "", ""
    utc = _round_dt(utc, 10_000)
    return f"{utc:%H%M%S}.{utc.microsecond // 10_000:02d}", f"{utc:%d%m%y}"


def format_gga(sol, talker: str = "GN", decimals: int = 5) -> str:
    """GGA sentence (no CR LF) of a solution.

    Fields: UTC time hhmmss.ss, latitude ddmm.mmmmm, N/S, longitude dddmm.mmmmm, E/W,
    quality (1 fix, 0 none), satellites used (2 digits), HDOP (0.1), altitude [m] (ellipsoidal
    height, 0.001), M, geoid separation 0.0, M, empty age and station of differential data.
    """
    hms, _ = _time_fields(sol)
    ok = sol.valid
    pos = _latlon_fields(sol, decimals)
    hdop = sol.dops.hdop
    fields = [f"{talker}GGA", hms, *pos, "1" if ok else "0", f"{int(sol.n_sats):02d}",
              f"{hdop:.1f}" if ok and math.isfinite(hdop) else "",
              f"{float(sol.llh[2]):.3f}" if ok else "", "M" if ok else "",
              "0.0" if ok else "", "M" if ok else "", "", ""]
    return nmea_sentence(",".join(fields))


def format_rmc(sol, talker: str = "GN", decimals: int = 5) -> str:
    """RMC sentence (NMEA 2.3, no CR LF) of a solution.

    Fields: UTC time, status A/V, latitude, N/S, longitude, E/W, speed over ground [knots]
    (0.001), course over ground [deg true] (0.01; empty without a valid velocity), date
    ddmmyy, empty magnetic variation and its direction, mode A (autonomous) or N.
    """
    hms, date = _time_fields(sol)
    ok = sol.valid
    pos = _latlon_fields(sol, decimals)
    v = np.asarray(sol.v_n, float)
    vel_ok = ok and sol.velocity_valid and np.all(np.isfinite(v[:2]))
    if vel_ok:
        speed = math.hypot(v[0], v[1]) * _KNOTS_PER_MPS
        course = math.degrees(math.atan2(v[0], v[1])) % 360.0
        spd_s, cog_s = f"{speed:.3f}", f"{course:.2f}"
        if cog_s == "360.00":
            cog_s = "0.00"
    else:
        spd_s = cog_s = ""
    fields = [f"{talker}RMC", hms, "A" if ok else "V", *pos, spd_s, cog_s, date, "", "",
              "A" if ok else "N"]
    return nmea_sentence(",".join(fields))


_FORMATTERS = {"GGA": format_gga, "RMC": format_rmc}


class NmeaWriter(_StreamWriter):
    """Streaming NMEA 0183 writer (GGA and/or RMC per epoch, CR LF terminated).

    Parameters
    ----------
    path : path
        Final file name (written as ``path.part`` until :meth:`close`).
    rate_hz : float, optional
        Output rate [Hz] (default 1 Hz, the usual NMEA rate); None writes every epoch.
    talker : str
        Two-character talker identifier (default ``GN``).
    sentences : sequence of str
        Sentences per epoch, from ``GGA``, ``RMC`` (default both, in this order).
    decimals : int
        Decimals of the minutes of latitude/longitude (default 5).
    """

    def __init__(self, path: str | Path, rate_hz: float | None = 1.0, talker: str = "GN",
                 sentences: Sequence[str] = ("GGA", "RMC"), decimals: int = 5):
        if len(talker) != 2 or not talker.isalpha() or not talker.isupper():
            raise ValueError(f"NMEA talker must be two upper-case letters, got {talker!r}")
        bad = [s for s in sentences if s not in _FORMATTERS]
        if bad or not sentences:
            raise ValueError(f"NMEA sentences must be from {sorted(_FORMATTERS)}, got "
                             f"{list(sentences)!r}")
        if not 0 <= int(decimals) <= 8:
            raise ValueError(f"NMEA decimals must be 0..8, got {decimals!r}")
        self.talker = talker
        self.sentences = tuple(sentences)
        self.decimals = int(decimals)
        super().__init__(path, rate_hz)

    def _format(self, sol) -> str:
        return "".join(_FORMATTERS[s](sol, self.talker, self.decimals) + "\r\n"
                       for s in self.sentences)


def write_nmea(path: str | Path, solutions: Iterable, rate_hz: float | None = 1.0,
               **kw) -> Path:
    """Write all ``solutions`` as NMEA atomically (options as :class:`NmeaWriter`)."""
    with NmeaWriter(path, rate_hz, **kw) as w:
        w.write_all(solutions)
    return Path(path)
