"""Read BDS broadcast ephemerides from RINEX 3.0x and 4.0x navigation files.

Design
------
georinex 1.16.2 is the project's RINEX library, but on real BDS navigation files it silently
fails: a record whose all-blank *spare* fields are written as 19 spaces makes its
``float()`` fail, the whole record turns into NaN and the only trace is a logging INFO line
("malformed line for C22"). Every shipped station file (ESBC, MOJN, NYA1, BRDC00WRD) is
affected, so ``georinex.load(..., use='C')`` returns the right satellites and times with
NaN for every value. RINEX 4 files are not read by georinex at all (1.16.2); this module
reads their BDS frames itself (below).

This module therefore reads the BDS records with its own small fixed-width parser, which is
the path that actually works, and uses georinex only where it is reliable:

* **Records** are parsed here: RINEX 3 layout ``A3,1X,I4,5(1X,I2)`` + 3 x D19.12 on the
  first line, then 7 lines of ``4X,4D19.12``. Exponents may be written ``D`` or ``E``. A
  blank field is read as 0 only in the four documented spare slots (broadcast orbit 5
  fields 2 and 4, broadcast orbit 7 fields 3 and 4); a blank required field, a field that
  is not a number, a NaN/inf value or a truncated record raises :class:`EphemerisError`.
  Records of other constellations are skipped (every RINEX 3 record line starts with the
  satellite system letter, continuation lines start with blanks, so no per-system line
  count is needed).
* **Header**: the ``RINEX VERSION / TYPE`` line is parsed here (so that RINEX 2 and 5,
  observation files and garbage are rejected with a precise one-line message), and the
  ``BDSA``/``BDSB IONOSPHERIC CORR`` lines are read here and cross-checked against
  georinex's header reader (:func:`georinex.rinexheader`) whenever that reader works on the
  file; a disagreement raises :class:`EphemerisError`.
* **Optional record cross-check**: ``load_nav(path, crosscheck=True)`` (or
  :func:`crosscheck_with_georinex`) also runs ``georinex.load(path, use='C')`` and compares
  every value georinex returns as finite with the records parsed here (relative 1e-12).
  On the shipped station files georinex returns no finite BDS value at all, which is
  reported, never used.

RINEX 3.0x BDS record -> :class:`~sdr_di.orbits.ephemeris.Ephemeris`::

    SV / EPOCH (toc, BDT) / af0 af1 af2
    AODE   Crs      Delta n   M0
    Cuc    e        Cus       sqrtA
    Toe    Cic      OMEGA0    Cis
    i0     Crc      omega     OMEGA DOT
    IDOT   spare    BDT week  spare
    SV accuracy [m] SatH1     TGD1      TGD2
    t_tx   AODC     spare     spare

RINEX 4.0x (4.00-4.02 layout; IGS merged daily files since 2023) frames every record with a
marker line ``> TYP SVN MSG`` (``A1,1X,A3,1X,A3,1X,A4``):

* ``> EPH Cnn D1`` / ``> EPH Cnn D2`` (the B1I/B3I D1 and D2 messages this receiver uses):
  the record that follows has the RINEX 3 BDS layout above and is read by the same code,
  with the same checks; the marker's satellite must start the record's first line.
* ``> ION Cnn D1D2``: BDS Klobuchar coefficients, ``4X,I4,5(1X,I2)`` transmission time
  (BDT) + alpha0-2, then ``4X`` + alpha3 beta0-2, then ``4X`` + beta3. RINEX 4 headers have
  no ``IONOSPHERIC CORR`` lines; these frames replace them. A daily file holds several (15
  in the shipped BRD400DLR, from C02, C03, C05, C56 and C57, one every 1-5 h: alpha0
  4.0e-8 to 4.6e-8 s from the GEOs, beta0 84 000 to 119 000 s, beta1 -1.6e5 to 1.0e6
  s/semicircle). **Rule:** :attr:`NavData.iono` is the earliest frame
  (smallest transmission time, file order for ties), the one a receiver switched on at the
  start of the file would have had; all frames are kept, sorted by time, in
  :attr:`NavData.iono_frames` for a caller that wants the one in force at another time.
  A header ``BDSA``/``BDSB`` pair (not written in RINEX 4) is used only without such frames.
* Skipped up to the next marker: B-CNAV ephemerides (``CNV1``, ``CNV2``, ``CNV3``), ``STO``,
  ``EOP`` and ``ION ... CNVX`` frames, and every frame of another system.

A marker of an unknown record type, an EPH frame that does not hold its whole record, an ION
frame cut short and a malformed number in either raise :class:`EphemerisError`; a version
5.x file is refused (``unsupported RINEX version 5.00: ...``).

Angles in RINEX are radians already. The SV accuracy [m] is converted to the ICD URA index
(``URAI``). ``toc`` is the epoch of the first line expressed as BDT seconds of week; the
record's week is the RINEX BDT week, checked against the toc epoch (a writer that puts the
*GPS* week in the BDS field, 1356 weeks too many, is corrected with a warning; any other
disagreement of more than half a week is an error).

Duplicates (same PRN, week and toe, e.g. after merging two station files) are reduced to one
record deterministically: a healthy record wins over an unhealthy one, otherwise the first
occurrence wins (file order; argument order for :func:`merge_nav`). Their number is kept in
:attr:`NavData.n_duplicates`; :attr:`NavData.n_conflicts` counts duplicate groups whose
orbit/clock parameters differ.

Record selection (:meth:`NavData.select`): the healthy record whose toe is nearest to the
requested time (week-aware), within a validity window. BDS uploads a new ephemeris every
hour (toe on the hour), so with continuous data the nearest toe is at most 30 min away. The
default windows, :data:`DEFAULT_MAX_AGE_S` = 7200 s for MEO/IGSO and
:data:`DEFAULT_MAX_AGE_GEO_S` = 3600 s for GEO, tolerate one or two missing uploads (one for
GEO, whose broadcast fit degrades faster away from toe). A tie (time exactly half-way between
two toes) goes to the earlier toe, the record a receiver would already have received.

Broadcast selection (``select(..., broadcast=True)``): the record a satellite is *sending* at
the requested time, i.e. the healthy record most recently put on the air: the latest
transmission time (RINEX line 8, field 1; the earliest over merged files) at or before the
time, records without one counted from their toe. BDS puts a new record on the air shortly
after its toe (on the hour: C27's 06:00 record of 2020-06-25 from 06:00:18), so at 06:40 the
nearest toe is 07:00 but the satellite still sends the 06:00 record. Consecutive records
differ by decimetres along the orbit, so a receiver whose assistance record differs from the
broadcast one sees a per-satellite pseudorange bias of that size (measured: -0.28 m on
C27, 0.45 m of height bias in the deep receiver); the generator and the receivers'
assistance use this selection. Where the file has no record on the air within the validity
window (before the first transmission, or a station that missed uploads: C32 in the shipped
ESBC file has none between its 01:00 and 08:00 records) it falls back to the nearest toe.

Measured on 2020-06-25 (ESBC+MOJN records vs IAC SP3, 3D, antenna offset not removed): the
error does not grow up to 2 h from toe and then grows fast::

    |t - toe|      0-1 h            1-2 h            2-3 h            3-4 h
    BDS-3 MEO      1.2 (max 1.5)    1.3 (max 5.6)    3.2 (max 22)     14 (max 73)   median m
    BDS-2 MEO/IGSO 2.3 (max 6.6)    2.3 (max 9.8)    3.0 (max 22)     10 (max 61)
    GEO C05        15.8 (max 17.3)  16.0 (max 20.0)  16.0 (max 32)    17 (max 64)

Records are treated as read-only: build a new :class:`NavData` (or use :func:`merge_nav`)
rather than editing ``records`` in place, since the selection index is built at creation.
"""

