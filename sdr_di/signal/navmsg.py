"""BDS B3I D1 (MEO/IGSO) and D2 (GEO) navigation message encoder and decoder.

Follows BDS-SIS-ICD-B3I-1.0 section 5 (message structure identical to the B1I D1/D2 messages).

Time structure
--------------
* **D1**, 50 bit/s: subframe 300 bits = 6 s, frame = subframes 1-5 = 30 s, superframe = 24
  frames = 12 min (subframes 4 and 5 carry pages 1-24). Subframe k of the week starts at
  BDT sow 6k; its SOW field is that start time (leading edge of the first preamble bit);
  FraID = k mod 5 + 1; the page of subframes 4/5 is (sow // 30) mod 24 + 1.
* **D2**, 500 bit/s: subframe 300 bits = 0.6 s, frame = 3 s, superframe = 120 frames = 6 min.
  Subframe 1 carries the basic navigation data in pages 1-10 (page = frame mod 10 + 1, so one
  full set every 30 s), subframe 2 pages 1-6, subframe 5 pages 1-120 (page = frame mod 120 + 1).
  The 20-bit SOW is a whole second and, in D2, is the start time of subframe 1 of the frame
  (a multiple of 3 s) in all five subframes of that frame: subframe j starts 0.6 (j-1) s after
  the SOW it carries. (This is how receivers such as GNSS-SDR interpret the D2 SOW.)

The paging is anchored at the start of the BDT week, which holds a whole number of superframes
of both messages.

Content
-------
D1 subframes 1-3 and D2 subframe 1 pages 1-10 carry the clock, health, group delays, Klobuchar
coefficients and ephemeris of the encoded :class:`~sdr_di.orbits.ephemeris.Ephemeris` (angles
converted to semicircles with the ICD pi, every value rounded to the nearest LSB). Almanac-type
pages are filled with valid content:

* almanac pages: the almanac of the encoded satellite (derived from its own ephemeris at
  toa = toe rounded down to 4096 s; clock terms saturate to their field range) and of any other
  satellite passed in ``almanac``; other satellites' pages are empty (all fields zero, which is
  how a missing almanac is broadcast), as is the page of a satellite whose orbit does not fit
  the almanac fields (e.g. e > 0.0625). AmEpID = 3 ("11"), so D1 subframe 5 pages 11-24 (D2
  pages 103-116) carry the expanded almanac/health of PRN 31-63, selected by AmID = 1, 2, 3 in
  successive superframes;
* health pages: 0 (healthy) for every satellite except an encoded one whose SatH1 = 1, which
  gets 0b100000010 (clock and navigation-message flags set);
* WNa/toa of the encoded satellite's almanac; time offsets to GPS/Galileo/GLONASS zero; UTC page
  with the BDT-UTC leap seconds of the broadcast time (A0UTC = A1UTC = 0);
* D2 ionospheric grid pages: every grid point "not available" (dtau = 511, GIVEI = 15);
* D2 subframes 2-4 (integrity and differential corrections): no satellite flagged
  (BDID1-30 = 0, BDEpID = 0), all other bits zero, page number in subframe 2;
* reserved bits are zero.

Polarity: logic 0 is the +1 level, see :mod:`sdr_di.signal.codes`.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
from collections.abc import Mapping

import numpy as np

from ..constants import GM_CGCS, SECONDS_PER_WEEK
from ..errors import NavMessageError
from ..orbits.ephemeris import Ephemeris, Klobuchar
from ..timebase import bdt_minus_utc, bdt_to_datetime, datetime_to_bdt, wrap_week_seconds
from . import fields as F
from ..constants import check_prn
from .codes import NH20, nav_type as _nav_type
from .fields import PARAMS, PI_ICD
from .words import PREAMBLE, SUBFRAME_BITS, build_info, decode_words, encode_words, parse_header

__all__ = [
    "EphemerisAssembler",
    "HeldSubframes",
    "assistance_klobuchar",
    "klobuchar_of_subframe",
    "NavBits",
    "code_period_signs",
    "decode_stream",
    "decode_subframe",
    "encode_subframe",
    "find_preamble",
    "nav_bits",
]

_SUB_MS = {"D1": 6000, "D2": 600}
_BIT_RATE = {"D1": 50.0, "D2": 500.0}
_SUB_PER_WEEK = {"D1": 604800 // 6, "D2": 604800 * 10 // 6}
_WEEK_S = int(SECONDS_PER_WEEK)
_HALF_WEEK = _WEEK_S // 2
_UNHEALTHY = 0b100000010
_AMID_BASE = {1: 31, 2: 44, 3: 57}
_AMID_COUNT = {1: 13, 2: 13, 3: 7}

#: Ephemeris attribute for each broadcast clock/ephemeris parameter.
_EPH_ATTR = {
    "SatH1": "SatH1", "AODC": "AODC", "URAI": "URAI", "toc": "toc", "TGD1": "TGD1",
    "TGD2": "TGD2", "a0": "af0", "a1": "af1", "a2": "af2", "AODE": "AODE", "toe": "toe",
    "sqrtA": "sqrtA", "e": "e", "omega": "omega", "Delta_n": "Delta_n", "M0": "M0",
    "Omega0": "Omega0", "Omega_dot": "Omega_dot", "i0": "i0", "IDOT": "IDOT",
    "Cuc": "Cuc", "Cus": "Cus", "Crc": "Crc", "Crs": "Crs", "Cic": "Cic", "Cis": "Cis",
}
_ANGLES = ("M0", "omega", "Omega0")
_ALM_NAMES = ("sqrtA_alm", "a1_alm", "a0_alm", "Omega0_alm", "e_alm", "delta_i", "toa",
              "Omega_dot_alm", "omega_alm", "M0_alm")


# --------------------------------------------------------------------------------------------
# public data container
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class NavBits:
    """A stretch of navigation data bits as transmitted (after BCH coding and interleaving).

    Attributes
    ----------
    bits : numpy.ndarray
        uint8 0/1 data bits in transmission order (what modulates the signal; the D1 NH code is
        *not* applied, see :func:`code_period_signs`).
    bit_rate : float
        50.0 (D1) or 500.0 (D2) [bit/s].
    t0 : float
        BDT seconds of week of the leading edge of ``bits[0]``, a subframe start [s]. Later bits
        may run past the end of the week (t0 + i / bit_rate >= 604800); their SOW fields wrap.
    week : int
        BDT week of ``t0``.
    prn : int
        Satellite PRN.
    nav_type : str
        ``'D1'`` or ``'D2'``.
    """

    bits: np.ndarray
    bit_rate: float
    t0: float
    week: int
    prn: int = 0
    nav_type: str = "D1"

    @property
    def duration(self) -> float:
        """Time covered by the bits [s]."""
        return self.bits.size / self.bit_rate

    @property
    def t_end(self) -> float:
        """BDT sow just after the last bit [s] (not wrapped at the week end)."""
        return self.t0 + self.duration

    @property
    def subframe_period(self) -> float:
        """Subframe duration [s]."""
        return SUBFRAME_BITS / self.bit_rate

    def bit_index(self, sow: float) -> int:
        """Index of the bit being transmitted at BDT ``sow`` [s] of :attr:`week`."""
        return int(math.floor((sow - self.t0) * self.bit_rate + 1e-9))


# --------------------------------------------------------------------------------------------
# encoder
# --------------------------------------------------------------------------------------------


def _wrap_angle(x: float) -> float:
    """Wrap an angle to [-pi, pi) with the ICD pi (so it fits the signed semicircle fields)."""
    two_pi = 2.0 * PI_ICD
    return x - two_pi * math.floor((x + PI_ICD) / two_pi)


def _raw(name: str, value: float, prn: int, *, saturate: bool = False) -> int:
    try:
        return PARAMS[name].to_raw(value, saturate=saturate)
    except NavMessageError as exc:
        raise NavMessageError(f"PRN {prn}: {exc}") from None


def ephemeris_raw(eph: Ephemeris, iono: Klobuchar | None = None) -> dict[str, int]:
    """Raw field values of the clock/ephemeris/Klobuchar parameters of ``eph`` (WN excluded).

    Raises
    ------
    NavMessageError
        A value that does not fit its field (e.g. toe not below one week, e > 0.5).
    """
    if not eph.finite():
        raise NavMessageError(f"PRN {eph.prn}: ephemeris has non-finite fields")
    for name in ("toe", "toc"):
        t = float(getattr(eph, name))
        if not 0.0 <= t < SECONDS_PER_WEEK:
            raise NavMessageError(f"PRN {eph.prn}: {name} = {t} s is not a time of week")
    raw: dict[str, int] = {}
    for name, attr in _EPH_ATTR.items():
        value = float(getattr(eph, attr))
        if name in _ANGLES:
            value = _wrap_angle(value)
        raw[name] = _raw(name, value, eph.prn)
    alpha = iono.alpha if iono is not None else (0.0,) * 4
    beta = iono.beta if iono is not None else (0.0,) * 4
    for k in range(4):
        raw[f"alpha{k}"] = _raw(f"alpha{k}", alpha[k], eph.prn)
        raw[f"beta{k}"] = _raw(f"beta{k}", beta[k], eph.prn)
    return raw


def almanac_toa(eph: Ephemeris) -> int:
    """Almanac reference time used for ``eph``: toe rounded down to a multiple of 4096 s [s]."""
    return int(eph.toe // 4096) * 4096


def almanac_raw(eph: Ephemeris, toa: float) -> dict[str, int]:
    """Raw almanac fields of a satellite, derived from its broadcast ephemeris at ``toa``.

    The mean anomaly, node longitude and inclination are propagated from toe to toa; the clock
    terms are evaluated at toa and saturate at the (coarse) almanac field limits. The reference
    inclination of delta_i is 0.30 semicircles for MEO/IGSO and 0 for GEO satellites.
    """
    dt = wrap_week_seconds(toa - eph.toe)
    a = eph.sqrtA**2
    n = math.sqrt(GM_CGCS / a**3) + eph.Delta_n
    i_ref = 0.0 if eph.is_geo else 0.30 * PI_ICD
    values = {
        "sqrtA_alm": eph.sqrtA,
        "a1_alm": eph.af1,
        "a0_alm": eph.af0 + eph.af1 * wrap_week_seconds(toa - eph.toc),
        "Omega0_alm": _wrap_angle(eph.Omega0 + eph.Omega_dot * dt),
        "e_alm": eph.e,
        "delta_i": eph.i0 + eph.IDOT * dt - i_ref,
        "toa": toa,
        "Omega_dot_alm": eph.Omega_dot,
        "omega_alm": _wrap_angle(eph.omega),
        "M0_alm": _wrap_angle(eph.M0 + n * dt),
    }
    return {k: _raw(k, v, eph.prn, saturate=k in ("a0_alm", "a1_alm")) for k, v in values.items()}


def _almanac_or_empty(eph: Ephemeris, toa: float) -> dict[str, int] | None:
    """Almanac fields of ``eph``, or None (empty page) when an orbit field does not fit."""
    try:
        return almanac_raw(eph, toa)
    except NavMessageError:
        return None


def _utc_raw(week: int, sow: float) -> dict[str, int]:
    """UTC page fields: leap seconds at (week, sow) and the week/day of the last leap second."""
    t = bdt_to_datetime(week, sow)
    dtls = bdt_minus_utc(t)
    wnlsf, dn = 0, 0
    year = t.year
    for y in range(year, 2005, -1):
        for month in (7, 1):
            d = _dt.datetime(y, month, 1)
            if d > t or d <= _dt.datetime(2006, 1, 2):
                continue
            if bdt_minus_utc(d) != bdt_minus_utc(d - _dt.timedelta(days=1)):
                wk, s = datetime_to_bdt(d - _dt.timedelta(days=1))
                wnlsf, dn = wk % 256, int(s // 86400)
                break
        else:
            continue
        break
    return {
        "dtLS": PARAMS["dtLS"].count_to_raw(dtls), "dtLSF": PARAMS["dtLSF"].count_to_raw(dtls),
        "WNLSF": wnlsf, "A0UTC": 0, "A1UTC": 0, "DN": dn,
    }


@dataclasses.dataclass
class _Context:
    prn: int
    nav: str
    eph: dict[str, int]
    alm: dict[int, dict[str, int]]
    health: dict[int, int]
    wna: int
    toa_raw: int
    utc: dict[str, int]


def _zeros(items) -> dict[str, int]:
    return {it.name: 0 for it in items if it.name != "rev"}


def _page(items, pnum_name: str, page: int, **values: int) -> tuple[tuple, dict[str, int]]:
    raw = _zeros(items)
    raw[pnum_name] = page
    raw.update(values)
    return items, raw


def _almanac_page(ctx: _Context, page: int, prn: int, id_name: str, id_value: int):
    items = F.ALMANAC if id_name == "AmEpID" else F.ALMANAC_EXT
    items, raw = _page(items, "Pnum", page)
    if prn in ctx.alm:
        raw.update(ctx.alm[prn])
    raw[id_name] = id_value
    return items, raw


def _health_page(ctx: _Context, items, page: int, prns, **extra: int):
    items, raw = _page(items, "Pnum", page, **extra)
    for slot, prn in prns:
        raw[slot] = ctx.health.get(prn, 0)
    return items, raw


def _ext_pages(ctx: _Context, page: int, index: int, amid: int, health: bool):
    """Expanded almanac (index 0..12) or health page selected by AmID."""
    if health:
        base, count = _AMID_BASE[amid], _AMID_COUNT[amid]
        slots = [(f"HeaX{k + 1}", base + k) for k in range(count)]
        return _health_page(ctx, F.HEALTH_EXT, page, slots, AmID=amid)
    if index >= _AMID_COUNT[amid]:
        return _page(F.RESERVED_PAGE, "Pnum", page)
    return _almanac_page(ctx, page, _AMID_BASE[amid] + index, "AmID", amid)


def _d1_content(k: int, ctx: _Context, week: int):
    fraid = k % 5 + 1
    frame = k // 5
    if fraid == 1:
        raw = dict(ctx.eph, WN=week % 8192)
        return fraid, F.D1_SF1, raw
    if fraid == 2:
        return fraid, F.D1_SF2, ctx.eph
    if fraid == 3:
        return fraid, F.D1_SF3, ctx.eph
    page = frame % 24 + 1
    amid = (frame // 24) % 3 + 1
    if fraid == 4:
        return (fraid, *_almanac_page(ctx, page, page, "AmEpID", 3))
    if page <= 6:
        return (fraid, *_almanac_page(ctx, page, 24 + page, "AmEpID", 3))
    kind = {7: "h1", 8: "h2", 9: "to", 10: "utc", 24: "hx"}.get(page, "ax")
    return (fraid, *_sf5_page(ctx, page, kind, page - 11, amid))


def _sf5_page(ctx: _Context, page: int, kind: str, index: int, amid: int):
    if kind == "h1":
        return _health_page(ctx, F.HEALTH_1_19, page, [(f"Hea{p}", p) for p in range(1, 20)])
    if kind == "h2":
        return _health_page(ctx, F.HEALTH_20_30, page, [(f"Hea{p}", p) for p in range(20, 31)],
                            WNa=ctx.wna, toa=ctx.toa_raw)
    if kind == "to":
        return _page(F.TIME_OFFSETS, "Pnum", page)
    if kind == "utc":
        return _page(F.UTC, "Pnum", page, **ctx.utc)
    if kind == "hx":
        return _ext_pages(ctx, page, 0, amid, health=True)
    if kind == "ax":
        return _ext_pages(ctx, page, index, amid, health=False)
    return _page(F.RESERVED_PAGE, "Pnum", page)


def _iono_grid_page(page: int, n: int):
    items = F.IONO_GRID_13 if n == 13 else F.IONO_GRID_4
    values = {}
    for j in range(1, n + 1):
        values[f"dtau{j}"] = 511
        values[f"GIVEI{j}"] = 15
    return _page(items, "Pnum", page, **values)


def _d2_content(k: int, ctx: _Context, week: int):
    fraid = k % 5 + 1
    frame = k // 5
    if fraid == 1:
        page = frame % 10 + 1
        raw = dict(ctx.eph, WN=week % 8192, Pnum4=page)
        return fraid, F.D2_SF1[page - 1], raw
    if fraid == 2:
        return (fraid, *_page(F.D2_SF2, "Pnum4", frame % 6 + 1))
    if fraid in (3, 4):
        return fraid, F.D2_SF34, {}
    page = frame % 120 + 1
    amid = (frame // 120) % 3 + 1
    if page <= 12 or 61 <= page <= 72:
        return (fraid, *_iono_grid_page(page, 13))
    if page in (13, 73):
        return (fraid, *_iono_grid_page(page, 4))
    if 37 <= page <= 60:
        return (fraid, *_almanac_page(ctx, page, page - 36, "AmEpID", 3))
    if 95 <= page <= 100:
        return (fraid, *_almanac_page(ctx, page, page - 70, "AmEpID", 3))
    kind = {35: "h1", 36: "h2", 101: "to", 102: "utc", 116: "hx"}.get(page)
    if kind is None and 103 <= page <= 115:
        kind = "ax"
    return (fraid, *_sf5_page(ctx, page, kind or "rev", page - 103, amid))


def encode_subframe(fraid: int, sow: int, items, raw: Mapping[str, int]) -> np.ndarray:
    """Encode one subframe (300 transmitted bits) from FraID, SOW [s], a body layout and raw values."""
    return encode_words(build_info(fraid, sow, F.pack_body(items, raw)))


def _context(eph: Ephemeris, iono: Klobuchar | None, almanac: Mapping[int, Ephemeris] | None,
             week: int, sow: float) -> _Context:
    prn = eph.prn
    eph_raw = ephemeris_raw(eph, iono)
    toa = almanac_toa(eph)
    alm = {prn: _almanac_or_empty(eph, toa)}
    health = {prn: 0 if eph.healthy else _UNHEALTHY}
    for p, other in (almanac or {}).items():
        p = check_prn(p)
        if p == prn:
            continue
        if other.prn != p:
            raise NavMessageError(f"almanac entry for PRN {p} holds the ephemeris of PRN {other.prn}")
        alm[p] = _almanac_or_empty(other, toa)
        health[p] = 0 if other.healthy else _UNHEALTHY
    alm = {p: a for p, a in alm.items() if a is not None}
    return _Context(prn, _nav_type(prn), eph_raw, alm, health,
                    eph.week % 256, toa // 4096, _utc_raw(week, sow))


def nav_bits(
    eph: Ephemeris,
    week: int,
    sow_start: float,
    duration_s: float,
    iono: Klobuchar | None = None,
    almanac: Mapping[int, Ephemeris] | None = None,
) -> NavBits:
    """Navigation data bits broadcast by ``eph.prn`` over a time interval.

    Parameters
    ----------
    eph : Ephemeris
        Broadcast record to encode (D1 for MEO/IGSO PRNs, D2 for GEO PRNs 1-5 and 59-63).
    week : int
        BDT week of ``sow_start``.
    sow_start : float
        BDT seconds of week of the start of the interval [s], 0 <= sow_start < 604800.
    duration_s : float
        Length of the interval [s], >= 0.
    iono : Klobuchar, optional
        Broadcast Klobuchar coefficients (zeros when None).
    almanac : mapping of PRN to Ephemeris, optional
        Records of other satellites whose almanac and health pages should be filled.

    Returns
    -------
    NavBits
        Whole subframes from the last subframe start at or before ``sow_start`` through the
        first subframe end at or after ``sow_start + duration_s``.

    Raises
    ------
    NavMessageError
        Bad interval, ephemeris more than half a week from the interval (its week could not be
        recovered from the broadcast WN), or a parameter outside its ICD field range.
    """
    prn = check_prn(eph.prn)
    nav = _nav_type(prn)
    week = int(week)
    sow_start = float(sow_start)
    duration_s = float(duration_s)
    if not (math.isfinite(sow_start) and 0.0 <= sow_start < SECONDS_PER_WEEK):
        raise NavMessageError(f"sow_start {sow_start!r} outside [0, 604800) s")
    if not (math.isfinite(duration_s) and duration_s >= 0.0):
        raise NavMessageError(f"duration_s {duration_s!r} must be finite and >= 0")
    if not 0 <= week:
        raise NavMessageError(f"BDT week {week} is negative")
    age = (week - eph.week) * SECONDS_PER_WEEK + sow_start - eph.toe
    if abs(age) > _HALF_WEEK:
        raise NavMessageError(
            f"PRN {prn}: ephemeris toe (week {eph.week}, {eph.toe} s) is {age:.0f} s from the "
            "requested time, more than half a week"
        )
    sub_ms = _SUB_MS[nav]
    k0 = int(math.floor(sow_start * 1000.0 / sub_ms + 1e-9))
    k1 = int(math.ceil((sow_start + duration_s) * 1000.0 / sub_ms - 1e-9))
    n_sub = max(k1 - k0, 1)
    ctx = _context(eph, iono, almanac, week, sow_start)
    per_week = _SUB_PER_WEEK[nav]
    content = _d1_content if nav == "D1" else _d2_content
    out = np.empty(n_sub * SUBFRAME_BITS, dtype=np.uint8)
    for j in range(n_sub):
        k = k0 + j
        wk = week + k // per_week
        kw = k % per_week
        fraid, items, raw = content(kw, ctx, wk)
        sow = kw * 6 if nav == "D1" else (kw // 5) * 3
        out[j * SUBFRAME_BITS : (j + 1) * SUBFRAME_BITS] = encode_subframe(fraid, sow, items, raw)
    out.setflags(write=False)
    return NavBits(out, _BIT_RATE[nav], k0 * sub_ms / 1000.0, week, prn, nav)


def code_period_signs(nb: NavBits) -> np.ndarray:
    """Data (times NH code for D1) level in every 1-ms primary code period of ``nb``.

    Returns
    -------
    numpy.ndarray
        int8 +/-1, one value per 1 ms starting at ``nb.t0``: D1 bit level (20 ms per bit) times
        NH20 (which restarts at every bit edge); D2 bit level (2 ms per bit).
    """
    level = (1 - 2 * nb.bits.astype(np.int8)).astype(np.int8)
    if nb.nav_type == "D1":
        return (np.repeat(level, 20).reshape(-1, 20) * NH20[None, :]).reshape(-1).astype(np.int8)
    return np.repeat(level, 2).astype(np.int8)


# --------------------------------------------------------------------------------------------
# decoder
# --------------------------------------------------------------------------------------------


def _bits_value(bits: np.ndarray) -> int:
    v = 0
    for b in bits:
        v = (v << 1) | int(b)
    return v


def _d1_layout(fraid: int, pnum: int):
    if fraid == 1:
        return F.D1_SF1, "D1_SF1"
    if fraid == 2:
        return F.D1_SF2, "D1_SF2"
    if fraid == 3:
        return F.D1_SF3, "D1_SF3"
    if fraid == 4 or pnum <= 6:
        return F.ALMANAC, "almanac"
    return {7: (F.HEALTH_1_19, "health_1_19"), 8: (F.HEALTH_20_30, "health_20_30"),
            9: (F.TIME_OFFSETS, "time_offsets"), 10: (F.UTC, "utc"),
            24: (F.HEALTH_EXT, "health_ext")}.get(pnum, (F.ALMANAC_EXT, "almanac_ext"))


def _d2_sf5_layout(pnum: int):
    if pnum <= 12 or 61 <= pnum <= 72:
        return F.IONO_GRID_13, "iono_grid"
    if pnum in (13, 73):
        return F.IONO_GRID_4, "iono_grid"
    if 37 <= pnum <= 60 or 95 <= pnum <= 100:
        return F.ALMANAC, "almanac"
    if 103 <= pnum <= 115:
        return F.ALMANAC_EXT, "almanac_ext"
    return {35: (F.HEALTH_1_19, "health_1_19"), 36: (F.HEALTH_20_30, "health_20_30"),
            101: (F.TIME_OFFSETS, "time_offsets"), 102: (F.UTC, "utc"),
            116: (F.HEALTH_EXT, "health_ext")}.get(pnum, (F.RESERVED_PAGE, "reserved"))


def decode_subframe(
    bits300: np.ndarray,
    nav_type: str | None = None,
    prn: int | None = None,
    *,
    strict: bool = True,
) -> dict:
    """Decode one 300-bit subframe (normal polarity, first bit = first preamble bit).

    Parameters
    ----------
    bits300 : array_like
        300 received data bits 0/1 in transmission order.
    nav_type : {'D1', 'D2'}, optional
        Message type; taken from ``prn`` when given, else D1.
    prn : int, optional
        Transmitting PRN (selects D1/D2).
    strict : bool
        Apply the message-level consistency checks that catch BCH miscorrections: SOW on the
        subframe grid (multiple of 6 s in D1, 3 s in D2), FraID (D1) and page numbers equal to
        the values implied by SOW, page numbers in range.

    Returns
    -------
    dict
        ``nav_type``, ``FraID``, ``SOW`` [s], ``Pnum`` (page number or None), ``layout`` (name),
        ``t_start`` (BDT sow of the subframe's first bit [s]), ``n_corrected`` (bits corrected
        by BCH), ``word_corrections`` (per word), ``raw`` (raw unsigned field bits keyed by
        field name, ``name[a:b]`` for a slice of a parameter split across D2 pages) and
        ``values`` (physical values of the complete parameters: SI units, radians).

    Raises
    ------
    NavMessageError
        Wrong length, bad preamble, FraID or SOW out of range, or (``strict``) inconsistent
        SOW / FraID / page number.
    """
    if prn is not None:
        nav_type = _nav_type(prn)
    nav = (nav_type or "D1").upper()
    if nav not in _SUB_MS:
        raise NavMessageError(f"unknown navigation message type {nav_type!r}")
    info, nc = decode_words(bits300)
    ok, _rev, fraid, sow = parse_header(info)
    if not ok:
        raise NavMessageError("bad preamble (expected 11100010010)")
    if not 1 <= fraid <= 5:
        raise NavMessageError(f"FraID {fraid} outside 1..5")
    if sow >= _WEEK_S:
        raise NavMessageError(f"SOW {sow} s beyond the end of the week")
    body = info[F.HEADER_BITS :]
    pnum = None
    if nav == "D1":
        if strict and (sow % 6 or fraid != (sow // 6) % 5 + 1):
            raise NavMessageError(f"D1 SOW {sow} s inconsistent with FraID {fraid}")
        if fraid >= 4:
            pnum = _bits_value(body[1:8])
            if not 1 <= pnum <= 24:
                raise NavMessageError(f"D1 subframe {fraid} page number {pnum} outside 1..24")
            if strict and pnum != (sow // 30) % 24 + 1:
                raise NavMessageError(f"D1 page {pnum} inconsistent with SOW {sow} s")
        items, name = _d1_layout(fraid, pnum or 0)
        t_start = float(sow)
    else:
        if strict and sow % 3:
            raise NavMessageError(f"D2 SOW {sow} s not a multiple of 3 s")
        frame = sow // 3
        if fraid == 1:
            pnum = _bits_value(body[0:4])
            items, name = (F.D2_SF1[pnum - 1], f"D2_SF1_P{pnum}") if 1 <= pnum <= 10 else (None, "")
            expect, top = frame % 10 + 1, 10
        elif fraid == 2:
            pnum = _bits_value(body[1:5])
            items, name = F.D2_SF2, "D2_SF2"
            expect, top = frame % 6 + 1, 6
        elif fraid == 5:
            pnum = _bits_value(body[1:8])
            items, name = _d2_sf5_layout(pnum)
            expect, top = frame % 120 + 1, 120
        else:
            items, name = F.D2_SF34, f"D2_SF{fraid}"
            expect = top = None
        if pnum is not None:
            if not 1 <= pnum <= top:
                raise NavMessageError(f"D2 subframe {fraid} page number {pnum} outside 1..{top}")
            if strict and pnum != expect:
                raise NavMessageError(f"D2 subframe {fraid} page {pnum} inconsistent with SOW {sow} s")
        t_start = sow + 0.6 * (fraid - 1)
    raw = F.unpack_body(items, body)
    values = {k: PARAMS[k].from_raw(v) for k, v in raw.items() if k in PARAMS}
    return {
        "nav_type": nav,
        "FraID": fraid,
        "SOW": sow,
        "Pnum": pnum,
        "layout": name,
        "t_start": t_start,
        "n_corrected": int(nc.sum()),
        "word_corrections": nc,
        "raw": raw,
        "values": values,
    }


def _header_plausible(bits300: np.ndarray) -> bool:
    """Type-independent check of a candidate subframe header: FraID 1-5, SOW < 1 week and a
    multiple of 3 s (after BCH correction of word 1)."""
    try:
        info, nc = decode_words(bits300)
    except NavMessageError:  # pragma: no cover - length is checked by the caller
        return False
    ok, _rev, fraid, sow = parse_header(info)
    return ok and 1 <= fraid <= 5 and sow < _WEEK_S and sow % 3 == 0


def find_preamble(bits: np.ndarray, start: int = 0, *, confirm: bool = True) -> tuple[int, int] | None:
    """Locate a subframe start in a demodulated bit stream of unknown polarity.

    Parameters
    ----------
    bits : array_like
        Hard-decision data bits 0/1.
    start : int
        First position searched.
    confirm : bool
        Accept a preamble match only when the 300 bits from there form a plausible subframe
        header (after BCH correction: FraID 1-5, SOW < 1 week and a multiple of 3 s) and, when
        the stream is long enough, the next subframe starts 300 bits later with the same
        preamble polarity and a plausible header too. Without it the first pattern match is
        returned (a random data pattern matches with probability 2^-10 per position).

    Returns
    -------
    (offset, polarity) or None
        ``polarity`` is +1 when the bits are as transmitted and -1 when inverted (the 180-degree
        carrier-phase ambiguity of a Costas loop); invert the stream (``1 - bits``) in that case.
    """
    b = np.asarray(bits, dtype=np.uint8) & 1
    n = b.size
    if n - start < PREAMBLE.size:
        return None
    win = np.lib.stride_tricks.sliding_window_view(b[start:], PREAMBLE.size)
    normal = np.all(win == PREAMBLE, axis=1)
    inverted = np.all(win == (1 - PREAMBLE), axis=1)
    for i in np.flatnonzero(normal | inverted):
        off = start + int(i)
        pol = 1 if normal[i] else -1
        if not confirm:
            return off, pol
        if off + SUBFRAME_BITS > n:
            break
        seg = b[off : off + SUBFRAME_BITS] if pol == 1 else 1 - b[off : off + SUBFRAME_BITS]
        if not _header_plausible(seg):
            continue
        nxt = off + SUBFRAME_BITS
        if nxt + PREAMBLE.size <= n:
            rep = b[nxt : nxt + PREAMBLE.size] if pol == 1 else 1 - b[nxt : nxt + PREAMBLE.size]
            if not np.array_equal(rep, PREAMBLE):
                continue
        if nxt + SUBFRAME_BITS <= n:
            seg2 = b[nxt : nxt + SUBFRAME_BITS] if pol == 1 else 1 - b[nxt : nxt + SUBFRAME_BITS]
            if not _header_plausible(seg2):
                continue
        return off, pol
    return None


def decode_stream(
    bits: np.ndarray, nav_type: str | None = None, prn: int | None = None, *, strict: bool = True
) -> list[dict]:
    """Synchronise on a bit stream of unknown polarity and decode every complete subframe.

    Each returned dict is a :func:`decode_subframe` result with two more keys: ``offset`` (index
    of the subframe's first bit in ``bits``) and ``polarity`` (+1/-1). Subframes that fail to
    decode are skipped; a polarity flip (half-cycle slip) is followed when the preamble reappears
    inverted at the expected place.
    """
    b = np.asarray(bits, dtype=np.uint8) & 1
    sync = find_preamble(b)
    out: list[dict] = []
    if sync is None:
        return out
    pos, pol = sync
    while pos + SUBFRAME_BITS <= b.size:
        seg = b[pos : pos + SUBFRAME_BITS]
        head = seg[: PREAMBLE.size] if pol == 1 else 1 - seg[: PREAMBLE.size]
        if not np.array_equal(head, PREAMBLE) and np.array_equal(1 - head, PREAMBLE):
            pol = -pol
        try:
            d = decode_subframe(seg if pol == 1 else 1 - seg, nav_type, prn, strict=strict)
        except NavMessageError:
            pos += SUBFRAME_BITS
            continue
        d["offset"] = pos
        d["polarity"] = pol
        out.append(d)
        pos += SUBFRAME_BITS
    return out


class HeldSubframes:
    """Decoded subframes held until the signal is confirmed present after their last bit.

    D1/D2 words are BCH(15,11) coded, a perfect code that "corrects" every noise word to some
    codeword, so a subframe whose last bits were demodulated after the signal had gone
    (a blockage, a fade) decodes cleanly with wrong fields. A receiver channel therefore
    holds each decoded subframe and passes it on (to its
    :class:`EphemerisAssembler`) only when a signal-presence test whose window starts at or
    after the subframe's end has passed; a failed or lost channel drops what it holds. The
    scalar channel counts in code epochs and tests with its code-lock C/N0
    (:mod:`~sdr_di.receiver.channel`), the vector loop's decoder in data bits with its fast
    C/N0 test (:mod:`~sdr_di.deep.navdecode`). At the deep hand-over what the scalar channel
    still holds moves to the loop's decoder (:meth:`take`, ends converted to its bits) and
    waits for the loop's test: no subframe skips the test.
    """

    def __init__(self) -> None:
        self._held: list[tuple[int, dict]] = []

    def __len__(self) -> int:
        return len(self._held)

    def hold(self, sf: dict, end: int) -> None:
        """Hold subframe ``sf``, whose last bit ends at ``end`` (the caller's unit, exclusive:
        the first epoch or bit after it). Subframes are held in the order of their ends
        (:meth:`confirmed` passes on the oldest first)."""
        self._held.append((int(end), sf))

    def confirmed(self, window_start: int) -> list[dict]:
        """The held subframes that end at or before ``window_start``, the start of the window
        of a passed test, oldest first; they are no longer held."""
        n = 0
        while n < len(self._held) and self._held[n][0] <= window_start:
            n += 1
        out = [sf for _, sf in self._held[:n]]
        del self._held[:n]
        return out

    def take(self) -> list[tuple[int, dict]]:
        """Every held subframe with its end, ``(end, sf)`` oldest first, for another holder
        to go on holding until its own test (the deep hand-over: the scalar channel's
        subframes move to the vector loop's decoder, :mod:`~sdr_di.integration.receiver`);
        none held here after."""
        out = self._held
        self._held = []
        return out

    def drop(self) -> None:
        """Forget the held subframes (the signal was not confirmed)."""
        self._held = []


class EphemerisAssembler:
    """Collects decoded subframes of one satellite and rebuilds its broadcast record.

    D1: subframes 2 and 3 of one 30-s frame plus subframe 1 of that frame or of another frame
    whose toc equals their toe (same upload) form one data set. D2: pages 1-10 of
    subframe 1 of the same 30-s cycle (pages split parameters across page boundaries, so pages
    of different cycles are never mixed). The toe week is recovered from the broadcast WN with
    the half-week crossover rule against the SOW of the subframe that carried WN.

    Parameters
    ----------
    prn : int
        Satellite PRN (selects D1/D2).
    """

    def __init__(self, prn: int) -> None:
        self.prn = check_prn(prn)
        self.nav_type = _nav_type(self.prn)
        self._parts: dict[int, dict] = {}
        self._done_group: tuple[int, ...] | None = None
        self._done_sows: set = set()   # SOW of the subframes of the last set returned
        self.ephemeris: Ephemeris | None = None
        self.klobuchar: Klobuchar | None = None

    def add(self, sf: dict) -> tuple[Ephemeris, Klobuchar] | None:
        """Add one :func:`decode_subframe` result.

        Returns
        -------
        (Ephemeris, Klobuchar) or None
            The record, when this subframe completes a consistent data set not returned before;
            a set equal to the last one and sharing a subframe with it (D1: a new subframe 1
            with the last subframes 2 and 3, or the last subframe 1 with new ones) is not
            returned again, so that two returned copies of a record are independent decodes.
        """
        if sf.get("nav_type") != self.nav_type:
            raise NavMessageError(
                f"PRN {self.prn} expects {self.nav_type} subframes, got {sf.get('nav_type')}"
            )
        group = sf["SOW"] // 30
        if self.nav_type == "D1":
            if sf["FraID"] not in (1, 2, 3):
                return None
            key, needed = sf["FraID"], (1, 2, 3)
        else:
            if sf["FraID"] != 1 or sf["Pnum"] is None:
                return None
            key, needed = sf["Pnum"], tuple(range(1, 11))
        self._parts[key] = sf
        if any(k not in self._parts for k in needed):
            return None
        groups = tuple(self._parts[k]["SOW"] // 30 for k in needed)
        if self.nav_type == "D1":
            # Subframes 2 and 3 split toe between them and must come from one frame; subframe 1
            # (clock, health, Klobuchar) may come from another frame when its toc equals that
            # toe (the same upload), so a receiver that missed the first subframe 1 completes
            # the set with the next one instead of waiting for a whole new frame.
            if groups[1] != groups[2]:
                return None
            if groups[0] != groups[1] and not self._same_upload():
                return None
        elif any(g != group for g in groups):
            return None
        if self._done_group == groups:
            return None
        result = self._build([self._parts[k] for k in needed])
        self._done_group = groups
        sows = {self._parts[k]["SOW"] for k in needed}
        if sows & self._done_sows and result == (self.ephemeris, self.klobuchar):
            # the last set returned, rebuilt with some of its subframes: not a second,
            # independent copy (NavDataInForce's two-copies rule would count it as one)
            return None
        self._done_sows = sows
        self.ephemeris, self.klobuchar = result
        return result

    def _same_upload(self) -> bool:
        """D1: subframe 1's toc equals the toe of subframes 2 and 3 (raw counts)."""
        pieces: dict[str, int] = {}
        for k in (2, 3):
            pieces.update(self._parts[k]["raw"])
        toe = F.join_slices("toe", pieces)
        toc = F.join_slices("toc", self._parts[1]["raw"])
        return toe is not None and toc is not None and toe == toc

    def _build(self, parts: list[dict]) -> tuple[Ephemeris, Klobuchar]:
        pieces: dict[str, int] = {}
        for p in parts:
            pieces.update(p["raw"])

        def value(name: str) -> float:
            raw = F.join_slices(name, pieces)
            if raw is None:
                raise NavMessageError(f"PRN {self.prn}: parameter {name} incomplete")
            return PARAMS[name].from_raw(raw)

        kwargs = {attr: value(name) for name, attr in _EPH_ATTR.items()}
        for name in ("SatH1", "AODC", "URAI", "AODE"):
            kwargs[name] = int(kwargs[name])
        wn = int(value("WN"))
        sow_wn = parts[0]["SOW"]
        toe = kwargs["toe"]
        week = wn
        if toe - sow_wn > _HALF_WEEK:
            week -= 1
        elif sow_wn - toe > _HALF_WEEK:
            week += 1
        eph = Ephemeris(prn=self.prn, week=week, **kwargs)
        klob = Klobuchar(
            alpha=tuple(value(f"alpha{k}") for k in range(4)),
            beta=tuple(value(f"beta{k}") for k in range(4)),
        )
        return eph, klob


def broadcast_klobuchar(iono: Klobuchar) -> Klobuchar:
    """The Klobuchar coefficients as a receiver decodes them: each rounded to its ICD LSB.

    The IF generator simulates the ionosphere with these values, so the delay model in the
    signal and in the broadcast message are identical.

    Raises
    ------
    NavMessageError
        A coefficient does not fit its 8-bit field.
    """
    names = ("alpha0", "alpha1", "alpha2", "alpha3", "beta0", "beta1", "beta2", "beta3")
    values = [F.PARAMS[n].from_raw(F.PARAMS[n].to_raw(v))
              for n, v in zip(names, (*iono.alpha, *iono.beta))]
    return Klobuchar(alpha=tuple(values[:4]), beta=tuple(values[4:]))


def assistance_klobuchar(nav) -> tuple[Klobuchar | None, str]:
    """Klobuchar coefficients of a navigation file, as the satellites broadcast them.

    The file's BDS coefficients when present (``nav.iono``: the RINEX 3 header's
    ``BDSA``/``BDSB`` lines, or the RINEX 4 ION frame :func:`~sdr_di.orbits.rinex_nav.load_nav`
    chose, labelled by ``nav.iono_label``); otherwise its GPS
    coefficients (``GPSA``/``GPSB``: the same eight-parameter set with the same scale factors,
    describing the same day's ionosphere), used with the BDS model; otherwise none. Each is
    rounded to its ICD LSB (:func:`broadcast_klobuchar`), so a receiver taking them as
    assistance uses the values the IF generator simulates and the D1/D2 messages carry.

    Returns
    -------
    (Klobuchar or None, str)
        The coefficients and where they come from, in words.
    """
    if getattr(nav, "iono", None) is not None:
        return broadcast_klobuchar(nav.iono), getattr(nav, "iono_label", "") or "BDSA/BDSB"
    if getattr(nav, "iono_gps", None) is not None:
        return broadcast_klobuchar(nav.iono_gps), "GPSA/GPSB (file has no BDS coefficients)"
    return None, "none (file has no Klobuchar coefficients)"


def klobuchar_of_subframe(sf: dict) -> Klobuchar | None:
    """The Klobuchar coefficients a decoded subframe carries whole (D1 subframe 1), else None.

    A receiver can use them as soon as subframe 1 is decoded, before subframes 2-3 complete
    the ephemeris (:class:`EphemerisAssembler` returns them only with a complete set).

    Parameters
    ----------
    sf : dict
        A :func:`decode_subframe` result.
    """
    raw = sf.get("raw", {})
    vals = []
    for name in ("alpha0", "alpha1", "alpha2", "alpha3", "beta0", "beta1", "beta2", "beta3"):
        r = F.join_slices(name, raw)
        if r is None:
            return None
        vals.append(PARAMS[name].from_raw(r))
    return Klobuchar(alpha=tuple(vals[:4]), beta=tuple(vals[4:]))
