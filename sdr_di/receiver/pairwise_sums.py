"""Sums in numba kernels in numpy's order, so that a kernel's values equal its numpy
reference's bit for bit.

numpy adds a contiguous float array by pairwise summation (``np.add.reduce``, ``x.sum()``):
below 8 values one after the other from -0.0; up to 128 values in 8 running partial sums
(every 8th value), combined as ``((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))``, then
the remainder; above 128 the two halves (the first a multiple of 8 long) summed alike and
added. Complex arrays are summed as their interleaved real and imaginary parts, so the same
rule runs on 4 complex values per block of 8 reals (the real parts in ``r0, r2, r4, r6``).
``np.add.reduceat`` starts each segment from its first value and adds the pairwise sum of
the rest; ``np.add.reduce`` adds the pairwise sum to its identity, 0.0 (so a sum of
negative zeros is +0.0 there and -0.0 in a segment of ``reduceat``). (numpy 2.x; ``tests/test_deep_channel_tests.py`` checks these against numpy.)

The halves are walked with an explicit stack, not by recursion: numba's cache does not
reload a recursive kernel called from another (a segmentation fault on the second run).
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: numpy's block of the pairwise summation (``PW_BLOCKSIZE``) [values].
_BLOCK = 128


@njit(cache=True, boundscheck=False)
def _leaf(a, lo, n, squares):
    """One leaf of the pairwise sum of floats (``n <= 128``), of the values or their
    squares."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += a[i] * a[i] if squares else a[i]
        return res
    if squares:
        r0, r1, r2, r3 = a[lo] * a[lo], a[lo + 1] * a[lo + 1], a[lo + 2] * a[lo + 2], \
            a[lo + 3] * a[lo + 3]
        r4, r5, r6, r7 = a[lo + 4] * a[lo + 4], a[lo + 5] * a[lo + 5], \
            a[lo + 6] * a[lo + 6], a[lo + 7] * a[lo + 7]
    else:
        r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
        r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        j = lo + i
        if squares:
            r0 += a[j] * a[j]
            r1 += a[j + 1] * a[j + 1]
            r2 += a[j + 2] * a[j + 2]
            r3 += a[j + 3] * a[j + 3]
            r4 += a[j + 4] * a[j + 4]
            r5 += a[j + 5] * a[j + 5]
            r6 += a[j + 6] * a[j + 6]
            r7 += a[j + 7] * a[j + 7]
        else:
            r0 += a[j]
            r1 += a[j + 1]
            r2 += a[j + 2]
            r3 += a[j + 3]
            r4 += a[j + 4]
            r5 += a[j + 5]
            r6 += a[j + 6]
            r7 += a[j + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        j = lo + i
        res += a[j] * a[j] if squares else a[j]
        i += 1
    return res


@njit(cache=True, boundscheck=False)
def _leaf_complex(a, lo, n):
    """One leaf of the pairwise sum of complex values (``n <= 64``)."""
    if n < 4:
        rr = -0.0
        ri = -0.0
        for i in range(lo, lo + n):
            rr += a[i].real
            ri += a[i].imag
        return complex(rr, ri)
    r0, r1, r2, r3 = a[lo].real, a[lo].imag, a[lo + 1].real, a[lo + 1].imag
    r4, r5, r6, r7 = a[lo + 2].real, a[lo + 2].imag, a[lo + 3].real, a[lo + 3].imag
    i = 4
    while i < n - n % 4:
        j = lo + i
        r0 += a[j].real
        r1 += a[j].imag
        r2 += a[j + 1].real
        r3 += a[j + 1].imag
        r4 += a[j + 2].real
        r5 += a[j + 2].imag
        r6 += a[j + 3].real
        r7 += a[j + 3].imag
        i += 4
    rr = (r0 + r2) + (r4 + r6)
    ri = (r1 + r3) + (r5 + r7)
    while i < n:
        rr += a[lo + i].real
        ri += a[lo + i].imag
        i += 1
    return complex(rr, ri)


@njit(cache=True, boundscheck=False)
def _halves(m, values):
    """Length of the first half of ``m`` values split by the pairwise sum: half of ``m``
    less its remainder of 8 (``values``: 1 float, 2 complex of 2 interleaved reals)."""
    if values == 2:
        return (m - m % 8) // 2
    h = m // 2
    return h - h % 8


@njit(cache=True, boundscheck=False)
def _walk(a, lo, n, squares):
    """The pairwise sum of floats above one leaf: the halves depth first, left before
    right, each pair added as it completes (numpy's recursion)."""
    node_lo = np.empty(64, np.int64)
    node_n = np.empty(64, np.int64)
    stage = np.zeros(64, np.int64)
    vals = np.empty(64)
    sp, vp = 0, 0
    node_lo[0], node_n[0] = lo, n
    while sp >= 0:
        m = node_n[sp]
        if m <= _BLOCK:
            vals[vp] = _leaf(a, node_lo[sp], m, squares)
            vp += 1
            sp -= 1
        elif stage[sp] < 2:
            h = _halves(m, 1)
            node_lo[sp + 1] = node_lo[sp] + (h if stage[sp] else 0)
            node_n[sp + 1] = m - h if stage[sp] else h
            stage[sp + 1] = 0
            stage[sp] += 1
            sp += 1
        else:
            vals[vp - 2] = vals[vp - 2] + vals[vp - 1]
            vp -= 1
            sp -= 1
    return vals[0]


@njit(cache=True, boundscheck=False)
def _walk_complex(a, lo, n):
    """:func:`_walk` of complex values (leaves of up to 64). (A second walker, not one with
    a flag: numba types both branches of a flag, and a float leaf of complex values, or a
    float stack of complex sums, does not type.)"""
    node_lo = np.empty(64, np.int64)
    node_n = np.empty(64, np.int64)
    stage = np.zeros(64, np.int64)
    vals = np.empty(64, np.complex128)
    sp, vp = 0, 0
    node_lo[0], node_n[0] = lo, n
    while sp >= 0:
        m = node_n[sp]
        if m <= _BLOCK // 2:
            vals[vp] = _leaf_complex(a, node_lo[sp], m)
            vp += 1
            sp -= 1
        elif stage[sp] < 2:
            h = _halves(m, 2)
            node_lo[sp + 1] = node_lo[sp] + (h if stage[sp] else 0)
            node_n[sp + 1] = m - h if stage[sp] else h
            stage[sp + 1] = 0
            stage[sp] += 1
            sp += 1
        else:
            x, y = vals[vp - 2], vals[vp - 1]
            vals[vp - 2] = complex(x.real + y.real, x.imag + y.imag)
            vp -= 1
            sp -= 1
    return vals[0]


@njit(cache=True, boundscheck=False)
def pairwise_sum(a, lo, n):
    """``np.add.reduce(a[lo:lo + n])`` of a float64 array, bit for bit (module notes)."""
    return 0.0 + (_leaf(a, lo, n, False) if n <= _BLOCK else _walk(a, lo, n, False))


@njit(cache=True, boundscheck=False)
def pairwise_sum_squares(a, lo, n):
    """``np.add.reduce(a[lo:lo + n] * a[lo:lo + n])`` of a float64 array, bit for bit."""
    return 0.0 + (_leaf(a, lo, n, True) if n <= _BLOCK else _walk(a, lo, n, True))


@njit(cache=True, boundscheck=False)
def pairwise_sum_complex(a, lo, n):
    """``np.add.reduce(a[lo:lo + n])`` of a complex128 array, bit for bit (module notes)."""
    s = _leaf_complex(a, lo, n) if n <= _BLOCK // 2 else _walk_complex(a, lo, n)
    return complex(0.0 + s.real, 0.0 + s.imag)


@njit(cache=True, boundscheck=False)
def segment_sum_complex(a, lo, n):
    """One segment of ``np.add.reduceat`` of a complex128 array, ``a[lo:lo + n]`` (n >= 1):
    its first value plus the pairwise sum of the rest, bit for bit."""
    m = n - 1
    s = _leaf_complex(a, lo + 1, m) if m <= _BLOCK // 2 else _walk_complex(a, lo + 1, m)
    return complex(a[lo].real + s.real, a[lo].imag + s.imag)


@njit(cache=True, boundscheck=False)
def segment_sum(a, lo, n):
    """One segment of ``np.add.reduceat`` of a float64 array, ``a[lo:lo + n]`` (n >= 1): its
    first value plus the pairwise sum of the rest, bit for bit."""
    m = n - 1
    return a[lo] + (_leaf(a, lo + 1, m, False) if m <= _BLOCK else _walk(a, lo + 1, m, False))