from __future__ import annotations

import bisect
import dataclasses
import datetime as _dt
import gzip
import io
import logging
import math
import warnings
import zlib
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..constants import BDT_WEEK_OFFSET, SECONDS_PER_WEEK, check_prn, is_geo
from ..errors import EphemerisError, NoEphemerisError
from ..timebase import bdt_to_datetime, datetime_to_bdt
from .ephemeris import Ephemeris, Klobuchar

__all__ = [
    "DEFAULT_MAX_AGE_S",
    "DEFAULT_MAX_AGE_GEO_S",
    "URA_BOUNDS_M",
    "IonFrame",
    "NavData",
    "load_nav",
    "merge_nav",
    "read_klobuchar",
    "toc_datetime",
    "crosscheck_with_georinex",
    "ura_index",
]

_log = logging.getLogger(__name__)

#: Default validity window |t - toe| [s] for MEO/IGSO records in :meth:`NavData.select`.
DEFAULT_MAX_AGE_S = 7200.0
#: Default validity window |t - toe| [s] for GEO records in :meth:`NavData.select`.
DEFAULT_MAX_AGE_GEO_S = 3600.0

#: Field width of RINEX 3 navigation data [characters].
_FW = 19
#: Number of continuation lines of a BDS record.
_BDS_LINES = 7
#: Names of the 31 values of a BDS record, in file order (first line: 3, then 7 x 4).
_FIELDS = (
    "af0", "af1", "af2",
    "AODE", "Crs", "Delta_n", "M0",
    "Cuc", "e", "Cus", "sqrtA",
    "toe", "Cic", "Omega0", "Cis",
    "i0", "Crc", "omega", "Omega_dot",
    "IDOT", "spare_5_2", "week", "spare_5_4",
    "sv_accuracy_m", "SatH1", "TGD1", "TGD2",
    "t_tx", "AODC", "spare_7_3", "spare_7_4",
)
#: Documented spare slots: blank reads as 0.
_SPARE = frozenset(("spare_5_2", "spare_5_4", "spare_7_3", "spare_7_4"))

#: URA upper bounds [m] for URA index 0..14 (BDS ICD / GPS convention; 15 = no prediction).
URA_BOUNDS_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0,
                1536.0, 3072.0, 6144.0)


def ura_index(accuracy_m: float) -> int:
    """ICD user range accuracy index for an accuracy [m] (smallest index whose bound holds)."""
    for i, bound in enumerate(URA_BOUNDS_M):
        if accuracy_m <= bound:
            return i
    return 15


# --------------------------------------------------------------------------------------
# NavData
# --------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class IonFrame:
    """One RINEX 4 ``> ION Cnn D1D2`` frame: BDS Klobuchar coefficients as a satellite sent them.

    Attributes
    ----------
    prn : int
        BDS PRN of the satellite the frame was received from.
    epoch : datetime.datetime
        Transmission time of the message (naive, BDT).
    klobuchar : Klobuchar
        alpha [s, s/semicircle, s/semicircle^2, s/semicircle^3] and beta [s, ...].
    """

    prn: int
    epoch: _dt.datetime
    klobuchar: Klobuchar


