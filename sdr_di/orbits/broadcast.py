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

import numpy as np

from ..constants import F_REL, GM_CGCS, OMEGA_E, SECONDS_PER_WEEK
from .ephemeris import Ephemeris

__all__ = ["sat_pos_vel_clock", "kepler_E", "sat_states", "GEO_INCLINATION_ROT"]

#: Rotation angle of the GEO inertial-like frame about X [rad] (ICD: -5 deg).
GEO_INCLINATION_ROT = np.deg2rad(-5.0)
_HALF_WEEK = SECONDS_PER_WEEK / 2.0


def _time_from(t_sow: np.ndarray, week: int | None, ref_week: int, ref_sow: float) -> np.ndarray:
    """t - ref [s]: full week-aware difference if ``week`` is given, else wrapped (ICD)."""
    if week is not None:
        return (int(week) - int(ref_week)) * SECONDS_PER_WEEK + (t_sow - ref_sow)
    d = t_sow - ref_sow
    return (d + _HALF_WEEK) % SECONDS_PER_WEEK - _HALF_WEEK


def kepler_E(M: np.ndarray, e: float, tol: float = 1e-15, max_iter: int = 30) -> np.ndarray:
    """Solve Kepler's equation M = E - e sin E for E [rad] (Newton, vectorized)."""
    M = np.asarray(M, float)
    E = M.copy()
    for _ in range(max_iter):
        dE = (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
        E = E - dE
        if np.all(np.abs(dE) < tol):
            break
    return E


def sat_pos_vel_clock(eph: Ephemeris, t_sow: np.ndarray | float, week: int | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Satellite ECEF position, velocity and clock offset/drift from a broadcast record.

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
    tk = _time_from(t, week, eph.week, eph.toe)

    A = eph.sqrtA * eph.sqrtA
    n0 = np.sqrt(GM_CGCS / A**3)
    n = n0 + eph.Delta_n
    e = eph.e
    Mk = eph.M0 + n * tk
    Ek = kepler_E(Mk, e)
    sE, cE = np.sin(Ek), np.cos(Ek)
    one_m_ecE = 1.0 - e * cE
    sq1e2 = np.sqrt(1.0 - e * e)
    vk = np.arctan2(sq1e2 * sE, cE - e)
    phik = vk + eph.omega
    s2, c2 = np.sin(2.0 * phik), np.cos(2.0 * phik)
    du = eph.Cus * s2 + eph.Cuc * c2
    dr = eph.Crs * s2 + eph.Crc * c2
    di = eph.Cis * s2 + eph.Cic * c2
    uk = phik + du
    rk = A * one_m_ecE + dr
    ik = eph.i0 + eph.IDOT * tk + di

    # time derivatives
    Ek_dot = n / one_m_ecE
    vk_dot = sq1e2 * n / one_m_ecE**2
    uk_dot = vk_dot * (1.0 + 2.0 * (eph.Cus * c2 - eph.Cuc * s2))
    rk_dot = A * e * sE * Ek_dot + 2.0 * vk_dot * (eph.Crs * c2 - eph.Crc * s2)
    ik_dot = eph.IDOT + 2.0 * vk_dot * (eph.Cis * c2 - eph.Cic * s2)

    su, cu = np.sin(uk), np.cos(uk)
    xp, yp = rk * cu, rk * su
    xp_dot = rk_dot * cu - rk * su * uk_dot
    yp_dot = rk_dot * su + rk * cu * uk_dot

    if eph.is_geo:
        Om = eph.Omega0 + eph.Omega_dot * tk - OMEGA_E * eph.toe
        Om_dot = eph.Omega_dot
    else:
        Om = eph.Omega0 + (eph.Omega_dot - OMEGA_E) * tk - OMEGA_E * eph.toe
        Om_dot = eph.Omega_dot - OMEGA_E
    sO, cO = np.sin(Om), np.cos(Om)
    si, ci = np.sin(ik), np.cos(ik)
    X = xp * cO - yp * ci * sO
    Y = xp * sO + yp * ci * cO
    Z = yp * si
    Xd = xp_dot * cO - yp_dot * ci * sO + yp * si * sO * ik_dot - Om_dot * Y
    Yd = xp_dot * sO + yp_dot * ci * cO - yp * si * cO * ik_dot + Om_dot * X
    Zd = yp_dot * si + yp * ci * ik_dot
    r = np.stack([X, Y, Z], axis=-1)
    v = np.stack([Xd, Yd, Zd], axis=-1)

    if eph.is_geo:
        cx, sx = np.cos(GEO_INCLINATION_ROT), np.sin(GEO_INCLINATION_ROT)
        Rx = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
        r_g = r @ Rx.T
        v_g = v @ Rx.T
        a = OMEGA_E * tk
        sa, ca = np.sin(a), np.cos(a)
        # R_Z(a) = [[ca, sa, 0], [-sa, ca, 0], [0, 0, 1]]; dR_Z/dt = omega_e [[-sa, ca, 0], [-ca, -sa, 0], [0,0,0]]
        x, y, z = r_g[:, 0], r_g[:, 1], r_g[:, 2]
        vx, vy, vz = v_g[:, 0], v_g[:, 1], v_g[:, 2]
        r = np.stack([ca * x + sa * y, -sa * x + ca * y, z], axis=-1)
        v = np.stack([
            ca * vx + sa * vy + OMEGA_E * (-sa * x + ca * y),
            -sa * vx + ca * vy + OMEGA_E * (-ca * x - sa * y),
            vz,
        ], axis=-1)

    # clock
    dtc = _time_from(t, week, _toc_week(eph), eph.toc)
    rel = F_REL * e * eph.sqrtA * sE
    rel_dot = F_REL * e * eph.sqrtA * cE * Ek_dot
    dt_sv = eph.af0 + eph.af1 * dtc + eph.af2 * dtc * dtc + rel
    ddt_sv = eph.af1 + 2.0 * eph.af2 * dtc + rel_dot
    return r, v, dt_sv, ddt_sv


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
