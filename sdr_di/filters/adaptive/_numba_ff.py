"""Jitted kernels of the forgetting-factor AUKF rule (paper 004 eq 26-39), on plain arrays.

The rule's per-epoch work is a few hundred multiply-adds (``n m`` for the diagonal of
``K diag(v o v) K^T``, ``W (n + n_blocks)`` for the weighted window sums, ``O(m)`` for the
block traces). Written as numpy expressions it is about twenty small array calls whose fixed
overhead (~0.5 us each) costs more than the arithmetic, so the two kernels below do each hook
in one call. :mod:`.ff_aukf` calls them; ``tests/test_filters_adaptive.py`` checks them
against a plain transcription of the equations.

Both kernels are compiled when the first rule is bound to a filter (``warm_up``), outside the
timed hooks, so :attr:`~sdr_di.filters.adaptive.base.AdaptiveRule.adaptation_time_s` never
includes compilation (``cache=True`` keeps the machine code between processes).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["ff_after_update", "scale_r", "warm_up"]


@njit(cache=True)
def scale_r(R_prior, s, n_blocks):  # pragma: no cover - jitted (tested through the rule)
    """``R^+ = S_k R^-`` (paper 004 eq 35-36) and whether ``R^-`` is diagonal (eq 34).

    Element ``(i, j)`` is multiplied by ``sqrt(s_b(i) s_b(j))``: ``s_b R^-`` on the diagonal
    blocks, so the product is ``S_k R^-`` for the diagonal ``R^-`` of eq 34 and stays symmetric
    for a full one (``sqrt(S) R^- sqrt(S)``).

    Parameters
    ----------
    R_prior : (m, m) float64 array
        The epoch's prior ``R^-`` [m^2 and (m/s)^2 blocks].
    s : (n_blocks,) float64 array
        Block factors ``s_b``.
    n_blocks : int
        Number of equal contiguous blocks (2: pseudorange, pseudorange rate).

    Returns
    -------
    R_used : (m, m) ndarray
    diagonal : bool
    """
    m = R_prior.shape[0]
    N = m // n_blocks
    out = np.empty((m, m))
    diagonal = True
    for i in range(m):
        si = s[i // N]
        for j in range(m):
            a = R_prior[i, j]
            if i == j:
                out[i, j] = a * si
            elif a == 0.0:
                out[i, j] = 0.0
            else:
                diagonal = False
                out[i, j] = a * math.sqrt(si * s[j // N])
    return out, diagonal


@njit(cache=True)
def ff_after_update(K, v, r, R_used, S_inv, rho, diagonal, buf, p, w, n_blocks, q_floor,
                    adapt_q, adapt_r, s_prev, s_lo, s_hi):  # pragma: no cover - jitted
    """One epoch of the Q- and R-adaptation of paper 004 (eq 27-31, 37-39).

    Writes the epoch's row of the window (the ``n`` diagonal elements of ``Q_cur,k``,
    eq 27-29, then the per-channel residual power ``(v^+)_b^T (v^+)_b / N_k`` of each block,
    eq 39) into ``buf[p]``, forms the normalized forgetting-factor sums with the weights ``w``
    of each ring slot (eq 30, 39), and returns the next ``Q`` and factors.

    Parameters
    ----------
    K : (n, m) gain; v : (m,) innovation (eq 26); r : (m,) residual (eq 32)
    R_used : (m, m) the ``R^+ = S_k R^-`` used in the update; S_inv : (m, m) ``S^-1``
    rho : (m,) diagonal of the prior ``R^-`` (eq 38 denominators)
    diagonal : bool, ``R_used`` is diagonal (then ``diag(R S^-1 R) = R_ii^2 S^-1_ii``)
    buf : (W, n + n_blocks) ring of stored rows; p : slot of this epoch
    w : (W,) weight of each slot, ``mu_age / sum(mu)`` (eq 30-31)
    q_floor : (n,) floor of the adapted ``Q`` diagonal
    s_prev : (n_blocks,) factors used in this update; s_lo, s_hi : factor bounds

    Returns
    -------
    Q : (n, n) ndarray
        Diagonal ``Q_{k+1}`` (eq 30) floored (meaningful when ``adapt_q``).
    s : (n_blocks,) ndarray
        ``s_b,k+1`` (eq 38), with eq 37 evaluated per channel:
        ``[tr(H P+ H^T)_b + tr(C_v+)_b] / tr(R^-_b)``, ``H P+ H^T = R - R S^-1 R``
        (``s_prev`` when not ``adapt_r``).
    """
    n, m = K.shape
    N = m // n_blocks
    W = buf.shape[0]
    row = buf[p]
    for i in range(n):                                  # diag(K diag(v o v) K^T)
        acc = 0.0
        for j in range(m):
            kv = K[i, j] * v[j]
            acc += kv * kv
        row[i] = acc
    for b in range(n_blocks):                           # (v+)_b^T (v+)_b / N_k
        acc = 0.0
        for j in range(b * N, (b + 1) * N):
            acc += r[j] * r[j]
        row[n + b] = acc / N
    ncol = n + n_blocks
    avg = np.zeros(ncol)                                # eq 30 / eq 39 weighted sums
    for k in range(W):
        wk = w[k]
        if wk != 0.0:
            bk = buf[k]
            for c in range(ncol):
                avg[c] += wk * bk[c]
    Q = np.zeros((n, n))
    if adapt_q:
        for i in range(n):
            Q[i, i] = max(avg[i], q_floor[i])
    s = s_prev.copy()
    if adapt_r:
        for b in range(n_blocks):
            hph = 0.0
            tr = 0.0
            for i in range(b * N, (b + 1) * N):
                ri = R_used[i, i]
                if diagonal:
                    u = ri * ri * S_inv[i, i]
                else:
                    u = 0.0
                    for j in range(m):
                        t = 0.0
                        for k in range(m):
                            t += S_inv[j, k] * R_used[k, i]
                        u += R_used[i, j] * t
                hph += ri - u
                tr += rho[i]
            val = (hph / N + avg[n + b]) / (tr / N)
            s[b] = min(max(val, s_lo), s_hi)
    return Q, s


def warm_up() -> None:
    """Compile (or load from the cache) both kernels with the argument types the rule uses."""
    n, m, W = 2, 2, 2
    R = np.eye(m)
    Rj, diag = scale_r(R, np.ones(2), 2)
    # rho is always R_prior.diagonal(): a read-only strided view
    ff_after_update(np.zeros((n, m)), np.zeros(m), np.zeros(m), Rj, R, R.diagonal(), diag,
                    np.zeros((W, n + 2)), 0, np.zeros(W), 2, np.ones(n), True, True,
                    np.ones(2), 1e-3, 1e6)