@dataclasses.dataclass
class NavData:
    """BDS broadcast ephemerides read from one or more RINEX 3 or 4 navigation files.

    Attributes
    ----------
    records : dict[int, list[Ephemeris]]
        Records per PRN, sorted by (week, toe), one per (week, toe) after deduplication.
    iono : Klobuchar or None
        BDS Klobuchar coefficients: RINEX 3 from the header (``BDSA``/``BDSB``), RINEX 4
        from the earliest ``> ION Cnn D1D2`` frame (module notes); None when absent.
    path : Path
        The file read (the first one for merged data).
    sources : tuple[Path, ...]
        All files the records come from.
    version : float
        RINEX version of the (first) file.
    n_records_read : int
        BDS records read before deduplication.
    n_duplicates : int
        Records dropped as duplicates of another (PRN, week, toe).
    n_conflicts : int
        Duplicate groups whose parameters differ (the kept record is the rule's choice).
    iono_gps : Klobuchar or None
        GPS Klobuchar coefficients of the same header (``GPSA``/``GPSB``), None when absent.
    tx_times : dict[(int, int, float), float]
        Transmission time of each record [s since the BDT epoch], keyed by (PRN, week, toe);
        the earliest when merged (module notes, broadcast selection).
    iono_frames : tuple[IonFrame, ...]
        RINEX 4 only: every ``> ION Cnn D1D2`` frame (BDS Klobuchar as sent by a satellite),
        sorted by transmission time (file order for equal times); ``iono`` is the first one.
        Empty for RINEX 3.
    iono_label : str
        Where ``iono`` comes from, in words (e.g. ``"BDSA/BDSB"``, or the ION frame chosen);
        empty when ``iono`` is None or the NavData was built by hand.
    """

    records: dict[int, list[Ephemeris]]
    iono: Klobuchar | None
    path: Path
    sources: tuple[Path, ...] = ()
    version: float = 3.0
    n_records_read: int = 0
    n_duplicates: int = 0
    n_conflicts: int = 0
    iono_gps: Klobuchar | None = None
    tx_times: dict = dataclasses.field(default_factory=dict)
    iono_frames: tuple[IonFrame, ...] = ()
    iono_label: str = ""

    def __post_init__(self) -> None:
        if not self.sources:
            self.sources = (self.path,)
        self._index: dict[int, tuple[list[float], list[Ephemeris]]] = {}
        self._on_air: dict[int, tuple[list[float], list[Ephemeris]]] = {}
        for prn, recs in self.records.items():
            healthy = [r for r in recs if r.healthy]
            self._index[prn] = ([_toe_abs(r) for r in healthy], healthy)
            sent = sorted(((self.tx_times.get((prn, r.week, r.toe), _toe_abs(r)), _toe_abs(r)), r)
                          for r in healthy)
            self._on_air[prn] = ([k[0] for k, _ in sent], [r for _, r in sent])

    # ---- queries ----------------------------------------------------------------
    @property
    def prns(self) -> tuple[int, ...]:
        """PRNs with at least one record, ascending."""
        return tuple(sorted(self.records))

    @property
    def n_records(self) -> int:
        """Number of records kept (after deduplication)."""
        return sum(len(v) for v in self.records.values())

    def select(self, prn: int, week: int, sow: float,
               max_age_s: float | None = None, broadcast: bool = False) -> Ephemeris:
        """Healthy record of ``prn`` with the toe nearest to BDT (``week``, ``sow``), or
        with ``broadcast`` the one the satellite is sending then (module notes).

        Parameters
        ----------
        prn : int
            BDS PRN, 1..63.
        week : int
            BDT week of the requested time.
        sow : float
            BDT seconds of week of the requested time [s] (values outside 0..604800 are
            accepted and counted from the start of ``week``).
        max_age_s : float, optional
            Largest accepted |t - toe| [s]. Default :data:`DEFAULT_MAX_AGE_S` (MEO/IGSO) or
            :data:`DEFAULT_MAX_AGE_GEO_S` (GEO).
        broadcast : bool, optional
            Select the record on the air at the time (latest transmission time at or
            before it) instead of the nearest toe; the nearest toe when that record is
            missing or outside ``max_age_s``. Default False.

        Returns
        -------
        Ephemeris
            The selected record (ties between two toes go to the earlier toe).

        Raises
        ------
        UnknownPrnError
            ``prn`` is not an integer in 1..63.
        NoEphemerisError
            No healthy record of ``prn`` has a toe within ``max_age_s`` of the time.
        """
        prn = check_prn(prn)
        if max_age_s is None:
            max_age_s = DEFAULT_MAX_AGE_GEO_S if is_geo(prn) else DEFAULT_MAX_AGE_S
        t = int(week) * SECONDS_PER_WEEK + float(sow)
        when = f"BDT week {int(week)} sow {float(sow):.3f}"
        toes, recs = self._index.get(prn, ([], []))
        if not recs:
            n_all = len(self.records.get(prn, []))
            what = f"{n_all} record(s), none healthy" if n_all else "no record"
            raise NoEphemerisError(
                f"no ephemeris for C{prn:02d} at {when}: {what} in {self._where()}")
        rec = None
        if broadcast:
            sent, on_air = self._on_air[prn]
            k = bisect.bisect_right(sent, t) - 1
            if k >= 0 and abs(t - _toe_abs(on_air[k])) <= max_age_s:
                rec = on_air[k]
        if rec is None:
            i = bisect.bisect_left(toes, t)
            best = None
            for j in (i - 1, i):  # earlier candidate first: it wins ties
                if 0 <= j < len(toes) and (best is None
                                           or abs(t - toes[j]) < abs(t - toes[best])):
                    best = j
            rec = recs[best]
        age = abs(t - _toe_abs(rec))
        if age > max_age_s:
            near = rec
            raise NoEphemerisError(
                f"no healthy ephemeris for C{prn:02d} within {max_age_s:.0f} s of {when} in "
                f"{self._where()} (nearest toe: week {near.week} sow {near.toe:.0f}, "
                f"{age:.0f} s away)")
        return rec

    def _where(self) -> str:
        if len(self.sources) == 1:
            return self.sources[0].name
        return "+".join(p.name for p in self.sources)


def _toe_abs(eph: Ephemeris) -> float:
    """toe as BDT seconds since the BDT epoch [s]."""
    return eph.week * SECONDS_PER_WEEK + eph.toe




# --------------------------------------------------------------------------------------
# File reading
# --------------------------------------------------------------------------------------


