"""Ephemeris source of a receiver given assistance data (a RINEX navigation file).

The rules (decoded records first, the navigation file's record *on the air* before them,
validity checks, which wins when both exist) live in one place,
:class:`~sdr_di.receiver.navdata.NavDataInForce`; :class:`AssistedEphemerides` is that class
under the name the experiments know (``AssistedEphemerides(nav)``, ``.decoded = {prn: eph}``
offers decoded records, ``.select``/``.has``).

The record on the air (:meth:`~sdr_di.orbits.rinex_nav.NavData.select` with
``broadcast=True``) is the one an assistance server would send: the record the satellite's
message carries, so the receiver's orbit and clock model is the one in the signal. (The
record with the nearest toe is the next hour's from half past on, and differs from the
broadcast one by decimetres.)
"""

from __future__ import annotations

from .navdata import NavDataInForce

__all__ = ["AssistedEphemerides"]

AssistedEphemerides = NavDataInForce
