"""BDS satellite position, velocity and clock from a broadcast ephemeris (ICD B3I 5.2.4).

All computations use the CGCS2000 constants of :mod:`sdr_di.constants` (GM = 3.986004418e14
m^3/s^2, omega_e = 7.2921150e-5 rad/s, F = -4.442807309e-10 s/m^0.5) and BDT. Output frame:
ECEF CGCS2000 at the given time (no Earth-rotation/light-time correction: that is the
caller's business; give the signal transmission time).

* MEO/IGSO: ICD table 5-11, Omega_k = Omega_0 + (Omega_dot - omega_e) t_k - omega_e t_oe.
* GEO (PRN 1-5, 59-63): Omega_k = Omega_0 + Omega_dot t_k - omega_e t_oe, position computed in
  the user-defined inertial-like frame, then r = R_Z(omega_e t_k) R_X(-5 deg) r_GK with the
  ICD's rotation matrices R_X(phi) = [[1,0,0],[0,cos,sin],[0,-sin,cos]],
  R_Z(phi) = [[cos,sin,0],[-sin,cos,0],[0,0,1]].
* Velocity: analytic time derivative of exactly the same formulas (tested against a finite
  difference of the position).
* Clock: dt_sv = a0 + a1 (t - toc) + a2 (t - toc)^2 + F e sqrtA sin E_k (relativistic term)
  and its derivative. B3I is the clock reference signal: no TGD is applied.

Time: ``t_sow`` is BDT seconds of week. Without ``week``, t_k = t - t_oe is wrapped into
[-302400, 302400) s (ICD week-crossover rule); with ``week`` the full difference
(week - eph.week) * 604800 + t - t_oe is used, which is exact for any distance.
"""

from __future__ import annotations

import dataclasses
import threading

import numpy as np

from ..constants import F_REL, GM_CGCS, OMEGA_E, SECONDS_PER_WEEK
from .ephemeris import Ephemeris

__all__ = ["EphemerisStack", "GEO_INCLINATION_ROT", "kepler_E", "sat_pos_vel_clock",
           "geo_to_ecef", "sat_pos_vel_clock_stacked", "sat_states",
           "stack_ephemerides"]

#: Rotation angle of the GEO inertial-like frame about X [rad] (ICD: -5 deg).
GEO_INCLINATION_ROT = np.deg2rad(-5.0)
_HALF_WEEK = SECONDS_PER_WEEK / 2.0


def _time_from(t_sow: np.ndarray, week: int | None, ref_week, ref_sow) -> np.ndarray:
    """t - ref [s]: full week-aware difference if ``week`` is given, else wrapped (ICD).
    ``ref_week``, ``ref_sow``: numbers, or arrays broadcasting with ``t_sow``."""
    if week is not None:
        return (int(week) - np.asarray(ref_week, np.int64)) * SECONDS_PER_WEEK \
            + (t_sow - ref_sow)
    d = t_sow - ref_sow
    return (d + _HALF_WEEK) % SECONDS_PER_WEEK - _HALF_WEEK