def _read_text(path: Path) -> str:
    """Whole file as text (plain or gzip), with EphemerisError for any I/O problem."""
    if not path.exists():
        raise EphemerisError(f"navigation file {path}: not found")
    if not path.is_file():
        raise EphemerisError(f"navigation file {path}: not a regular file")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise EphemerisError(f"navigation file {path}: cannot read ({exc.strerror or exc})") from None
    if raw[:2] == b"\x1f\x8b":
        try:
            raw = gzip.decompress(raw)
        except (OSError, EOFError, zlib.error) as exc:  # BadGzipFile is an OSError
            raise EphemerisError(f"navigation file {path}: corrupt gzip data ({exc})") from None
    elif raw[:2] == b"\x1f\x9d":
        raise EphemerisError(
            f"navigation file {path}: Unix-compress (.Z) data is not supported; decompress it first")
    if not raw.strip():
        raise EphemerisError(f"navigation file {path}: empty file")
    if b"\x00" in raw:
        raise EphemerisError(f"navigation file {path}: binary data, not a RINEX text file")
    return raw.decode("latin-1")


def _parse_version_line(line: str, path: Path) -> tuple[float, str, str]:
    """(version, file type letter, system letter) from the first header line."""
    if line[60:80].strip() != "RINEX VERSION / TYPE":
        raise EphemerisError(
            f"navigation file {path}: not a RINEX file (first line is not 'RINEX VERSION / TYPE')")
    try:
        version = float(line[0:9])
    except ValueError:
        raise EphemerisError(
            f"navigation file {path}: unreadable RINEX version {line[0:9].strip()!r}") from None
    ftype = line[20:21].upper()
    system = line[40:41].upper()
    return version, ftype, system


def _f(text: str) -> float:
    """Parse one Fortran number (D or E exponent); ValueError when not a number."""
    return float(text.strip().replace("D", "E").replace("d", "e"))



def _finite(txt: str, path: Path, where: str) -> float:
    """The finite number of a record field ``txt`` (``D`` exponents allowed).

    Raises
    ------
    EphemerisError
        Malformed or non-finite, naming the file and ``where`` (field, record, line).
    """
    try:
        v = _f(txt)
    except ValueError:
        raise EphemerisError(
            f"navigation file {path}: malformed number {txt.strip()!r} in {where}") from None
    if not math.isfinite(v):
        raise EphemerisError(
            f"navigation file {path}: non-finite value {txt.strip()!r} in {where}")
    return v

def _parse_header(lines: list[str], path: Path
                  ) -> tuple[float, int, Klobuchar | None, Klobuchar | None]:
    """Validate the header; return (version, first body line, BDS and GPS Klobuchar)."""
    first = next((i for i, ln in enumerate(lines) if ln.strip()), None)
    if first is None:
        raise EphemerisError(f"navigation file {path}: empty file")
    version, ftype, system = _parse_version_line(lines[first], path)
    vtxt = f"{version:.2f}"
    if not 3.0 <= version < 5.0:
        raise EphemerisError(
            f"unsupported RINEX version {vtxt}: {path} (only RINEX 3.0x and 4.0x navigation "
            f"files are read)")
    if ftype != "N":
        kind = {"O": "an observation", "M": "a meteorological", "C": "a clock"}.get(ftype, f"a type-{ftype!r}")
        raise EphemerisError(f"navigation file {path}: is {kind} file, not a navigation file")
    if system not in ("M", "C", " ", ""):
        raise EphemerisError(
            f"navigation file {path}: no BDS records (RINEX navigation file for system {system!r})")

    end = None
    coeffs: dict[str, tuple[float, ...]] = {}
    for i in range(first + 1, len(lines)):
        ln = lines[i]
        label = ln[60:80].strip()
        if label == "END OF HEADER":
            end = i + 1
            break
        if label == "IONOSPHERIC CORR" and ln[:4] in ("BDSA", "BDSB", "GPSA", "GPSB"):
            try:
                vals = tuple(_f(ln[5 + 12 * k:17 + 12 * k]) for k in range(4))
            except ValueError:
                raise EphemerisError(
                    f"navigation file {path}: malformed {ln[:4]} IONOSPHERIC CORR line {i + 1}") from None
            if not all(math.isfinite(v) for v in vals):
                raise EphemerisError(
                    f"navigation file {path}: non-finite {ln[:4]} IONOSPHERIC CORR line {i + 1}")
            coeffs[ln[:4]] = vals
    if end is None:
        raise EphemerisError(f"navigation file {path}: no END OF HEADER line")
    sets = []
    for sysname in ("BDS", "GPS"):
        a, b = coeffs.get(sysname + "A"), coeffs.get(sysname + "B")
        if (a is None) != (b is None):
            have, miss = (sysname + "A", sysname + "B") if a else (sysname + "B", sysname + "A")
            raise EphemerisError(
                f"navigation file {path}: header has {have} without {miss} IONOSPHERIC CORR")
        sets.append(Klobuchar(alpha=a, beta=b) if a is not None else None)
    return version, end, sets[0], sets[1]


def _crosscheck_header(text: str, iono: Klobuchar | None, path: Path) -> None:
    """Compare our BDS Klobuchar with georinex's header reader, where that reader works.

    Without BDS coefficients in the header there is nothing to compare, and georinex is not
    imported (about 0.25 s of CPU, xarray and pandas, in every ``sdr-di run`` with a file
    such as the shipped ESBC one)."""
    if iono is None:
        return
    try:
        import georinex
        hdr = georinex.rinexheader(io.StringIO(text))
    except Exception as exc:  # georinex cannot read this header: nothing to compare
        _log.debug("georinex header reader failed on %s: %s", path, exc)
        return
    corr = hdr.get("IONOSPHERIC CORR", {}) if isinstance(hdr, dict) else {}
    if not isinstance(corr, dict) or "BDSA" not in corr or "BDSB" not in corr or iono is None:
        return
    theirs = np.concatenate([np.asarray(corr["BDSA"], float), np.asarray(corr["BDSB"], float)])
    ours = np.concatenate([iono.alpha, iono.beta])
    if theirs.shape != ours.shape or not np.allclose(theirs, ours, rtol=1e-9, atol=0.0):
        raise EphemerisError(
            f"navigation file {path}: BDS Klobuchar coefficients disagree with georinex "
            f"({ours.tolist()} vs {theirs.tolist()})")


