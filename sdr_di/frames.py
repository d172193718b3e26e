"""Coordinate frames on the CGCS2000 ellipsoid.

Conventions: ECEF is CGCS2000 (``e``); the navigation frame is local East-North-Up (``n``);
the body frame is Right-Front-Up (``b``). ``C_a_b`` rotates a vector from frame ``a`` to frame
``b`` (``v_b = C_a_b @ v_a``). Attitude is (pitch, roll, yaw) [rad] with yaw positive
clockwise from North (heading), body axes x = right, y = front, z = up; ``C_b_n`` =
R_z(-yaw) R_x(pitch) R_y(roll) (paper 004 Table 1 conventions).
"""

from __future__ import annotations

import numpy as np

from .constants import A_CGCS, E2_CGCS, OMEGA_E


def llh_to_ecef(lat, lon, h) -> np.ndarray:
    """Geodetic latitude/longitude [rad] and ellipsoidal height [m] to ECEF [m] (..., 3)."""
    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    h = np.asarray(h, float)
    sl, cl = np.sin(lat), np.cos(lat)
    N = A_CGCS / np.sqrt(1.0 - E2_CGCS * sl * sl)
    x = (N + h) * cl * np.cos(lon)
    y = (N + h) * cl * np.sin(lon)
    z = (N * (1.0 - E2_CGCS) + h) * sl
    return _stack3(x, y, z)


