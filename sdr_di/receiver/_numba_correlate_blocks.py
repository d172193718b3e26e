"""Block stages shared by the E/P/L correlator kernels (float32 and integer).

Both kernels (:func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_float`,
:func:`~sdr_di.receiver._numba_correlate_int.correlate_epl_int8`) cut a row's samples into
blocks of ``B`` samples and, per block, wipe the carrier off with a rotation table, split the
block where the code phase wraps, and sum the code runs; per task they add the block sums
into partial sums that are then added per row. The stages they share are here, inlined into
each kernel at numba's IR level (``inline="always"``). An inlined function keeps its own
fast-math flags, so these carry the kernels' (``reassoc``, ``contract``): without them the
float32 wipe-off was not contracted as in the kernel, and its sums differed in the last
bits. :func:`rotation_tables` makes the rows' rotation tables (a compiled function of its own,
called by :func:`~sdr_di.receiver.correlator.carrier_rotation`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(inline="always", fastmath={"reassoc", "contract"}, boundscheck=False)
def rotate_block(xs, n_comp, xo, m_end, rr, ri, buf_r, buf_i):
    """Carrier wipe-off of one block: ``buf[m] = x[xo + m] * (rr[m] + j ri[m])``,
    ``m < m_end``, in float32 (``rr``, ``ri`` the row's rotation table ``exp(-j 2 pi m
    dphi)`` or its integer rounding; ``xs`` I/Q interleaved when ``n_comp == 2``, real
    otherwise)."""
    if n_comp == 2:
        a = xs[2 * xo:2 * (xo + m_end)]
        for m in range(m_end):
            xr = np.float32(a[2 * m])
            xi = np.float32(a[2 * m + 1])
            buf_r[m] = xr * rr[m] - xi * ri[m]
            buf_i[m] = xr * ri[m] + xi * rr[m]
    else:
        a = xs[xo:xo + m_end]
        for m in range(m_end):
            xr = np.float32(a[m])
            buf_r[m] = xr * rr[m]
            buf_i[m] = xr * ri[m]


@njit(inline="always", fastmath={"reassoc", "contract"})
def code_wrap_split(th0, k0, dc, lf, m_end):
    """``(off, lim, mw)`` of the block starting at sample ``k0`` of a row (code phase
    ``th0 + k dc`` [chips], code period ``lf`` chips): the block's code phase starts in
    ``[off, lim)``, ``lim = off + lf``, and its first ``mw`` samples lie below ``lim`` (the
    rest wrap into the next period), exactly as the float64 phase of each sample says."""
    tb = th0 + k0 * dc
    off = math.floor(tb / lf) * lf
    lim = off + lf
    mw = min(max(math.ceil((lim - tb) / dc), 0), m_end)
    while mw > 0 and th0 + (k0 + mw - 1) * dc >= lim:
        mw -= 1
    while mw < m_end and th0 + (k0 + mw) * dc < lim:
        mw += 1
    return off, lim, mw


@njit(inline="always", fastmath={"reassoc", "contract"})
def add_task_parts(part, n_sub, out):
    """``out[c] = [[E.re, E.im], [P.re, P.im], [L.re, L.im]]``: the sum over row ``c``'s
    ``n_sub`` tasks of their partial sums ``part[c n_sub + s] = (E.re, E.im, P.re, ...)``."""
    for c in range(out.shape[0]):
        for j in range(3):
            out[c, j, 0] = 0.0
            out[c, j, 1] = 0.0
        for s in range(n_sub):
            t = c * n_sub + s
            for j in range(3):
                out[c, j, 0] += part[t, 2 * j]
                out[c, j, 1] += part[t, 2 * j + 1]


#: Columns between the anchors of a rotation table (:func:`rotation_tables`).
ROT_ANCHOR = 16


@njit(cache=True, nogil=True)
def rotation_tables(dphi, rot_re, rot_im):
    """``rot_re[r, m] = cos(2 pi m dphi[r])``, ``rot_im[r, m] = -sin(2 pi m dphi[r])``,
    evaluated in float64 and rounded to float32.

    With ``m = i + j``, ``i`` a multiple of ``S = ROT_ANCHOR`` and ``j < S``, the phasor is
    the float64 product of ``exp(j 2 pi i dphi)`` and ``exp(j 2 pi j dphi)`` (angle
    addition). Both factors come from two libm evaluations a row, ``exp(j 2 pi dphi)`` and
    ``exp(j 2 pi S dphi)`` on their phases reduced to ``[0, 1)`` cycles, by complex
    products in float64 (``S - 1`` steps each): 4 libm calls a row instead of 32 with
    every factor from libm (256 columns; 140 rows, one deep interval at 2.5 MHz: 0.05
    against 0.10 ms; 0.46 ms with every column from libm). Each value is within about
    1e-14 of the directly evaluated ``cos``/``sin`` of the reduced ``m dphi``; after the
    rounding to float32 about one value in 2.5 million lies one float32 ulp (6e-8 at most)
    from the directly rounded one (41 of 102 million values of random steps), and the
    integer kernel's tables (``rint(127 v)``) were equal to the directly rounded values'
    in all of them (``tests/test_receiver_correlator.py``, docs/notes/speed.md session
    29)."""
    two_pi = 2.0 * math.pi
    n = rot_re.shape[1]
    c_j = np.empty(ROT_ANCHOR)
    s_j = np.empty(ROT_ANCHOR)
    for r in range(dphi.shape[0]):
        d = dphi[r]
        rr = rot_re[r]
        ri = rot_im[r]
        a = (d - math.floor(d)) * two_pi
        c1 = math.cos(a)
        s1 = math.sin(a)
        a = d * float(ROT_ANCHOR)
        a = (a - math.floor(a)) * two_pi
        c_step = math.cos(a)
        s_step = math.sin(a)
        c_j[0] = 1.0
        s_j[0] = 0.0
        for j in range(1, ROT_ANCHOR):
            c_j[j] = c_j[j - 1] * c1 - s_j[j - 1] * s1
            s_j[j] = s_j[j - 1] * c1 + c_j[j - 1] * s1
        c_i = 1.0
        s_i = 0.0
        for i in range(0, n, ROT_ANCHOR):
            if i + ROT_ANCHOR <= n:     # a whole anchor span (a constant trip count: SIMD)
                for j in range(ROT_ANCHOR):
                    rr[i + j] = np.float32(c_i * c_j[j] - s_i * s_j[j])
                    ri[i + j] = np.float32(-(s_i * c_j[j] + c_i * s_j[j]))
            else:
                for j in range(n - i):
                    rr[i + j] = np.float32(c_i * c_j[j] - s_i * s_j[j])
                    ri[i + j] = np.float32(-(s_i * c_j[j] + c_i * s_j[j]))
            c_next = c_i * c_step - s_i * s_step
            s_i = s_i * c_step + c_i * s_step
            c_i = c_next
