"""Reader and interpolator for SP3-c/d precise orbit files (used to test broadcast orbits).

Positions are returned in metres in the file's terrestrial frame (for IGS/IAC products an
ITRF realisation such as IGS14; it differs from CGCS2000 by a few cm, which this module does
not correct) and refer to the satellite **centre of mass**. Broadcast BDS orbits refer to the
antenna phase centre; the difference (about 1-2 m, mostly along the body z axis) is not
modelled here.

Epochs are kept on the file's time scale (``%c`` line: GPS, BDT, GAL, QZS, TAI or UTC) and
converted to BDT: GPST, GST and QZSST are BDT + 14 s, TAI is BDT + 33 s, UTC via the leap
second table of :mod:`sdr_di.timebase`. Times on the BDT scale are handled as *BDT seconds*
``t_bdt = week * 604800 + sow`` (seconds since 2006-01-01 00:00:00 BDT).

Bad or absent values: a position of 0.000000 in all three components and a clock of
999999.999999 (or larger in magnitude) become NaN.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import gzip
import zlib
from pathlib import Path

import numpy as np

from ..constants import SECONDS_PER_WEEK
from ..errors import EphemerisError
from ..timebase import BDT_EPOCH, bdt_minus_utc

__all__ = ["Sp3Orbits", "load_sp3", "bdt_seconds"]

#: Offset BDT - (file time scale) [s] for the scales with a fixed offset.
_SCALE_TO_BDT = {"GPS": -14.0, "GAL": -14.0, "QZS": -14.0, "BDT": 0.0, "BDS": 0.0, "TAI": -33.0}
_BAD_CLOCK = 999999.0


def bdt_seconds(week, sow) -> np.ndarray:
    """BDT seconds since the BDT epoch, ``week * 604800 + sow`` [s]."""
    return np.asarray(week, float) * SECONDS_PER_WEEK + np.asarray(sow, float)


@dataclasses.dataclass
class Sp3Orbits:
    """Precise orbits and clocks of an SP3 file.

    Attributes
    ----------
    path : Path
        The file read.
    version : str
        ``'c'`` or ``'d'`` (or ``'a'``/``'b'``, read the same way).
    time_system : str
        Time scale of the epochs in the file (``'GPS'``, ``'BDT'``, ...).
    coord_system : str
        Coordinate system label of the header (e.g. ``'IGS14'``).
    agency : str
        Producing agency.
    epochs : list[datetime.datetime]
        Epochs on the file's time scale (naive datetimes).
    t_bdt : ndarray, shape (n_epoch,)
        The same epochs as BDT seconds (``week * 604800 + sow``) [s].
    svs : tuple[str, ...]
        Satellite ids (``'C05'``, ``'G01'``...), in header order.
    positions : ndarray, shape (n_epoch, n_sv, 3)
        Centre-of-mass positions, ECEF of the file's frame [m]; NaN where bad/absent.
    clocks : ndarray, shape (n_epoch, n_sv)
        Clock offsets [s]; NaN where bad/absent.
    """

    path: Path
    version: str
    time_system: str
    coord_system: str
    agency: str
    epochs: list[_dt.datetime]
    t_bdt: np.ndarray
    svs: tuple[str, ...]
    positions: np.ndarray
    clocks: np.ndarray

    def index(self, sv: str) -> int:
        """Column of satellite ``sv`` (e.g. ``'C05'``); KeyError naming the file if absent."""
        try:
            return self.svs.index(sv)
        except ValueError:
            raise KeyError(f"satellite {sv} not in {self.path.name}") from None

    def bdt_week_sow(self) -> tuple[np.ndarray, np.ndarray]:
        """Epochs as (BDT week, BDT seconds of week [s]) arrays."""
        week = np.floor(self.t_bdt / SECONDS_PER_WEEK).astype(int)
        return week, self.t_bdt - week * SECONDS_PER_WEEK

    def position(self, sv: str, t_bdt, order: int = 10) -> np.ndarray:
        """Lagrange-interpolated position of ``sv`` at BDT seconds ``t_bdt`` [m], shape (n, 3).

        Uses ``order`` consecutive valid epochs (default 10, i.e. degree 9) centred on each
        time; at 15-min sampling this is good to a few mm for MEO/IGSO/GEO orbits. Times
        outside the span of valid epochs, or whose window would bridge a gap longer than
        twice the nominal sampling, give NaN.
        """
        return self._interp(self.positions[:, self.index(sv), :], t_bdt, order)

    def clock(self, sv: str, t_bdt, order: int = 2) -> np.ndarray:
        """Clock offset of ``sv`` at BDT seconds ``t_bdt`` [s], shape (n,) (linear by default)."""
        return self._interp(self.clocks[:, self.index(sv), None], t_bdt, order)[:, 0]

    def _interp(self, values: np.ndarray, t_bdt, order: int) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t_bdt, float)).ravel()
        ok = np.all(np.isfinite(values), axis=1)
        tv, yv = self.t_bdt[ok], values[ok]
        out = np.full((t.size, values.shape[1]), np.nan)
        m = tv.size
        if m < order:
            return out
        step = float(np.median(np.diff(self.t_bdt))) if self.t_bdt.size > 1 else np.inf
        for i, ti in enumerate(t):
            if not (tv[0] <= ti <= tv[-1]):
                continue
            j = int(np.searchsorted(tv, ti))
            lo = min(max(j - order // 2, 0), m - order)
            ts, ys = tv[lo:lo + order], yv[lo:lo + order]
            if np.max(np.diff(ts)) > 2.0 * step + 1e-6:
                continue
            exact = np.nonzero(ts == ti)[0]
            if exact.size:
                out[i] = ys[exact[0]]
                continue
            x = (ts - ti) / step
            # Lagrange weights w_k = prod_{l != k} (0 - x_l) / (x_k - x_l)
            diff = x[:, None] - x[None, :]
            np.fill_diagonal(diff, 1.0)
            num = np.prod(-x) / (-x)
            w = num / np.prod(diff, axis=1)
            out[i] = w @ ys
        return out


def _open_text(path: Path) -> list[str]:
    if not path.is_file():
        raise EphemerisError(f"SP3 file {path}: not found")
    raw = path.read_bytes()
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:
            raise EphemerisError(f"SP3 file {path}: corrupt gzip data ({exc})") from None
    if b"\x00" in raw or not raw.strip():
        raise EphemerisError(f"SP3 file {path}: empty or binary, not an SP3 text file")
    return raw.decode("latin-1").splitlines()


def _to_bdt_seconds(t: _dt.datetime, scale: str) -> float:
    if scale in _SCALE_TO_BDT:
        return (t - BDT_EPOCH).total_seconds() + _SCALE_TO_BDT[scale]
    if scale == "UTC":
        return (t - BDT_EPOCH).total_seconds() + bdt_minus_utc(t)
    raise ValueError(scale)


def load_sp3(path: str | Path) -> Sp3Orbits:
    """Read an SP3-c or SP3-d file (plain or gzip).

    Raises
    ------
    EphemerisError
        Missing/unreadable file, not SP3, unsupported time system, malformed record line,
        or fewer epochs than the header announces.
    """
    path = Path(path)
    lines = _open_text(path)
    first = lines[0]
    if not first.startswith("#") or len(first) < 3 or first[1] not in "abcd":
        raise EphemerisError(f"SP3 file {path}: not an SP3 file (first line {first[:20]!r})")
    version = first[1]
    try:
        n_epochs = int(first[32:39])
    except ValueError:
        raise EphemerisError(f"SP3 file {path}: unreadable number of epochs in line 1") from None
    coord = first[46:51].strip()
    agency = first[55:60].strip()

    svs: list[str] = []
    n_sat = None
    time_system = None
    body = None
    for i, ln in enumerate(lines[1:], start=1):
        if ln.startswith("+ "):
            if n_sat is None:
                try:
                    n_sat = int(ln[3:6])
                except ValueError:
                    raise EphemerisError(f"SP3 file {path}: bad satellite count, line {i + 1}") from None
            for k in range(17):
                s = ln[9 + 3 * k:12 + 3 * k]
                if not s.strip() or int(s[1:].strip() or 0) == 0 or len(svs) >= n_sat:
                    continue
                svs.append(("G" if s[0] == " " else s[0]) + s[1:].replace(" ", "0"))
        elif ln.startswith("%c") and time_system is None:
            time_system = ln[9:12].strip()
        elif ln.startswith("* "):
            body = i
            break
    if body is None or not svs:
        raise EphemerisError(f"SP3 file {path}: no satellite list or no epoch record")
    if time_system in ("BDS",):
        time_system = "BDT"
    if time_system not in _SCALE_TO_BDT and time_system != "UTC":
        raise EphemerisError(f"SP3 file {path}: unsupported time system {time_system!r}")
    col = {s: k for k, s in enumerate(svs)}

    epochs: list[_dt.datetime] = []
    pos_rows: list[np.ndarray] = []
    clk_rows: list[np.ndarray] = []
    for i in range(body, len(lines)):
        ln = lines[i]
        if ln.startswith("* "):
            try:
                y, mo, d, hh, mi = (int(x) for x in ln[3:31].split()[:5])
                sec = float(ln[3:31].split()[5])
            except (ValueError, IndexError):
                raise EphemerisError(f"SP3 file {path}: bad epoch line {i + 1}") from None
            epochs.append(_dt.datetime(y, mo, d, hh, mi) + _dt.timedelta(seconds=sec))
            pos_rows.append(np.full((len(svs), 3), np.nan))
            clk_rows.append(np.full(len(svs), np.nan))
        elif ln.startswith("P") and epochs:
            sv = ln[1:4].replace(" ", "0")
            k = col.get(sv)
            if k is None:
                continue
            try:
                xyz = np.array([float(ln[4:18]), float(ln[18:32]), float(ln[32:46])])
                clk = float(ln[46:60]) if ln[46:60].strip() else np.nan
            except ValueError:
                raise EphemerisError(f"SP3 file {path}: bad position line {i + 1}") from None
            if np.all(xyz == 0.0):
                xyz[:] = np.nan
            if not np.isfinite(clk) or abs(clk) >= _BAD_CLOCK:
                clk = np.nan
            pos_rows[-1][k] = xyz * 1e3  # km -> m
            clk_rows[-1][k] = clk * 1e-6  # us -> s
        elif ln.startswith("EOF"):
            break
    if len(epochs) < n_epochs:
        raise EphemerisError(
            f"SP3 file {path}: {len(epochs)} epochs, header announces {n_epochs} (truncated file)")
    try:
        t_bdt = np.array([_to_bdt_seconds(t, time_system) for t in epochs])
    except ValueError as exc:   # UTC epochs before 2006: no BDT - UTC leap seconds
        raise EphemerisError(f"SP3 file {path}: {exc}") from None
    return Sp3Orbits(path=path, version=version, time_system=time_system, coord_system=coord,
                     agency=agency, epochs=epochs, t_bdt=t_bdt, svs=tuple(svs),
                     positions=np.stack(pos_rows), clocks=np.stack(clk_rows))
