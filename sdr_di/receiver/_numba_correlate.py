"""Numba kernel of the multi-channel early/prompt/late correlator (plain arrays in and out).

For channel ``c`` and sample ``k = 0 .. n_c - 1`` of its interval (input sample
``x[start_c + k]``):

* code phase ``theta_k = theta0_c + k * dchip_c`` [chips], ``theta0_c`` reduced to
  ``[0, L)`` by the caller, ``dchip_c = code rate / fs``; the replica chip is
  ``code[floor(theta_k + delta) mod L]`` for ``delta = +d`` (early), ``0`` (prompt),
  ``-d`` (late);
* carrier phase ``phi_k = phi0_c + k * dphi_c`` [cycles], ``dphi_c = f_carrier / fs``;
  the wipe-off multiplies by ``exp(-j 2 pi phi_k)``.

The interval is processed in blocks of ``B`` samples (``B = rot_re.shape[1]``, 256), each in
two passes:

1. **carrier wipe-off** into two float64 buffers (real, imaginary): the carrier phasor is the
   product of a block phasor ``exp(-j 2 pi (phi0 + k0 dphi))`` computed with ``cos``/``sin`` of
   the exact phase at the first sample ``k0`` of the block and a per-channel table
   ``exp(-j 2 pi m dphi)``, ``m < B``: float64 accuracy (~1e-15). This pass has no table
   look-ups and vectorizes.
2. **E/P/L sums** over the wiped block. No phase is accumulated from sample to sample: the code
   phase is recomputed as ``theta0 + k * dchip`` (float64), minus an integer multiple ``w L``
   of the code length fixed per block segment. The block is split where the code wraps (at
   most once per block, since ``B dchip < L`` is checked by the caller): the first sample of
   the second segment is the first ``k`` with ``theta0 + k dchip >= (w + 1) L``, found from
   ``ceil(((w + 1) L - theta_k0) / dchip)`` and corrected by evaluating that comparison, so no
   per-sample branch remains. The table index is ``int(theta + (M + delta))`` on a
   non-negative argument (``theta >= 0``, ``M > d + 1``), i.e. ``M + floor(theta + delta)``
   without a ``floor`` call. ``theta`` is exact relative to ``theta0 + k dchip`` up to the
   rounding of these additions: the chip boundaries are placed to ~1e-12 chip (one ulp of a
   float64 below ``2 L``), as before; a sample within that distance of a boundary may take
   either chip, and the periodic padding of the table keeps every index valid whichever
   segment such a sample falls in.

The E/P/L products and sums are float64 throughout; per-block sums are added into per-task
float64 totals. The kernel is compiled with the ``reassoc`` and ``contract`` fast-math flags
only (no ``nnan``/``ninf``/``arcp``), which lets LLVM vectorize the wipe-off and the six
accumulations (reordered float64 additions within a block: relative effect ~1e-15, far below
the 1e-9 the tests check) and fuse multiply-adds. Float32 buffers and float32 block sums were
measured as no faster on the development machine (AVX without AVX2: the code look-ups are
scalar either way), so the float64 accuracy is kept.

The work is split into ``n_ch * n_sub`` tasks (channel x contiguous range of whole blocks) run
with ``prange``; each block's sums do not depend on the split, each task writes its partial
sums, which are added in a fixed order, so results depend on the thread count only through the
float64 association of whole-block sums (~1e-16 relative), not on scheduling.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True, fastmath={"reassoc", "contract"}, boundscheck=False)
def correlate_epl(
    x,  # complex64 (n,) or float32 (n,): input samples
    codes,  # float32 (n_ch, L + 2 M): +/-1 chips, padded: codes[c, M + i] = code[i mod L]
    pad,  # int: M, the padding (M > spacing + 1)
    code_len,  # int: L, chips per code period
    start,  # int64 (n_ch,): first input sample of each channel's interval
    nsamp,  # int64 (n_ch,): samples of each channel's interval
    theta0,  # float64 (n_ch,): code phase at the first sample [chips], in [0, L)
    dchip,  # float64 (n_ch,): code phase step [chips/sample], > 0, B * dchip < L
    phi0,  # float64 (n_ch,): carrier phase at the first sample [cycles], in [0, 1)
    dphi,  # float64 (n_ch,): carrier phase step [cycles/sample]
    rot_re,  # float64 (n_ch, B): cos(2 pi m dphi)
    rot_im,  # float64 (n_ch, B): -sin(2 pi m dphi)
    spacing,  # float64: early/late offset d [chips]
    n_sub,  # int: tasks per channel
    out,  # float64 (n_ch, 3, 2): E, P, L real/imag (written)
):
    """Fill ``out[c] = [[E.re, E.im], [P.re, P.im], [L.re, L.im]]`` for every channel."""
    n_ch = codes.shape[0]
    blk = rot_re.shape[1]
    lf = float(code_len)
    part = np.zeros((n_ch * n_sub, 6))
    two_pi = 2.0 * math.pi
    # table offsets of the early, prompt and late replicas: index = int(theta + a)
    a_e = pad + spacing
    a_p = float(pad)
    a_l = pad - spacing
    for t in prange(n_ch * n_sub):
        c = t // n_sub
        s = t - c * n_sub
        n = nsamp[c]
        nblk = (n + blk - 1) // blk
        b0 = (s * nblk) // n_sub
        b1 = ((s + 1) * nblk) // n_sub
        x0 = start[c]
        th0 = theta0[c]
        dc = dchip[c]
        p0 = phi0[c]
        dp = dphi[c]
        code = codes[c]
        rr = rot_re[c]
        ri = rot_im[c]
        buf_r = np.empty(blk)
        buf_i = np.empty(blk)
        er = 0.0
        ei = 0.0
        pr = 0.0
        pi_ = 0.0
        lr = 0.0
        li = 0.0
        for b in range(b0, b1):
            k0 = b * blk
            m_end = min(blk, n - k0)
            xo = x0 + k0
            # pass 1: carrier wipe-off, exp(-j 2 pi phi_k) = block phasor x table entry
            ph = p0 + k0 * dp
            ph -= math.floor(ph)
            cr = math.cos(two_pi * ph)
            ci = -math.sin(two_pi * ph)
            for m in range(m_end):
                wr_ = cr * rr[m] - ci * ri[m]
                wi_ = cr * ri[m] + ci * rr[m]
                v = x[xo + m]
                xr = v.real
                xi = v.imag
                buf_r[m] = xr * wr_ - xi * wi_
                buf_i[m] = xr * wi_ + xi * wr_
            # code phase at the block start in [w L, (w + 1) L); split at (w + 1) L
            tb = th0 + k0 * dc
            off = math.floor(tb / lf) * lf
            lim = off + lf
            mw = int(math.ceil((lim - tb) / dc))
            if mw < 0:
                mw = 0
            if mw > m_end:
                mw = m_end
            while mw > 0 and th0 + (k0 + mw - 1) * dc >= lim:
                mw -= 1
            while mw < m_end and th0 + (k0 + mw) * dc < lim:
                mw += 1
            # pass 2: E/P/L sums of the block, before and after the wrap
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            s4 = 0.0
            s5 = 0.0
            s6 = 0.0
            for m in range(mw):
                th = (th0 + (k0 + m) * dc) - off
                ce = code[int(th + a_e)]
                cp = code[int(th + a_p)]
                cl = code[int(th + a_l)]
                wr = buf_r[m]
                wi = buf_i[m]
                s1 += ce * wr
                s2 += ce * wi
                s3 += cp * wr
                s4 += cp * wi
                s5 += cl * wr
                s6 += cl * wi
            for m in range(mw, m_end):
                th = (th0 + (k0 + m) * dc) - lim
                ce = code[int(th + a_e)]
                cp = code[int(th + a_p)]
                cl = code[int(th + a_l)]
                wr = buf_r[m]
                wi = buf_i[m]
                s1 += ce * wr
                s2 += ce * wi
                s3 += cp * wr
                s4 += cp * wi
                s5 += cl * wr
                s6 += cl * wi
            er += s1
            ei += s2
            pr += s3
            pi_ += s4
            lr += s5
            li += s6
        part[t, 0] = er
        part[t, 1] = ei
        part[t, 2] = pr
        part[t, 3] = pi_
        part[t, 4] = lr
        part[t, 5] = li
    for c in range(n_ch):
        for j in range(3):
            out[c, j, 0] = 0.0
            out[c, j, 1] = 0.0
        for s in range(n_sub):
            t = c * n_sub + s
            for j in range(3):
                out[c, j, 0] += part[t, 2 * j]
                out[c, j, 1] += part[t, 2 * j + 1]