def _fields_of_record(lines: list[str], start: int, path: Path) -> dict[str, float]:
    """Parse the 8 lines of a BDS record starting at ``lines[start]``."""
    sv = lines[start][:3]
    slots: list[tuple[str, int]] = []  # (text, line number)
    head = lines[start]
    for k in range(3):
        slots.append((head[23 + _FW * k:23 + _FW * (k + 1)], start + 1))
    for j in range(1, _BDS_LINES + 1):
        ln = lines[start + j]
        if ln[:4].strip():
            raise EphemerisError(
                f"navigation file {path}: truncated {sv} record at line {start + 1} "
                f"(line {start + j + 1} starts a new record)")
        for k in range(4):
            slots.append((ln[4 + _FW * k:4 + _FW * (k + 1)], start + j + 1))
    out: dict[str, float] = {}
    for name, (txt, lineno) in zip(_FIELDS, slots):
        if not txt.strip():
            if name in _SPARE:
                out[name] = 0.0
                continue
            raise EphemerisError(
                f"navigation file {path}: blank required field {name!r} in {sv} record, line {lineno}")
        out[name] = _finite(txt, path, f"field {name!r} of {sv} record, line {lineno}")
    return out


def _record_to_ephemeris(start: int, lines: list[str], path: Path) -> tuple[Ephemeris, float]:
    """Build an Ephemeris from the record at ``lines[start]``; also return t_tx [s of week]."""
    head = lines[start]
    sv = head[:3]
    try:
        prn = int(sv[1:3].replace(" ", "0"))
    except ValueError:
        raise EphemerisError(f"navigation file {path}: bad satellite id {sv!r} at line {start + 1}") from None
    if not 1 <= prn <= 63:
        raise EphemerisError(
            f"navigation file {path}: BDS PRN {prn} outside 1..63 at line {start + 1}")
    try:
        y, mo, d, hh, mi, ss = (int(x) for x in head[4:23].split())
        toc_dt = _dt.datetime(y, mo, d, hh, mi, ss)
    except ValueError:
        raise EphemerisError(
            f"navigation file {path}: bad epoch {head[4:23]!r} in {sv} record at line {start + 1}") from None
    if start + _BDS_LINES >= len(lines):
        raise EphemerisError(f"navigation file {path}: truncated {sv} record at line {start + 1} (end of file)")
    v = _fields_of_record(lines, start, path)

    try:
        toc_week, toc = datetime_to_bdt(toc_dt)
    except ValueError:          # before the BDT epoch (a year "0023" for "2023", say)
        raise EphemerisError(
            f"navigation file {path}: epoch {head[4:23].strip()!r} of {sv} record at line "
            f"{start + 1} is before the BDT epoch 2006-01-01") from None
    week = int(round(v["week"]))
    toe = v["toe"]
    if not 0.0 <= toe < SECONDS_PER_WEEK:
        raise EphemerisError(
            f"navigation file {path}: toe {toe} outside 0..604800 s in {sv} record at line {start + 1}")
    toc_abs = toc_week * SECONDS_PER_WEEK + toc

    def gap(w: int) -> float:
        return abs(w * SECONDS_PER_WEEK + toe - toc_abs)

    if gap(week) > SECONDS_PER_WEEK / 2:
        if gap(week - BDT_WEEK_OFFSET) <= SECONDS_PER_WEEK / 2:
            _log.warning("%s: %s record at line %d carries the GPS week %d in the BDT week field; "
                         "using BDT week %d", path.name, sv, start + 1, week, week - BDT_WEEK_OFFSET)
            week -= BDT_WEEK_OFFSET
        else:
            raise EphemerisError(
                f"navigation file {path}: BDT week {week} / toe {toe:.0f} inconsistent with toc "
                f"{toc_dt:%Y-%m-%d %H:%M:%S} in {sv} record at line {start + 1}")
    sqrtA, e = v["sqrtA"], v["e"]
    if not (sqrtA > 1000.0 and 0.0 <= e < 1.0):
        raise EphemerisError(
            f"navigation file {path}: impossible orbit (sqrtA {sqrtA}, e {e}) in {sv} record "
            f"at line {start + 1}")
    eph = Ephemeris(
        prn=prn, week=week, toc=toc, af0=v["af0"], af1=v["af1"], af2=v["af2"], toe=toe,
        sqrtA=sqrtA, e=e, i0=v["i0"], Omega0=v["Omega0"], omega=v["omega"], M0=v["M0"],
        Delta_n=v["Delta_n"], Omega_dot=v["Omega_dot"], IDOT=v["IDOT"], Cuc=v["Cuc"],
        Cus=v["Cus"], Cic=v["Cic"], Cis=v["Cis"], Crc=v["Crc"], Crs=v["Crs"],
        TGD1=v["TGD1"], TGD2=v["TGD2"], AODE=int(round(v["AODE"])), AODC=int(round(v["AODC"])),
        SatH1=int(round(v["SatH1"])), URAI=ura_index(v["sv_accuracy_m"]),
    )
    if not eph.finite():  # belt and braces: nothing non-finite may leave this module
        raise EphemerisError(f"navigation file {path}: non-finite parameter in {sv} record at line {start + 1}")
    return eph, v["t_tx"]


def _parse_body(lines: list[str], first: int, path: Path
                ) -> tuple[list[Ephemeris], dict[tuple[int, int, float], float]]:
    """All BDS records of the body, in file order, and their transmission times [s since
    the BDT epoch] keyed by (PRN, week, toe) (the earliest of duplicates)."""
    out: list[Ephemeris] = []
    tx: dict[tuple[int, int, float], float] = {}
    i = first
    n = len(lines)
    while i < n:
        ln = lines[i]
        if not ln.strip():
            i += 1
            continue
        c = ln[0]
        if c == " ":  # continuation line of a skipped (non-BDS) record
            i += 1
            continue
        if c == ">":
            raise EphemerisError(
                f"navigation file {path}: RINEX 4 record marker '>' at line {i + 1} in a "
                f"RINEX 3 file")
        if c == "C":
            eph, t_tx = _record_to_ephemeris(i, lines, path)
            out.append(eph)
            key = (eph.prn, eph.week, eph.toe)
            t_abs = _tx_abs(eph, t_tx)
            tx[key] = min(tx.get(key, t_abs), t_abs)
            i += _BDS_LINES + 1
        else:
            i += 1
    return out, tx