def kepler_E(M: np.ndarray, e, tol: float = 1e-15, max_iter: int = 30) -> np.ndarray:
    """Solve Kepler's equation M = E - e sin E for E [rad] (Newton, vectorized).

    ``M`` of up to one dimension stops when every element has converged; with two or more
    (rows: records of :func:`sat_pos_vel_clock_stacked`, ``e`` of shape (n, 1)) each row
    stops when its own elements have, as it would alone."""
    M = np.asarray(M, float)
    E = M.copy()
    if M.ndim < 2:
        for _ in range(max_iter):
            dE = (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
            E = E - dE
            if np.all(np.abs(dE) < tol):
                break
        return E
    # rows (records of a stack) converge separately: a row stops where it would alone
    active = np.ones(M.shape[0], bool)
    rows = active.reshape((-1,) + (1,) * (M.ndim - 1))     # (a view: follows `active`)
    inner = tuple(range(1, M.ndim))
    for _ in range(max_iter):
        dE = (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
        E = np.where(rows, E - dE, E)
        active &= ~(np.abs(dE) < tol).all(axis=inner)
        if not active.any():
            break
    return E


@dataclasses.dataclass(frozen=True)
class EphemerisStack:
    """The parameters of ``n`` broadcast records as column arrays (``(n, 1)`` float64, or
    ``(n,)`` where noted), for :func:`sat_pos_vel_clock_stacked`: one numpy pass over all
    records instead of one call per record. Built by :func:`stack_ephemerides`.

    The per-record constants the orbit formulas use (``A``, mean motion ``n``,
    ``sqrt(1 - e^2)``, node rate, ``F e sqrtA``) are computed here once per record, in
    Python floats with the same expressions as the per-record evaluation had, so the stacked
    results equal those of one record at a time bit for bit.
    """

    ephs: tuple                 # the records, in row order (kept: the cache keys on them)
    week: np.ndarray            # int64 (n, 1): BDT week of toe
    toc_week: np.ndarray        # int64 (n, 1): BDT week of toc (:func:`_toc_week`)
    toe: np.ndarray             # [s of week]
    toc: np.ndarray             # [s of week]
    A: np.ndarray               # semi-major axis [m]
    sqrtA: np.ndarray           # [m^0.5]
    n: np.ndarray               # corrected mean motion n0 + Delta_n [rad/s]
    e: np.ndarray               # eccentricity
    sq1e2: np.ndarray           # sqrt(1 - e^2)
    M0: np.ndarray
    omega: np.ndarray
    i0: np.ndarray
    IDOT: np.ndarray
    Omega0: np.ndarray
    om_rate: np.ndarray         # node rate in ECEF (MEO/IGSO: Omega_dot - omega_e; GEO: Omega_dot)
    om_toe: np.ndarray          # omega_e toe [rad]
    Cus: np.ndarray
    Cuc: np.ndarray
    Crs: np.ndarray
    Crc: np.ndarray
    Cis: np.ndarray
    Cic: np.ndarray
    af0: np.ndarray
    af1: np.ndarray
    af2: np.ndarray
    f_e_sqrtA: np.ndarray       # F e sqrtA [s/rad]: the relativistic clock term's factor
    geo: np.ndarray             # bool (n,): GEO rows
    #: (26, n) float64: the 24 columns above in the order of :func:`stack_ephemerides`'
    #: ``names``, then ``week`` and ``toc_week`` (for the range model's numba kernels)
    table: np.ndarray = dataclasses.field(repr=False, compare=False,
                                          default_factory=lambda: np.empty((26, 0)))

    @property
    def size(self) -> int:
        """Number of records ``n``."""
        return len(self.ephs)


#: :func:`stack_ephemerides`' cache: ``{ids of the records: EphemerisStack}`` (the stack
#: holds its records, so their ids stay theirs while the entry lives).
_STACKS: dict[tuple[int, ...], EphemerisStack] = {}
_STACKS_MAX = 64
#: Guards the cache's eviction and insertion (loose/tight run their loop on a second thread).
_STACKS_LOCK = threading.Lock()


def stack_ephemerides(ephemerides) -> EphemerisStack:
    """The :class:`EphemerisStack` of a sequence of records (cached by record identity:
    records are frozen, and a set in force is reused for many epochs)."""
    ephs = tuple(ephemerides)
    key = tuple(map(id, ephs))
    st = _STACKS.get(key)
    if st is not None and all(a is b for a, b in zip(st.ephs, ephs)):
        return st
    rows = []
    for eph in ephs:
        A = eph.sqrtA * eph.sqrtA
        n0 = np.sqrt(GM_CGCS / A**3)
        om_rate = eph.Omega_dot if eph.is_geo else eph.Omega_dot - OMEGA_E
        rows.append((A, eph.sqrtA, n0 + eph.Delta_n, eph.e, np.sqrt(1.0 - eph.e * eph.e),
                     eph.M0, eph.omega, eph.i0, eph.IDOT, eph.Omega0, om_rate,
                     OMEGA_E * eph.toe, eph.Cus, eph.Cuc, eph.Crs, eph.Crc, eph.Cis, eph.Cic,
                     eph.af0, eph.af1, eph.af2, F_REL * eph.e * eph.sqrtA, eph.toe, eph.toc))
    cols = np.array(rows, dtype=np.float64).reshape(len(ephs), 24).T[:, :, None].copy()
    names = ("A", "sqrtA", "n", "e", "sq1e2", "M0", "omega", "i0", "IDOT", "Omega0",
             "om_rate", "om_toe", "Cus", "Cuc", "Crs", "Crc", "Cis", "Cic", "af0", "af1",
             "af2", "f_e_sqrtA", "toe", "toc")
    week = np.array([e.week for e in ephs], np.int64).reshape(-1, 1)
    toc_week = np.array([_toc_week(e) for e in ephs], np.int64).reshape(-1, 1)
    table = np.concatenate([cols[:, :, 0], week.T, toc_week.T]).astype(np.float64)
    st = EphemerisStack(
        ephs=ephs, week=week, toc_week=toc_week,
        geo=np.array([e.is_geo for e in ephs], bool), table=table,
        **{k: cols[i] for i, k in enumerate(names)})
    with _STACKS_LOCK:
        if len(_STACKS) >= _STACKS_MAX:
            _STACKS.pop(next(iter(_STACKS)))
        _STACKS[key] = st
    return st


def sat_pos_vel_clock_stacked(stack: EphemerisStack, t_sow, week: int | None = None
                              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Satellite ECEF position, velocity and clock of ``n`` records at ``m`` times each.

    Parameters
    ----------
    stack : EphemerisStack
        The records (:func:`stack_ephemerides`).
    t_sow : array_like, shape (n, m) or broadcastable to it
        BDT seconds of week [s], row ``i`` for record ``i`` (signal transmission times).
    week : int, optional
        BDT week of ``t_sow`` (as :func:`sat_pos_vel_clock`).

    Returns
    -------
    r_e, v_e : ndarray, shape (n, m, 3)
        Position [m] and velocity [m/s], ECEF CGCS2000 (as :func:`sat_pos_vel_clock`).
    dt_sv, ddt_sv : ndarray, shape (n, m)
        Clock offset [s] and drift [s/s], relativistic term included.

    Notes
    -----
    Row ``i`` equals :func:`sat_pos_vel_clock` of record ``i`` at the times of row ``i``
    bit for bit: the same elementwise operations, and Kepler's equation iterated until
    each row has converged (:func:`kepler_E`), as one record alone would be.
    """
    s = stack
    t = np.asarray(t_sow, float)
    if t.ndim < 2:
        t = t.reshape(1, -1)
    t = np.ascontiguousarray(np.broadcast_to(t, (s.size, t.shape[1])))
    tk = _time_from(t, week, s.week, s.toe)

    A, e, n = s.A, s.e, s.n
    Mk = s.M0 + n * tk
    Ek = kepler_E(Mk, e)
    sE, cE = np.sin(Ek), np.cos(Ek)
    one_m_ecE = 1.0 - e * cE
    sq1e2 = s.sq1e2
    vk = np.arctan2(sq1e2 * sE, cE - e)
    phik = vk + s.omega
    s2, c2 = np.sin(2.0 * phik), np.cos(2.0 * phik)
    du = s.Cus * s2 + s.Cuc * c2
    dr = s.Crs * s2 + s.Crc * c2
    di = s.Cis * s2 + s.Cic * c2
    uk = phik + du
    rk = A * one_m_ecE + dr
    ik = s.i0 + s.IDOT * tk + di

    # time derivatives
    Ek_dot = n / one_m_ecE
    vk_dot = sq1e2 * n / one_m_ecE**2
    uk_dot = vk_dot * (1.0 + 2.0 * (s.Cus * c2 - s.Cuc * s2))
    rk_dot = A * e * sE * Ek_dot + 2.0 * vk_dot * (s.Crs * c2 - s.Crc * s2)
    ik_dot = s.IDOT + 2.0 * vk_dot * (s.Cis * c2 - s.Cic * s2)

    su, cu = np.sin(uk), np.cos(uk)
    xp, yp = rk * cu, rk * su
    xp_dot = rk_dot * cu - rk * su * uk_dot
    yp_dot = rk_dot * su + rk * cu * uk_dot

    # MEO/IGSO: Omega_k = Omega_0 + (Omega_dot - omega_e) t_k - omega_e t_oe;
    # GEO: Omega_k = Omega_0 + Omega_dot t_k - omega_e t_oe (ICD 5.2.4; stack.om_rate)
    Om = s.Omega0 + s.om_rate * tk - s.om_toe
    Om_dot = s.om_rate
    sO, cO = np.sin(Om), np.cos(Om)
    si, ci = np.sin(ik), np.cos(ik)
    X = xp * cO - yp * ci * sO
    Y = xp * sO + yp * ci * cO
    Z = yp * si
    Xd = xp_dot * cO - yp_dot * ci * sO + yp * si * sO * ik_dot - Om_dot * Y
    Yd = xp_dot * sO + yp_dot * ci * cO - yp * si * cO * ik_dot + Om_dot * X
    Zd = yp_dot * si + yp * ci * ik_dot
    r = np.empty(X.shape + (3,))        # filled in place: cheaper than np.stack
    v = np.empty(X.shape + (3,))
    r[..., 0], r[..., 1], r[..., 2] = X, Y, Z
    v[..., 0], v[..., 1], v[..., 2] = Xd, Yd, Zd

    if s.geo.any():
        geo_to_ecef(r, v, tk, s.geo)

    # clock
    dtc = _time_from(t, week, s.toc_week, s.toc)
    rel = s.f_e_sqrtA * sE
    rel_dot = s.f_e_sqrtA * cE * Ek_dot
    dt_sv = s.af0 + s.af1 * dtc + s.af2 * dtc * dtc + rel
    ddt_sv = s.af1 + 2.0 * s.af2 * dtc + rel_dot
    return r, v, dt_sv, ddt_sv


def geo_to_ecef(r: np.ndarray, v: np.ndarray, tk: np.ndarray, geo: np.ndarray) -> None:
    """GEO rows of ``r``, ``v`` (n, m, 3), in their inertial-like frame [m, m/s], to ECEF
    CGCS2000 in place: ``R_Z(omega_e t_k) R_X(-5 deg)`` and its time derivative (ICD 5.2.4);
    ``tk`` (n, m) time from toe [s], ``geo`` (n,) bool."""
    g = np.flatnonzero(geo)
    cx, sx = np.cos(GEO_INCLINATION_ROT), np.sin(GEO_INCLINATION_ROT)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    r_g = r[g] @ Rx.T
    v_g = v[g] @ Rx.T
    a = OMEGA_E * tk[g]
    sa, ca = np.sin(a), np.cos(a)
    # R_Z(a) = [[ca, sa, 0], [-sa, ca, 0], [0, 0, 1]]; dR_Z/dt = omega_e [[-sa, ca, 0], [-ca, -sa, 0], [0,0,0]]
    x, y, z = r_g[..., 0], r_g[..., 1], r_g[..., 2]
    vx, vy, vz = v_g[..., 0], v_g[..., 1], v_g[..., 2]
    r[g] = np.stack([ca * x + sa * y, -sa * x + ca * y, z], axis=-1)
    v[g] = np.stack([
        ca * vx + sa * vy + OMEGA_E * (-sa * x + ca * y),
        -sa * vx + ca * vy + OMEGA_E * (-ca * x - sa * y),
        vz,
    ], axis=-1)


def sat_pos_vel_clock(eph: Ephemeris, t_sow: np.ndarray | float, week: int | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Satellite ECEF position, velocity and clock offset/drift from a broadcast record.

    The one-record case of :func:`sat_pos_vel_clock_stacked`.

    Parameters
    ----------
    eph : Ephemeris
        Broadcast record (MEO/IGSO or GEO, decided by ``eph.is_geo``).
    t_sow : float or array_like, shape (n,)
        BDT seconds of week [s] (the signal transmission time for pseudorange work).
    week : int, optional
        BDT week of ``t_sow``. When given, time from toe/toc is the full week-aware
        difference; otherwise it is wrapped into +-302400 s (ICD rule).

    Returns
    -------
    r_e : ndarray, shape (n, 3)
        Position, ECEF CGCS2000 [m].
    v_e : ndarray, shape (n, 3)
        Velocity relative to the rotating ECEF frame [m/s].
    dt_sv : ndarray, shape (n,)
        Satellite clock offset incl. the relativistic term [s]: the satellite clock reads
        t_sv = t + dt_sv (ICD: t = t_sv - Delta t_sv), so a pseudorange contains -c*dt_sv.
    ddt_sv : ndarray, shape (n,)
        Clock drift incl. the derivative of the relativistic term [s/s].
    """
    t = np.atleast_1d(np.asarray(t_sow, float)).ravel()
    r, v, dt, ddt = sat_pos_vel_clock_stacked(stack_ephemerides((eph,)), t[None, :], week)
    return r[0], v[0], dt[0], ddt[0]


def _toc_week(eph: Ephemeris) -> int:
    """Week of toc: the one putting toc next to toe (they normally coincide for BDS)."""
    d = eph.toc - eph.toe
    if d > _HALF_WEEK:
        return eph.week - 1
    if d < -_HALF_WEEK:
        return eph.week + 1
    return eph.week


def sat_states(nav, prn: int, week: int, t_sow: np.ndarray | float,
               max_age_s: float | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`sat_pos_vel_clock` over many times, each with its own selected record.

    For each time the record is chosen by ``nav.select(prn, week, t)`` (nearest healthy
    toe within the validity window); times are grouped by record so the evaluation stays
    vectorized.

    Parameters
    ----------
    nav : NavData
        Loaded navigation data (:func:`sdr_di.orbits.rinex_nav.load_nav`).
    prn : int
        BDS PRN.
    week : int
        BDT week the ``t_sow`` are counted from.
    t_sow : float or array_like, shape (n,)
        BDT seconds from the start of ``week`` [s] (may exceed 604800).
    max_age_s : float, optional
        Validity window passed to ``nav.select``.

    Returns
    -------
    r_e, v_e, dt_sv, ddt_sv
        As :func:`sat_pos_vel_clock`, shapes (n, 3), (n, 3), (n,), (n,).

    Raises
    ------
    NoEphemerisError, UnknownPrnError
        As ``nav.select``.
    """
    t = np.atleast_1d(np.asarray(t_sow, float)).ravel()
    r = np.empty((t.size, 3))
    v = np.empty((t.size, 3))
    dt = np.empty(t.size)
    ddt = np.empty(t.size)
    groups: dict[int, tuple[Ephemeris, list[int]]] = {}
    for i, ti in enumerate(t):
        eph = nav.select(prn, week, ti, max_age_s=max_age_s)
        groups.setdefault(id(eph), (eph, []))[1].append(i)
    for eph, idx in groups.values():
        ii = np.asarray(idx)
        r[ii], v[ii], dt[ii], ddt[ii] = sat_pos_vel_clock(eph, t[ii], week=week)
    return r, v, dt, ddt
