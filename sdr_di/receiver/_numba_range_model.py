"""Numba kernels of the forward range model at one receive instant (the deep loop's NCO
commands, every interval).

Plain arrays and scalars in and out; the model and the numpy form these transcribe (the
tested reference) are :func:`sdr_di.receiver.range_model.predict_ranges`,
:func:`sdr_di.orbits.broadcast.sat_pos_vel_clock_stacked`,
:func:`sdr_di.receiver.pvt.sagnac_rotation` and :mod:`sdr_di.orbits.atmosphere`. The same
float64 operations in the same order, so the same values: the basic operations and
``sqrt`` are correctly rounded everywhere, and ``sin`` and ``cos`` are the C library's in
numba and (on x86-64, numpy 2.x) in numpy as well. The functions whose numpy loops are
SIMD library code that the C library does not repeat bit for bit (``arctan2``, ``arcsin``,
``hypot``, ``exp``, ``power``) stay numpy calls between the kernels:

:func:`orbit_anomaly`
    time from toe and toc, mean anomaly, Kepler's equation; the arguments of ``arctan2``
    for the true anomaly.
:func:`orbit_state`
    position, velocity and clock from the true anomaly (before the GEO frame rotation).
:func:`sagnac`
    the travel-time iteration of :func:`~sdr_di.receiver.pvt.sagnac_rotation`.
:func:`line_of_sight_enu`
    ENU components of the lines of sight, laid out for one ``hypot`` and one ``arctan2``.
:func:`klobuchar_1`, :func:`klobuchar_2`, :func:`klobuchar_3`
    azimuth, floored elevation and the pierce point between the ``arcsin`` calls.
:func:`ranges`
    the Klobuchar delay's rest, the troposphere's slant delay, ``P``, ``Pc`` and the unit
    lines of sight.
"""

from __future__ import annotations

import math

from numba import njit

from ..constants import C_LIGHT, OMEGA_E, SECONDS_PER_WEEK

# rows of EphemerisStack.table (orbits.broadcast.stack_ephemerides)
_A, _SQRTA, _N, _E, _SQ1E2, _M0, _OMEGA, _I0, _IDOT, _OMEGA0 = range(10)
_OM_RATE, _OM_TOE, _CUS, _CUC, _CRS, _CRC, _CIS, _CIC, _AF0, _AF1 = range(10, 20)
_AF2, _FESQRTA, _TOE, _TOC, _WEEK, _TOC_WEEK = range(20, 26)

_KEPLER_TOL = 1e-15
_KEPLER_ITER = 30
_TWO_PI = 2 * math.pi


@njit(cache=True, boundscheck=False)
def orbit_anomaly(tab, week, t_r, tau, w):
    """Rows ``w[0:6, i]`` of record ``i`` at transmit time ``t_r - tau[i]``: ``t_k`` [s],
    ``t - toc`` [s], ``sin E_k``, ``cos E_k`` and the arguments ``y, x`` of
    ``v_k = arctan2(y, x)``. ``tab`` (26, n): the stack's table; ``week`` the BDT week of
    ``t_r`` (float); ``t_r`` BDT of reception [s of week]; ``tau`` (n,) travel times [s]."""
    for i in range(tab.shape[1]):
        t = t_r - tau[i]
        tk = (week - tab[_WEEK, i]) * SECONDS_PER_WEEK + (t - tab[_TOE, i])
        e = tab[_E, i]
        M = tab[_M0, i] + tab[_N, i] * tk
        E = M
        for _ in range(_KEPLER_ITER):
            dE = (E - e * math.sin(E) - M) / (1.0 - e * math.cos(E))
            E = E - dE
            if abs(dE) < _KEPLER_TOL:
                break
        sE, cE = math.sin(E), math.cos(E)
        w[0, i] = tk
        w[1, i] = (week - tab[_TOC_WEEK, i]) * SECONDS_PER_WEEK + (t - tab[_TOC, i])
        w[2, i] = sE
        w[3, i] = cE
        w[4, i] = tab[_SQ1E2, i] * sE
        w[5, i] = cE - e


