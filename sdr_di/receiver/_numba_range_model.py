"""Numba kernels of the forward range model at one receive instant (the deep loop's NCO
commands, every interval).

Plain arrays and scalars in and out; the model and the numpy form these transcribe (the
tested reference) are :func:`sdr_di.receiver.range_model.predict_ranges`,
:func:`sdr_di.orbits.broadcast.sat_pos_vel_clock_stacked`,
:func:`sdr_di.orbits.broadcast.geo_to_ecef`, :func:`sdr_di.receiver.pvt.sagnac_rotation`,
:func:`sdr_di.frames.ecef_to_llh` and :mod:`sdr_di.orbits.atmosphere`. The same float64
operations in the same order, with the C library's ``atan2``, ``asin``, ``hypot``, ``exp``
and ``pow`` where numpy's loops are SIMD library code: those may differ from numpy's in the
last bit, so the kernel's ranges equal the numpy form's to a few ulp (about 1e-8 m at
2e7 m; ``tests/test_range_model_kernels.py`` holds them to 1e-12 of each field's scale).

:func:`predict_instant`
    the whole model at one instant, in one call (the travel-time passes, the GEO frame
    rotation, the receiver's geodetic position, the atmosphere, ``P``, ``Pc``, ``U``), made of:
:func:`orbit_anomaly`
    time from toe and toc, mean anomaly, Kepler's equation; the arguments of ``atan2``
    for the true anomaly.
:func:`orbit_state`
    position, velocity and clock from the true anomaly (before the GEO frame rotation).
:func:`geo_to_ecef`
    the GEO records' rotation into ECEF (ICD 5.2.4).
:func:`sagnac`
    the travel-time iteration of :func:`~sdr_di.receiver.pvt.sagnac_rotation`.
:func:`ecef_to_llh`
    the receiver's geodetic position (the iteration of :func:`sdr_di.frames.ecef_to_llh`).
:func:`saastamoinen_zenith`
    the troposphere's zenith delay (:func:`sdr_di.orbits.atmosphere.saastamoinen_zenith`).
:func:`atmosphere`
    elevations, azimuths and both delays of one receiver, satellite by satellite (also the
    PVT's, :func:`sdr_di.receiver.pvt.atmosphere_delays`), with :func:`_klobuchar_m`;
:func:`ranges`
    ``P``, ``Pc`` and the unit lines of sight.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..constants import A_CGCS, C_LIGHT, E2_CGCS, OMEGA_E, SECONDS_PER_WEEK

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
def _clip1(a):
    if a < -1.0:
        return -1.0
    if a > 1.0:
        return 1.0
    return a


@njit(cache=True, boundscheck=False)
def _klobuchar_m(phi_m, asin_lam, lon, t_day, alpha, beta, ratio, iono_m_per_s):
    """B3I Klobuchar code delay [m] from the pierce point's geomagnetic latitude ``phi_m``
    [rad], ``asin_lam`` (its longitude less the receiver's ``lon``) [rad], ``t_day =
    mod(t, 86400)`` [s] and ``ratio = R / (R + h) cos(el)``; ``iono_m_per_s = c (f_B1I /
    f_B3I)^2`` (:func:`sdr_di.orbits.atmosphere.klobuchar_delay`)."""
    lam_m = lon + asin_lam
    tl = (t_day + lam_m * 43200.0 / math.pi) % 86400.0
    x = abs(phi_m / math.pi)
    A2 = alpha[0] + x * (alpha[1] + x * (alpha[2] + x * alpha[3]))
    A2 = A2 if (A2 >= 0.0 or A2 != A2) else 0.0
    A4 = beta[0] + x * (beta[1] + x * (beta[2] + x * beta[3]))
    A4 = _clip(A4, 72000.0, 172800.0)
    dt = tl - 50400.0
    day = A2 * math.cos(2.0 * math.pi * dt / A4) if abs(dt) < A4 / 4.0 else 0.0
    Iz = 5.0e-9 + day
    return iono_m_per_s * (Iz / math.sqrt(1.0 - ratio * ratio))


@njit(cache=True, boundscheck=False)
def ranges(rho, b, dt_sv, trop, ion, r_rot, r_rx, P, Pc, U):
    """``P = rho + b - c dt_sv + T + I``, ``Pc = P - 2 I`` (n,) [m] and the unit lines of
    sight ``U`` (n, 3): ``b`` the clock bias [m], ``dt_sv`` (n,) the satellite clocks [s]."""
    for i in range(rho.shape[0]):
        d = rho[i]
        p = d + b - C_LIGHT * dt_sv[i] + trop[i] + ion[i]
        P[i] = p
        Pc[i] = p - 2.0 * ion[i]
        for k in range(3):
            U[i, k] = (r_rot[i, k] - r_rx[k]) / d


@njit(cache=True, boundscheck=False)
def atmosphere(r_rot, r_rx, t_r, ion_on, alpha, beta, trop_on, humidity, el_floor, ratio_k,
               iono_m_per_s, el, az, trop, ion):
    """Elevation (not floored) and azimuth in [0, 2 pi) [rad], tropospheric and B3I
    ionospheric delays [m] (n,) of satellites ``r_rot`` (n, 3) seen from the receiver
    ``r_rx`` (3,) [m] at BDT ``t_r`` [s of week]: :func:`sdr_di.receiver.pvt.
    atmosphere_delays` (its numpy form). Arguments after ``t_r`` as
    :func:`predict_instant`'s. The ENU components are summed in ``np.einsum``'s order;
    elevations are floored at ``el_floor`` for the delays, which are zero at non-positive
    floored elevations or with the switch (``ion_on``, ``trop_on``) off."""
    lat, lon, h = ecef_to_llh(r_rx)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    zenith_m = saastamoinen_zenith(lat, h, humidity) if trop_on else 0.0
    t_day = t_r % 86400.0 if ion_on else 0.0
    for i in range(r_rot.shape[0]):
        d0, d1, d2 = r_rot[i, 0] - r_rx[0], r_rot[i, 1] - r_rx[1], r_rot[i, 2] - r_rx[2]
        e = 0.0 + ((-so * d0 + 0.0 * d2) + co * d1)
        nn = 0.0 + ((-sl * co * d0 + cl * d2) + -sl * so * d1)
        u = 0.0 + ((cl * co * d0 + sl * d2) + cl * so * d1)
        el_i = math.atan2(u, math.hypot(e, nn))
        az_i = math.atan2(e, nn) % _TWO_PI     # Python's and numpy's float modulo alike
        el_pos = el_i if (el_i >= el_floor or el_i != el_i) else el_floor
        el_c = el_pos if (el_pos >= 0.0 or el_pos != el_pos) else 0.0
        ratio = ratio_k * math.cos(el_c)
        d_ion = 0.0
        if ion_on and el_pos > 0.0:
            psi = math.pi / 2.0 - el_c - math.asin(ratio)
            phi_m = math.asin(_clip1(sl * math.cos(psi) + cl * math.sin(psi) * math.cos(az_i)))
            asin_lam = math.asin(_clip1(math.sin(psi) * math.sin(az_i) / math.cos(phi_m)))
            d_ion = _klobuchar_m(phi_m, asin_lam, lon, t_day, alpha, beta, ratio,
                                 iono_m_per_s)
        d_trop = 0.0
        if trop_on:
            sin_el = math.sin(el_pos if el_pos >= 1e-3 or el_pos != el_pos else 1e-3)
            d_trop = zenith_m / sin_el if el_pos > 0.0 else 0.0
        el[i] = el_i
        az[i] = az_i
        trop[i] = d_trop
        ion[i] = d_ion


@njit(cache=True, boundscheck=False)
def _clip(a, lo, hi):
    if a < lo:
        return lo
    if a > hi:
        return hi
    return a


@njit(cache=True, boundscheck=False)
def geo_to_ecef(r, v, tk, geo, cx, sx):
    """GEO rows of ``r``, ``v`` (n, 3) [m, m/s] (``geo`` (n,) bool) from their
    inertial-like frame to ECEF in place: ``R_Z(omega_e t_k) R_X(-5 deg)`` and its time
    derivative; ``tk`` (n,) time from toe [s]; ``cx, sx`` cosine and sine of the -5 deg."""
    for i in range(r.shape[0]):
        if not geo[i]:
            continue
        x, y, z = r[i, 0], cx * r[i, 1] + sx * r[i, 2], -sx * r[i, 1] + cx * r[i, 2]
        vx, vy, vz = v[i, 0], cx * v[i, 1] + sx * v[i, 2], -sx * v[i, 1] + cx * v[i, 2]
        a = OMEGA_E * tk[i]
        sa, ca = math.sin(a), math.cos(a)
        r[i, 0] = ca * x + sa * y
        r[i, 1] = -sa * x + ca * y
        r[i, 2] = z
        v[i, 0] = ca * vx + sa * vy + OMEGA_E * (-sa * x + ca * y)
        v[i, 1] = -sa * vx + ca * vy + OMEGA_E * (-ca * x - sa * y)
        v[i, 2] = vz


@njit(cache=True, boundscheck=False)
def ecef_to_llh(r):
    """Geodetic latitude, longitude [rad] and ellipsoidal height [m] (CGCS2000) of the ECEF
    position ``r`` (3,) [m]: the iteration of :func:`sdr_di.frames.ecef_to_llh`."""
    x, y, z = r[0], r[1], r[2]
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - E2_CGCS))
    for _ in range(10):
        sl = math.sin(lat)
        N = A_CGCS / math.sqrt(1.0 - E2_CGCS * sl * sl)
        h = p / math.cos(lat) - N
        lat = math.atan2(z, p * (1.0 - E2_CGCS * N / (N + h)))
    sl = math.sin(lat)
    N = A_CGCS / math.sqrt(1.0 - E2_CGCS * sl * sl)
    cl = math.cos(lat)
    h = p / cl - N if abs(cl) > 1e-9 else abs(z) - A_CGCS * math.sqrt(1 - E2_CGCS)
    return lat, lon, h


@njit(cache=True, boundscheck=False)
def saastamoinen_zenith(lat, h, humidity):
    """Zenith total delay [m] of the standard atmosphere at geodetic latitude ``lat``
    [rad] and height ``h`` [m] (clipped to 0..11000 m), relative humidity ``humidity``."""
    hc = _clip(h, 0.0, 11000.0)
    P = 1013.25 * (1.0 - 2.2557e-5 * hc) ** 5.2568
    hyd = 0.0022768 * P / (1.0 - 0.00266 * math.cos(2.0 * lat) - 0.00028 * hc / 1e3)
    T = 15.0 - 6.5e-3 * hc + 273.15
    e = 6.108 * humidity * math.exp((17.15 * T - 4684.0) / (T - 38.45))
    return hyd + 0.002277 * (1255.0 / T + 0.05) * e


@njit(cache=True, boundscheck=False)
def predict_instant(tab, geo, cx, sx, week, t_r, r_rx, b, tau, passes, ion_on, alpha, beta,
                    trop_on, humidity, el_floor, ratio_k, iono_m_per_s,
                    r_rot, v_sat, P, Pc, U):
    """The range model at one receive instant (:func:`~sdr_di.receiver.range_model.
    predict_ranges`'s numpy form, to a few ulp), in place.

    ``tab`` (26, n) and ``geo`` (n,) the ephemeris stack's table and GEO flags; ``cx, sx``
    the GEO rotation's cosine and sine; ``week`` BDT week (float); ``t_r`` BDT of reception
    [s of week]; ``r_rx`` (3,) receiver ECEF [m]; ``b`` clock bias [m]; ``tau`` (n,) travel
    times [s], seeds in, the last pass's out; ``passes`` travel-time passes; ``ion_on``,
    ``trop_on`` the atmosphere switches with the Klobuchar ``alpha``, ``beta`` (4,);
    ``humidity`` of the troposphere model; ``el_floor`` [rad], ``ratio_k = R / (R + h)``,
    ``iono_m_per_s = c (f_B1I / f_B3I)^2`` the Klobuchar constants. Out: ``r_rot``,
    ``v_sat`` (n, 3) [m, m/s], ``P``, ``Pc`` (n,) [m], ``U`` (n, 3)."""
    n = tab.shape[1]
    w = np.empty((6, n))
    vk = np.empty(n)
    r_sat = np.empty((n, 3))
    dt_sv = np.empty(n)
    rho = np.empty(n)
    any_geo = False
    for i in range(n):
        any_geo = any_geo or geo[i]
    for _ in range(passes):
        orbit_anomaly(tab, week, t_r, tau, w)
        for i in range(n):
            vk[i] = math.atan2(w[4, i], w[5, i])
        orbit_state(tab, w, vk, r_sat, v_sat, dt_sv)
        if any_geo:
            geo_to_ecef(r_sat, v_sat, w[0], geo, cx, sx)
        sagnac(r_sat, r_rx, r_rot, rho)
        for i in range(n):
            tau[i] = rho[i] / C_LIGHT
    # the atmosphere (pvt.atmosphere_delays) at the receiver's geodetic position
    el = np.empty(n)
    az = np.empty(n)
    trop = np.empty(n)
    ion = np.empty(n)
    atmosphere(r_rot, r_rx, t_r, ion_on, alpha, beta, trop_on, humidity, el_floor, ratio_k,
               iono_m_per_s, el, az, trop, ion)
    ranges(rho, b, dt_sv, trop, ion, r_rot, r_rx, P, Pc, U)
