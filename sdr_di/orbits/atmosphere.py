"""Atmospheric delay models: BDS broadcast Klobuchar ionosphere and Saastamoinen troposphere.

Ionosphere
----------
:func:`klobuchar_delay` is the BDS version of the Klobuchar model (BDS-SIS-ICD B1I/B3I,
section 5.2.4.7), which differs from the GPS one: the ionospheric pierce point (IPP) is
computed exactly on a thin shell at h = 375 km above a spherical Earth R = 6378 km, the
amplitude and period polynomials are evaluated at the *geographic* latitude of the IPP
(|phi_M| in semicircles, no geomagnetic-latitude conversion), local time uses BDT, and the
obliquity factor is 1 / sqrt(1 - (R cos E / (R + h))^2)::

    psi    = pi/2 - E - arcsin(R / (R + h) cos E)
    phi_M  = arcsin(sin phi_u cos psi + cos phi_u sin psi cos A)
    lam_M  = lam_u + arcsin(sin psi sin A / cos phi_M)
    t      = (t_E + lam_M * 43200 / pi) mod 86400             [s, t_E = BDT seconds of day]
    A2     = max(sum_n alpha_n |phi_M / pi|^n, 0)
    A4     = clip(sum_n beta_n |phi_M / pi|^n, 72000, 172800)
    Iz     = 5 ns + A2 cos(2 pi (t - 50400) / A4)  if |t - 50400| < A4 / 4, else 5 ns
    I_B1I  = Iz / sqrt(1 - (R cos E / (R + h))^2)

The broadcast model gives the delay on **B1I**. The delay on B3I, used by this project, is
scaled by the first-order dispersion (f_B1I / f_B3I)^2 = (1561.098 / 1268.52)^2 = 1.5145
(:func:`iono_delay_b3i_m`). The model applies to code (a delay); the carrier phase sees the
same magnitude as an advance.

Troposphere
-----------
:func:`saastamoinen_delay` is the Saastamoinen model with a standard atmosphere (the same
formulation as RTKLIB's ``tropmodel``): pressure P = 1013.25 (1 - 2.2557e-5 h)^5.2568 hPa,
temperature T = 15 - 6.5e-3 h + 273.15 K, relative humidity 50 % by default, water vapour
pressure from the Magnus-type formula, delay = [0.0022768 P / (1 - 0.00266 cos 2 phi
- 0.00028 h / 1e3) + 0.002277 (1255 / T + 0.05) e] / cos z with z the zenith angle. The
heights are clipped to 0..11000 m (standard troposphere; a receiver below sea level is
treated as at 0 m). At sea level the zenith delay is about 2.39 m. The 1/cos z mapping is
adequate above ~5 deg; non-positive elevations return 0 (satellite below the horizon).
"""

from __future__ import annotations

import numpy as np

from ..constants import C_LIGHT, F_B3I
from .ephemeris import Klobuchar

__all__ = [
    "F_B1I",
    "B1I_TO_B3I",
    "klobuchar_delay",
    "iono_delay_b3i_m",
    "saastamoinen_delay",
    "saastamoinen_zenith",
    "saastamoinen_zenith_wet",
    "KLOBUCHAR_R_M",
    "KLOBUCHAR_H_M",
]

#: B1I carrier frequency [Hz] (reference frequency of the BDS Klobuchar model).
F_B1I = 1561.098e6
#: Ionospheric delay ratio B3I / B1I = (f_B1I / f_B3I)^2 [-].
B1I_TO_B3I = (F_B1I / F_B3I) ** 2
#: Earth radius of the BDS Klobuchar model [m].
KLOBUCHAR_R_M = 6378.0e3
#: Height of the ionospheric single layer of the BDS Klobuchar model [m].
KLOBUCHAR_H_M = 375.0e3
_NIGHT_S = 5.0e-9
_PEAK_S = 50400.0


def klobuchar_delay(iono: Klobuchar, lat, lon, el, az, t_sow) -> np.ndarray:
    """BDS Klobuchar ionospheric delay on **B1I** [s] (vectorized, broadcasting inputs).

    Parameters
    ----------
    iono : Klobuchar
        Broadcast coefficients alpha [s, s/semicircle, ...] and beta [s, s/semicircle, ...].
    lat, lon : array_like
        Receiver geodetic latitude and longitude [rad].
    el, az : array_like
        Satellite elevation and azimuth (clockwise from North) [rad].
    t_sow : array_like
        Receive time, BDT seconds of week (or of day) [s].

    Returns
    -------
    ndarray
        Slant delay [s] (>= 5 ns times the obliquity factor). Non-positive elevations give 0.
    """
    # (the ufuncs broadcast: no np.broadcast_arrays, which cost a third of the call)
    lat, lon, el, az, t = (np.asarray(a, float) for a in (lat, lon, el, az, t_sow))
    R, h = KLOBUCHAR_R_M, KLOBUCHAR_H_M
    el_c = np.maximum(el, 0.0)
    ratio = R / (R + h) * np.cos(el_c)
    psi = np.pi / 2.0 - el_c - np.arcsin(ratio)
    phi_m = np.arcsin(np.clip(np.sin(lat) * np.cos(psi) + np.cos(lat) * np.sin(psi) * np.cos(az), -1.0, 1.0))
    lam_m = lon + np.arcsin(np.clip(np.sin(psi) * np.sin(az) / np.cos(phi_m), -1.0, 1.0))
    t_local = np.mod(np.mod(t, 86400.0) + lam_m * 43200.0 / np.pi, 86400.0)
    x = np.abs(phi_m / np.pi)
    a, b = iono.alpha, iono.beta
    A2 = np.maximum(a[0] + x * (a[1] + x * (a[2] + x * a[3])), 0.0)
    A4 = np.clip(b[0] + x * (b[1] + x * (b[2] + x * b[3])), 72000.0, 172800.0)
    dt = t_local - _PEAK_S
    day = np.abs(dt) < A4 / 4.0
    Iz = _NIGHT_S + np.where(day, A2 * np.cos(2.0 * np.pi * dt / A4), 0.0)
    delay = Iz / np.sqrt(1.0 - ratio * ratio)
    return np.where(el > 0.0, delay, 0.0)


