"""Numba kernel of the Kalman correction every filter shares
(:meth:`sdr_di.filters.base.KalmanFilterBase._correct`, every update of every integrated
run): ``S``, its Cholesky factor and inverse, the gain, the corrected state and covariance
and the NIS in one call. The numpy form (LAPACK ``dpotrf``/``dtrtri``, BLAS products) stays
the tested reference (``KalmanFilterBase.jit = False``); the kernel's sums run in index
order, so the two agree to rounding, not bit for bit. A factorization that fails here
(``S`` not positive definite, or not finite) is left to the numpy form, which owns the
filter's failure policy (``psd_fallback``)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, boundscheck=False)
def cholesky_lower(A, L):
    """Lower Cholesky factor ``L`` (n, n) of ``A`` (n, n; its lower triangle read), the upper
    triangle zeroed. Returns False (``L`` unfinished) when ``A`` is not positive definite
    (a pivot not above zero, or NaN). The correction's and the sigma points' factor
    (:func:`sdr_di.filters._numba_sigma.draw`; numba's cache does not see a change here
    from that module: delete its cache files after editing this function, speed notes,
    session 27)."""
    n = A.shape[0]
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        d = math.sqrt(s)
        L[j, j] = d
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / d
        for i in range(j):
            L[i, j] = 0.0
    return True


@njit(cache=True, boundscheck=False)
def correct(x, P, y, Pzz, Pxz, R, S, L, S_inv, K, x_out, P_out):
    """The correction of prior ``x`` (n,), ``P`` (n, n) by innovation ``y`` (m,) with the
    prediction's ``Pzz`` (m, m), ``Pxz`` (n, m) and noise ``R`` (m, m). Out: ``S = sym(Pzz
    + R)``, its lower factor ``L`` and inverse ``S_inv`` (m, m), the gain ``K = Pxz S^-1``
    (n, m), ``x_out = x + K y``, ``P_out = sym(P - K Pxz^T)``. Returns ``(ok, nis, sum of
    log diag L)``; ``ok`` False (the outputs unfinished) when ``S`` is not positive
    definite or not finite."""
    n, m = Pxz.shape
    for i in range(m):
        for j in range(m):
            S[i, j] = 0.5 * ((Pzz[i, j] + R[i, j]) + (Pzz[j, i] + R[j, i]))
            if not math.isfinite(S[i, j]):
                return False, 0.0, 0.0
    if not cholesky_lower(S, L):
        return False, 0.0, 0.0
    log_det = 0.0
    for j in range(m):
        log_det += math.log(L[j, j])
    # S^-1 = L^-T L^-1 from the lower inverse L^-1 (forward substitution)
    Li = np.zeros((m, m))
    for j in range(m):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, m):
            s = 0.0
            for k in range(j, i):
                s += L[i, k] * Li[k, j]
            Li[i, j] = -s / L[i, i]
    for i in range(m):
        for j in range(i + 1):
            s = 0.0
            for k in range(i, m):
                s += Li[k, i] * Li[k, j]
            S_inv[i, j] = s
            S_inv[j, i] = s
    # gain, state, covariance, NIS
    for a in range(n):
        for b in range(m):
            s = 0.0
            for c in range(m):
                s += Pxz[a, c] * S_inv[c, b]
            K[a, b] = s
    for a in range(n):
        s = 0.0
        for b in range(m):
            s += K[a, b] * y[b]
        x_out[a] = x[a] + s
    for a in range(n):
        for b in range(n):
            s = 0.0
            for c in range(m):
                s += K[a, c] * Pxz[b, c]
            P_out[a, b] = P[a, b] - s
    for a in range(n):
        for b in range(a):
            v = 0.5 * (P_out[a, b] + P_out[b, a])
            P_out[a, b] = v
            P_out[b, a] = v
    nis = 0.0
    for i in range(m):
        s = 0.0
        for j in range(m):
            s += S_inv[i, j] * y[j]
        nis += y[i] * s
    return True, nis, log_det