@njit(cache=True, boundscheck=False)
def orbit_state(tab, w, vk, r, v, dt_sv):
    """Position ``r`` (n, 3) [m], velocity ``v`` (n, 3) [m/s] (GEO rows still in their
    inertial-like frame) and clock ``dt_sv`` (n,) [s] from :func:`orbit_anomaly`'s rows
    and the true anomalies ``vk`` (n,) [rad]."""
    for i in range(tab.shape[1]):
        tk, dtc, sE, cE = w[0, i], w[1, i], w[2, i], w[3, i]
        A, e, n, sq1e2 = tab[_A, i], tab[_E, i], tab[_N, i], tab[_SQ1E2, i]
        Cus, Cuc, Crs, Crc = tab[_CUS, i], tab[_CUC, i], tab[_CRS, i], tab[_CRC, i]
        Cis, Cic, IDOT = tab[_CIS, i], tab[_CIC, i], tab[_IDOT, i]
        one_m_ecE = 1.0 - e * cE
        phik = vk[i] + tab[_OMEGA, i]
        s2, c2 = math.sin(2.0 * phik), math.cos(2.0 * phik)
        du = Cus * s2 + Cuc * c2
        dr = Crs * s2 + Crc * c2
        di = Cis * s2 + Cic * c2
        uk = phik + du
        rk = A * one_m_ecE + dr
        ik = tab[_I0, i] + IDOT * tk + di
        Ek_dot = n / one_m_ecE
        vk_dot = sq1e2 * n / (one_m_ecE * one_m_ecE)
        uk_dot = vk_dot * (1.0 + 2.0 * (Cus * c2 - Cuc * s2))
        rk_dot = A * e * sE * Ek_dot + 2.0 * vk_dot * (Crs * c2 - Crc * s2)
        ik_dot = IDOT + 2.0 * vk_dot * (Cis * c2 - Cic * s2)
        su, cu = math.sin(uk), math.cos(uk)
        xp, yp = rk * cu, rk * su
        xp_dot = rk_dot * cu - rk * su * uk_dot
        yp_dot = rk_dot * su + rk * cu * uk_dot
        Om_dot = tab[_OM_RATE, i]
        Om = tab[_OMEGA0, i] + Om_dot * tk - tab[_OM_TOE, i]
        sO, cO = math.sin(Om), math.cos(Om)
        si, ci = math.sin(ik), math.cos(ik)
        X = xp * cO - yp * ci * sO
        Y = xp * sO + yp * ci * cO
        r[i, 0] = X
        r[i, 1] = Y
        r[i, 2] = yp * si
        v[i, 0] = xp_dot * cO - yp_dot * ci * sO + yp * si * sO * ik_dot - Om_dot * Y
        v[i, 1] = xp_dot * sO + yp_dot * ci * cO - yp * si * cO * ik_dot + Om_dot * X
        v[i, 2] = yp_dot * si + yp * ci * ik_dot
        dt_sv[i] = tab[_AF0, i] + tab[_AF1, i] * dtc + tab[_AF2, i] * dtc * dtc \
            + tab[_FESQRTA, i] * sE


@njit(cache=True, boundscheck=False)
def sagnac(r_sat, r_rx, r_rot, rho):
    """Satellites ``r_sat`` (n, 3) rotated into the ECEF frame of the reception instant
    (``r_rot``, (n, 3) [m]) and the ranges ``rho`` (n,) [m] from ``r_rx`` (3,) [m]."""
    x0, y0, z0 = r_rx[0], r_rx[1], r_rx[2]
    for i in range(r_sat.shape[0]):
        X, Y, Z = r_sat[i, 0], r_sat[i, 1], r_sat[i, 2]
        dx, dy, dz = X - x0, Y - y0, Z - z0
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        x = y = 0.0
        for k in range(4):
            theta = OMEGA_E * d / C_LIGHT
            c, s = math.cos(theta), math.sin(theta)
            x = c * X + s * Y
            y = -s * X + c * Y
            dx, dy, dz = x - x0, y - y0, Z - z0
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
        r_rot[i, 0] = x
        r_rot[i, 1] = y
        r_rot[i, 2] = Z
        rho[i] = d


@njit(cache=True, boundscheck=False)
def line_of_sight_enu(r_rot, r_rx, sl, cl, so, co, h01, y, x):
    """ENU components of ``r_rot - r_rx`` at geodetic latitude/longitude with sines and
    cosines ``sl, cl, so, co`` (``np.einsum``'s order of the sums): ``h01`` (2, n) East,
    North (for ``hypot``), ``y`` (2 n,) Up then East, ``x[n:]`` North (``arctan2(y, x)``
    gives elevation then unreduced azimuth once ``x[:n]`` holds the horizontal norms)."""
    n = r_rot.shape[0]
    for i in range(n):
        d0, d1, d2 = r_rot[i, 0] - r_rx[0], r_rot[i, 1] - r_rx[1], r_rot[i, 2] - r_rx[2]
        e = 0.0 + ((-so * d0 + 0.0 * d2) + co * d1)
        nn = 0.0 + ((-sl * co * d0 + cl * d2) + -sl * so * d1)
        u = 0.0 + ((cl * co * d0 + sl * d2) + cl * so * d1)
        h01[0, i] = e
        h01[1, i] = nn
        y[i] = u
        y[n + i] = e
        x[n + i] = nn