def iono_delay_b3i_m(iono: Klobuchar, lat, lon, el, az, t_sow) -> np.ndarray:
    """BDS Klobuchar ionospheric code delay scaled to **B3I**, in metres.

    ``c * klobuchar_delay(...) * (f_B1I / f_B3I)^2`` with f_B1I = 1561.098 MHz and
    f_B3I = 1268.52 MHz (factor 1.5145). Same parameters as :func:`klobuchar_delay`.
    """
    return C_LIGHT * B1I_TO_B3I * klobuchar_delay(iono, lat, lon, el, az, t_sow)


#: Relative humidity of the standard atmosphere (the Saastamoinen functions' default).
STANDARD_HUMIDITY = 0.5


def saastamoinen_delay(lat, h, el, humidity: float = STANDARD_HUMIDITY) -> np.ndarray:
    """Saastamoinen tropospheric slant delay [m] with a standard atmosphere (vectorized).

    Parameters
    ----------
    lat : array_like
        Geodetic latitude [rad].
    h : array_like
        Ellipsoidal height [m] (clipped to 0..11000 m).
    el : array_like
        Elevation [rad]; non-positive values give 0.
    humidity : float, optional
        Relative humidity 0..1 (default 0.5).

    Returns
    -------
    ndarray
        Slant delay [m] (hydrostatic + wet), same shape as the broadcast inputs.
    """
    lat, h, el = (np.asarray(a, float) for a in (lat, h, el))
    if lat.ndim == 0 and h.ndim == 0 and el.ndim > 0:
        # one receiver, several satellites (the range model's every call): its terms on
        # one-element arrays, as each element of the broadcast arrays gets them
        lat, h = lat.reshape(1), h.reshape(1)
    else:
        # broadcast first: numpy's power of an array and of a 0-d value (scalar maths) may
        # differ in the last bit
        lat, h, el = np.broadcast_arrays(lat, h, el)
    sin_el = np.sin(np.maximum(el, 1e-3))
    return np.where(el > 0.0, saastamoinen_zenith(lat, h, humidity) / sin_el, 0.0)


def saastamoinen_zenith(lat, h, humidity: float = STANDARD_HUMIDITY):
    """Zenith total (hydrostatic + wet) delay [m] of :func:`saastamoinen_delay`'s standard
    atmosphere (its slant delay is this over ``sin(el)``): geodetic latitude ``lat`` [rad],
    ellipsoidal height ``h`` [m] (clipped to 0..11000 m); arrays or numpy scalars.
    ``np.power``, not ``**``: numpy's scalar power (the C library's) and its array power
    (SIMD) may differ in the last bit, and this must give one receiver the same value in
    both forms."""
    hc = np.clip(h, 0.0, 11000.0)
    P = 1013.25 * np.power(1.0 - 2.2557e-5 * hc, 5.2568)          # hPa
    hyd = 0.0022768 * P / (1.0 - 0.00266 * np.cos(2.0 * lat) - 0.00028 * hc / 1e3)
    return hyd + _zenith_wet(hc, humidity)


def _zenith_wet(hc, humidity: float):
    """Saastamoinen zenith wet delay [m] of the standard atmosphere at clipped height ``hc``:
    T = 15 - 6.5e-3 h + 273.15 K, water vapour pressure from the Magnus-type formula."""
    T = 15.0 - 6.5e-3 * hc + 273.15                          # K
    e = 6.108 * humidity * np.exp((17.15 * T - 4684.0) / (T - 38.45))  # hPa
    return 0.002277 * (1255.0 / T + 0.05) * e


def saastamoinen_zenith_wet(h, humidity: float = STANDARD_HUMIDITY) -> np.ndarray:
    """Zenith wet delay [m] of :func:`saastamoinen_delay`'s standard atmosphere (its slant
    wet part is this over ``sin(el)``); ``h`` ellipsoidal height [m], clipped to 0..11000 m.
    About 0.086 m at sea level with 50 % humidity."""
    return _zenith_wet(np.clip(np.asarray(h, float), 0.0, 11000.0), humidity)
