"""Numba E/P/L correlator kernel for low sample rates: one bit-window word per sample.

:func:`correlate_epl_gather` computes what the float32 kernel
:func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_float` computes (same arguments,
same blocks of ``B = 256`` samples, same rotation pass, block phasor, code-wrap split and
float64 code phase per sample; its module notes), with another pass 2. The float32 kernel
reads the replica chips of a *run* of samples from two bit-window words loaded once per run;
a run spans at most 124 table entries, so at ``dchip`` chips per sample it holds
``(124 - 2 d) / dchip`` samples: 256 (a whole block) at 25 MHz, but 30 at 2.5 MHz
(``dchip = 4.09``). Each run is a vectorized loop with its own set-up, vector remainder,
scalar remainder and six horizontal reductions, and at 2.5 MHz those cost more than the
samples: 3.7-4.8 ns per sample-channel against 1.3-1.6 ns at 25 MHz (7 channels, 1 ms rows,
one thread, ``scripts/bench_correlate.py``; session 23 of ``docs/notes/speed.md``).

Here every sample loads its own word: ``w = bits[c, il]`` with ``il = floor(theta + M - d)``
the late replica's table index, i.e. bit ``b`` of ``w`` is entry ``il + b`` of the padded
table, and the early and prompt chips are bits ``floor(theta + M + d) - il`` and
``floor(theta + M) - il`` (at most ``2 d + 1 < 64``). The loop over a whole block segment
(up to 256 samples, split only where the code wraps) then vectorizes with a gather of one
64-bit word per sample and no runs: 1.7-2.0 ns per sample-channel at 2.5 MHz, 1.5-1.6 at
10 MHz, but 1.8-2.3 at 25 MHz (where the float32 kernel's one run per block is cheaper than
a gather per sample). :func:`gather_kernel_pays` says where this kernel is the faster one.

**Arithmetic.** The wipe-off, the chip indices (float64 ``theta + M +- d``; the float32 kernel
adds ``M +- d - c0`` for the run's base entry ``c0``, the same chip but for a sample within
about 1e-12 chip of a chip boundary) and the float32 products are those of the float32
kernel; the float32 sums run over a block segment (up to 256 samples, as the float32 kernel's
runs do at 25 MHz) instead of a run of about 30 samples, added in float64 per block. The
sums differ from the float32 kernel's in the last float32 bits of a segment's sum (rounding
about 2e-7 of the sums' noise level, ``tests/test_receiver_correlator.py``). The float32
kernel stays the reference (``SDR_DI_CORRELATOR=float``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._numba_correlate_blocks import add_task_parts, code_wrap_split, rotate_block

#: Samples per run of the float32 kernel below which this kernel is the faster one.
_RUN_PAYS = 128
#: Table entries one run of the float32 kernel may span (its ``_SPAN``).
_FLOAT_SPAN = 124.0


def gather_kernel_pays(spacing: float, dchip_max: float) -> bool:
    """Whether :func:`correlate_epl_gather` is faster than the float32 run kernel for rows
    with code steps up to ``dchip_max`` [chips/sample] and E/L offset ``spacing`` [chips]:
    when the float32 kernel's runs, ``(124 - 2 d) / dchip`` samples, are shorter than 128
    (B3I below about 10.6 MHz at ``d = 0.5``). Measured (7 channels, 1 ms rows, one thread,
    ns per sample-channel, gather / float32): 1.97 / 3.91 at 2.5 MHz, 1.69 / 2.19 at 5 MHz,
    1.57 / 1.73 at 10 MHz, 1.8-2.3 / 1.3-1.6 at 25 MHz."""
    return dchip_max > 0.0 and (_FLOAT_SPAN - 2.0 * spacing) / dchip_max < _RUN_PAYS


@njit(cache=True, fastmath={"reassoc", "contract"}, boundscheck=False)
def _segment_sums(bw, br, bi, k, th0, dc, off, a_e, a_p, a_l):
    """E/P/L sums of one block segment: wiped samples ``br + j bi`` at interval samples
    ``k, k + 1, ..`` (code phase ``th0 + k dc - off`` [chips]), each sample's chips from its
    own bit-window word ``bw[floor(theta + a_l)]`` (``a_e``, ``a_p``, ``a_l``: the padding
    ``M`` plus ``d``, ``0``, ``-d``). Indices in float64, signs, products and sums in
    float32."""
    one = np.float32(1.0)
    s1 = np.float32(0.0)
    s2 = np.float32(0.0)
    s3 = np.float32(0.0)
    s4 = np.float32(0.0)
    s5 = np.float32(0.0)
    s6 = np.float32(0.0)
    for q in range(br.size):
        th = (th0 + (k + q) * dc) - off
        il = np.int64(th + a_l)
        # unsigned index: no negative-index wrap code in the vector loop (il >= 0 always)
        w = np.int64(bw[np.uint64(il)])
        ie = np.int64(th + a_e) - il
        ip = np.int64(th + a_p) - il
        ce = -one if (w >> ie) & 1 else one
        cp = -one if (w >> ip) & 1 else one
        cl = -one if w & 1 else one
        wr = br[q]
        wi = bi[q]
        s1 += ce * wr
        s2 += ce * wi
        s3 += cp * wr
        s4 += cp * wi
        s5 += cl * wr
        s6 += cl * wi
    return s1, s2, s3, s4, s5, s6


@njit(cache=True, nogil=True, parallel=True, fastmath={"reassoc"}, boundscheck=False)
def correlate_epl_gather(xs, n_comp, bits, tab_idx, pad, code_len, start, nsamp, theta0,
                         dchip, phi0, dphi, rot_re, rot_im, rot_idx, spacing, n_sub, out):
    """Fill ``out[r] = [[E.re, E.im], [P.re, P.im], [L.re, L.im]]`` for every row ``r``.

    Arguments, types and shapes as in :func:`~sdr_di.receiver._numba_correlate_bits.
    correlate_epl_float` (``spacing < 31``, so that the early chip lies within the late
    chip's word); the sums of a row do not depend on ``n_sub`` but for the float64
    association of whole-block sums."""
    n_rows = start.shape[0]
    blk = rot_re.shape[1]
    lf = float(code_len)
    part = np.zeros((n_rows * n_sub, 6))
    two_pi = 2.0 * math.pi
    a_e = pad + spacing
    a_p = float(pad)
    a_l = pad - spacing
    for t in prange(n_rows * n_sub):
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
        bw = bits[tab_idx[c]]
        rr = rot_re[rot_idx[c]]
        ri = rot_im[rot_idx[c]]
        buf_r = np.empty(blk, np.float32)
        buf_i = np.empty(blk, np.float32)
        acc = np.zeros(6)
        for b in range(b0, b1):
            k0 = b * blk
            m_end = min(blk, n - k0)
            xo = x0 + k0
            # pass 1: rotation (the float32 kernel's; block phasor after pass 2)
            ph = p0 + k0 * dp
            ph -= math.floor(ph)
            cr = math.cos(two_pi * ph)
            ci = -math.sin(two_pi * ph)
            rotate_block(xs, n_comp, xo, m_end, rr, ri, buf_r, buf_i)
            off, lim, mw = code_wrap_split(th0, k0, dc, lf, m_end)
            # pass 2: E/P/L sums over the segments below and above the code wrap
            g1 = 0.0
            g2 = 0.0
            g3 = 0.0
            g4 = 0.0
            g5 = 0.0
            g6 = 0.0
            if mw > 0:
                s1, s2, s3, s4, s5, s6 = _segment_sums(bw, buf_r[:mw], buf_i[:mw], k0, th0,
                                                       dc, off, a_e, a_p, a_l)
                g1 += s1
                g2 += s2
                g3 += s3
                g4 += s4
                g5 += s5
                g6 += s6
            if mw < m_end:
                s1, s2, s3, s4, s5, s6 = _segment_sums(bw, buf_r[mw:m_end], buf_i[mw:m_end],
                                                       k0 + mw, th0, dc, lim, a_e, a_p, a_l)
                g1 += s1
                g2 += s2
                g3 += s3
                g4 += s4
                g5 += s5
                g6 += s6
            # block phasor
            acc[0] += cr * g1 - ci * g2
            acc[1] += cr * g2 + ci * g1
            acc[2] += cr * g3 - ci * g4
            acc[3] += cr * g4 + ci * g3
            acc[4] += cr * g5 - ci * g6
            acc[5] += cr * g6 + ci * g5
        for j in range(6):
            part[t, j] = acc[j]
    add_task_parts(part, n_sub, out)
