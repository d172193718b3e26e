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
  a newer toe, or the same toe with another AODE (a new upload), replaces it, provided it
  passes the next check;
* **plausibility** of a new data set (another week, toe or AODE than the decoded record in
  force, or the first decoded record where an assistance record is in force): its satellite
  position and clock are compared with those of the record in force (:meth:`select`, decoded
  or assistance) at its toe and 30 min either side (:data:`PLAUSIBLE_CHECK_DT_S`; the rate
  fields ``Delta_n``, ``IDOT``, ``Omega_dot``, ``af1``, ``af2`` have no effect at toe). Two
  consecutive broadcast data sets of one satellite agree closely inside their fit intervals:
  over the 730 consecutive BDS pairs of the three CN/MN files in ``ephemeris/`` (toes 1 h
  apart, compared at the later toe and +-1800 s), position differences have a median of
  0.1 m, a 99th percentile of 1 m and a maximum of 4.4 m, clock differences 0.1 m, 1.4 m and
  2.4 m. A field a BCH(15,11) miscorrection or noise bits changed moves the satellite by
  40 m to thousands of km (count-change C10: argument of perigee 2.4e-5 rad off; the TCXO
  25 MHz seed-3 C30 record with AODE 30: 202 km of range, 333 km of height, 360 km of
  position error for the rest of the run). A new record farther than
  :data:`PLAUSIBLE_POSITION_M` (50 m) in position or :data:`PLAUSIBLE_CLOCK_M` (50 m times
  1/c) in clock from the one in force at any of those times, 10 times the largest
  legitimate difference, is held and takes force only when a second, separately decoded,
  identical copy arrives (the two-copies rule above; a real change that large, after a
  manoeuvre, waits one more frame); each held copy counts in ``n_implausible`` and
  ``n_rejected``. Without a record in force at those times the record is taken as it is
  (nothing to check against), unless a decoded record of the satellite is held: its toe is
  then out of reach of the new one's (a week or toe field corrupted forwards; an older toe
  is refused outright), and the new record would displace a good one with a record that is
  in force at no time the receiver sees, so it is held for a second copy as well;
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

import numpy as np

from ..constants import C_LIGHT, SECONDS_PER_WEEK, is_geo
from ..errors import NoEphemerisError, UnknownPrnError
from ..orbits.broadcast import sat_pos_vel_clock
from ..orbits.ephemeris import Ephemeris, Klobuchar
from ..orbits.rinex_nav import DEFAULT_MAX_AGE_GEO_S, DEFAULT_MAX_AGE_S
from ..signal.navmsg import assistance_klobuchar

__all__ = ["BROADCAST", "RINEX", "NavDataInForce", "NavDataWarning", "NavEvent"]

#: Largest satellite-position difference [m] between a new decoded data set and the record
#: in force that lets it take force alone (module notes: 10 times the 4.4 m maximum of
#: consecutive broadcast data sets).
PLAUSIBLE_POSITION_M = 50.0
#: Same for the satellite clock, as range [m] (c times the clock-offset difference).
PLAUSIBLE_CLOCK_M = 50.0
#: Times from the new record's toe [s] at which the two are compared.
PLAUSIBLE_CHECK_DT_S = (-1800.0, 0.0, 1800.0)

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
        Decoded copies ignored (same data-set identity, other content) and records rejected
        (stale, or held as implausible).
    n_implausible : int
        New data sets held because they disagree with the record in force (module notes).
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
        self.n_implausible = 0
        self._challenger: dict[int, Ephemeris] = {}  # a copy held for a second one (notes)
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
        if cur is not None and (cur.week, cur.toe, cur.AODE) == (eph.week, eph.toe, eph.AODE):
            if cur == eph:
                self._challenger.pop(prn, None)  # two copies agree with the one in force
                return False
            vote = self._second_copy(prn, eph)
            if vote is None:
                return False
            self.n_conflicts += 1
            if not vote:
                return False
        else:
            if cur is not None and _toe_abs(eph) < _toe_abs(cur):
                self.n_rejected += 1
                return False
            if self._implausible(eph):
                vote = self._second_copy(prn, eph)
                if not vote:
                    if vote is not None:
                        self.n_implausible += 1
                        self.n_rejected += 1
                    return False
        self._challenger.pop(prn, None)
        self._decoded[prn] = eph
        self.events.append(NavEvent(t_s, "ephemeris", prn, eph.toe, eph.week, eph.AODE))
        return True

    def _second_copy(self, prn: int, eph: Ephemeris) -> bool | None:
        """The two-copies rule for a decoded copy that may not take force alone (module
        notes): True when ``eph`` is a second, separately decoded copy equal to the one held
        for ``prn`` (it takes force), None when it is that held copy offered again (no vote),
        False when it is now the one held."""
        held = self._challenger.get(prn)
        if held is eph:
            return None
        if held == eph:
            return True
        self._challenger[prn] = eph
        return False

    def _implausible(self, eph: Ephemeris) -> bool:
        """True when the satellite position or clock of ``eph`` differs from the record in
        force (decoded or assistance) by more than :data:`PLAUSIBLE_POSITION_M` /
        :data:`PLAUSIBLE_CLOCK_M` at one of the times :data:`PLAUSIBLE_CHECK_DT_S` from its
        toe (module notes). No record in force at any of them: True while a decoded record
        of the satellite is held (its toe is then far from the new one's: a corrupted week
        or toe, which would displace it; a second copy decides), else False (nothing to
        check against)."""
        compared = False
        for dt in PLAUSIBLE_CHECK_DT_S:
            t = _toe_abs(eph) + dt
            week, sow = divmod(t, SECONDS_PER_WEEK)
            try:
                ref = self.select(eph.prn, int(week), sow)
            except (NoEphemerisError, UnknownPrnError):
                continue
            compared = True
            r0, _, c0, _ = sat_pos_vel_clock(ref, sow, int(week))
            r1, _, c1, _ = sat_pos_vel_clock(eph, sow, int(week))
            if not (float(np.linalg.norm(r1 - r0)) <= PLAUSIBLE_POSITION_M
                    and abs(float(c1[0] - c0[0])) * C_LIGHT <= PLAUSIBLE_CLOCK_M):
                return True
        return not compared and int(eph.prn) in self._decoded

    def offer_klobuchar(self, klob: Klobuchar | None, t_s: float = math.nan) -> bool:
        """Offer decoded ionosphere coefficients; True when the set in force changed.

        A set whose eight coefficients are all zero carries none (a transmitter with none
        to send: SignalSim, given a RINEX file without BDS ionosphere lines, broadcasts
        zeros while its signal carries the GPS set's delays); it does not displace a set in
        force (the assistance file's, or one decoded before), and with none in force it is
        taken as what it is, Klobuchar's night-time constant (5 ns at the zenith).
        """
        if klob is None or klob == self._klob:
            return False
        if not all(math.isfinite(v) for v in (*klob.alpha, *klob.beta)):
            return False
        if not any((*klob.alpha, *klob.beta)) and self.klobuchar is not None:
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
