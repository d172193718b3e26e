"""Navigation data in force: the one place that decides which ephemeris, ionosphere and
troposphere model every receiver mode uses (DESIGN section 7).

Sources
-------
* **broadcast**: records and Klobuchar coefficients decoded from the signal (the scalar
  channels before the hand-over, the deep loop's channels after it), offered as they arrive
  (:meth:`NavDataInForce.offer_ephemeris`, :meth:`NavDataInForce.offer_klobuchar`);
* **rinex**: the assistance navigation file (:class:`~sdr_di.orbits.rinex_nav.NavData`): per
  satellite the record *on the air* at the time (``select(..., broadcast=True)``, the one an
  assistance server would send), and its header's Klobuchar coefficients
  (:func:`~sdr_di.signal.navmsg.assistance_klobuchar`: BDS lines, else GPS lines).

Validity checks on a decoded record (the same for every mode)
-------------------------------------------------------------
* **finite** fields and **health** (``SatH1 = 0``): an unhealthy decoded record withdraws
  the satellite's decoded data (the assistance record, healthy by construction of
  :class:`~sdr_di.orbits.rinex_nav.NavData`, is used until a healthy one is decoded);
* **data-set change** by (week, toe, AODE): a record with the data-set identity of the one in
  force changes nothing (a second copy whose other fields differ is a decoding error the BCH
  code missed, counted in ``n_conflicts`` and ignored), unless a later copy (another decoded
  object, not the same one offered again) agrees with that differing one: two copies
  against one replace the record in force, so a wrong first copy
  (bits decoded after the signal was gone; :mod:`~sdr_di.receiver.channel` notes) is
  corrected by the next frame instead of staying in force for the data set's life; a
  record whose toe is *older* than the one in force is stale and rejected (``n_rejected``);
  a newer toe, or the same toe with another AODE (a new upload), replaces it;
* **toe age** at use: a decoded record is in force while ``|t - toe|`` is within
  ``max_age_s`` (:data:`~sdr_di.orbits.rinex_nav.DEFAULT_MAX_AGE_S`, GEO
  :data:`~sdr_di.orbits.rinex_nav.DEFAULT_MAX_AGE_GEO_S`), as for the assistance records.

Which wins (:meth:`NavDataInForce.select`)
------------------------------------------
Both a valid decoded record and an assistance record: **the decoded record**, whatever the
two toes, as long as it passes the checks above. It is what the satellite sends, and the
file's choice of the record "on the air" rests on transmission times a foreign or merged
file may not have right (the issue-18 file: its record on the air was an hour older than the
signal's). When a satellite switches to a new upload, the old decoded record stays in force
until the new one is decoded (at most one D1 frame, 30 s, well inside its fit interval;
decimetres at most); a RINEX record newer than the decoded one is not taken in between, so
a generated file, whose signal keeps one record for its whole length, never gets a model
its signal does not carry. Klobuchar: the decoded set whenever one has been decoded, else
the file's.

Troposphere: Saastamoinen with the standard atmosphere (:mod:`~sdr_di.receiver.pvt`), needing
no broadcast data; recorded here so the summaries name it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

from ..constants import SECONDS_PER_WEEK, is_geo
from ..errors import NoEphemerisError, UnknownPrnError
from ..orbits.ephemeris import Ephemeris, Klobuchar
from ..orbits.rinex_nav import DEFAULT_MAX_AGE_GEO_S, DEFAULT_MAX_AGE_S
from ..signal.navmsg import assistance_klobuchar

__all__ = ["BROADCAST", "RINEX", "NavDataInForce", "NavDataWarning", "NavEvent"]

BROADCAST = "broadcast"
RINEX = "rinex"
TROPOSPHERE_MODEL = "saastamoinen"


class NavDataWarning(UserWarning):
    """A receiver runs without navigation data it would normally have (e.g. no ionosphere
    coefficients at the deep hand-over)."""


def _toe_abs(e: Ephemeris) -> float:
    return e.week * SECONDS_PER_WEEK + float(e.toe)


@dataclasses.dataclass(frozen=True)
class NavEvent:
    """One change of the navigation data in force (or of what was offered).

    Attributes
    ----------
    t_s : float
        Caller's time tag (seconds since the IF file start; NaN when not given).
    kind : str
        ``"ephemeris"`` (accepted decoded record), ``"unhealthy"`` (decoded health flag set),
        ``"ionosphere"`` (decoded Klobuchar set accepted).
    prn : int or None
    toe, week, aode : record identity (ephemeris events)
    """

    t_s: float
    kind: str
    prn: int | None = None
    toe: float | None = None
    week: int | None = None
    aode: int | None = None


class NavDataInForce:
    """Decoded broadcast data first, assistance (RINEX) data before it (module notes).

    Parameters
    ----------
    nav : NavData or None
        Assistance navigation data (:func:`~sdr_di.orbits.rinex_nav.load_nav`); None: decoded
        data only.
    decoded : dict[int, Ephemeris], optional
        Decoded records to offer at once.

    Attributes
    ----------
    events : list of NavEvent
        Accepted decoded data, in order.
    n_conflicts, n_rejected : int
        Decoded copies ignored (same data-set identity, other content) and stale records
        rejected.
    """

    def __init__(self, nav=None, decoded: Mapping | None = None) -> None:
        self.nav = nav
        self._decoded: dict[int, Ephemeris] = {}
        self._klob: Klobuchar | None = None
        self._nav_klob, self.assistance_iono_label = (
            assistance_klobuchar(nav) if nav is not None else (None, "no assistance file"))
        self.events: list[NavEvent] = []
        self.n_conflicts = 0
        self.n_rejected = 0
        self._challenger: dict[int, Ephemeris] = {}  # a differing copy of the set in force
        if decoded:
            self.offer_decoded(decoded)

    # -- decoded data ---------------------------------------------------------------------
    def offer_ephemeris(self, eph: Ephemeris, t_s: float = math.nan) -> bool:
        """Offer a record decoded from the signal (validity checks in the module notes).

        Returns
        -------
        bool
            True when the decoded data of ``eph.prn`` changed (accepted, or withdrawn by a
            set health flag).
        """
        prn = int(eph.prn)
        cur = self._decoded.get(prn)
        if cur is eph or not eph.finite():
            return False
        if not eph.healthy:
            if cur is None:
                return False
            del self._decoded[prn]
            self.events.append(NavEvent(t_s, "unhealthy", prn, eph.toe, eph.week, eph.AODE))
            return True
        if cur is not None:
            if (cur.week, cur.toe, cur.AODE) == (eph.week, eph.toe, eph.AODE):
                if cur == eph:
                    self._challenger.pop(prn, None)  # two copies agree with the one in force
                    return False
                ch = self._challenger.get(prn)
                if ch is eph:               # the same decoded copy offered again
                    return False
                self.n_conflicts += 1
                if ch != eph:
                    self._challenger[prn] = eph
                    return False
            if _toe_abs(eph) < _toe_abs(cur):
                self.n_rejected += 1
                return False
        self._challenger.pop(prn, None)
        self._decoded[prn] = eph
        self.events.append(NavEvent(t_s, "ephemeris", prn, eph.toe, eph.week, eph.AODE))
        return True

    def offer_klobuchar(self, klob: Klobuchar | None, t_s: float = math.nan) -> bool:
        """Offer decoded ionosphere coefficients; True when the set in force changed."""
        if klob is None or klob == self._klob:
            return False
        if not all(math.isfinite(v) for v in (*klob.alpha, *klob.beta)):
            return False
        self._klob = klob
        self.events.append(NavEvent(t_s, "ionosphere"))
        return True

    def offer_decoded(self, ephemerides: Mapping, klobuchar: Klobuchar | None = None,
                      t_s: float = math.nan) -> NavDataInForce:
        """Offer every record of ``{prn: Ephemeris}`` and a Klobuchar set; returns self."""
        for e in ephemerides.values():
            if e is not None:
                self.offer_ephemeris(e, t_s)
        self.offer_klobuchar(klobuchar, t_s)
        return self

    @property
    def decoded(self) -> dict:
        """``{prn: Ephemeris}`` accepted from the signal (assigning a dict offers its records)."""
        return dict(self._decoded)

    @decoded.setter
    def decoded(self, ephemerides: Mapping) -> None:
        self.offer_decoded(ephemerides)

    # -- selection ------------------------------------------------------------------------
    def select_with_source(self, prn: int, week: int, sow: float) -> tuple[Ephemeris, str]:
        """``(record, source)`` in force for ``prn`` at BDT (``week``, ``sow``) (module
        notes: a valid decoded record, else the assistance record on the air).

        Raises
        ------
        NoEphemerisError
            Neither a valid decoded record nor an assistance record.
        UnknownPrnError
            Bad PRN (from the assistance file's lookup).
        """
        t = int(week) * SECONDS_PER_WEEK + float(sow)
        d = self._decoded.get(int(prn))
        max_age = DEFAULT_MAX_AGE_GEO_S if is_geo(int(prn)) else DEFAULT_MAX_AGE_S
        if d is not None and abs(t - _toe_abs(d)) <= max_age:
            return d, BROADCAST
        if self.nav is not None:
            try:
                return self.nav.select(prn, week, sow, broadcast=True), RINEX
            except NoEphemerisError:
                pass
        raise NoEphemerisError(f"no ephemeris for C{int(prn):02d} at BDT week {int(week)} "
                               f"sow {float(sow):.3f}: none decoded"
                               + ("" if self.nav is not None else ", no assistance file"))

    def select(self, prn: int, week: int, sow: float) -> Ephemeris:
        """The record in force (see :meth:`select_with_source`)."""
        return self.select_with_source(prn, week, sow)[0]

    def has(self, prn: int, week: int, sow: float) -> bool:
        """True when :meth:`select` has a record."""
        try:
            self.select(prn, week, sow)
        except (NoEphemerisError, UnknownPrnError):
            return False
        return True

    # -- atmosphere -----------------------------------------------------------------------
    @property
    def klobuchar(self) -> Klobuchar | None:
        """Ionosphere coefficients in force: decoded, else the assistance file's, else None."""
        return self._klob if self._klob is not None else self._nav_klob

    @property
    def iono_source(self) -> str | None:
        """``"broadcast"``, ``"rinex"`` or None (no ionosphere model)."""
        if self._klob is not None:
            return BROADCAST
        return RINEX if self._nav_klob is not None else None

    def models(self) -> dict:
        """Atmosphere models in force, for summaries."""
        src = self.iono_source
        return {
            "ionosphere": {"model": "klobuchar" if src else "none", "source": src,
                           "assistance_file": self.assistance_iono_label},
            "troposphere": {"model": TROPOSPHERE_MODEL,
                            "source": "standard atmosphere (no broadcast data needed)"},
        }
