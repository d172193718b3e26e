"""Numba kernel of the filter update's block NIS (every update of every integrated run):
the numpy form, the tested reference, is :func:`sdr_di.integration.consistency.block_nis`
with ``consistency.jit = False``. The same LAPACK solve (``gesv``) through numba's
``np.linalg.solve``, without numpy's per-call checks; the two agree to an ulp (numba links
scipy's LAPACK, numpy its own)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def block_nis(y, S, n_blocks, out):
    """``out[b] = y_b^T S_bb^-1 y_b / k`` of the ``n_blocks`` equal contiguous blocks of
    ``y`` (m,) with covariance ``S`` (m, m), ``k = m / n_blocks``; when ``m`` is not a
    multiple of ``n_blocks``: ``out[0]`` of the whole ``y`` (``out`` NaN in, left NaN
    elsewhere)."""
    m = y.size
    if m == 0:
        return
    if m % n_blocks:
        out[0] = np.dot(y, np.linalg.solve(np.ascontiguousarray(S), y)) / m
        return
    k = m // n_blocks
    for b in range(n_blocks):
        a = b * k
        yb = np.ascontiguousarray(y[a:a + k])
        out[b] = np.dot(yb, np.linalg.solve(np.ascontiguousarray(S[a:a + k, a:a + k]), yb)) / k