#: RINEX 4 frame record types (``> EPH``, ``> STO``, ``> EOP``, ``> ION``).
_V4_FRAME_TYPES = frozenset(("EPH", "STO", "EOP", "ION"))
#: RINEX 4 BDS message types read as ephemerides (B1I/B3I D1 and D2; B-CNAV is skipped).
_V4_BDS_EPH = frozenset(("D1", "D2"))
#: Lines of a BDS ``ION ... D1D2`` frame body: epoch + alpha0-2, alpha3 + beta0-2, beta3.
_ION_LINES = 3


def _ion_frame(i: int, lines: list[str], sv: str, path: Path) -> IonFrame:
    """The Klobuchar coefficients of the ``> ION Cnn D1D2`` frame whose marker is ``lines[i]``.

    Layout (RINEX 4.00-4.02, BDS D1/D2 Klobuchar): ``4X,I4,5(1X,I2)`` transmission time
    (BDT) + alpha0 alpha1 alpha2 (3 x D19.12); ``4X`` + alpha3 beta0 beta1 beta2; ``4X`` +
    beta3.
    """
    if i + _ION_LINES >= len(lines):
        raise EphemerisError(
            f"navigation file {path}: truncated ION {sv} D1D2 frame at line {i + 1} (end of file)")
    body = lines[i + 1:i + 1 + _ION_LINES]
    for j, ln in enumerate(body):
        if ln[:1] == ">":
            raise EphemerisError(
                f"navigation file {path}: truncated ION {sv} D1D2 frame at line {i + 1} "
                f"(line {i + j + 2} starts a new frame)")
    try:
        y, mo, d, hh, mi, ss = (int(x) for x in body[0][4:23].split())
        epoch = _dt.datetime(y, mo, d, hh, mi, ss)
    except (ValueError, OverflowError):
        raise EphemerisError(
            f"navigation file {path}: bad epoch {body[0][4:23]!r} in ION {sv} D1D2 frame at "
            f"line {i + 2}") from None
    slots = [(body[0][23 + _FW * k:23 + _FW * (k + 1)], i + 2) for k in range(3)]
    slots += [(body[1][4 + _FW * k:4 + _FW * (k + 1)], i + 3) for k in range(4)]
    slots.append((body[2][4:4 + _FW], i + 4))
    vals = []
    for txt, lineno in slots:
        vals.append(_finite(txt, path, f"ION {sv} D1D2 frame, line {lineno}"))
    prn = int(sv[1:])
    if not 1 <= prn <= 63:
        raise EphemerisError(
            f"navigation file {path}: BDS PRN {prn} outside 1..63 in ION frame at line {i + 1}")
    return IonFrame(prn=prn, epoch=epoch,
                    klobuchar=Klobuchar(alpha=tuple(vals[:4]), beta=tuple(vals[4:])))


def _parse_body_v4(lines: list[str], first: int, path: Path, want_eph: bool = True
                   ) -> tuple[list[Ephemeris], dict[tuple[int, int, float], float],
                              list[IonFrame]]:
    """BDS D1/D2 records, their transmission times (as :func:`_parse_body`) and the BDS
    ``ION ... D1D2`` frames of a RINEX 4 body, in file order.

    Every line of the body belongs to a frame opened by a marker ``> TYP SVN MSG``
    (``A1,1X,A3,1X,A3,1X,A4``). ``> EPH Cnn D1|D2`` frames hold a BDS record laid out as in
    RINEX 3 (SV / EPOCH line + 7 broadcast-orbit lines, parsed by
    :func:`_record_to_ephemeris`); ``> ION Cnn D1D2`` frames the Klobuchar coefficients
    (:func:`_ion_frame`). Every other frame (B-CNAV ``CNV1-3`` ephemerides, ``STO``, ``EOP``,
    ``ION ... CNVX``, other systems) is skipped up to the next marker. ``want_eph=False``
    skips the ephemerides too (:func:`read_klobuchar`).
    """
    out: list[Ephemeris] = []
    tx: dict[tuple[int, int, float], float] = {}
    ions: list[IonFrame] = []
    i = first
    n = len(lines)
    while i < n:
        ln = lines[i]
        if ln[:1] != ">":  # blank line or a line of a skipped frame
            i += 1
            continue
        tokens = ln[1:].split()
        if len(tokens) < 3 or tokens[0] not in _V4_FRAME_TYPES:
            raise EphemerisError(
                f"navigation file {path}: malformed RINEX 4 frame marker {ln.strip()!r} at "
                f"line {i + 1}")
        kind, sv, msg = tokens[0], tokens[1], tokens[2]
        bds = len(sv) == 3 and sv[0] == "C" and sv[1:].isascii() and sv[1:].isdigit()
        if bds and kind == "EPH" and msg in _V4_BDS_EPH and want_eph:
            if i + 1 >= n or lines[i + 1][:3].replace(" ", "0") != sv:
                got = lines[i + 1][:3] if i + 1 < n else "end of file"
                raise EphemerisError(
                    f"navigation file {path}: truncated EPH {sv} {msg} frame at line {i + 1} "
                    f"(next line starts with {got!r}, not the record's {sv})")
            eph, t_tx = _record_to_ephemeris(i + 1, lines, path)
            out.append(eph)
            key = (eph.prn, eph.week, eph.toe)
            t_abs = _tx_abs(eph, t_tx)
            tx[key] = min(tx.get(key, t_abs), t_abs)
            i += 1 + _BDS_LINES + 1
        elif bds and kind == "ION" and msg == "D1D2":
            ions.append(_ion_frame(i, lines, sv, path))
            i += 1 + _ION_LINES
        else:
            i += 1
    return out, tx, ions


