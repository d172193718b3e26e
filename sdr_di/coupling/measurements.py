"""Measurement models of the integration filter (17-state layout, errors = computed - true).

Both models take ``n_states`` (default 17): with scale-factor states (``error_states=sf``,
:mod:`sdr_di.filters.state`) the filter has 23 states, appended after the clock, which no
measurement sees: ``H`` gets zero columns for them and every column below keeps its index.

Deep / tight coupling (paper 004 eq 6-12): :class:`RangeRateMeasurementModel`
    ``z = [drho_1..N, drho_dot_1..N]`` (eq 7) with ``drho_i = rho^_INS,i - rho_i`` the
    pseudorange error [m] (``c / f_code * dtau_i``, eq 8, in deep mode; INS-predicted minus
    measured pseudorange in tight mode) and ``drho_dot_i`` the pseudorange-rate error [m/s]
    (eq 9). Linear in the state (eq 6), ``H`` of eq 10-12::

        H = [ 0_Nx6   H_rho1      0_Nx6  [1 0] ]       H_rho1    = -U C1
            [ 0_Nx3   H_rhodot1   0_Nx9  [0 1] ]       H_rhodot1 = -U C2

    ``U`` (N, 3) the ECEF unit line-of-sight vectors receiver -> satellite (from the
    INS-predicted position), ``C1 = d r_e / d(lat, lon, h)`` (3, 3) and ``C2 = C_n^e`` (ENU to
    ECEF). The number of satellites ``N_k`` may change every epoch: call :meth:`set_epoch`.
    :func:`predicted_observables` gives the INS-predicted ranges and range rates the NCOs (deep)
    or the residual formation (tight) need.

Loosely coupled (paper 000 eq 8-9, paper 003 eq 13-14): :class:`LooseMeasurementModel`
    ``z = [v_INS - v_GNSS (E, N, U) [m/s], (L_INS - L_GNSS)(R_M + h), (lambda_INS -
    lambda_GNSS)(R_N + h) cos L, h_INS - h_GNSS] [m]``; ``H = [0 I3 0 ...; 0 0 diag(R_M + h,
    (R_N + h) cos L, 1) ...]`` (paper 003 ``H_p``, with ``+h`` and the position in metres
    North, East, Up, so ``R`` is in m^2 and (m/s)^2).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..filters.models import LinearMeasurementModel
from ..filters.state import CLOCK_BIAS, CLOCK_DRIFT, N_STATES, POS, VEL
from ..frames import C_e_n, llh_to_ecef, radii_of_curvature
from ._numba_measurements import range_rate_H

__all__ = [
    "LooseMeasurementModel",
    "RangeRateMeasurementModel",
    "dr_e_dllh",
    "loose_measurement",
    "predicted_observables",
]


def dr_e_dllh(llh) -> np.ndarray:
    """``C1 = d r_e / d(lat, lon, h)`` (3, 3) at ``llh`` (rad, rad, m)."""
    lat, lon, h = (float(v) for v in llh)
    return _dr_e_dllh_of(lat, h, C_e_n(lat, lon).T)


def _dr_e_dllh_of(lat: float, h: float, C_n_e: np.ndarray) -> np.ndarray:
    """:func:`dr_e_dllh` from ``C_n_e`` (3, 3) at the same position."""
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    cl = math.cos(lat)
    # columns of C_n_e: E, N, U unit vectors in ECEF
    return np.column_stack([C_n_e[:, 1] * (R_M + h), C_n_e[:, 0] * (R_N + h) * cl,
                            C_n_e[:, 2]])


def _position_matrices(llh) -> tuple[np.ndarray, np.ndarray]:
    """``C1`` (:func:`dr_e_dllh`) and ``C2 = C_n_e`` at ``llh`` (rad, rad, m), read-only.

    The last position's are kept (:func:`_position_matrices_at`): the deep loop sets the
    geometry twice per interval at the same INS position (the filter's channels, then every
    channel for the feedback)."""
    return _position_matrices_at(float(llh[0]), float(llh[1]), float(llh[2]))


@functools.lru_cache(maxsize=1)
def _position_matrices_at(lat: float, lon: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_position_matrices` at one position, cached (read-only arrays)."""
    C2 = C_e_n(lat, lon).T
    C1 = _dr_e_dllh_of(lat, h, C2)
    C1.flags.writeable = False
    C2.flags.writeable = False
    return C1, C2


def predicted_observables(llh, v_n, sat_pos_e, sat_vel_e, clock_bias_m: float = 0.0,
                          clock_drift_mps: float = 0.0):
    """INS-predicted geometric pseudoranges and rates and the unit line-of-sight vectors.

    Parameters
    ----------
    llh, v_n : (3,)
        INS position (rad, rad, m) and ENU velocity [m/s].
    sat_pos_e, sat_vel_e : (N, 3)
        Satellite ECEF positions [m] and velocities [m/s] at the epoch (Sagnac and signal
        transit time are the caller's business, as for the measured observables).
    clock_bias_m, clock_drift_mps : float
        Receiver clock estimates added to the predictions.

    Returns
    -------
    rho : (N,) [m], rho_dot : (N,) [m/s], U : (N, 3) unit vectors receiver -> satellite.
    """
    r = llh_to_ecef(*llh)
    v = C_e_n(llh[0], llh[1]).T @ np.asarray(v_n, float)
    d = np.atleast_2d(np.asarray(sat_pos_e, float)) - r
    rng = np.linalg.norm(d, axis=1)
    U = d / rng[:, None]
    rate = np.einsum("ij,ij->i", U, np.atleast_2d(np.asarray(sat_vel_e, float)) - v)
    return rng + clock_bias_m, rate + clock_drift_mps, U