def _stack3(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``np.stack([a, b, c], axis=-1)`` of three same-shape arrays, filled in place (the
    per-epoch conversions call it on 0-d arrays, where np.stack costs ~3x as much)."""
    out = np.empty(a.shape + (3,))
    out[..., 0], out[..., 1], out[..., 2] = a, b, c
    return out


def ecef_to_llh(r_e) -> np.ndarray:
    """ECEF position [m] (..., 3) to geodetic (lat [rad], lon [rad], h [m]) (..., 3).

    Iterative solution, converged to below 1e-12 rad / 1e-6 m for terrestrial and orbital heights.
    """
    r = np.asarray(r_e, float)
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    lon = np.arctan2(y, x)
    p = np.hypot(x, y)
    lat = np.arctan2(z, p * (1.0 - E2_CGCS))
    for _ in range(10):
        sl = np.sin(lat)
        N = A_CGCS / np.sqrt(1.0 - E2_CGCS * sl * sl)
        h = p / np.cos(lat) - N
        lat = np.arctan2(z, p * (1.0 - E2_CGCS * N / (N + h)))
    sl = np.sin(lat)
    N = A_CGCS / np.sqrt(1.0 - E2_CGCS * sl * sl)
    h = np.where(np.abs(np.cos(lat)) > 1e-9, p / np.cos(lat) - N, np.abs(z) - A_CGCS * np.sqrt(1 - E2_CGCS))
    return _stack3(lat, lon, h)


def C_e_n(lat, lon) -> np.ndarray:
    """Rotation ECEF -> ENU at geodetic (lat, lon) [rad]; shape (..., 3, 3)."""
    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    C = np.empty(np.broadcast_shapes(sl.shape, so.shape) + (3, 3))
    # filled in place (as skew): the deep loop calls this per interval, and four np.stack
    # calls cost ~6x the element writes
    C[..., 0, 0], C[..., 0, 1], C[..., 0, 2] = -so, co, 0.0
    C[..., 1, 0], C[..., 1, 1], C[..., 1, 2] = -sl * co, -sl * so, cl
    C[..., 2, 0], C[..., 2, 1], C[..., 2, 2] = cl * co, cl * so, sl
    return C


def radii_of_curvature(lat) -> tuple[np.ndarray, np.ndarray]:
    """Meridian R_M and prime-vertical R_N radii of curvature [m] at latitude [rad]."""
    sl2 = np.sin(np.asarray(lat, float)) ** 2
    w = 1.0 - E2_CGCS * sl2
    R_N = A_CGCS / np.sqrt(w)
    R_M = A_CGCS * (1.0 - E2_CGCS) / w**1.5
    return R_M, R_N


def enu_velocity_to_ecef(v_n, lat, lon) -> np.ndarray:
    """ENU velocity [m/s] (..., 3) to ECEF velocity [m/s]."""
    C = C_e_n(lat, lon)
    return np.einsum("...ji,...j->...i", C, np.asarray(v_n, float))


def euler_to_C_b_n(pitch, roll, yaw) -> np.ndarray:
    """Body (Right-Front-Up) to ENU rotation from pitch, roll, yaw [rad].

    Yaw (heading) is positive clockwise from North, pitch positive nose up, roll positive
    right wing down. C_b_n = R_z(-yaw) @ R_x(pitch) @ R_y(roll), with R_a(t) the active
    rotation by t about axis a.
    """
    p, r, y = (np.asarray(a, float) for a in (pitch, roll, yaw))
    cp, sp, cr, sr, cy, sy = np.cos(p), np.sin(p), np.cos(r), np.sin(r), np.cos(y), np.sin(y)
    return np.stack(
        [
            np.stack([cy * cr + sy * sp * sr, sy * cp, cy * sr - sy * sp * cr], axis=-1),
            np.stack([-sy * cr + cy * sp * sr, cy * cp, -sy * sr - cy * sp * cr], axis=-1),
            np.stack([-cp * sr, sp, cp * cr], axis=-1),
        ],
        axis=-2,
    )


def C_b_n_to_euler(C_b_n) -> np.ndarray:
    """Inverse of :func:`euler_to_C_b_n`: (pitch, roll, yaw) [rad], yaw in [0, 2 pi)."""
    C = np.asarray(C_b_n, float)
    pitch = np.arcsin(np.clip(C[..., 2, 1], -1.0, 1.0))
    roll = np.arctan2(-C[..., 2, 0], C[..., 2, 2])
    yaw = np.arctan2(C[..., 0, 1], C[..., 1, 1]) % (2 * np.pi)
    return np.stack([pitch, roll, yaw], axis=-1)


def earth_rate_n(lat) -> np.ndarray:
    """Earth rotation rate expressed in ENU, omega_ie^n [rad/s] (..., 3)."""
    lat = np.asarray(lat, float)
    return np.stack([np.zeros_like(lat), OMEGA_E * np.cos(lat), OMEGA_E * np.sin(lat)], axis=-1)


def elevation_azimuth(r_rx_e, r_sat_e, llh=None) -> tuple[np.ndarray, np.ndarray]:
    """Elevation and azimuth [rad] of satellites seen from a receiver, both ECEF [m].

    ``llh``: the receiver's ``ecef_to_llh(r_rx_e)`` if the caller has it (not recomputed).
    """
    r_rx = np.asarray(r_rx_e, float)
    if llh is None:
        llh = ecef_to_llh(r_rx)
    d = np.asarray(r_sat_e, float) - r_rx
    enu = np.einsum("...ij,...j->...i", C_e_n(llh[..., 0], llh[..., 1]), d)
    el = np.arctan2(enu[..., 2], np.hypot(enu[..., 0], enu[..., 1]))
    az = np.arctan2(enu[..., 0], enu[..., 1]) % (2 * np.pi)
    return el, az


def transport_rate_n(lat, h, v_n) -> np.ndarray:
    """Transport rate omega_en^n [rad/s] (..., 3): rotation of ENU w.r.t. ECEF, in ENU.

    ``omega_en^n = (-v_N / (R_M + h), v_E / (R_N + h), v_E tan(lat) / (R_N + h))`` for
    geodetic latitude ``lat`` [rad], ellipsoidal height ``h`` [m] and ENU velocity ``v_n``
    [m/s] (..., 3). Singular at the poles (ENU itself is).
    """
    lat = np.asarray(lat, float)
    h = np.asarray(h, float)
    v = np.asarray(v_n, float)
    R_M, R_N = radii_of_curvature(lat)
    ve, vn = v[..., 0], v[..., 1]
    return np.stack(
        [-vn / (R_M + h), ve / (R_N + h), ve * np.tan(lat) / (R_N + h)], axis=-1
    )


def skew(v) -> np.ndarray:
    """Cross-product matrix [v x] (..., 3, 3) of a vector (..., 3): ``skew(a) @ b = a x b``."""
    v = np.asarray(v, float)
    S = np.zeros(v.shape[:-1] + (3, 3))      # filled in place: 3x faster than stacking
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S
