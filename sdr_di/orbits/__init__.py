"""Broadcast ephemerides, satellite orbits and clocks, precise orbits, atmosphere models.

Modules
-------
``ephemeris``   the :class:`Ephemeris` / :class:`Klobuchar` records shared with the other stages
``rinex_nav``   RINEX 3.0x navigation reader (:func:`load_nav`, :class:`NavData`, record selection)
``broadcast``   satellite position / velocity / clock from a record (MEO/IGSO/GEO, CGCS2000, BDT)
``sp3``         SP3-c/d precise orbit reader and interpolator (for tests and validation)
``atmosphere``  BDS Klobuchar ionosphere (B1I, scaled to B3I) and Saastamoinen troposphere
"""

from .atmosphere import iono_delay_b3i_m, klobuchar_delay, saastamoinen_delay
from .broadcast import sat_pos_vel_clock, sat_states
from .ephemeris import Ephemeris, Klobuchar
from .rinex_nav import NavData, load_nav, merge_nav, read_klobuchar
from .sp3 import Sp3Orbits, load_sp3

__all__ = [
    "Ephemeris", "Klobuchar", "NavData", "load_nav", "merge_nav", "read_klobuchar",
    "sat_pos_vel_clock", "sat_states", "Sp3Orbits", "load_sp3",
    "klobuchar_delay", "iono_delay_b3i_m", "saastamoinen_delay",
]
