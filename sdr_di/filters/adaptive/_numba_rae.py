"""Jitted kernel of the Sage-window RAE/IAE rule (:mod:`.rae_aukf`), on plain arrays.

Compiled with the same options as :mod:`._numba_ff` (no fastmath), so the adaptation times of
``ff-aukf`` and ``rae-aukf`` compare the two rules' arithmetic, not numpy call overhead: at
``m = 14`` measurements each numpy call (~0.5-2 us) costs more than its arithmetic, and the
numpy version of this rule (five small matrix products) takes about twice as long as this
kernel. ``tests/test_filters_adaptive.py`` checks the kernel against the numpy version.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["rae_window_estimates", "warm_up"]


@njit(cache=True)
def rae_window_estimates(V, E, R_used, S_inv, K, rho, r_floor_rel, q_floor, adapt_r,
                         adapt_q):  # pragma: no cover - jitted (tested through the rule)
    """Window estimates of the Sage-window rule (full matrices).

    ::

        C_r = (1/W) E^T E,   R_hat = C_r + R - R S^-1 R + r_floor_rel diag(R^-)
        C_v = (1/W) V^T V,   Q_hat = K C_v K^T + diag(q_floor)

    Parameters
    ----------
    V, E : (W, m) arrays
        Window of innovations ``v^-`` and residuals ``v^+`` (one epoch per row).
    R_used : (m, m) ``R`` of the last update; S_inv : (m, m) ``S^-1``; K : (n, m) gain
    rho : (m,) diagonal of the prior ``R^-`` (floor scale)
    r_floor_rel : float; q_floor : (n,) ``Q`` floor
    adapt_r, adapt_q : bool
        Which estimates to form (the other is returned as an empty array).

    Returns
    -------
    R_hat : (m, m) ndarray; Q_hat : (n, n) ndarray
    """
    W, m = E.shape
    n = K.shape[0]
    inv_w = 1.0 / W
    R_hat = np.empty((0, 0))
    Q_hat = np.empty((0, 0))
    # all inner loops run along rows (contiguous)
    if adapt_r:
        T = np.zeros((m, m))                            # R S^-1
        for i in range(m):
            for k in range(m):
                a = R_used[i, k]
                if a != 0.0:
                    for j in range(m):
                        T[i, j] += a * S_inv[k, j]
        R_hat = np.zeros((m, m))
        for w in range(W):                              # C_r = E^T E / W (upper triangle)
            for i in range(m):
                a = E[w, i] * inv_w
                for j in range(i, m):
                    R_hat[i, j] += a * E[w, j]
        for i in range(m):                              # + R - R S^-1 R
            for k in range(m):
                a = T[i, k]
                if a != 0.0:
                    for j in range(i, m):
                        R_hat[i, j] -= a * R_used[k, j]
            for j in range(i, m):
                R_hat[i, j] += R_used[i, j]
            R_hat[i, i] += r_floor_rel * rho[i]
        for i in range(m):
            for j in range(i + 1, m):
                R_hat[j, i] = R_hat[i, j]
    if adapt_q:
        C = np.zeros((m, m))
        for w in range(W):                              # C_v = V^T V / W
            for i in range(m):
                a = V[w, i] * inv_w
                for j in range(i, m):
                    C[i, j] += a * V[w, j]
        for i in range(m):
            for j in range(i + 1, m):
                C[j, i] = C[i, j]
        KC = np.zeros((n, m))
        for i in range(n):
            for k in range(m):
                a = K[i, k]
                for j in range(m):
                    KC[i, j] += a * C[k, j]
        Q_hat = np.empty((n, n))
        for i in range(n):
            for j in range(i, n):
                acc = 0.0
                for k in range(m):
                    acc += KC[i, k] * K[j, k]
                Q_hat[i, j] = acc
                Q_hat[j, i] = acc
            Q_hat[i, i] += q_floor[i]
    return R_hat, Q_hat


def warm_up() -> None:
    """Compile (or load from the cache) the kernel with the argument types the rule uses."""
    W, m, n = 2, 2, 2
    R = np.eye(m)
    # rho is always R_prior.diagonal(): a read-only strided view
    rae_window_estimates(np.zeros((W, m)), np.zeros((W, m)), R, R, np.zeros((n, m)),
                         R.diagonal(), 1e-6, np.ones(n), True, True)
