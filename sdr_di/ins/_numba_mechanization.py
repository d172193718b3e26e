"""Numba kernel of the strapdown INS step (:meth:`sdr_di.ins.mechanization.StrapdownINS.step`).

Plain arrays only; the algorithm, frames and notation are those of
:mod:`sdr_di.ins.mechanization` (Savage's velocity and attitude updates with two-sample
sculling and coning). :func:`strapdown_steps` runs ``N`` IMU samples in one call: the deep
loop steps its INS 4 times a 20 ms interval (200 Hz IMU), and the Python step's cost was
per call, not per operation (about 31 us a step; the kernel takes 15 us for the 4,
docs/notes/speed.md, session 26).

The kernel makes the same IEEE operations, in the same order, as the Python reference
:meth:`StrapdownINS.step <sdr_di.ins.mechanization.StrapdownINS.step>` (``StrapdownINS.jit =
False`` runs it; tested bit for bit, ``tests/test_ins_mechanization_kernel.py``):
every sum is written out left to right (``a + b + c`` is ``(a + b) + c``), the matrix-vector
products as ``C[i, 0] v0 + C[i, 1] v1 + C[i, 2] v2``, and no BLAS or SIMD reduction is
involved, so neither form depends on the CPU's vector units.

``state`` (:data:`STATE_LEN`) packs the INS: ``q_b_n`` (4), ``v_n`` (3), ``llh`` (3), the
previous step's ``v_n`` and ``llh`` (3 + 3) and length ``dt`` [s], the previous increments
``dtheta``, ``dv`` (3 + 3), the time ``t`` [s]; ``flags`` (2,): previous state known,
previous increments known. ``comp`` (:data:`COMP_LEN`): gyro bias, accelerometer bias,
gyro scale factor, accelerometer scale factor (3 each), then 1.0 when the scale factors
apply (``StrapdownINS.compensate``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..constants import A_CGCS, E2_CGCS, F_CGCS, OMEGA_E
from .gravity import GAMMA_E, K_SOMIGLIANA, M_CGCS

#: Offsets in ``state``.
S_Q, S_V, S_LLH, S_V_PREV, S_LLH_PREV, S_DT_PREV, S_DTH_PREV, S_DV_PREV, S_T = (
    0, 4, 7, 10, 13, 16, 17, 20, 23)
STATE_LEN = 24
#: Offsets in ``comp``.
C_GYRO_BIAS, C_ACCEL_BIAS, C_GYRO_SCALE, C_ACCEL_SCALE, C_SCALED = 0, 3, 6, 9, 12
COMP_LEN = 13


@numba.njit(cache=True)
def _radii(lat):
    """R_M, R_N [m] at latitude ``lat`` [rad] (``mechanization._radii``)."""
    sl = math.sin(lat)
    w = 1.0 - E2_CGCS * sl * sl
    R_N = A_CGCS / math.sqrt(w)
    return R_N * (1.0 - E2_CGCS) / w, R_N


@numba.njit(cache=True)
def _gravity(lat, h):
    """Normal gravity [m/s^2] (``mechanization._gravity``)."""
    s2 = math.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / math.sqrt(1.0 - E2_CGCS * s2)
    return g0 * (1.0 - 2.0 / A_CGCS * (1.0 + F_CGCS + M_CGCS - 2.0 * F_CGCS * s2) * h
                 + 3.0 * h * h / A_CGCS**2)


@numba.njit(cache=True)
def _rates(lat, h, v0, v1, out):
    """``w_ie^n`` into ``out[0:3]``, ``w_en^n`` into ``out[3:6]`` [rad/s]
    (``mechanization._rate_components``) at (lat [rad], h [m]) with ENU velocity
    (v0, v1) [m/s] (east, north)."""
    R_M, R_N = _radii(lat)
    sl, cl = math.sin(lat), math.cos(lat)
    out[0] = 0.0
    out[1] = OMEGA_E * cl
    out[2] = OMEGA_E * sl
    out[3] = -v1 / (R_M + h)
    out[4] = v0 / (R_N + h)
    out[5] = v0 * sl / cl / (R_N + h)


@numba.njit(cache=True)
def _cross(a, b, out):
    """``out = a x b`` (3-vectors)."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@numba.njit(cache=True)
def _mat_vec(C, v, out):
    """``out = C v`` (3x3 by 3), each row summed left to right."""
    for i in range(3):
        out[i] = C[i, 0] * v[0] + C[i, 1] * v[1] + C[i, 2] * v[2]


