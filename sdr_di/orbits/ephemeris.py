"""The BDS broadcast ephemeris record shared by the orbit, signal and receiver code.

Field names and units follow BDS-SIS-ICD-B3I-1.0 section 5.2.4 (angles in radians here, even
where the ICD broadcasts semicircles; the message encoder converts). Times are BDT.
"""

from __future__ import annotations

import dataclasses
import math

from ..constants import is_geo


@dataclasses.dataclass(frozen=True)
class Ephemeris:
    """One BDS broadcast clock + ephemeris record (B3I; D1 or D2 message).

    Attributes
    ----------
    prn : int
        Satellite PRN, 1..63.
    week : int
        BDT week number of toe (RINEX "BDT week"; the ICD broadcasts it modulo 8192).
    toc : float
        Clock reference time, BDT seconds of week [s].
    af0, af1, af2 : float
        Clock bias [s], drift [s/s], drift rate [s/s^2].
    toe : float
        Ephemeris reference time, BDT seconds of week [s].
    sqrtA : float
        Square root of the semi-major axis [m^0.5].
    e : float
        Eccentricity [-].
    i0, Omega0, omega, M0 : float
        Inclination, longitude of ascending node at week start, argument of perigee,
        mean anomaly at toe [rad].
    Delta_n, Omega_dot, IDOT : float
        Mean motion difference, rate of right ascension, rate of inclination [rad/s].
    Cuc, Cus, Cic, Cis : float
        Harmonic corrections to argument of latitude and inclination [rad].
    Crc, Crs : float
        Harmonic corrections to orbit radius [m].
    TGD1, TGD2 : float
        Group delays B1I/B3I and B2I/B3I [s] (B3I is the clock reference: not applied).
    AODE, AODC : int
        Age of data, ephemeris and clock (ICD 5-bit codes; RINEX carries them directly).
    SatH1 : int
        Autonomous satellite health flag (0 = healthy).
    URAI : int
        User range accuracy index.
    """

    prn: int
    week: int
    toc: float
    af0: float
    af1: float
    af2: float
    toe: float
    sqrtA: float
    e: float
    i0: float
    Omega0: float
    omega: float
    M0: float
    Delta_n: float
    Omega_dot: float
    IDOT: float
    Cuc: float
    Cus: float
    Cic: float
    Cis: float
    Crc: float
    Crs: float
    TGD1: float = 0.0
    TGD2: float = 0.0
    AODE: int = 0
    AODC: int = 0
    SatH1: int = 0
    URAI: int = 0

    @property
    def is_geo(self) -> bool:
        """True for GEO satellites (D2 message, GEO orbit rotation)."""
        return is_geo(self.prn)

    @property
    def healthy(self) -> bool:
        """True when the autonomous health flag SatH1 is 0."""
        return self.SatH1 == 0

    def finite(self) -> bool:
        """True when every numeric field is finite (no NaN/inf slipped through a reader)."""
        return all(
            math.isfinite(float(getattr(self, f.name))) for f in dataclasses.fields(self)
        )


@dataclasses.dataclass(frozen=True)
class Klobuchar:
    """BDS broadcast Klobuchar ionosphere coefficients (ICD 5.2.4.7).

    alpha [s, s/semicircle, s/semicircle^2, s/semicircle^3],
    beta [s, s/semicircle, s/semicircle^2, s/semicircle^3].
    """

    alpha: tuple[float, float, float, float]
    beta: tuple[float, float, float, float]
