"""Parameter table and subframe/page bit layouts of the BDS D1/D2 navigation messages.

One table (:data:`PARAMS`) gives, for every broadcast parameter, its bit width, scale factor
(LSB), signedness (two's complement) and whether the ICD broadcasts it in semicircles while the
project stores radians. Encoder and decoder both go through :meth:`Param.to_raw` and
:meth:`Param.from_raw`: there is one implementation of the scaling.

Layouts
-------
A subframe carries 224 information bits (word 1: 26, words 2-10: 22 each) plus parity. With the
parity removed, every field that the ICD splits across words ("MSBs" in one word, "LSBs" in the
next) is contiguous, so a layout is simply the ordered list of fields of the information stream.
The first 38 bits are the common header (preamble 11, Rev 4, FraID 3, SOW 20); the layouts below
describe the remaining 186-bit *body* (BDS-SIS-ICD-B3I-1.0 section 5.2.3 for D1, 5.3.2 for D2).
A D2 parameter that spans two pages of subframe 1 appears as two slices ``(name, start, n)``
(bits ``start .. start+n-1`` of the parameter, MSB = bit 0).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import NavMessageError

__all__ = [
    "BODY_BITS",
    "HEADER_BITS",
    "INFO_BITS",
    "PARAMS",
    "PI_ICD",
    "Item",
    "Param",
    "layout",
    "pack_body",
    "unpack_body",
]

#: pi as defined by the ICD for semicircle <-> radian conversion.
PI_ICD = 3.1415926535898
#: Information bits per subframe (26 + 9 * 22).
INFO_BITS = 224
#: Header bits (preamble 11, Rev 4, FraID 3, SOW 20).
HEADER_BITS = 38
#: Body bits per subframe after the header.
BODY_BITS = INFO_BITS - HEADER_BITS


@dataclasses.dataclass(frozen=True)
class Param:
    """One broadcast parameter.

    Attributes
    ----------
    name : str
        Parameter name (ICD spelling where practical).
    bits : int
        Width in bits.
    scale : float
        ICD scale factor (LSB) in broadcast units (semicircles for angles).
    signed : bool
        Two's complement when True.
    semicircles : bool
        Broadcast in semicircles (or semicircles/s); the physical value is in radians (rad/s).
    unit : str
        Unit of the physical value.
    """

    name: str
    bits: int
    scale: float = 1.0
    signed: bool = False
    semicircles: bool = False
    unit: str = ""

    @property
    def lsb(self) -> float:
        """LSB in physical units (radians for semicircle parameters)."""
        return self.scale * PI_ICD if self.semicircles else self.scale

    @property
    def int_range(self) -> tuple[int, int]:
        """Inclusive range of the integer count."""
        if self.signed:
            return -(1 << (self.bits - 1)), (1 << (self.bits - 1)) - 1
        return 0, (1 << self.bits) - 1

    def to_count(self, value: float, *, saturate: bool = False) -> int:
        """Quantize a physical value to the nearest LSB count.

        Raises
        ------
        NavMessageError
            Value not finite, or outside the field range (unless ``saturate``).
        """
        x = float(value)
        if not math.isfinite(x):
            raise NavMessageError(f"{self.name}: value {value!r} is not finite")
        k = math.floor(x / self.lsb + 0.5)
        lo, hi = self.int_range
        if not lo <= k <= hi:
            if saturate:
                return min(max(k, lo), hi)
            raise NavMessageError(
                f"{self.name}: value {x!r}{' ' + self.unit if self.unit else ''} does not fit in {self.bits} bits "
                f"{'signed' if self.signed else 'unsigned'} with LSB {self.lsb:g}"
            )
        return k

    def to_raw(self, value: float, *, saturate: bool = False) -> int:
        """Physical value -> raw unsigned field bits (two's complement for signed fields)."""
        return self.count_to_raw(self.to_count(value, saturate=saturate))

    def count_to_raw(self, count: int) -> int:
        """Integer count -> raw unsigned field bits, with range check."""
        lo, hi = self.int_range
        k = int(count)
        if not lo <= k <= hi:
            raise NavMessageError(f"{self.name}: count {k} outside {lo}..{hi}")
        return k & ((1 << self.bits) - 1)

    def raw_to_count(self, raw: int) -> int:
        """Raw unsigned field bits -> integer count (sign-extended for signed fields)."""
        r = int(raw) & ((1 << self.bits) - 1)
        if self.signed and r >= 1 << (self.bits - 1):
            r -= 1 << self.bits
        return r

    def from_raw(self, raw: int) -> float:
        """Raw unsigned field bits -> physical value."""
        return self.raw_to_count(raw) * self.lsb


def _p(name, bits, scale=1.0, signed=False, semicircles=False, unit=""):
    return Param(name, bits, float(scale), signed, semicircles, unit)


_TABLE: list[Param] = [
    # header and page numbers
    _p("FraID", 3), _p("SOW", 20, unit="s"), _p("Pnum", 7), _p("Pnum4", 4),
    # clock, health, group delays (D1 subframe 1 / D2 subframe 1 pages 1-4)
    _p("SatH1", 1), _p("AODC", 5), _p("URAI", 4), _p("WN", 13, unit="week"),
    _p("toc", 17, 2.0**3, unit="s"),
    _p("TGD1", 10, 1e-10, True, unit="s"), _p("TGD2", 10, 1e-10, True, unit="s"),
    _p("a0", 24, 2.0**-33, True, unit="s"), _p("a1", 22, 2.0**-50, True, unit="s/s"),
    _p("a2", 11, 2.0**-66, True, unit="s/s^2"), _p("AODE", 5),
    # Klobuchar (per-semicircle units, no radian conversion: the Klobuchar record keeps them)
    _p("alpha0", 8, 2.0**-30, True, unit="s"), _p("alpha1", 8, 2.0**-27, True, unit="s/sc"),
    _p("alpha2", 8, 2.0**-24, True, unit="s/sc^2"), _p("alpha3", 8, 2.0**-24, True, unit="s/sc^3"),
    _p("beta0", 8, 2.0**11, True, unit="s"), _p("beta1", 8, 2.0**14, True, unit="s/sc"),
    _p("beta2", 8, 2.0**16, True, unit="s/sc^2"), _p("beta3", 8, 2.0**16, True, unit="s/sc^3"),
    # ephemeris
    _p("toe", 17, 2.0**3, unit="s"),
    _p("sqrtA", 32, 2.0**-19, unit="m^0.5"), _p("e", 32, 2.0**-33),
    _p("omega", 32, 2.0**-31, True, True, "rad"), _p("Delta_n", 16, 2.0**-43, True, True, "rad/s"),
    _p("M0", 32, 2.0**-31, True, True, "rad"), _p("Omega0", 32, 2.0**-31, True, True, "rad"),
    _p("Omega_dot", 24, 2.0**-43, True, True, "rad/s"), _p("i0", 32, 2.0**-31, True, True, "rad"),
    _p("IDOT", 14, 2.0**-43, True, True, "rad/s"),
    _p("Cuc", 18, 2.0**-31, True, unit="rad"), _p("Cus", 18, 2.0**-31, True, unit="rad"),
    _p("Crc", 18, 2.0**-6, True, unit="m"), _p("Crs", 18, 2.0**-6, True, unit="m"),
    _p("Cic", 18, 2.0**-31, True, unit="rad"), _p("Cis", 18, 2.0**-31, True, unit="rad"),
    # almanac
    _p("sqrtA_alm", 24, 2.0**-11, unit="m^0.5"), _p("a1_alm", 11, 2.0**-38, True, unit="s/s"),
    _p("a0_alm", 11, 2.0**-20, True, unit="s"), _p("Omega0_alm", 24, 2.0**-23, True, True, "rad"),
    _p("e_alm", 17, 2.0**-21), _p("delta_i", 16, 2.0**-19, True, True, "rad"),
    _p("toa", 8, 2.0**12, unit="s"), _p("Omega_dot_alm", 17, 2.0**-38, True, True, "rad/s"),
    _p("omega_alm", 24, 2.0**-23, True, True, "rad"), _p("M0_alm", 24, 2.0**-23, True, True, "rad"),
    _p("AmEpID", 2), _p("AmID", 2), _p("WNa", 8, unit="week"),
    # time offsets and UTC
    _p("A0GPS", 14, 1e-10, True, unit="s"), _p("A1GPS", 16, 1e-10, True, unit="s/s"),
    _p("A0Gal", 14, 1e-10, True, unit="s"), _p("A1Gal", 16, 1e-10, True, unit="s/s"),
    _p("A0GLO", 14, 1e-10, True, unit="s"), _p("A1GLO", 16, 1e-10, True, unit="s/s"),
    _p("dtLS", 8, 1, True, unit="s"), _p("dtLSF", 8, 1, True, unit="s"), _p("WNLSF", 8, unit="week"),
    _p("A0UTC", 32, 2.0**-30, True, unit="s"), _p("A1UTC", 24, 2.0**-50, True, unit="s/s"),
    _p("DN", 8, unit="day"),
    # D2 integrity (subframe 2): only the leading fields are named, the rest is zero-filled
    _p("SatH2", 2), _p("BDID", 30),
]
_TABLE += [_p(f"Hea{k}", 9) for k in range(1, 31)]
_TABLE += [_p(f"HeaX{k}", 9) for k in range(1, 14)]
for _k in range(1, 14):
    _TABLE += [_p(f"dtau{_k}", 9, 0.125, unit="m"), _p(f"GIVEI{_k}", 4)]

#: All parameters by name.
PARAMS: dict[str, Param] = {p.name: p for p in _TABLE}
if len(PARAMS) != len(_TABLE):  # pragma: no cover - guards the table itself
    raise RuntimeError("duplicate parameter name in the navigation parameter table")


@dataclasses.dataclass(frozen=True)
class Item:
    """One layout entry: ``n`` bits of parameter ``name`` starting at its bit ``start``
    (MSB = 0), or ``n`` reserved bits when ``name == 'rev'``."""

    name: str
    n: int
    start: int = 0

    @property
    def whole(self) -> bool:
        """True when the item is the complete parameter."""
        return self.name != "rev" and self.start == 0 and self.n == PARAMS[self.name].bits

    @property
    def key(self) -> str:
        """Name of the item in decoded output: the parameter, or ``name[start:stop]`` for a slice."""
        return self.name if self.whole else f"{self.name}[{self.start}:{self.start + self.n}]"


def layout(*specs: str | tuple) -> tuple[Item, ...]:
    """Build a body layout, padding with reserved bits to :data:`BODY_BITS`.

    Each spec is a parameter name, ``('rev', n)`` or a slice ``(name, start, n)``.
    """
    items: list[Item] = []
    for s in specs:
        if isinstance(s, str):
            items.append(Item(s, PARAMS[s].bits))
        elif s[0] == "rev":
            items.append(Item("rev", int(s[1])))
        else:
            name, start, n = s
            if start < 0 or start + n > PARAMS[name].bits:
                raise ValueError(f"slice {s} outside parameter {name}")
            items.append(Item(name, int(n), int(start)))
    used = sum(it.n for it in items)
    if used > BODY_BITS:
        raise ValueError(f"layout uses {used} > {BODY_BITS} bits")
    if used < BODY_BITS:
        items.append(Item("rev", BODY_BITS - used))
    return tuple(items)


def pack_body(items: Sequence[Item], raw: Mapping[str, int]) -> np.ndarray:
    """Pack raw field values into the 186-bit body (uint8 0/1, MSB first).

    ``raw`` maps parameter names to raw unsigned field bits (see :meth:`Param.to_raw`); every
    parameter of the layout must be present (reserved bits are zero).
    """
    out = np.zeros(BODY_BITS, dtype=np.uint8)
    pos = 0
    for it in items:
        if it.name != "rev":
            try:
                value = int(raw[it.name])
            except KeyError:
                raise NavMessageError(f"no value for navigation field {it.name}") from None
            width = PARAMS[it.name].bits
            if not 0 <= value < 1 << width:
                raise NavMessageError(f"raw {it.name}={value} does not fit {width} bits")
            piece = (value >> (width - it.start - it.n)) & ((1 << it.n) - 1)
            out[pos : pos + it.n] = (piece >> np.arange(it.n - 1, -1, -1)) & 1
        pos += it.n
    return out


def unpack_body(items: Sequence[Item], body: np.ndarray) -> dict[str, int]:
    """Inverse of :func:`pack_body`: raw unsigned values keyed by :attr:`Item.key`
    (reserved bits are dropped)."""
    out: dict[str, int] = {}
    pos = 0
    for it in items:
        if it.name != "rev":
            v = 0
            for b in body[pos : pos + it.n]:
                v = (v << 1) | int(b)
            out[it.key] = v
        pos += it.n
    return out


def join_slices(name: str, pieces: Mapping[str, int]) -> int | None:
    """Reassemble a parameter from its slices ``name[a:b]`` found in ``pieces`` (raw values);
    returns None unless the slices cover the whole parameter exactly."""
    width = PARAMS[name].bits
    if name in pieces:
        return int(pieces[name])
    found = []
    prefix = name + "["
    for key, val in pieces.items():
        if key.startswith(prefix):
            a, b = key[len(prefix) : -1].split(":")
            found.append((int(a), int(b), int(val)))
    found.sort()
    value, pos = 0, 0
    for a, b, v in found:
        if a != pos:
            return None
        value = (value << (b - a)) | v
        pos = b
    return value if pos == width else None


# --- layouts -------------------------------------------------------------------------------------

_KLOB = ("alpha0", "alpha1", "alpha2", "alpha3", "beta0", "beta1", "beta2", "beta3")

#: D1 subframe 1: clock, health, group delays, Klobuchar, AODE.
D1_SF1 = layout("SatH1", "AODC", "URAI", "WN", "toc", "TGD1", "TGD2", *_KLOB, "a2", "a0", "a1", "AODE")
#: D1 subframe 2: ephemeris I (toe MSBs at the end).
D1_SF2 = layout("Delta_n", "Cuc", "M0", "e", "Cus", "Crc", "Crs", "sqrtA", ("toe", 0, 2))
#: D1 subframe 3: ephemeris II (toe LSBs first, 1 reserved bit at the end).
D1_SF3 = layout(("toe", 2, 15), "i0", "Cic", "Omega_dot", "Cis", "IDOT", "Omega0", "omega", ("rev", 1))

_PG = (("rev", 1), "Pnum")
_ALM = ("sqrtA_alm", "a1_alm", "a0_alm", "Omega0_alm", "e_alm", "delta_i", "toa",
        "Omega_dot_alm", "omega_alm", "M0_alm")
#: Almanac page (D1 SF4 p1-24, SF5 p1-6; D2 SF5 p37-60, p95-100).
ALMANAC = layout(*_PG, *_ALM, "AmEpID")
#: Expanded almanac page (D1 SF5 p11-23, D2 SF5 p103-115) when AmEpID = 3: AmID in place of AmEpID.
ALMANAC_EXT = layout(*_PG, *_ALM, "AmID")
#: Health of PRN 1-19 (D1 SF5 p7, D2 SF5 p35).
HEALTH_1_19 = layout(*_PG, *(f"Hea{k}" for k in range(1, 20)))
#: Health of PRN 20-30, almanac week and toa (D1 SF5 p8, D2 SF5 p36).
HEALTH_20_30 = layout(*_PG, *(f"Hea{k}" for k in range(20, 31)), "WNa", "toa")
#: Expanded health of 13 satellites selected by AmID (D1 SF5 p24, D2 SF5 p116).
HEALTH_EXT = layout(*_PG, *(f"HeaX{k}" for k in range(1, 14)), "AmID")
#: Time offsets to GPS/Galileo/GLONASS (D1 SF5 p9, D2 SF5 p101).
TIME_OFFSETS = layout(*_PG, ("rev", 30), "A0GPS", "A1GPS", "A0Gal", "A1Gal", "A0GLO", "A1GLO")
#: UTC parameters (D1 SF5 p10, D2 SF5 p102).
UTC = layout(*_PG, "dtLS", "dtLSF", "WNLSF", "A0UTC", "A1UTC", "DN")
#: Reserved page (page number only).
RESERVED_PAGE = layout(*_PG)
#: D2 SF5 ionospheric grid page with 13 grid points (p1-12, p61-72).
IONO_GRID_13 = layout(*_PG, *(x for k in range(1, 14) for x in (f"dtau{k}", f"GIVEI{k}")))
#: D2 SF5 ionospheric grid page with 4 grid points (p13, p73).
IONO_GRID_4 = layout(*_PG, *(x for k in range(1, 5) for x in (f"dtau{k}", f"GIVEI{k}")))

#: D2 subframe 1 pages 1..10 (index 0 = page 1).
D2_SF1 = (
    layout("Pnum4", "SatH1", "AODC", "URAI", "WN", "toc", "TGD1", "TGD2"),
    layout("Pnum4", *_KLOB),
    layout("Pnum4", ("rev", 38), "a0", ("a1", 0, 4)),
    layout("Pnum4", ("a1", 4, 18), "a2", "AODE", "Delta_n", ("Cuc", 0, 14)),
    layout("Pnum4", ("Cuc", 14, 4), "M0", "Cus", ("e", 0, 10)),
    layout("Pnum4", ("e", 10, 22), "sqrtA", ("Cic", 0, 10)),
    layout("Pnum4", ("Cic", 10, 8), "Cis", "toe", ("i0", 0, 21)),
    layout("Pnum4", ("i0", 21, 11), "Crc", "Crs", ("Omega_dot", 0, 19)),
    layout("Pnum4", ("Omega_dot", 19, 5), "Omega0", ("omega", 0, 27)),
    layout("Pnum4", ("omega", 27, 5), "IDOT"),
)
#: D2 subframe 2 (integrity and differential corrections): Pnum, SatH2, BDID1-30, rest zero.
D2_SF2 = layout(("rev", 1), "Pnum4", "SatH2", "BDID")
#: D2 subframes 3 and 4: no page number; all zero when no corrections are broadcast.
D2_SF34 = layout()