@numba.njit(cache=True)
def _quat_from_rotvec(x, y, z, out):
    """Quaternion of the rotation vector (x, y, z) [rad] (``rotation.quat_from_rotvec``)."""
    a2 = x * x + y * y + z * z
    if a2 < 1e-8:
        c = 1.0 - a2 / 8.0 + a2 * a2 / 384.0
        s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    else:
        a = math.sqrt(a2)
        c = math.cos(0.5 * a)
        s = math.sin(0.5 * a) / a
    out[0] = c
    out[1] = s * x
    out[2] = s * y
    out[3] = s * z


@numba.njit(cache=True)
def _quat_mult(p, q, out):
    """Hamilton product ``out = p * q`` (``rotation.quat_mult``)."""
    p0, p1, p2, p3 = p[0], p[1], p[2], p[3]
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    out[0] = p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3
    out[1] = p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2
    out[2] = p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1
    out[3] = p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0


@numba.njit(cache=True)
def _dcm_from_quat(q, C):
    """Rotation matrix of a unit quaternion (``rotation.dcm_from_quat``) into ``C``."""
    q0, q1, q2, q3 = q[0], q[1], q[2], q[3]
    C[0, 0] = q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3
    C[0, 1] = 2 * (q1 * q2 - q0 * q3)
    C[0, 2] = 2 * (q1 * q3 + q0 * q2)
    C[1, 0] = 2 * (q1 * q2 + q0 * q3)
    C[1, 1] = q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3
    C[1, 2] = 2 * (q2 * q3 - q0 * q1)
    C[2, 0] = 2 * (q1 * q3 - q0 * q2)
    C[2, 1] = 2 * (q2 * q3 + q0 * q1)
    C[2, 2] = q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3


