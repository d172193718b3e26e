"""CGCS2000 normal gravity: the one gravity model of the whole project.

Normal gravity is the gravity (gravitation plus centrifugal acceleration of the Earth's
rotation) of the level ellipsoid defined by the four CGCS2000 constants a, f, GM, omega_e
(:mod:`sdr_di.constants`). On the ellipsoid it follows Somigliana's closed formula

    gamma_0(L) = gamma_e (1 + k sin^2 L) / sqrt(1 - e^2 sin^2 L),   k = b gamma_p / (a gamma_e) - 1

with the equatorial and polar normal gravity gamma_e, gamma_p computed from the defining
constants (Moritz, *Geodetic Reference System 1980*, eqs. for a level ellipsoid; for
CGCS2000 they evaluate to gamma_e = 9.7803253361 m/s^2 and gamma_p = 9.8321849379 m/s^2,
the published CGCS2000 values). Above the ellipsoid the second-order free-air expansion
(NIMA TR8350.2 eq. 4-3) is used:

    gamma(L, h) = gamma_0(L) [1 - 2/a (1 + f + m - 2 f sin^2 L) h + 3 h^2 / a^2],
    m = omega_e^2 a^2 b / GM.

The gravity vector is taken along the ellipsoid normal: ``g_n = (0, 0, -gamma)`` in ENU
(the normal-gravity deflection above the ellipsoid, below 1e-7 rad at aircraft heights, is
neglected). The trajectory generator (:mod:`sdr_di.sim.trajectory`) and the INS
(:mod:`sdr_di.ins.mechanization`) both use this module, so they agree exactly.
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import A_CGCS, B_CGCS, E2_CGCS, F_CGCS, GM_CGCS, OMEGA_E


def _level_ellipsoid_gravity() -> tuple[float, float, float]:
    """Equatorial, polar normal gravity [m/s^2] and m [-] of the CGCS2000 level ellipsoid."""
    a, b = A_CGCS, B_CGCS
    ep = math.sqrt(a * a - b * b) / b  # second eccentricity e'
    q0 = 0.5 * ((1.0 + 3.0 / ep**2) * math.atan(ep) - 3.0 / ep)
    q0p = 3.0 * (1.0 + 1.0 / ep**2) * (1.0 - math.atan(ep) / ep) - 1.0
    m = OMEGA_E**2 * a * a * b / GM_CGCS
    g_e = GM_CGCS / (a * b) * (1.0 - m - m / 6.0 * ep * q0p / q0)
    g_p = GM_CGCS / (a * a) * (1.0 + m / 3.0 * ep * q0p / q0)
    return g_e, g_p, m


#: Normal gravity on the equator [m/s^2] (CGCS2000: 9.7803253361).
GAMMA_E, GAMMA_P, M_CGCS = _level_ellipsoid_gravity()
#: Somigliana constant k = b gamma_p / (a gamma_e) - 1 [-].
K_SOMIGLIANA = B_CGCS * GAMMA_P / (A_CGCS * GAMMA_E) - 1.0


def normal_gravity(lat, h) -> np.ndarray:
    """Magnitude of CGCS2000 normal gravity [m/s^2].

    Parameters
    ----------
    lat : float or array
        Geodetic latitude [rad].
    h : float or array
        Ellipsoidal height [m].

    Returns
    -------
    array
        gamma(lat, h) [m/s^2], broadcast shape of the inputs.
    """
    s2 = np.sin(np.asarray(lat, float)) ** 2
    h = np.asarray(h, float)
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / np.sqrt(1.0 - E2_CGCS * s2)
    return g0 * (1.0 - 2.0 / A_CGCS * (1.0 + F_CGCS + M_CGCS - 2.0 * F_CGCS * s2) * h
                 + 3.0 * h * h / A_CGCS**2)


def gravity_n(lat, h) -> np.ndarray:
    """Normal gravity vector in ENU, ``(0, 0, -gamma(lat, h))`` [m/s^2], shape (..., 3)."""
    g = normal_gravity(lat, h)
    z = np.zeros_like(g)
    return np.stack([z, z, -g], axis=-1)
