"""Numba helper of the acquisition search: non-coherent power accumulation with code-Doppler
alignment (fused |R|^2, circular shift and sum; no temporaries)."""

from __future__ import annotations

from numba import njit

_CHUNK = 4096


@njit(cache=True, nogil=True)
def accumulate_power(r, shifts, acc):
    """``acc[t] += sum_b |r[b, (t - shifts[b]) mod n]|^2`` for ``t < n = acc.size``.

    Parameters
    ----------
    r : complex64 (K, >= n)
        Circular correlations of the K coherent blocks (lags 0..n-1 used).
    shifts : int64 (K,)
        Code-Doppler alignment of each block [samples] (added to the lag).
    acc : float32 (n,)
        Non-coherent sum, updated in place.
    """
    n = acc.size
    k = r.shape[0]
    n_chunks = (n + _CHUNK - 1) // _CHUNK
    for c in range(n_chunks):
        t0 = c * _CHUNK
        t1 = min(n, t0 + _CHUNK)
        for b in range(k):
            s = shifts[b] % n
            # t < s reads the tail r[b, t - s + n], t >= s reads r[b, t - s]: two plain loops
            mid = min(max(s, t0), t1)
            for t in range(t0, mid):
                v = r[b, t - s + n]
                acc[t] += v.real * v.real + v.imag * v.imag
            for t in range(mid, t1):
                v = r[b, t - s]
                acc[t] += v.real * v.real + v.imag * v.imag
