"""Numba kernel of the multi-channel early/prompt/late correlator (plain arrays in and out).

For channel ``c`` and sample ``k = 0 .. n_c - 1`` of its interval (input sample
``x[start_c + k]``):

* code phase ``theta_k = theta0_c + k * dchip_c`` [chips], ``theta0_c`` reduced to
  ``[0, L)`` by the caller, ``dchip_c = code rate / fs``; the replica chip is
  ``code[floor(theta_k + delta) mod L]`` for ``delta = +d`` (early), ``0`` (prompt),
  ``-d`` (late);
* carrier phase ``phi_k = phi0_c + k * dphi_c`` [cycles], ``dphi_c = f_carrier / fs``;
  the wipe-off multiplies by ``exp(-j 2 pi phi_k)``.

No phase is accumulated from sample to sample: the code phase is recomputed as
``theta0 + k * dchip`` (float64: the error is one rounding of a number below ``L + n dchip``,
about 1e-12 chip), with exact integer wraps (subtracting ``L`` from a float64 in ``[L, 2L)``
is exact). The carrier phasor is the product of a block phasor ``exp(-j 2 pi (phi0 + k0
dphi))`` computed with ``cos``/``sin`` of the exact phase at the first sample ``k0`` of each
block of ``B`` samples and a per-channel table ``exp(-j 2 pi m dphi)``, ``m < B``: float64
accuracy (~1e-15) at the cost of one complex multiply per sample.

The work is split into ``n_ch * n_sub`` tasks (channel x contiguous range of blocks) run with
``prange``; each task writes its partial sums, which are added in a fixed order, so results do
not depend on the thread count or scheduling.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True, fastmath=False)
def correlate_epl(
    x,  # complex64 (n,) or float32 (n,): input samples
    codes,  # float32 (n_ch, L + 2 M): +/-1 chips, padded: codes[c, M + i] = code[i mod L]
    pad,  # int: M, the padding (M > spacing + 1)
    code_len,  # int: L, chips per code period
    start,  # int64 (n_ch,): first input sample of each channel's interval
    nsamp,  # int64 (n_ch,): samples of each channel's interval
    theta0,  # float64 (n_ch,): code phase at the first sample [chips], in [0, L)
    dchip,  # float64 (n_ch,): code phase step [chips/sample], > 0
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
        er = 0.0
        ei = 0.0
        pr = 0.0
        pi_ = 0.0
        lr = 0.0
        li = 0.0
        for b in range(b0, b1):
            k0 = b * blk
            ph = p0 + k0 * dp
            ph -= math.floor(ph)
            cr = math.cos(two_pi * ph)
            ci = -math.sin(two_pi * ph)
            # code phase at the block start, reduced to [0, L) once per block
            wraps = math.floor((th0 + k0 * dc) / lf)
            off = wraps * lf
            m_end = min(blk, n - k0)
            for m in range(m_end):
                k = k0 + m
                th = (th0 + k * dc) - off
                if th >= lf:
                    off += lf
                    th -= lf
                # carrier phasor exp(-j 2 pi phi_k) = block phasor x table entry
                rr = rot_re[c, m]
                ri = rot_im[c, m]
                wr_ = cr * rr - ci * ri
                wi_ = cr * ri + ci * rr
                v = x[x0 + k]
                xr = v.real
                xi = v.imag
                wr = xr * wr_ - xi * wi_
                wi = xr * wi_ + xi * wr_
                ce = codes[c, pad + int(math.floor(th + spacing))]
                cp = codes[c, pad + int(math.floor(th))]
                cl = codes[c, pad + int(math.floor(th - spacing))]
                er += ce * wr
                ei += ce * wi
                pr += cp * wr
                pi_ += cp * wi
                lr += cl * wr
                li += cl * wi
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
