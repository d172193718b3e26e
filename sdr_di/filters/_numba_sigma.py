"""Numba kernels of the sigma-point filters' points and weighted moments (every time update
and measurement prediction of the UKF, the CKF and the adaptive filters built on them): the
numpy forms, the tested references, are :meth:`~sdr_di.filters.sigma_filter.SigmaPointFilter.
_draw` (LAPACK's Cholesky factor), :func:`sdr_di.filters.sigma_filter.weighted_moments` and
the cross covariance of :meth:`~sdr_di.filters.sigma_filter.SigmaPointFilter.
predict_measurement` with ``sigma_filter.jit = False``. Sums over the points run in point
order (numpy's products call BLAS, whose order is its own), so the two agree to rounding,
not bit for bit."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._numba_correct import cholesky_lower


@njit(cache=True, boundscheck=False)
def moments(Y, wm, wc, mean, cov, D, delta):
    """Weighted mean ``mean`` (d,) and covariance ``cov`` (d, d) of the rows of ``Y``
    (p, d), about ``Y[0]``: deviations ``D = Y - Y[0]`` (p, d), ``delta = wm D`` (d,),
    ``cov = sum_i wc_i D_i D_i^T - delta c^T - c delta^T + (sum wc) delta delta^T`` with
    ``c = wc D``, symmetrized."""
    p, d = Y.shape
    c = np.zeros(d)
    sw = 0.0
    for i in range(p):
        sw += wc[i]
    for j in range(d):
        delta[j] = 0.0
    for i in range(p):
        for j in range(d):
            D[i, j] = Y[i, j] - Y[0, j]
            delta[j] += wm[i] * D[i, j]
            c[j] += wc[i] * D[i, j]
    for j in range(d):
        for k in range(j + 1):
            s = 0.0
            for i in range(p):
                s += wc[i] * D[i, j] * D[i, k]
            v_jk = s - delta[j] * c[k] - c[j] * delta[k] + sw * (delta[j] * delta[k])
            v_kj = s - delta[k] * c[j] - c[k] * delta[j] + sw * (delta[k] * delta[j])
            cov[j, k] = 0.5 * (v_jk + v_kj)
            cov[k, j] = 0.5 * (v_kj + v_jk)
    for j in range(d):
        mean[j] = Y[0, j] + delta[j]


@njit(cache=True, boundscheck=False)
def cross_covariance(dX, DZ, wc, dz, Pxz):
    """``Pxz`` (n, m) ``= sum_i wc_i dX_i DZ_i^T - (wc dX) dz^T`` of the points' state
    deviations ``dX`` (p, n) and measurement deviations ``DZ`` (p, m) about the first
    point, ``dz`` (m,) the measurement mean's deviation."""
    p, n = dX.shape
    m = DZ.shape[1]
    for a in range(n):
        cx = 0.0
        for i in range(p):
            cx += wc[i] * dX[i, a]
        for b in range(m):
            s = 0.0
            for i in range(p):
                s += wc[i] * dX[i, a] * DZ[i, b]
            Pxz[a, b] = s - cx * dz[b]


@njit(cache=True, boundscheck=False)
def draw(x, P, xi, X, dX):
    """Sigma points ``X = x + dX`` (p, n), ``dX = xi L^T`` (rows), ``L`` the lower Cholesky
    factor of ``P`` (n, n); ``xi`` (p, n) the unit points. Returns False (``X``, ``dX``
    unfinished) when ``P`` is not finite or not positive definite: the numpy form then
    applies the filter's failure policy."""
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            if not math.isfinite(P[i, j]):
                return False
    L = np.empty((n, n))
    if not cholesky_lower(P, L):
        return False
    for i in range(xi.shape[0]):
        for a in range(n):
            s = 0.0
            for b in range(a + 1):
                s += xi[i, b] * L[a, b]
            dX[i, a] = s
            X[i, a] = x[a] + s
    return True