@numba.njit(cache=True)
def strapdown_steps(state, flags, comp, f_b, w_ib_b, dt):
    """Propagate the packed INS ``state`` (module notes) over the IMU samples ``f_b``
    (N, 3) [m/s^2], ``w_ib_b`` (N, 3) [rad/s] (averages over each interval, body axes) of
    lengths ``dt`` (N,) [s], in place; ``flags`` are updated too."""
    dth = np.empty(3)
    dv = np.empty(3)
    dth_p = np.empty(3)
    dv_p = np.empty(3)
    rates = np.empty(6)
    v_mid = np.empty(3)
    C = np.empty((3, 3))
    a_x_v = np.empty(3)
    r = np.empty(3)
    m = np.empty(3)
    n = np.empty(3)
    dv_b = np.empty(3)
    Cdv = np.empty(3)
    dvn = np.empty(3)
    Caxv = np.empty(3)
    zeta = np.empty(3)
    k = np.empty(3)
    t1 = np.empty(3)
    zz = np.empty(3)
    za = np.empty(3)
    w2 = np.empty(3)
    cor = np.empty(3)
    v1 = np.empty(3)
    cpd = np.empty(3)
    q_z = np.empty(4)
    q_p = np.empty(4)
    q_a = np.empty(4)
    q = np.empty(4)
    scaled = comp[C_SCALED] != 0.0
    for j in range(f_b.shape[0]):
        h_dt = dt[j]
        # increments, compensated (StrapdownINS.compensate)
        for i in range(3):
            if scaled:
                dth[i] = (w_ib_b[j, i] - comp[C_GYRO_BIAS + i]) / (
                    1.0 + comp[C_GYRO_SCALE + i]) * h_dt
                dv[i] = (f_b[j, i] - comp[C_ACCEL_BIAS + i]) / (
                    1.0 + comp[C_ACCEL_SCALE + i]) * h_dt
            else:
                dth[i] = (w_ib_b[j, i] - comp[C_GYRO_BIAS + i]) * h_dt
                dv[i] = (f_b[j, i] - comp[C_ACCEL_BIAS + i]) * h_dt
        for i in range(3):
            dth_p[i] = state[S_DTH_PREV + i] if flags[1] else dth[i]
            dv_p[i] = state[S_DV_PREV + i] if flags[1] else dv[i]
        ve, vn, vu = state[S_V], state[S_V + 1], state[S_V + 2]
        lat0, lon0, h0 = state[S_LLH], state[S_LLH + 1], state[S_LLH + 2]
        # 1. mid-interval quantities by extrapolation from the previous step
        if flags[0] and state[S_DT_PREV] > 0:
            c = 0.5 * h_dt / state[S_DT_PREV]
            v_mid[0] = ve + c * (ve - state[S_V_PREV])
            v_mid[1] = vn + c * (vn - state[S_V_PREV + 1])
            v_mid[2] = vu + c * (vu - state[S_V_PREV + 2])
            lat_mid = lat0 + c * (lat0 - state[S_LLH_PREV])
            h_mid = h0 + c * (h0 - state[S_LLH_PREV + 2])
        else:
            v_mid[0], v_mid[1], v_mid[2] = ve, vn, vu
            lat_mid, h_mid = lat0, h0
        _rates(lat_mid, h_mid, v_mid[0], v_mid[1], rates)
        for i in range(3):
            zeta[i] = (rates[i] + rates[3 + i]) * h_dt
        g = _gravity(lat_mid, h_mid)

        # 2. velocity
        _dcm_from_quat(state[S_Q:S_Q + 4], C)
        _cross(dth, dv, a_x_v)
        a2 = dth[0] * dth[0] + dth[1] * dth[1] + dth[2] * dth[2]
        if a2 < 1e-6:
            c1 = 0.5 - a2 / 24.0 + a2 * a2 / 720.0
            c2 = 1.0 / 6.0 - a2 / 120.0 + a2 * a2 / 5040.0
        else:
            a = math.sqrt(a2)
            c1, c2 = (1.0 - math.cos(a)) / a2, (1.0 - math.sin(a) / a) / a2
        _cross(dth, a_x_v, r)
        _cross(dth_p, dv, m)
        _cross(dv_p, dth, n)
        for i in range(3):
            dv_b[i] = dv[i] + c1 * a_x_v[i] + c2 * r[i] + (m[i] + n[i]) / 12.0
        _mat_vec(C, dv, Cdv)
        _mat_vec(C, dv_b, dvn)
        _mat_vec(C, a_x_v, Caxv)
        _cross(zeta, dvn, k)
        _cross(zeta, Cdv, t1)
        _cross(zeta, t1, zz)
        _cross(zeta, Caxv, za)
        for i in range(3):
            dvn[i] = dvn[i] - 0.5 * k[i] + zz[i] / 6.0 - za[i] / 12.0
            w2[i] = 2.0 * rates[i] + rates[3 + i]
        _cross(w2, v_mid, cor)
        v1[0] = ve + dvn[0] + h_dt * -cor[0]
        v1[1] = vn + dvn[1] + h_dt * -cor[1]
        v1[2] = vu + dvn[2] + h_dt * (-g - cor[2])

        # 3. position (trapezoid, mid-point radii)
        va0, va1, va2 = 0.5 * (ve + v1[0]), 0.5 * (vn + v1[1]), 0.5 * (vu + v1[2])
        h1 = h0 + va2 * h_dt
        h_m = 0.5 * (h0 + h1)
        R_M, R_N = _radii(lat0)
        lat_m = lat0 + 0.5 * va1 / (R_M + h_m) * h_dt
        R_M, R_N = _radii(lat_m)
        lat1 = lat0 + va1 / (R_M + h_m) * h_dt
        lat_m = 0.5 * (lat0 + lat1)
        R_M, R_N = _radii(lat_m)
        lon1 = lon0 + va0 / ((R_N + h_m) * math.cos(lat_m)) * h_dt

        # 4. attitude
        _rates(lat_m, h_m, va0, va1, rates)
        for i in range(3):
            zeta[i] = (rates[i] + rates[3 + i]) * h_dt
        _cross(dth_p, dth, cpd)
        _quat_from_rotvec(-zeta[0], -zeta[1], -zeta[2], q_z)
        _quat_from_rotvec(dth[0] + cpd[0] / 12.0, dth[1] + cpd[1] / 12.0,
                          dth[2] + cpd[2] / 12.0, q_p)
        _quat_mult(state[S_Q:S_Q + 4], q_p, q_a)
        _quat_mult(q_z, q_a, q)
        norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])

        for i in range(3):
            state[S_V_PREV + i] = state[S_V + i]
            state[S_LLH_PREV + i] = state[S_LLH + i]
            state[S_DTH_PREV + i] = dth[i]
            state[S_DV_PREV + i] = dv[i]
            state[S_V + i] = v1[i]
        state[S_DT_PREV] = h_dt
        for i in range(4):
            state[S_Q + i] = q[i] / norm
        state[S_LLH] = lat1
        state[S_LLH + 1] = lon1
        state[S_LLH + 2] = h1
        state[S_T] += h_dt
        flags[0] = 1
        flags[1] = 1
