"""Ephemeris source of a receiver given assistance data (a RINEX navigation file).

Records decoded from the signal come first. Until a satellite's record is decoded, the
navigation file's record *on the air* at the time is used
(:meth:`~sdr_di.orbits.rinex_nav.NavData.select` with ``broadcast=True``), the one an
assistance server would send: it is the record the satellite's message carries, so the
receiver's orbit and clock model is the one in the signal. (The record with the nearest toe
is the next hour's from half past on, and differs from the broadcast one by decimetres.)
"""

from __future__ import annotations

from ..errors import NoEphemerisError, UnknownPrnError
from ..orbits.ephemeris import Ephemeris

__all__ = ["AssistedEphemerides"]


class AssistedEphemerides:
    """Decoded records first, then the navigation file's broadcast record.

    Parameters
    ----------
    nav : NavData or None
        Assistance navigation data (:func:`~sdr_di.orbits.rinex_nav.load_nav`); None: decoded
        records only.
    decoded : dict[int, Ephemeris], optional
        Decoded records per PRN (the receiver replaces this attribute as it decodes).
    """

    def __init__(self, nav, decoded: dict | None = None) -> None:
        self.nav = nav
        self.decoded: dict = {} if decoded is None else decoded

    def select(self, prn: int, week: int, sow: float) -> Ephemeris:
        """The decoded record of ``prn`` if healthy and finite, else the navigation file's
        record on the air at BDT (``week``, ``sow``).

        Raises
        ------
        NoEphemerisError
            Neither exists.
        """
        e = self.decoded.get(prn)
        if e is not None and e.healthy and e.finite():
            return e
        if self.nav is None:
            raise NoEphemerisError(f"no ephemeris for C{prn:02d}")
        return self.nav.select(prn, week, sow, broadcast=True)

    def has(self, prn: int, week: int, sow: float) -> bool:
        """True when :meth:`select` has a record."""
        try:
            self.select(prn, week, sow)
        except (NoEphemerisError, UnknownPrnError):
            return False
        return True
