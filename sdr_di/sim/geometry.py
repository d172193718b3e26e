"""Per-satellite signal geometry: code and carrier delays seen by a moving receiver.

For a receiver whose true ECEF position is ``r_rx(t)`` and whose clock reads
``tau = t + b(t)`` (``b = bias + drift * (t - t_start)``), the signal received at receiver
time ``tau`` left the satellite at true BDT ``t_tx`` solving the light-time equation

    c (t_r - t_tx) = | R_z(omega_e (t_r - t_tx)) r_sat(t_tx) - r_rx(t_r) | + T + I

(Sagnac effect by rotating the satellite position into the ECEF frame of reception). The
satellite clock then reads ``t_sv = t_tx + dt_sv(t_tx)`` (broadcast polynomial plus
relativistic term, exactly what a receiver using the same ephemeris will remove). The code
delay and carrier delay [s] relative to receiver time are

    D_code = b + (rho + T + I) / c - dt_sv,     D_carr = b + (rho + T - I) / c - dt_sv

(ionosphere: group delay on code, equal phase advance on carrier). The transmitted code phase
at the antenna is ``(tau - D_code)`` in code-chip time and the carrier phase (cycles, baseband)
is ``f_IF tau - f_B3I D_carr``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from ..constants import C_LIGHT, OMEGA_E
from ..frames import C_e_n, ecef_to_llh
from ..orbits.atmosphere import iono_delay_b3i_m, saastamoinen_delay
from ..orbits.broadcast import sat_pos_vel_clock
from ..orbits.ephemeris import Ephemeris, Klobuchar


class ReceiverPath:
    """True receiver ECEF position as a C1 cubic Hermite spline of the truth samples.

    Parameters
    ----------
    t : array (n,)
        True time since the scenario start [s].
    r_e, v_e : array (n, 3)
        ECEF position [m] and velocity [m/s] at ``t``.

    Between 200 Hz truth samples the Hermite spline's position error is of order
    ``jerk * dt^3 / 384`` (well below a millimetre for vehicle motion).
    """

    def __init__(self, t: np.ndarray, r_e: np.ndarray, v_e: np.ndarray):
        self._spline = CubicHermiteSpline(t, r_e, v_e, axis=0, extrapolate=True)

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position [m] and velocity [m/s] (ECEF) at true times ``t`` [s since start]."""
        return self._spline(t), self._spline(t, 1)


@dataclasses.dataclass
class Delays:
    """Delays of one satellite at a set of receiver times.

    Attributes
    ----------
    d_code, d_carr : array
        Code and carrier delays [s] (see module docstring).
    rho : array
        Geometric range [m] (Sagnac-corrected).
    iono_m, tropo_m : array
        Ionospheric group delay on B3I and tropospheric delay [m].
    el, az : array
        Elevation and azimuth [rad] at the receiver.
    dt_sv : array
        Satellite clock offset [s] (with relativistic term).
    """

    d_code: np.ndarray
    d_carr: np.ndarray
    rho: np.ndarray
    iono_m: np.ndarray
    tropo_m: np.ndarray
    el: np.ndarray
    az: np.ndarray
    dt_sv: np.ndarray


def satellite_delays(
    eph: Ephemeris,
    path: ReceiverPath,
    t_rx_true: np.ndarray,
    sow_start: float,
    clock_bias_s: np.ndarray,
    iono: Klobuchar | None,
    troposphere: bool,
    rx: tuple[np.ndarray, np.ndarray] | None = None,
    atmosphere=None,
) -> Delays:
    """Solve the light-time equation and atmosphere for one satellite.

    Parameters
    ----------
    eph : Ephemeris
        Broadcast record used both to place the satellite and (by the receiver) to decode it.
    path : ReceiverPath
        Receiver truth.
    t_rx_true : array (m,)
        True reception times [s since scenario start].
    sow_start : float
        BDT seconds of week of the scenario start (true time 0).
    clock_bias_s : array (m,)
        Receiver clock bias b [s] at those times.
    iono : Klobuchar or None
        Klobuchar coefficients; None disables the ionosphere.
    troposphere : bool
        Apply the Saastamoinen delay.
    rx : (r_rx, llh), optional
        Receiver ECEF position (m, 3) [m] and geodetic (lat, lon, h) (m, 3) at ``t_rx_true``,
        when the caller already has them (one evaluation for all satellites of an epoch).
    atmosphere : AtmosphereTruth, optional
        Truth residuals from the models (:mod:`sdr_di.sim.atmosphere`): the Klobuchar delay
        scaled by its drawn factor, the wet residual added to the Saastamoinen delay (when
        the respective model is on). None: truth = model.
    """
    t_rx_true = np.asarray(t_rx_true, float)
    if rx is None:
        r_rx = path(t_rx_true)[0]
        llh = ecef_to_llh(r_rx)
    else:
        r_rx, llh = rx
    tau = np.full(t_rx_true.shape, 0.075)
    for _ in range(4):
        t_tx = sow_start + t_rx_true - tau
        r_s, _, dt_sv, _ = sat_pos_vel_clock(eph, t_tx)
        th = OMEGA_E * tau
        c, s = np.cos(th), np.sin(th)
        r_rot = np.stack([c * r_s[:, 0] + s * r_s[:, 1], -s * r_s[:, 0] + c * r_s[:, 1],
                          r_s[:, 2]], axis=-1)
        los = r_rot - r_rx
        rho = np.linalg.norm(los, axis=-1)
        tau = rho / C_LIGHT
    enu = np.einsum("...ij,...j->...i", C_e_n(llh[:, 0], llh[:, 1]), los)
    el = np.arctan2(enu[:, 2], np.hypot(enu[:, 0], enu[:, 1]))
    az = np.arctan2(enu[:, 0], enu[:, 1]) % (2 * np.pi)
    el_pos = np.maximum(el, np.radians(0.1))
    tropo = saastamoinen_delay(llh[:, 0], llh[:, 2], el_pos) if troposphere else np.zeros_like(rho)
    if iono is not None:
        iono_m = iono_delay_b3i_m(iono, llh[:, 0], llh[:, 1], el_pos, az, sow_start + t_rx_true)
    else:
        iono_m = np.zeros_like(rho)
    if atmosphere is not None:
        iono_m = iono_m * atmosphere.iono_factor(eph.prn, t_rx_true)
        if troposphere:
            tropo = tropo + atmosphere.tropo_residual_m(t_rx_true, el_pos)
    d_code = clock_bias_s + (rho + tropo + iono_m) / C_LIGHT - dt_sv
    d_carr = clock_bias_s + (rho + tropo - iono_m) / C_LIGHT - dt_sv
    return Delays(d_code, d_carr, rho, iono_m, tropo, el, az, dt_sv)