def _tx_abs(eph: Ephemeris, t_tx: float) -> float:
    """Transmission time [s of the record's week] as seconds since the BDT epoch, taken in
    the week that puts it nearest the toe (a record sent before a week rollover)."""
    t = eph.week * SECONDS_PER_WEEK + float(t_tx)
    toe = _toe_abs(eph)
    if t - toe > SECONDS_PER_WEEK / 2:
        t -= SECONDS_PER_WEEK
    elif toe - t > SECONDS_PER_WEEK / 2:
        t += SECONDS_PER_WEEK
    return t


def _dedup(recs: Iterable[Ephemeris]) -> tuple[dict[int, list[Ephemeris]], int, int]:
    """Sort per PRN by (week, toe); keep one record per (PRN, week, toe) (see module doc)."""
    groups: dict[tuple[int, int, float], list[Ephemeris]] = {}
    for r in recs:
        groups.setdefault((r.prn, r.week, r.toe), []).append(r)
    out: dict[int, list[Ephemeris]] = {}
    n_dup = n_conf = 0
    for key in sorted(groups):
        g = groups[key]
        healthy = [r for r in g if r.healthy]
        keep = healthy[0] if healthy else g[0]
        n_dup += len(g) - 1
        if any(r != keep for r in g):      # dataclass __eq__: the fields, no deep copy
            n_conf += 1
        out.setdefault(key[0], []).append(keep)
    return out, n_dup, n_conf


def load_nav(path: str | Path, crosscheck: bool = False) -> NavData:
    """Load the BDS broadcast ephemerides of a RINEX 3.0x or 4.0x navigation file.

    Parameters
    ----------
    path : str or Path
        RINEX 3.0x or 4.0x navigation file, mixed (``M``) or BDS-only (``C``), plain or
        gzip. Of a RINEX 4 file the ``EPH Cnn D1|D2`` and ``ION Cnn D1D2`` frames are read,
        every other frame is skipped (module notes).
    crosscheck : bool, optional
        Also read the file with ``georinex.load(use='C')`` and compare every value georinex
        returns as finite with ours (see :func:`crosscheck_with_georinex`). Default False
        (it costs about 0.5 s per file and georinex returns only NaN on most real files).

    Returns
    -------
    NavData
        Records per PRN (sorted by toe, deduplicated), BDS Klobuchar from the header
        (RINEX 3) or the earliest ION frame (RINEX 4).

    Raises
    ------
    EphemerisError
        Missing/unreadable/binary/empty file, not a RINEX file, RINEX version other than
        3.0x or 4.0x (``unsupported RINEX version 5.00: ...``), observation or other
        non-navigation file, no BDS record, malformed/blank required/non-finite field,
        truncated record or frame, malformed RINEX 4 frame marker, inconsistent week,
        georinex disagreement. The message is one line naming the file.
    """
    from ..paths import note_input

    path = Path(path)
    text = _read_text(path)
    note_input(path, what="ephemeris")
    lines = text.splitlines()
    version, body, iono, iono_gps = _parse_header(lines, path)
    _crosscheck_header(text, iono, path)
    frames: tuple[IonFrame, ...] = ()
    if version >= 4.0:
        recs, tx, ions = _parse_body_v4(lines, body, path)
        iono, label, frames = _klobuchar_of_frames(ions, iono)
    else:
        recs, tx = _parse_body(lines, body, path)
        label = "BDSA/BDSB" if iono is not None else ""
    if not recs:
        raise EphemerisError(f"navigation file {path}: no BDS records (RINEX {version:.2f})")
    records, n_dup, n_conf = _dedup(recs)
    nav = NavData(records=records, iono=iono, path=path, sources=(path,), version=version,
                  n_records_read=len(recs), n_duplicates=n_dup, n_conflicts=n_conf,
                  iono_gps=iono_gps, tx_times=tx, iono_frames=frames, iono_label=label)
    if crosscheck:
        crosscheck_with_georinex(nav)
    return nav


def _klobuchar_of_frames(ions: list[IonFrame], header: Klobuchar | None
                         ) -> tuple[Klobuchar | None, str, tuple[IonFrame, ...]]:
    """RINEX 4: (Klobuchar in force for the file, its label, the frames sorted by time).

    The rule (module notes): the earliest ``ION ... D1D2`` frame, ties to file order; a
    header with ``BDSA``/``BDSB`` lines (not written by RINEX 4, read if present) only when
    the file has no such frame.
    """
    frames = tuple(sorted(ions, key=lambda f: f.epoch))  # stable: file order for ties
    if frames:
        f = frames[0]
        return (f.klobuchar, f"ION C{f.prn:02d} D1D2 frame of {f.epoch:%Y-%m-%d %H:%M:%S} BDT "
                f"(earliest of {len(frames)})", frames)
    return header, ("BDSA/BDSB" if header is not None else ""), frames


def merge_nav(navs: Sequence[NavData]) -> NavData:
    """Merge several :class:`NavData` (e.g. two station files of the same day).

    Records are pooled and deduplicated with the module's rule (healthy first, then the
    first occurrence in argument order). ``iono`` is the first non-None one.
    """
    if not navs:
        raise EphemerisError("merge_nav: no navigation data given")
    pooled = [r for nav in navs for prn in nav.prns for r in nav.records[prn]]
    # keep argument order for equal keys: _dedup is stable (dict insertion order per group)
    records, n_dup, n_conf = _dedup(pooled)
    first_iono = next((n for n in navs if n.iono is not None), None)
    iono = first_iono.iono if first_iono is not None else None
    iono_gps = next((n.iono_gps for n in navs if n.iono_gps is not None), None)
    sources = tuple(p for n in navs for p in n.sources)
    tx: dict = {}
    for n in navs:
        for key, t in n.tx_times.items():
            tx[key] = min(tx.get(key, t), t)
    return NavData(records=records, iono=iono, path=navs[0].path, sources=sources,
                   version=navs[0].version,
                   n_records_read=sum(n.n_records_read for n in navs),
                   n_duplicates=sum(n.n_duplicates for n in navs) + n_dup,
                   n_conflicts=sum(n.n_conflicts for n in navs) + n_conf, iono_gps=iono_gps,
                   tx_times=tx, iono_frames=tuple(f for n in navs for f in n.iono_frames),
                   iono_label=first_iono.iono_label if first_iono is not None else "")