@njit(cache=True, boundscheck=False)
def klobuchar_1(el_az, el_floor, ratio_k, w):
    """From ``el_az`` (2 n,) (elevations, unreduced azimuths [rad]): rows of ``w``:
    0 elevation floored at ``el_floor``, 1 azimuth in [0, 2 pi), 2 ``el_c = max(el, 0)``,
    3 ``R / (R + h) cos el_c`` (``ratio_k = R / (R + h)``)."""
    n = w.shape[1]
    for i in range(n):
        el = el_az[i]
        el_pos = el if (el >= el_floor or el != el) else el_floor
        a = el_az[n + i]
        az = a % _TWO_PI            # Python's and numpy's float modulo: the same rule
        el_c = el_pos if (el_pos >= 0.0 or el_pos != el_pos) else 0.0
        w[0, i] = el_pos
        w[1, i] = az
        w[2, i] = el_c
        w[3, i] = ratio_k * math.cos(el_c)


@njit(cache=True, boundscheck=False)
def _clip1(a):
    if a < -1.0:
        return -1.0
    if a > 1.0:
        return 1.0
    return a


@njit(cache=True, boundscheck=False)
def klobuchar_2(w, asin_ratio, sl, cl, out):
    """Row 4 of ``w``: ``psi = pi/2 - el_c - arcsin(ratio)``; ``out`` (n,): the clipped
    ``sin phi_M`` of the pierce point (argument of ``arcsin``)."""
    for i in range(w.shape[1]):
        psi = math.pi / 2.0 - w[2, i] - asin_ratio[i]
        w[4, i] = psi
        out[i] = _clip1(sl * math.cos(psi) + cl * math.sin(psi) * math.cos(w[1, i]))


@njit(cache=True, boundscheck=False)
def klobuchar_3(w, phi_m, out):
    """``out`` (n,): the clipped ``sin(lam_M - lam_u)`` of the pierce point."""
    for i in range(w.shape[1]):
        psi = w[4, i]
        out[i] = _clip1(math.sin(psi) * math.sin(w[1, i]) / math.cos(phi_m[i]))


@njit(cache=True, boundscheck=False)
def ranges(w, phi_m, asin_lam, lon, t_day, alpha, beta, iono_m_per_s, ion_on, zenith_m,
           trop_on, rho, b, dt_sv, r_rot, r_rx, P, Pc, U):
    """``P``, ``Pc`` (n,) [m] and the unit lines of sight ``U`` (n, 3): the Klobuchar
    delay's rest (``t_day = mod(t, 86400)`` [s], ``iono_m_per_s = c (f_B1I / f_B3I)^2``),
    the troposphere ``zenith_m / sin(max(el, 1e-3))``, ``b`` the clock bias [m],
    ``dt_sv`` (n,) the satellite clocks [s]. ``ion_on``/``trop_on``: 0 for no delay."""
    for i in range(w.shape[1]):
        el_pos = w[0, i]
        ion = 0.0
        if ion_on:
            lam_m = lon + asin_lam[i]
            tl = (t_day + lam_m * 43200.0 / math.pi) % 86400.0
            x = abs(phi_m[i] / math.pi)
            A2 = alpha[0] + x * (alpha[1] + x * (alpha[2] + x * alpha[3]))
            A2 = A2 if (A2 >= 0.0 or A2 != A2) else 0.0
            A4 = beta[0] + x * (beta[1] + x * (beta[2] + x * beta[3]))
            A4 = _clip(A4, 72000.0, 172800.0)
            dt = tl - 50400.0
            day = A2 * math.cos(2.0 * math.pi * dt / A4) if abs(dt) < A4 / 4.0 else 0.0
            Iz = 5.0e-9 + day
            ratio = w[3, i]
            delay = Iz / math.sqrt(1.0 - ratio * ratio)
            ion = iono_m_per_s * (delay if el_pos > 0.0 else 0.0)
        trop = 0.0
        if trop_on:
            sin_el = math.sin(el_pos if el_pos >= 1e-3 or el_pos != el_pos else 1e-3)
            trop = zenith_m / sin_el if el_pos > 0.0 else 0.0
        d = rho[i]
        p = d + b - C_LIGHT * dt_sv[i] + trop + ion
        P[i] = p
        Pc[i] = p - 2.0 * ion
        for k in range(3):
            U[i, k] = (r_rot[i, k] - r_rx[k]) / d


@njit(cache=True, boundscheck=False)
def _clip(a, lo, hi):
    if a < lo:
        return lo
    if a > hi:
        return hi
    return a
