"""INS initial alignment at the hand-over, and the initial errors an experiment injects.

``align_ins``              the INS at the loop's first IMU sample: position and velocity
                           from the WLS fix, attitude from the reference (``align="truth"``)
                           or from the fix velocity and the IMU (``"gnss"``)
``gnss_alignment``         TRIAD from the GNSS velocity and the IMU (no sideslip,
                           coordinated turn)
``inject_initial_errors``  the configured attitude, velocity and position errors

Reasons: the notes of :mod:`sdr_di.integration.receiver` (*INS initial alignment*);
``docs/assumptions.md`` for the initial errors.
"""

from __future__ import annotations

import math

import numpy as np

from ..frames import ecef_to_llh, radii_of_curvature
from ..ins.mechanization import StrapdownINS
from ..coupling.config import IntegrationConfig
from .handover import HandoverError

__all__ = ["align_ins", "gnss_alignment", "inject_initial_errors"]


def align_ins(cfg: IntegrationConfig, imu, truth, sol, t_if: np.ndarray, i_h: int,
              t_fix_s: float):
    """INS at IMU sample ``i_h`` (receiver notes, *INS initial alignment*).

    Position and velocity are the WLS fix moved to ``t_if[i_h]``; attitude from the
    reference (``align="truth"``, INS coasting on the IMU from the reference's first
    record) or from the fix velocity and the IMU (``"gnss"``, :func:`gnss_alignment`).

    Returns
    -------
    ins : StrapdownINS
    llh_fix : (3,) the fix position at ``t_if[i_h]`` [rad, rad, m]
    att_sig : (3,) initial attitude sigmas (E, N, U) [rad]
    """
    dt_imu = 1.0 / imu.rate_hz
    r_fix = sol.r_e + sol.v_e * (t_if[i_h] - t_fix_s)
    llh_fix = ecef_to_llh(r_fix)
    if cfg.align == "truth":
        ins = StrapdownINS(truth.llh[0], truth.v_n[0], C_b_n=truth.C_b_n[0],
                           t=float(imu.t[0]))
        ins.set_previous_increments(imu.f_b[0], imu.w_ib_b[0], dt_imu)
        ins.step_many(imu.f_b[1:i_h + 1], imu.w_ib_b[1:i_h + 1], np.diff(imu.t[:i_h + 1]))
        ins.llh = np.array(llh_fix, float)
        ins.v_n = np.array(sol.v_n, float)
        att_sig = np.radians(np.asarray(cfg.p0_att_deg, float))
    else:
        v = np.asarray(sol.v_n, float)
        sp = math.hypot(v[0], v[1])
        if sp < 2.0:
            raise HandoverError(f"align='gnss' needs a moving receiver at the hand-over "
                                f"(horizontal speed {sp:.2f} m/s < 2 m/s)")
        lo, hi = max(i_h - 10, 0), min(i_h + 11, len(imu.t))
        C0 = gnss_alignment(v, imu.f_b[lo:hi].mean(axis=0), imu.w_ib_b[lo:hi].mean(axis=0))
        ins = StrapdownINS(llh_fix, v, C_b_n=C0, t=float(imu.t[i_h]))
        ins.set_previous_increments(imu.f_b[i_h], imu.w_ib_b[i_h], dt_imu)
        att_sig = np.radians([3.0, 3.0, 5.0])
    inject_initial_errors(ins, cfg)
    return ins, llh_fix, att_sig


def gnss_alignment(v_n, f_b, w_ib_b, g: float = 9.80) -> np.ndarray:
    """Body-to-ENU rotation from the GNSS velocity and the IMU at one instant (TRIAD).

    Assumes no sideslip (the velocity lies along the body Front axis) and a turn about the
    specific-force axis: the horizontal centripetal acceleration is ``omega x v`` with
    ``omega`` the gyro rate about the measured specific force, so the specific force in ENU
    is ``f_n = omega_up x v_n + (0, 0, g)``. TRIAD then pairs ``f_n`` with the measured
    ``f_b`` (primary: tilt, including the bank of a coordinated turn) and ``v_n`` with the
    Front axis (secondary: heading); ``omega_up`` is re-evaluated about the estimated Up axis
    (4 passes).

    Parameters
    ----------
    v_n : (3,) ENU velocity [m/s]; f_b : (3,) specific force [m/s^2] and w_ib_b : (3,)
        angular rate [rad/s], body Right-Front-Up, averaged around the instant.
    """
    v = np.asarray(v_n, float)
    fb = np.asarray(f_b, float)
    wb = np.asarray(w_ib_b, float)

    def frame(a, b):
        t1 = a / np.linalg.norm(a)
        t2 = np.cross(a, b)
        t2 /= np.linalg.norm(t2)
        return np.column_stack([t1, t2, np.cross(t1, t2)])

    up_b = fb / max(np.linalg.norm(fb), 1e-9)     # first guess of the Up axis in the body
    body = frame(fb, np.array([0.0, 1.0, 0.0]))
    for _ in range(4):                             # turn rate about the estimated Up axis
        w_up = float(np.dot(wb, up_b))
        C = frame(np.array([-w_up * v[1], w_up * v[0], g]), v) @ body.T
        up_b = C.T @ np.array([0.0, 0.0, 1.0])
    return C


def inject_initial_errors(ins: StrapdownINS, cfg: IntegrationConfig) -> None:
    """Add the configured initial errors to the aligned INS (errors = computed - true, as the
    filter's states): attitude ``C_b_n <- exp(-[phi x]) C_b_n`` for the ENU rotation vector
    ``phi``, velocity ``v_n += dv``, position ``+= (dE, dN, dU)`` [m] (the INS feedback
    :meth:`~sdr_di.ins.mechanization.StrapdownINS.correct` with the errors negated)."""
    phi = np.radians(np.asarray(cfg.init_att_err_deg, float))
    dv = np.asarray(cfg.init_vel_err_mps, float)
    dp = np.asarray(cfg.init_pos_err_m, float)
    if not (np.any(phi) or np.any(dv) or np.any(dp)):
        return
    lat, h = float(ins.llh[0]), float(ins.llh[2])
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    dllh = np.array([dp[1] / (R_M + h), dp[0] / ((R_N + h) * math.cos(lat)), dp[2]])
    ins.correct(-phi, -dv, -dllh)