def read_klobuchar(path: str | Path) -> Klobuchar | None:
    """BDS Klobuchar coefficients of a navigation file: RINEX 3 ``BDSA``/``BDSB IONOSPHERIC
    CORR`` header lines, RINEX 4 the earliest ``> ION Cnn D1D2`` frame (as :func:`load_nav`).

    Returns None when the file has no BDS coefficients. Raises :class:`EphemerisError`
    for the same file problems as :func:`load_nav` (a RINEX 3 body is not read; of a RINEX
    4 body only the ION frames are).
    """
    path = Path(path)
    text = _read_text(path)
    lines = text.splitlines()
    version, body, iono, _ = _parse_header(lines, path)
    _crosscheck_header(text, iono, path)
    if version >= 4.0:
        iono = _klobuchar_of_frames(_parse_body_v4(lines, body, path, want_eph=False)[2], iono)[0]
    return iono


# --------------------------------------------------------------------------------------
# georinex cross-check
# --------------------------------------------------------------------------------------

#: Ephemeris attribute -> georinex 1.16 variable name (BDS).
_GEORINEX_NAMES = {
    "af0": "SVclockBias", "af1": "SVclockDrift", "af2": "SVclockDriftRate", "AODE": "AODE",
    "Crs": "Crs", "Delta_n": "DeltaN", "M0": "M0", "Cuc": "Cuc", "e": "Eccentricity",
    "Cus": "Cus", "sqrtA": "sqrtA", "toe": "Toe", "Cic": "Cic", "Omega0": "Omega0",
    "Cis": "Cis", "i0": "Io", "Crc": "Crc", "omega": "omega", "Omega_dot": "OmegaDot",
    "IDOT": "IDOT", "week": "BDTWeek", "SatH1": "SatH1", "TGD1": "TGD1", "TGD2": "TGD2",
    "AODC": "AODC",
}


def crosscheck_with_georinex(nav: NavData) -> dict[str, int]:
    """Compare ``nav`` with ``georinex.load(path, use='C')`` wherever georinex is finite.

    For each source file, every record we keep is looked up in georinex's dataset (same
    satellite, same toc epoch). Where georinex's values are finite, every mapped parameter
    must agree to a relative 1e-12 (absolute 1e-25); where they are NaN (its silent failure
    on blank spare fields) the record is counted, not compared. Finite georinex records that
    we did not keep are an error as well.

    Returns
    -------
    dict
        ``compared`` (records compared), ``nan`` (our records that georinex returned as NaN
        or lacked), ``unavailable`` (files georinex raised on).

    Raises
    ------
    EphemerisError
        A finite georinex value disagrees with ours, or georinex has a finite record we did
        not keep.
    """
    import georinex

    stats = {"compared": 0, "nan": 0, "unavailable": 0}
    ours = {}
    for prn in nav.prns:
        for r in nav.records[prn]:
            ours[(prn, toc_datetime(r))] = r
    for path in nav.sources:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                root = logging.getLogger()
                old = root.level
                root.setLevel(max(old, logging.WARNING))
                try:
                    ds = georinex.load(path, use="C")
                finally:
                    root.setLevel(old)
        except Exception as exc:
            _log.info("georinex cannot read %s (%s): no cross-check", path, exc)
            stats["unavailable"] += 1
            continue
        names = {k: v for k, v in _GEORINEX_NAMES.items() if v in ds}
        cube = {k: np.asarray(ds[v].values, float) for k, v in names.items()}  # (time, sv)
        epoch0 = _dt.datetime(1970, 1, 1)
        times = [epoch0 + _dt.timedelta(seconds=int(t)) for t in
                 np.asarray(ds["time"].values).astype("datetime64[s]").astype(np.int64)]
        svs = [str(s) for s in ds["sv"].values]
        seen = set()
        for isv, sv in enumerate(svs):
            if not sv.startswith("C"):
                continue
            prn = int(sv[1:3])
            for it, tdt in enumerate(times):
                vals = {k: c[it, isv] for k, c in cube.items()}
                if not all(math.isfinite(x) for x in vals.values()):
                    continue
                rec = ours.get((prn, tdt))
                if rec is None:
                    raise EphemerisError(
                        f"navigation file {path}: georinex has a C{prn:02d} record at {tdt} "
                        f"that this reader did not keep")
                for k, x in vals.items():
                    mine = float(getattr(rec, k))
                    if not math.isclose(mine, x, rel_tol=1e-12, abs_tol=1e-25):
                        raise EphemerisError(
                            f"navigation file {path}: C{prn:02d} {tdt} field {k}: ours {mine!r} "
                            f"vs georinex {x!r}")
                seen.add((prn, tdt))
        stats["compared"] += len(seen)
        if len(nav.sources) == 1:
            stats["nan"] += len(ours) - len(seen)
    return stats


def toc_datetime(eph: Ephemeris) -> _dt.datetime:
    """toc of a record as a naive BDT datetime (toc week taken next to the toe week)."""
    week = eph.week
    d = eph.toc - eph.toe
    if d > SECONDS_PER_WEEK / 2:
        week -= 1
    elif d < -SECONDS_PER_WEEK / 2:
        week += 1
    return bdt_to_datetime(week, eph.toc)
