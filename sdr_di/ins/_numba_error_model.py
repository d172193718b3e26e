"""Numba kernels of the INS error dynamics (:func:`sdr_di.ins.error_model.error_derivative`).

Plain arrays only; the model and notation are those of :mod:`sdr_di.ins.error_model`. The
kernels are the per-row work of ``error_derivative`` in the same IEEE operations, in the
same order, as the numpy form, so that their rows are its rows bit for bit (tested,
``tests/test_ins_error_model_kernel.py``). The numpy form avoids the operations whose
arithmetic no kernel can repeat on every machine: its 3x3 products ``[phi x]^2`` and
``eps C_b^n^T``, ``nabla C_b^n^T`` are sums left to right (``matmul`` would call BLAS, whose
small kernels fuse multiply-adds in an order of their own, per CPU) and its meridian radius
is ``R_N (1 - e^2) / w`` (``w ** 1.5`` would be numpy's ``power``, a SIMD library's on
AVX-512). So :func:`improved_euler` runs a whole ``f_batch`` (both derivatives of the
improved-Euler step) in one call.

The orders the kernels repeat: ``np.einsum("pij,pj->pi")`` and ``("pij,j->pi")`` sum a row
of a contiguous matrix as ``0 + ((m0 v0 + m2 v2) + m1 v1)`` (numpy's two-lane dot), of a
strided one (``A^T``) as ``((0 + m0 v0) + m1 v1) + m2 v2``; ``np.sum(axis=-1)`` over three
as ``(a0 + a1) + a2``.

Per row ``p`` of ``X`` (p, n) the stages are: :func:`true_state_terms` (``w = 1 - e^2
sin^2 L`` of the true latitude and ``[phi x]``), :func:`products` (``[phi x]^2`` and the
residual biases in the navigation frame), then :func:`error_rows` (everything else);
:func:`derivative_rows` runs the three. ``cs`` packs the computed (INS) state's quantities,
which every row shares (:data:`CS_*` offsets).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..constants import A_CGCS, E2_CGCS, F_CGCS, OMEGA_E
from .gravity import GAMMA_E, K_SOMIGLIANA, M_CGCS

#: Offsets in ``cs`` (length :data:`CS_LEN`): w_in^n, w_ie^n, w_en^n of the computed state,
#: ``2 w_ie^n + w_en^n``, ``C_b^n f_b``, ``v_n`` (3 each), then latitude [rad], height [m],
#: normal gravity [m/s^2] and ``v_E / ((R_N + h) cos L)`` [rad/s].
CS_WIN, CS_WIE, CS_WEN, CS_W2, CS_CF, CS_V = 0, 3, 6, 9, 12, 15
CS_LAT, CS_H, CS_G, CS_LONDOT = 18, 19, 20, 21
CS_LEN = 22

_G_H1 = 2.0 / A_CGCS                        # normal_gravity's height terms
_G_F = 1.0 + F_CGCS + M_CGCS
_G_F2 = 2.0 * F_CGCS
_A2 = A_CGCS ** 2


@numba.njit(cache=True)
def true_state_terms(X, lat_c, h_c, w, K):
    """``w = 1 - e^2 sin^2(L)`` of each row's true latitude ``L = lat_c - X[:, 6]`` and the
    skew matrix ``[phi x]`` of its attitude error ``X[:, 0:3]``, into ``w`` (p,) and ``K``
    (p, 3, 3)."""
    for p in range(X.shape[0]):
        s = math.sin(lat_c - X[p, 6])
        w[p] = 1.0 - E2_CGCS * (s * s)
        K[p, 0, 0] = 0.0
        K[p, 0, 1] = -X[p, 2]
        K[p, 0, 2] = X[p, 1]
        K[p, 1, 0] = X[p, 2]
        K[p, 1, 1] = 0.0
        K[p, 1, 2] = -X[p, 0]
        K[p, 2, 0] = -X[p, 1]
        K[p, 2, 1] = X[p, 0]
        K[p, 2, 2] = 0.0


@numba.njit(cache=True, inline="always")
def _dot_m(M, r, v0, v1, v2):
    # one row of np.einsum's product with a vector, in its order
    return 0.0 + ((M[r, 0] * v0 + M[r, 2] * v2) + M[r, 1] * v1)


@numba.njit(cache=True)
def error_rows(X, cs, w, K, KK, eps_c, nab_c, gauss_markov, tau_g, tau_a, tau_clk, out):
    """Rows of ``xdot = fbar(x)`` (:func:`~sdr_di.ins.error_model.error_derivative`) into
    ``out`` (p, n), zero where the model has no dynamics.

    Parameters
    ----------
    X : float64 (p, n)
        Error states (layout of :mod:`sdr_di.filters.state`).
    cs : float64 (CS_LEN,)
        The computed state's shared quantities (module notes).
    w : float64 (p,)
        :func:`true_state_terms`'s ``w``.
    K, KK : float64 (p, 3, 3)
        ``[phi x]`` and ``[phi x] @ [phi x]`` (:func:`products`).
    eps_c, nab_c : float64 (p, 3)
        Effective residual gyro and accelerometer biases times ``C_b^n^T``
        (:func:`products`).
    gauss_markov : bool
        First-order Gauss-Markov biases (``gm``) of correlation times ``tau_g``, ``tau_a``
        [s]; ``tau_clk`` the clock drift's [s].
    """
    I = np.eye(3)
    A = np.empty((3, 3))
    M = np.empty((3, 3))
    IA = np.empty((3, 3))
    IAt = np.empty((3, 3))
    dw = np.empty(3)
    d_wie = np.empty(3)
    d_wen = np.empty(3)
    u = np.empty(3)
    lat_c, h_c, g_c = cs[CS_LAT], cs[CS_H], cs[CS_G]
    for p in range(X.shape[0]):
        for j in range(out.shape[1]):
            out[p, j] = 0.0
        # true state = computed - error; its rates (_rates, radii_of_curvature)
        lat_t = lat_c - X[p, 6]
        h_t = h_c - X[p, 8]
        vt0 = cs[CS_V] - X[p, 3]
        vt1 = cs[CS_V + 1] - X[p, 4]
        vt2 = cs[CS_V + 2] - X[p, 5]
        sl = math.sin(lat_t)
        cl = math.cos(lat_t)
        R_N = A_CGCS / math.sqrt(1.0 - E2_CGCS * (sl * sl))
        R_M = R_N * (1.0 - E2_CGCS) / w[p]
        RNh_t = R_N + h_t
        d_wie[0] = cs[CS_WIE] - 0.0
        d_wie[1] = cs[CS_WIE + 1] - OMEGA_E * cl
        d_wie[2] = cs[CS_WIE + 2] - OMEGA_E * sl
        d_wen[0] = cs[CS_WEN] - (-vt1) / (R_M + h_t)
        d_wen[1] = cs[CS_WEN + 1] - vt0 / RNh_t
        d_wen[2] = cs[CS_WEN + 2] - vt0 * sl / cl / RNh_t
        # so3 coefficients (_so3_coefficients with the Jacobian), row by row
        th2 = (X[p, 0] * X[p, 0] + X[p, 1] * X[p, 1]) + X[p, 2] * X[p, 2]
        th = math.sqrt(th2)
        s = co = 0.0
        if th2 < 1e-12:
            a = 1.0 - th2 / 6.0
            b = 0.5 - th2 / 24.0
        else:
            s = math.sin(th)
            co = math.cos(th)
            a = s / th
            b = (1.0 - co) / th2
        if th2 < 1e-8:
            c = 1.0 / 12.0 + th2 / 720.0
        else:
            c = 1.0 / th2 - (1.0 + co) / (2.0 * th * s)
        for i in range(3):
            for j in range(3):
                A[i, j] = (I[i, j] - a * K[p, i, j]) + b * KK[p, i, j]
                M[i, j] = (I[i, j] + 0.5 * K[p, i, j]) + c * KK[p, i, j]
        for i in range(3):
            for j in range(3):
                IA[i, j] = I[i, j] - A[i, j]
                IAt[i, j] = I[i, j] - A[j, i]
        for i in range(3):
            dw[i] = d_wie[i] + d_wen[i]
        # attitude (eq 2, line 1)
        for i in range(3):
            u[i] = (_dot_m(IA, i, cs[CS_WIN], cs[CS_WIN + 1], cs[CS_WIN + 2])
                    + _dot_m(A, i, dw[0], dw[1], dw[2])) - eps_c[p, i]
        for i in range(3):
            out[p, i] = _dot_m(M, i, u[0], u[1], u[2])
        # velocity (eq 2, line 2): A^T's rows are A's columns
        w20, w21, w22 = cs[CS_W2], cs[CS_W2 + 1], cs[CS_W2 + 2]
        e0 = 2.0 * d_wie[0] + d_wen[0]
        e1 = 2.0 * d_wie[1] + d_wen[1]
        e2 = 2.0 * d_wie[2] + d_wen[2]
        dv0, dv1, dv2 = X[p, 3], X[p, 4], X[p, 5]
        cr1 = (w21 * dv2 - w22 * dv1, w22 * dv0 - w20 * dv2, w20 * dv1 - w21 * dv0)
        cr2 = (e1 * vt2 - e2 * vt1, e2 * vt0 - e0 * vt2, e0 * vt1 - e1 * vt0)
        for i in range(3):
            # (A^T is a strided view there: einsum adds its row in turn)
            at = ((0.0 + A[0, i] * nab_c[p, 0]) + A[1, i] * nab_c[p, 1]) + A[2, i] * nab_c[p, 2]
            out[p, 3 + i] = ((_dot_m(IAt, i, cs[CS_CF], cs[CS_CF + 1], cs[CS_CF + 2]) + at)
                             - cr1[i]) - cr2[i]
        # normal gravity at the true state (gravity.normal_gravity)
        s2 = sl * sl
        g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / math.sqrt(1.0 - E2_CGCS * s2)
        g_t = g0 * ((1.0 - _G_H1 * (_G_F - _G_F2 * s2) * h_t) + 3.0 * h_t * h_t / _A2)
        out[p, 5] = out[p, 5] - (g_c - g_t)
        # position (eq 2, lines 3-5)
        out[p, 6] = -d_wen[0]
        out[p, 7] = cs[CS_LONDOT] - vt0 / (RNh_t * cl)
        out[p, 8] = X[p, 5]
        if gauss_markov:
            for i in range(3):
                out[p, 9 + i] = -X[p, 9 + i] / tau_g
                out[p, 12 + i] = -X[p, 12 + i] / tau_a
        # clock (eq 4)
        out[p, 15] = X[p, 16]
        out[p, 16] = -X[p, 16] / tau_clk


@numba.njit(cache=True)
def products(X, K, CT, w_ib_b, f_b, scale_start, KK, eps_c, nab_c):
    """``KK = K @ K`` (p, 3, 3) and the residual gyro and accelerometer biases of the rows of
    ``X`` times ``C_b^n^T`` (``CT`` = ``C_b^n^T``, contiguous), ``eps_c``, ``nab_c`` (p, 3):
    each entry summed left to right (``error_model._skew_squares``,
    ``_rows_times_transpose``). The biases are states 9-11 and 12-14, plus, with scale-factor
    states (``scale_start`` >= 0: gyro at ``scale_start``, accelerometer 3 after), those
    times ``w_ib_b`` and ``f_b`` (``error_model.residual_biases``)."""
    e = np.empty(3)
    a = np.empty(3)
    for p in range(X.shape[0]):
        for i in range(3):
            for j in range(3):
                KK[p, i, j] = (K[p, i, 0] * K[p, 0, j] + K[p, i, 1] * K[p, 1, j]) \
                    + K[p, i, 2] * K[p, 2, j]
        for k in range(3):
            e[k] = X[p, 9 + k]
            a[k] = X[p, 12 + k]
            if scale_start >= 0:
                e[k] = e[k] + X[p, scale_start + k] * w_ib_b[k]
                a[k] = a[k] + X[p, scale_start + 3 + k] * f_b[k]
        for j in range(3):
            eps_c[p, j] = (e[0] * CT[0, j] + e[1] * CT[1, j]) + e[2] * CT[2, j]
            nab_c[p, j] = (a[0] * CT[0, j] + a[1] * CT[1, j]) + a[2] * CT[2, j]


@numba.njit(cache=True)
def derivative_rows(X, cs, CT, w_ib_b, f_b, scale_start, gauss_markov, tau_g, tau_a,
                    tau_clk, out):
    """``xdot = fbar(x)`` of the rows of ``X`` into ``out`` (p, n): :func:`true_state_terms`,
    :func:`products` and :func:`error_rows` (``error_model.error_derivative``)."""
    p = X.shape[0]
    w = np.empty(p)
    K = np.empty((p, 3, 3))
    KK = np.empty((p, 3, 3))
    eps_c = np.empty((p, 3))
    nab_c = np.empty((p, 3))
    true_state_terms(X, cs[CS_LAT], cs[CS_H], w, K)
    products(X, K, CT, w_ib_b, f_b, scale_start, KK, eps_c, nab_c)
    error_rows(X, cs, w, K, KK, eps_c, nab_c, gauss_markov, tau_g, tau_a, tau_clk, out)


@numba.njit(cache=True)
def improved_euler(X, dt, cs0, cs1, C0T, C1T, w_ib_b, f_b, scale_start, gauss_markov, tau_g,
                   tau_a, tau_clk, out):
    """One improved-Euler step of the rows of ``X`` over ``dt`` [s] (``InsErrorModel.
    f_batch``): ``out = X + (dt / 2) (g0 + g1)``, ``g0 = fbar(X)`` on the computed state at
    the interval start (``cs0``, ``C0T``), ``g1 = fbar(X + dt g0)`` at its end (``cs1``,
    ``C1T``); the same element-wise operations as the numpy form."""
    g0 = np.empty(X.shape)
    g1 = np.empty(X.shape)
    X1 = np.empty(X.shape)
    derivative_rows(X, cs0, C0T, w_ib_b, f_b, scale_start, gauss_markov, tau_g, tau_a,
                    tau_clk, g0)
    for p in range(X.shape[0]):
        for j in range(X.shape[1]):
            X1[p, j] = X[p, j] + dt * g0[p, j]
    derivative_rows(X1, cs1, C1T, w_ib_b, f_b, scale_start, gauss_markov, tau_g, tau_a,
                    tau_clk, g1)
    h = 0.5 * dt
    for p in range(X.shape[0]):
        for j in range(X.shape[1]):
            out[p, j] = X[p, j] + h * (g0[p, j] + g1[p, j])


@numba.njit(cache=True)
def f_and_jacobian(x, steps, dt, cs0, cs1, C0T, C1T, w_ib_b, f_b, scale_start, gauss_markov,
                   tau_g, tau_a, tau_clk, fx, F):
    """``InsErrorModel.f_and_F``: :func:`improved_euler` of the ``2 n + 1`` rows ``x + e_i
    h_i``, ``x - e_i h_i`` (``h = steps``) and ``x``; ``fx`` (n,) the last row, ``F`` (n, n)
    the central differences ``F[j, i] = (Y[i, j] - Y[n + i, j]) / (2 h_i)``."""
    n = x.shape[0]
    X = np.empty((2 * n + 1, n))
    for i in range(n):
        for j in range(n):
            d = steps[i] if i == j else 0.0
            X[i, j] = x[j] + d
            X[n + i, j] = x[j] - d
    for j in range(n):
        X[2 * n, j] = x[j]
    Y = np.empty(X.shape)
    improved_euler(X, dt, cs0, cs1, C0T, C1T, w_ib_b, f_b, scale_start, gauss_markov, tau_g,
                   tau_a, tau_clk, Y)
    for j in range(n):
        fx[j] = Y[2 * n, j]
        for i in range(n):
            F[j, i] = (Y[i, j] - Y[n + i, j]) / (2.0 * steps[i])


@numba.njit(cache=True)
def computed_terms(llh, v, C, f_b, cs):
    """The computed (INS) state's shared quantities into ``cs`` (:data:`CS_LEN`,): those of
    :func:`~sdr_di.ins.error_model.computed_state_terms` (its numpy form, the same values)
    at geodetic ``llh`` (3,) [rad, rad, m], ENU velocity ``v`` (3,) [m/s], ``C = C_b^n``
    (3, 3) and specific force ``f_b`` (3,) [m/s^2]."""
    lat, h = llh[0], llh[2]
    sl = math.sin(lat)
    cl = math.cos(lat)
    w = 1.0 - E2_CGCS * (sl * sl)
    R_N = A_CGCS / math.sqrt(w)
    R_M = R_N * (1.0 - E2_CGCS) / w
    RN_h = R_N + h
    wie0, wie1, wie2 = 0.0, OMEGA_E * cl, OMEGA_E * sl
    wen0, wen1, wen2 = -v[1] / (R_M + h), v[0] / RN_h, v[0] * sl / cl / RN_h
    cs[CS_WIN], cs[CS_WIN + 1], cs[CS_WIN + 2] = wie0 + wen0, wie1 + wen1, wie2 + wen2
    cs[CS_WIE], cs[CS_WIE + 1], cs[CS_WIE + 2] = wie0, wie1, wie2
    cs[CS_WEN], cs[CS_WEN + 1], cs[CS_WEN + 2] = wen0, wen1, wen2
    cs[CS_W2] = 2.0 * wie0 + wen0
    cs[CS_W2 + 1] = 2.0 * wie1 + wen1
    cs[CS_W2 + 2] = 2.0 * wie2 + wen2
    for i in range(3):
        cs[CS_CF + i] = (C[i, 0] * f_b[0] + C[i, 1] * f_b[1]) + C[i, 2] * f_b[2]
        cs[CS_V + i] = v[i]
    cs[CS_LAT], cs[CS_H] = lat, h
    s2 = sl * sl
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / math.sqrt(1.0 - E2_CGCS * s2)
    cs[CS_G] = g0 * ((1.0 - _G_H1 * (_G_F - _G_F2 * s2) * h) + 3.0 * h * h / _A2)
    cs[CS_LONDOT] = v[0] / (RN_h * math.cos(lat))


@numba.njit(cache=True)
def interval_terms(llh0, v0, C0, llh1, v1, C1, f_b, cs0, cs1, C0T, C1T):
    """:func:`computed_terms` at both ends of a filter interval (``cs0``, ``cs1``) and the
    transposes ``C0T``, ``C1T`` (3, 3) of their ``C_b^n``: the kernels' arguments of the
    interval (``InsErrorModel._kernel_args``) in one call."""
    computed_terms(llh0, v0, C0, f_b, cs0)
    computed_terms(llh1, v1, C1, f_b, cs1)
    for i in range(3):
        for j in range(3):
            C0T[i, j] = C0[j, i]
            C1T[i, j] = C1[j, i]
