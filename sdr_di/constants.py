"""Physical constants, CGCS2000 ellipsoid and BeiDou B3I signal parameters.

All values SI. CGCS2000 values follow BDS-SIS-ICD-B3I-1.0 section 5.2.4.
"""

#: Speed of light in vacuum [m/s].
C_LIGHT = 299_792_458.0

# --- CGCS2000 ellipsoid and Earth parameters -------------------------------------
#: Semi-major axis [m].
A_CGCS = 6_378_137.0
#: Flattening [-].
F_CGCS = 1.0 / 298.257222101
#: First eccentricity squared [-].
E2_CGCS = F_CGCS * (2.0 - F_CGCS)
#: Semi-minor axis [m].
B_CGCS = A_CGCS * (1.0 - F_CGCS)
#: Earth gravitational constant GM [m^3/s^2].
GM_CGCS = 3.986004418e14
#: Earth rotation rate [rad/s].
OMEGA_E = 7.2921150e-5
#: Relativistic clock correction constant F = -2 sqrt(GM)/c^2 [s/m^0.5].
F_REL = -4.442807309e-10

# --- BeiDou B3I ---------------------------------------------------------------------
#: B3I carrier frequency [Hz].
F_B3I = 1268.52e6
#: B3I chipping rate [chip/s].
CHIP_RATE_B3I = 10.23e6
#: Chips per primary code period.
CODE_LENGTH_B3I = 10230
#: Primary code period [s].
CODE_PERIOD_B3I = CODE_LENGTH_B3I / CHIP_RATE_B3I
#: Carrier wavelength [m].
LAMBDA_B3I = C_LIGHT / F_B3I
#: Carrier cycles per code chip (1268.52e6 / 10.23e6 = 124).
CARRIER_PER_CHIP_B3I = F_B3I / CHIP_RATE_B3I

#: GEO PRNs (D2 navigation message, no NH code).
GEO_PRNS = frozenset((1, 2, 3, 4, 5, 59, 60, 61, 62, 63))
#: IGSO PRNs (inclined geosynchronous orbits, D1 message): BDS-2 C06-C10, C13, C16 and
#: BDS-3 C38-C40 (the constellation status of the China Satellite Navigation Office).
IGSO_PRNS = frozenset((6, 7, 8, 9, 10, 13, 16, 38, 39, 40))
#: All B3I PRNs.
ALL_PRNS = tuple(range(1, 64))

# --- Time ---------------------------------------------------------------------------
#: Seconds per week.
SECONDS_PER_WEEK = 604_800.0
#: BDT = GPST - 14 s.
BDT_MINUS_GPST = -14.0
#: BDT week = GPS week - 1356.
BDT_WEEK_OFFSET = 1356


def check_prn(prn) -> int:
    """Return ``prn`` as an int if it is a B3I PRN (1..63), else raise ``UnknownPrnError``."""
    from .errors import UnknownPrnError

    try:
        p = int(prn)
    except (TypeError, ValueError):
        raise UnknownPrnError(f"unknown BDS PRN {prn!r} (valid: 1..63)") from None
    if p != prn or not 1 <= p <= 63:
        raise UnknownPrnError(f"unknown BDS PRN {prn!r} (valid: 1..63)")
    return p


def parse_prn(value) -> int:
    """Parse a PRN given as ``21``, ``"21"`` or ``"C21"``; raise ``UnknownPrnError`` otherwise."""
    from .errors import UnknownPrnError

    text = str(value).strip().upper()
    try:
        prn = int(text[1:] if text.startswith("C") else text)
    except ValueError:
        raise UnknownPrnError(f"{value!r} is not a BDS PRN (1..63 or C01..C63)") from None
    if not 1 <= prn <= 63:
        raise UnknownPrnError(f"unknown BDS PRN {value!r} (valid: 1..63)")
    return prn


class PrnListWarning(UserWarning):
    """A PRN list named a satellite more than once: each is searched (or simulated) once."""


def parse_prns(values, what: str = "--prn") -> list[int]:
    """PRNs of a list (``["C21", 22, "c21"]``) in order, each once (:func:`parse_prn`); a
    repeated PRN is dropped with one :class:`PrnListWarning` naming ``what`` (every command
    treats a list this way: issue 49 item 9).

    Raises
    ------
    UnknownPrnError
        An entry that is not a BDS PRN.
    """
    import collections
    import warnings

    prns = [parse_prn(v) for v in values]
    counts = collections.Counter(prns)
    twice = [f"C{p:02d} x{n}" for p, n in counts.items() if n > 1]
    if twice:
        warnings.warn(f"{what}: {', '.join(twice)}: each PRN is used once",
                      PrnListWarning, stacklevel=2)
    return list(dict.fromkeys(prns))


def is_geo(prn: int) -> bool:
    """Return True for a GEO PRN (D2 message, GEO orbit computation)."""
    return int(prn) in GEO_PRNS


def orbit_type(prn: int) -> str:
    """``"GEO"``, ``"IGSO"`` or ``"MEO"`` of a PRN (:data:`GEO_PRNS`, :data:`IGSO_PRNS`)."""
    p = int(prn)
    return "GEO" if p in GEO_PRNS else "IGSO" if p in IGSO_PRNS else "MEO"
