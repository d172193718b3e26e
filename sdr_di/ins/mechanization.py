"""Strapdown INS mechanization in the local-level ENU frame (Right-Front-Up body).

Conventions: navigation frame ``n`` = ENU, body ``b`` = Right-Front-Up, attitude kept as the
quaternion ``q_b_n`` (``C_b_n`` rotates body vectors to ENU; scalar-first, see
:mod:`sdr_di.ins.rotation`), Earth-relative velocity ``v_n`` [m/s] in ENU, position
``llh`` = (lat [rad], lon [rad], h [m]) on CGCS2000, gravity = CGCS2000 normal gravity
(:mod:`sdr_di.ins.gravity`).

IMU input
---------
``step(f_b, w_ib_b, dt)`` takes the **average** specific force [m/s^2] and angular rate
[rad/s] over the interval ``(t_{k-1}, t_k]`` of length ``dt`` [s] (the convention of
:mod:`sdr_di.sim.trajectory` and of an integrating IMU), i.e. the increments
``dv_k = f_b dt``, ``dtheta_k = w_ib_b dt``. Estimated sensor biases ``gyro_bias`` [rad/s]
and ``accel_bias`` [m/s^2] held by the object are subtracted first, and, once a filter with
scale-factor states has fed back (:meth:`StrapdownINS.correct`), the estimated scale-factor
errors ``gyro_scale``, ``accel_scale`` [-] divided out: ``y^ = (y - b^) / (1 + s^)``
(:meth:`StrapdownINS.compensate`; the IMU model ``y = (1 + s) x + b`` of
:mod:`sdr_di.ins.imu`).

Algorithm (one update per IMU sample; Savage, *Strapdown Analytics*; Yan Gongmin's PSINS)
-----------------------------------------------------------------------------------------
1. Mid-interval navigation quantities (``v``, lat, h at ``t_{k-1/2}``) are linearly
   extrapolated from the two previous states; they give ``w_ie^n``, ``w_en^n``, ``g_n``.
2. Velocity, with rotation and two-sample sculling compensation (previous increments
   ``dtheta_{k-1}``, ``dv_{k-1}``)::

       dv_b  = dv_k + c1 a x dv_k + c2 a x (a x dv_k)
               + 1/12 (dtheta_{k-1} x dv_k + dv_{k-1} x dtheta_k)
       a = dtheta_k, c1 = (1 - cos|a|)/|a|^2 (~1/2), c2 = (1 - sin|a|/|a|)/|a|^2 (~1/6)

   (Savage's exact velocity-rotation coefficients: exact for constant rates, which matters in
   sustained turns where the usual 1/2 term alone leaves a dt^2 velocity drift);
       v_k   = v_{k-1} + (I - 1/2 [zeta x]) C_b_n(k-1) dv_b
               + 1/6 zeta x (zeta x C dv_k) - 1/12 zeta x C (a x dv_k)
               + (g_n - (2 w_ie^n + w_en^n) x v_mid) dt,         zeta = w_in^n dt

   (the two second-order nav-frame-rotation terms make the update exact to second order for
   constant rates; without them a stationary INS at 10 Hz accumulates a 2.5e-10 m/s^2
   spurious acceleration that the unstable vertical channel turns into mm in an hour);

3. Position by the trapezoid rule on velocity, radii of curvature at the mid point.
4. Attitude by rotation vectors with the two-sample coning correction::

       phi_k   = dtheta_k + 1/12 dtheta_{k-1} x dtheta_k
       q_b_n(k) = q(-zeta_mid) * q_b_n(k-1) * q(phi_k)

   with ``zeta_mid`` from the mid-interval position and average velocity of steps 2-3.

On the very first step the previous increments default to the current ones (no coning or
sculling term) unless :meth:`StrapdownINS.set_previous_increments` gave them.

Error convention for :meth:`StrapdownINS.correct` (closed loop, 17-state layout of
DESIGN section 4): errors are *computed minus true*. ``d_att`` is the misalignment
``phi`` [rad] of the computed navigation frame, ``C_b_n(computed) = (I - [phi x]) C_b_n(true)``
(paper 004 eq. 2 convention); ``d_v_n`` [m/s] ENU; ``d_llh`` (dlat [rad], dlon [rad], dh [m]).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..constants import A_CGCS, E2_CGCS, F_CGCS, OMEGA_E
from ..frames import C_b_n_to_euler, euler_to_C_b_n
from . import _numba_mechanization as _nb
from .gravity import GAMMA_E, K_SOMIGLIANA, M_CGCS
from .rotation import dcm_from_quat, quat_from_dcm, quat_from_rotvec, quat_mult


def _radii(lat: float) -> tuple[float, float]:
    """Scalar (math) version of :func:`sdr_di.frames.radii_of_curvature`: R_M, R_N [m]."""
    sl = math.sin(lat)
    w = 1.0 - E2_CGCS * sl * sl
    R_N = A_CGCS / math.sqrt(w)
    return R_N * (1.0 - E2_CGCS) / w, R_N


def _gravity(lat: float, h: float) -> float:
    """Scalar (math) version of :func:`sdr_di.ins.gravity.normal_gravity` [m/s^2]."""
    s2 = math.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / math.sqrt(1.0 - E2_CGCS * s2)
    return g0 * (1.0 - 2.0 / A_CGCS * (1.0 + F_CGCS + M_CGCS - 2.0 * F_CGCS * s2) * h
                 + 3.0 * h * h / A_CGCS**2)



def _rate_components(lat: float, h: float, v) -> tuple[tuple, tuple]:
    """Earth rate w_ie^n and transport rate w_en^n [rad/s] (ENU float triples) at (lat [rad],
    h [m]) with ENU velocity ``v`` [m/s]."""
    R_M, R_N = _radii(lat)
    sl, cl = math.sin(lat), math.cos(lat)
    return ((0.0, OMEGA_E * cl, OMEGA_E * sl),
            (-v[1] / (R_M + h), v[0] / (R_N + h), v[0] * sl / cl / (R_N + h)))


def _cross(a0: float, a1: float, a2: float, b0: float, b1: float, b2: float) -> tuple:
    """``a x b`` of float components (the products and differences of :func:`.rotation.cross`)."""
    return (a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)


def _mat_vec(C: np.ndarray, v) -> list:
    """``C v`` (3x3 by 3) as floats, each row summed left to right (the kernel's order;
    numpy's ``matmul`` hands this to BLAS, whose fused multiply-adds follow the CPU)."""
    (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = C.tolist()
    v0, v1, v2 = v
    return [c00 * v0 + c01 * v1 + c02 * v2, c10 * v0 + c11 * v1 + c12 * v2,
            c20 * v0 + c21 * v1 + c22 * v2]


class StrapdownINS:
    """Strapdown inertial navigator (ENU, Right-Front-Up body, CGCS2000).

    Parameters
    ----------
    llh : array_like (3,)
        Initial latitude [rad], longitude [rad], ellipsoidal height [m].
    v_n : array_like (3,)
        Initial ENU velocity [m/s].
    att : array_like (3,), optional
        Initial pitch, roll, yaw [rad] (yaw clockwise from North). Give ``att`` or ``C_b_n``.
    C_b_n : array_like (3, 3), optional
        Initial body-to-ENU rotation.
    t : float
        Time of the initial state [s].

    Attributes
    ----------
    q_b_n : (4,) array
        Attitude quaternion (scalar first).
    v_n : (3,) array
        ENU velocity [m/s].
    llh : (3,) array
        Position (lat [rad], lon [rad], h [m]).
    t : float
        Time of the state [s].
    gyro_bias, accel_bias : (3,) arrays
        Sensor bias estimates [rad/s], [m/s^2] subtracted from every sample (start at zero;
        updated by :meth:`correct`).
    gyro_scale, accel_scale : (3,) arrays
        Scale-factor error estimates [-] divided out of every sample after the bias (start
        at zero; updated by :meth:`correct`).
    """

    #: Whether :meth:`step_many` runs the numba kernel (else :meth:`step` row by row, the
    #: tested reference).
    jit = True

    def __init__(self, llh, v_n, att=None, C_b_n=None, t: float = 0.0):
        if (att is None) == (C_b_n is None):
            raise ValueError("give exactly one of att or C_b_n")
        if C_b_n is None:
            C_b_n = euler_to_C_b_n(*np.asarray(att, float).reshape(3))
        self.q_b_n = quat_from_dcm(np.asarray(C_b_n, float))
        self.v_n = np.array(v_n, float).reshape(3)
        self.llh = np.array(llh, float).reshape(3)
        self.t = float(t)
        self.gyro_bias = np.zeros(3)
        self.accel_bias = np.zeros(3)
        self.gyro_scale = np.zeros(3)
        self.accel_scale = np.zeros(3)
        self._scaled = False    # no scale factor fed back yet: the bias-only arithmetic
        self._dth_prev: np.ndarray | None = None
        self._dv_prev: np.ndarray | None = None
        self._v_prev: np.ndarray | None = None  # state one step back, for extrapolation
        self._llh_prev: np.ndarray | None = None
        self._dt_prev = 0.0

    # --- state access --------------------------------------------------------------------
    @property
    def C_b_n(self) -> np.ndarray:
        """Body-to-ENU rotation (3, 3)."""
        return dcm_from_quat(self.q_b_n)

    @property
    def att(self) -> np.ndarray:
        """Pitch, roll, yaw [rad] (yaw in [0, 2 pi))."""
        return C_b_n_to_euler(self.C_b_n)

    def set_previous_increments(self, f_b, w_ib_b, dt: float) -> None:
        """Give the IMU sample of the interval before the first step (for coning/sculling).

        Parameters as :meth:`step`; biases are compensated the same way.
        """
        f, w = self.compensate(f_b, w_ib_b)
        self._dth_prev = w * dt
        self._dv_prev = f * dt

    def compensate(self, f_b, w_ib_b) -> tuple[np.ndarray, np.ndarray]:
        """Specific force [m/s^2] and angular rate [rad/s] corrected with the estimates held:
        ``(y - b^) / (1 + s^)`` (just ``y - b^`` before any scale factor is fed back).

        Parameters
        ----------
        f_b, w_ib_b : array_like (3,)
            Measured specific force and angular rate, body axes.
        """
        f = np.asarray(f_b, float) - self.accel_bias
        w = np.asarray(w_ib_b, float) - self.gyro_bias
        if self._scaled:
            f = f / (1.0 + self.accel_scale)
            w = w / (1.0 + self.gyro_scale)
        return f, w

    # --- propagation ---------------------------------------------------------------------
    def step(self, f_b, w_ib_b, dt: float) -> None:
        """Propagate the state over one IMU interval.

        Parameters
        ----------
        f_b : array_like (3,)
            Average specific force over the interval, body axes [m/s^2].
        w_ib_b : array_like (3,)
            Average angular rate w.r.t. inertial space over the interval, body axes [rad/s].
        dt : float
            Interval length [s], > 0.
        """
        # Components as Python floats (the same IEEE operations as on numpy scalars, at a
        # fraction of the cost per operation), every sum written out left to right (no BLAS
        # or SIMD reduction): the operations of the numba kernel (step_many), bit for bit.
        if self._scaled:
            f, w = self.compensate(f_b, w_ib_b)
            dth, dv = w * dt, f * dt
        else:
            dth = (np.asarray(w_ib_b, float) - self.gyro_bias) * dt
            dv = (np.asarray(f_b, float) - self.accel_bias) * dt
        dth_p = dth if self._dth_prev is None else self._dth_prev
        dv_p = dv if self._dv_prev is None else self._dv_prev
        a0, a1, a2_ = dth.tolist()
        u0, u1, u2 = dv.tolist()
        p0, p1, p2 = dth_p.tolist()
        s0, s1, s2 = dv_p.tolist()

        v0 = self.v_n
        ve, vn, vu = v0.tolist()
        lat0, lon0, h0 = self.llh.tolist()
        # 1. mid-interval quantities by extrapolation from the previous step
        if self._v_prev is not None and self._dt_prev > 0:
            c = 0.5 * dt / self._dt_prev
            pe, pn, pu = self._v_prev.tolist()
            v_mid = (ve + c * (ve - pe), vn + c * (vn - pn), vu + c * (vu - pu))
            lat_mid = lat0 + c * (lat0 - float(self._llh_prev[0]))
            h_mid = h0 + c * (h0 - float(self._llh_prev[2]))
        else:
            v_mid, lat_mid, h_mid = (ve, vn, vu), lat0, h0
        w_ie, w_en = _rate_components(lat_mid, h_mid, v_mid)
        zeta = ((w_ie[0] + w_en[0]) * dt, (w_ie[1] + w_en[1]) * dt, (w_ie[2] + w_en[2]) * dt)
        g = _gravity(lat_mid, h_mid)

        # 2. velocity
        C = dcm_from_quat(self.q_b_n)
        a_x_v = _cross(a0, a1, a2_, u0, u1, u2)
        a2 = a0 * a0 + a1 * a1 + a2_ * a2_
        if a2 < 1e-6:  # series of Savage's exact coefficients (error < 1e-14)
            c1, c2 = 0.5 - a2 / 24.0 + a2 * a2 / 720.0, 1.0 / 6.0 - a2 / 120.0 + a2 * a2 / 5040.0
        else:
            a = math.sqrt(a2)
            c1, c2 = (1.0 - math.cos(a)) / a2, (1.0 - math.sin(a) / a) / a2
        r = _cross(a0, a1, a2_, *a_x_v)
        m = _cross(p0, p1, p2, u0, u1, u2)
        n = _cross(s0, s1, s2, a0, a1, a2_)
        dv_b = (u0 + c1 * a_x_v[0] + c2 * r[0] + (m[0] + n[0]) / 12.0,
                u1 + c1 * a_x_v[1] + c2 * r[1] + (m[1] + n[1]) / 12.0,
                u2 + c1 * a_x_v[2] + c2 * r[2] + (m[2] + n[2]) / 12.0)
        Cdv = _mat_vec(C, (u0, u1, u2))
        dvn = _mat_vec(C, dv_b)
        Caxv = _mat_vec(C, a_x_v)
        z0, z1, z2 = zeta
        k = _cross(z0, z1, z2, *dvn)
        zz = _cross(z0, z1, z2, *_cross(z0, z1, z2, *Cdv))
        za = _cross(z0, z1, z2, *Caxv)
        dvn = [dvn[i] - 0.5 * k[i] + zz[i] / 6.0 - za[i] / 12.0 for i in range(3)]
        cor = _cross(2.0 * w_ie[0] + w_en[0], 2.0 * w_ie[1] + w_en[1],
                     2.0 * w_ie[2] + w_en[2], *v_mid)
        v1 = (ve + dvn[0] + dt * -cor[0], vn + dvn[1] + dt * -cor[1],
              vu + dvn[2] + dt * (-g - cor[2]))

        # 3. position (trapezoid, mid-point radii)
        v_avg = (0.5 * (ve + v1[0]), 0.5 * (vn + v1[1]), 0.5 * (vu + v1[2]))
        h1 = h0 + v_avg[2] * dt
        h_m = 0.5 * (h0 + h1)
        R_M, _ = _radii(lat0)
        lat_m = lat0 + 0.5 * v_avg[1] / (R_M + h_m) * dt
        R_M, R_N = _radii(lat_m)
        lat1 = lat0 + v_avg[1] / (R_M + h_m) * dt
        lat_m = 0.5 * (lat0 + lat1)
        R_M, R_N = _radii(lat_m)
        lon1 = lon0 + v_avg[0] / ((R_N + h_m) * math.cos(lat_m)) * dt

        # 4. attitude
        w_ie_m, w_en_m = _rate_components(lat_m, h_m, v_avg)
        zeta = np.array([(w_ie_m[0] + w_en_m[0]) * dt, (w_ie_m[1] + w_en_m[1]) * dt,
                         (w_ie_m[2] + w_en_m[2]) * dt])
        cpd = _cross(p0, p1, p2, a0, a1, a2_)
        phi = np.array([a0 + cpd[0] / 12.0, a1 + cpd[1] / 12.0, a2_ + cpd[2] / 12.0])
        q0, q1, q2, q3 = quat_mult(quat_from_rotvec(-zeta),
                                   quat_mult(self.q_b_n, quat_from_rotvec(phi))).tolist()
        norm = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2 + q3 * q3)
        self.q_b_n = np.array([q0 / norm, q1 / norm, q2 / norm, q3 / norm])

        self._v_prev, self._llh_prev, self._dt_prev = v0, self.llh, dt
        self._dth_prev, self._dv_prev = dth, dv
        self.v_n = np.array(v1)
        self.llh = np.array([lat1, lon1, h1])
        self.t += dt

    def step_many(self, f_b, w_ib_b, dt) -> None:
        """Propagate the state over consecutive IMU intervals: :meth:`step` for each row.

        The numba kernel (:func:`sdr_di.ins._numba_mechanization.strapdown_steps`) makes
        the same operations as :meth:`step` in one call (tested bit for bit); with
        :attr:`jit` false, :meth:`step` runs row by row (the reference).

        Parameters
        ----------
        f_b, w_ib_b : array_like (N, 3)
            Average specific force [m/s^2] and angular rate [rad/s] over each interval,
            body axes.
        dt : array_like (N,)
            Interval lengths [s], > 0.
        """
        f_b = np.asarray(f_b, float)
        w_ib_b = np.asarray(w_ib_b, float)
        dt = np.asarray(dt, float)
        if not self.jit:
            for j in range(dt.size):
                self.step(f_b[j], w_ib_b[j], float(dt[j]))
            return
        state, flags, comp = self._packed()
        _nb.strapdown_steps(state, flags, comp, np.ascontiguousarray(f_b),
                            np.ascontiguousarray(w_ib_b), dt)
        self._unpack(state, flags)

    def _packed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The state, flags and compensation arrays of the kernel (its module notes)."""
        state = np.zeros(_nb.STATE_LEN)
        state[_nb.S_Q:_nb.S_Q + 4] = self.q_b_n
        state[_nb.S_V:_nb.S_V + 3] = self.v_n
        state[_nb.S_LLH:_nb.S_LLH + 3] = self.llh
        flags = np.zeros(2, np.int64)
        if self._v_prev is not None:
            flags[0] = 1
            state[_nb.S_V_PREV:_nb.S_V_PREV + 3] = self._v_prev
            state[_nb.S_LLH_PREV:_nb.S_LLH_PREV + 3] = self._llh_prev
        state[_nb.S_DT_PREV] = self._dt_prev
        if self._dth_prev is not None:
            flags[1] = 1
            state[_nb.S_DTH_PREV:_nb.S_DTH_PREV + 3] = self._dth_prev
            state[_nb.S_DV_PREV:_nb.S_DV_PREV + 3] = self._dv_prev
        state[_nb.S_T] = self.t
        comp = np.concatenate([self.gyro_bias, self.accel_bias, self.gyro_scale,
                               self.accel_scale, [1.0 if self._scaled else 0.0]])
        return state, flags, comp

    def _unpack(self, state: np.ndarray, flags: np.ndarray) -> None:
        """Take the kernel's state back (new arrays: holders of the old ones keep them)."""
        self.q_b_n = state[_nb.S_Q:_nb.S_Q + 4].copy()
        self.v_n = state[_nb.S_V:_nb.S_V + 3].copy()
        self.llh = state[_nb.S_LLH:_nb.S_LLH + 3].copy()
        if flags[0]:
            self._v_prev = state[_nb.S_V_PREV:_nb.S_V_PREV + 3].copy()
            self._llh_prev = state[_nb.S_LLH_PREV:_nb.S_LLH_PREV + 3].copy()
        self._dt_prev = float(state[_nb.S_DT_PREV])
        if flags[1]:
            self._dth_prev = state[_nb.S_DTH_PREV:_nb.S_DTH_PREV + 3].copy()
            self._dv_prev = state[_nb.S_DV_PREV:_nb.S_DV_PREV + 3].copy()
        self.t = float(state[_nb.S_T])

    # --- closed-loop feedback ------------------------------------------------------------
    def correct(self, d_att, d_v_n, d_llh, d_gyro_bias=None, d_accel_bias=None, *,
                d_gyro_scale=None, d_accel_scale=None) -> None:
        """Remove estimated errors from the state (closed-loop feedback).

        Parameters
        ----------
        d_att : array_like (3,)
            Attitude error (misalignment) ``phi`` [rad], ENU, with
            ``C_b_n(computed) = (I - [phi x]) C_b_n(true)``; the update is the exact rotation
            ``C_b_n <- exp([phi x]) C_b_n``.
        d_v_n : array_like (3,)
            Velocity error (computed - true) [m/s], ENU; ``v_n <- v_n - d_v_n``.
        d_llh : array_like (3,)
            Position error (computed - true): dlat [rad], dlon [rad], dh [m].
        d_gyro_bias, d_accel_bias : array_like (3,), optional
            Residual sensor bias estimates [rad/s], [m/s^2] (measured - true), *added* to the
            bias compensation ``gyro_bias`` / ``accel_bias``.
        d_gyro_scale, d_accel_scale : array_like (3,), optional
            Residual scale-factor error estimates [-] (compensated minus true, to first
            order: ``s - s^``), *added* to ``gyro_scale`` / ``accel_scale``.
        """
        d_att = np.asarray(d_att, float).reshape(3)
        d_v = np.asarray(d_v_n, float).reshape(3)
        d_p = np.asarray(d_llh, float).reshape(3)
        q = quat_mult(quat_from_rotvec(d_att), self.q_b_n)
        self.q_b_n = q / math.sqrt(float(q @ q))
        self.v_n = self.v_n - d_v
        self.llh = self.llh - d_p
        if self._v_prev is not None:  # keep the extrapolation history consistent
            self._v_prev = self._v_prev - d_v
            self._llh_prev = self._llh_prev - d_p
        if d_gyro_bias is not None:
            self.gyro_bias = self.gyro_bias + np.asarray(d_gyro_bias, float).reshape(3)
        if d_accel_bias is not None:
            self.accel_bias = self.accel_bias + np.asarray(d_accel_bias, float).reshape(3)
        if d_gyro_scale is not None:
            self.gyro_scale = self.gyro_scale + np.asarray(d_gyro_scale, float).reshape(3)
            self._scaled = True
        if d_accel_scale is not None:
            self.accel_scale = self.accel_scale + np.asarray(d_accel_scale, float).reshape(3)
            self._scaled = True


@dataclasses.dataclass
class InsSolution:
    """INS output at the IMU sample times.

    Attributes
    ----------
    t : (n,) array
        Time [s].
    llh : (n, 3) array
        Latitude [rad], longitude [rad], height [m].
    v_n : (n, 3) array
        ENU velocity [m/s].
    att : (n, 3) array
        Pitch, roll, yaw [rad].
    C_b_n : (n, 3, 3) array
        Body-to-ENU rotation.
    """

    t: np.ndarray
    llh: np.ndarray
    v_n: np.ndarray
    att: np.ndarray
    C_b_n: np.ndarray


def navigate(t, f_b, w_ib_b, llh0, v_n0, att0=None, C_b_n0=None) -> InsSolution:
    """Free-inertial navigation through a whole IMU record (open loop).

    Parameters
    ----------
    t : (n,) array
        Sample times [s]; the INS starts at ``t[0]`` with the given state and sample 0 (the
        average over the interval before ``t[0]``) serves only as the previous increment.
    f_b, w_ib_b : (n, 3) arrays
        Average specific force [m/s^2] and angular rate [rad/s] over ``(t[k-1], t[k]]``.
    llh0, v_n0, att0, C_b_n0
        Initial state at ``t[0]`` (see :class:`StrapdownINS`).

    Returns
    -------
    InsSolution
        The state at every ``t[k]`` (row 0 = initial state).
    """
    t = np.asarray(t, float)
    f_b = np.asarray(f_b, float)
    w_ib_b = np.asarray(w_ib_b, float)
    n = len(t)
    ins = StrapdownINS(llh0, v_n0, att=att0, C_b_n=C_b_n0, t=t[0])
    if n > 1:
        ins.set_previous_increments(f_b[0], w_ib_b[0], t[1] - t[0])
    llh = np.empty((n, 3))
    v = np.empty((n, 3))
    C = np.empty((n, 3, 3))
    llh[0], v[0], C[0] = ins.llh, ins.v_n, ins.C_b_n
    for k in range(1, n):
        ins.step(f_b[k], w_ib_b[k], t[k] - t[k - 1])
        llh[k], v[k], C[k] = ins.llh, ins.v_n, dcm_from_quat(ins.q_b_n)
    return InsSolution(t=t, llh=llh, v_n=v, att=C_b_n_to_euler(C), C_b_n=C)