class RangeRateMeasurementModel(LinearMeasurementModel):
    """Paper 004 eq 6-12 for ``N_k`` satellites; see the module docstring.

    Parameters
    ----------
    llh, v_n, sat_pos_e, sat_vel_e
        As :meth:`set_epoch` (optional at construction).
    n_states : int
        Columns of ``H``: the filter's state dimension (module notes).
    """

    #: Whether :meth:`set_geometry` fills ``H`` by the numba kernel
    #: (:func:`~sdr_di.coupling._numba_measurements.range_rate_H`, one call); False: the
    #: numpy form (the tested reference; the two agree to an ulp).
    jit = True

    def __init__(self, llh=None, v_n=None, sat_pos_e=None, sat_vel_e=None, *,
                 n_states: int = N_STATES) -> None:
        self.n_states = int(n_states)
        super().__init__(np.zeros((0, self.n_states)))
        self.U = np.zeros((0, 3))
        self.rho_pred = np.zeros(0)
        self.rate_pred = np.zeros(0)
        if llh is not None:
            self.set_epoch(llh, v_n, sat_pos_e, sat_vel_e)

    @property
    def n_sat(self) -> int:
        return self.U.shape[0]

    def set_epoch(self, llh, v_n, sat_pos_e, sat_vel_e, clock_bias_m: float = 0.0,
                  clock_drift_mps: float = 0.0) -> None:
        """Geometry of this epoch: INS state and satellite positions/velocities (N_k, 3)."""
        self.rho_pred, self.rate_pred, U = predicted_observables(
            llh, v_n, sat_pos_e, sat_vel_e, clock_bias_m, clock_drift_mps)
        self.set_geometry(llh, U)

    def set_geometry(self, llh, U) -> None:
        """``H`` of eq 10-12 from the INS position ``llh`` (rad, rad, m) and unit
        line-of-sight vectors ``U`` (N_k, 3) the caller already has (the deep loop's range
        predictions); leaves :attr:`rho_pred`/:attr:`rate_pred` untouched."""
        U = np.atleast_2d(np.asarray(U, float))
        self.U = U
        N = U.shape[0]
        C1, C2 = _position_matrices(llh)
        H = np.zeros((2 * N, self.n_states))
        if self.jit:
            range_rate_H(U, C1, C2, POS.start, VEL.start, CLOCK_BIAS, CLOCK_DRIFT, H)
            self.matrix = H
            return
        H[:N, POS] = -U @ C1          # H_rho1 (eq 11)
        H[:N, CLOCK_BIAS] = 1.0       # H_rho2 = [1 0]
        H[N:, VEL] = -U @ C2          # H_rhodot1 (eq 12)
        H[N:, CLOCK_DRIFT] = 1.0      # H_rhodot2 = [0 1]
        self.matrix = H

    def measurement(self, rho_meas, rate_meas) -> np.ndarray:
        """``z`` (eq 7) of tight coupling: INS-predicted minus measured observables."""
        return np.concatenate([self.rho_pred - np.asarray(rho_meas, float),
                               self.rate_pred - np.asarray(rate_meas, float)])


def _loose_H(llh, n_states: int = N_STATES) -> np.ndarray:
    lat, h = float(llh[0]), float(llh[2])
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    H = np.zeros((6, n_states))
    H[0:3, VEL] = np.eye(3)
    H[3, POS.start] = R_M + h
    H[4, POS.start + 1] = (R_N + h) * math.cos(lat)
    H[5, POS.start + 2] = 1.0
    return H


class LooseMeasurementModel(LinearMeasurementModel):
    """Papers 000/003 eq 13-14 (velocity then N/E/U position differences, metres);
    ``n_states`` columns (module notes)."""

    def __init__(self, llh=None, *, n_states: int = N_STATES) -> None:
        self.n_states = int(n_states)
        super().__init__(np.zeros((6, self.n_states)) if llh is None
                         else _loose_H(llh, self.n_states))

    def set_epoch(self, llh) -> None:
        """Scale of the position rows at the INS position of this epoch."""
        self.matrix = _loose_H(llh, self.n_states)


def loose_measurement(ins_llh, ins_v_n, gnss_llh, gnss_v_n) -> np.ndarray:
    """``z`` of eq 13: INS minus GNSS velocity [m/s] and position N, E, U [m]."""
    lat, h = float(ins_llh[0]), float(ins_llh[2])
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    d = np.asarray(ins_llh, float) - np.asarray(gnss_llh, float)
    return np.concatenate([np.asarray(ins_v_n, float) - np.asarray(gnss_v_n, float),
                           [d[0] * (R_M + h), d[1] * (R_N + h) * math.cos(lat), d[2]]])
