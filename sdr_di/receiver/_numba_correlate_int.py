"""Numba kernel of the E/P/L correlator on integer (``int8``) samples: integer arithmetic.

Same interface, blocks, code-wrap split and block phasor as the float32 kernel
(:func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_float`, module notes there);
:func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_bits` chooses this one for
``int8`` samples when its runs hold at least 64 samples (:func:`int_kernel_pays`: B3I at
11 MHz or more). Every integer format of :mod:`~sdr_di.io.sample_formats` except the 16-bit
ones reaches the receiver as ``int8`` (the 2/3/4-bit formats unpacked by table). What
differs, per task (row x range of blocks):

* **Integer rotation table.** The row's float32 table ``exp(-j 2 pi m dphi)``, ``m < B``, is
  rounded once to integers ``qr_m = rint(S cos)``, ``qi_m = rint(-S sin)`` with
  ``S = ROT_SCALE = 127``: an amplitude quantization of the exact phasors (each component
  within 1/(2 S) of the exact value), not a coarse phase table, so the carrier phase error is
  at most ``1 / (sqrt(2) S)`` rad (0.32 degree) and about 0.0023 rad rms. The block phasor
  stays float64 (exact every ``PHASOR_REFRESH`` blocks, advanced by a float64 rotation in
  between), so no phase error accumulates.
* **Integer wipe-off.** ``wr = xr qr - xi qi``, ``wi = xr qi + xi qr`` (real input:
  ``xr qr``, ``xr qi``); with ``|x| <= 128`` and ``|q| <= 127`` every value is an integer
  within ``2 * 128 * 127 = 32512``.
* **Code as sign flips** from **32-bit bit windows** (the low 32 bits of the
  :func:`~sdr_di.receiver.correlator.bit_windows` words at the run's lowest entry and 32
  entries on: a run spans at most ``_SPAN = 60`` entries), so the shifts use 16 lanes.
* **Code index in fixed point.** Within a run the E/P/L table indices are
  ``(e0 + q st) >> 23`` (int32), ``e0 = floor((theta_run + a) 2^23)`` computed in float64 at
  the run's first sample, ``st = round(dchip 2^23)``: a chip boundary is placed within
  ``q / 2^24 + 2^-23`` chip of the float64 one (``q < 256`` the sample's place in its run:
  at most 1.5e-5 chip, 0.45 mm of range, four orders of magnitude below the thermal
  code-phase noise).
* **Integer sums, carried in float32 lanes.** A run's six E/P/L sums have at most 256 terms
  of at most 32512, so every partial sum is an integer below 2^24: float32 holds each exactly
  whatever the order of the additions, and the sums equal the integer sums bit for bit. They
  go to the block's int64 sums, which are multiplied by the float64 block phasor and divided
  by ``S``: the returned sums are in input units x samples, as the float kernel's. (numba
  types ``int16 * int16`` as int64, and int16/int32 loops measured slower than float32
  lanes carrying the same integers: ``docs/notes/correlator.md``.)

Loss against the float path (quantized phasor): the rounding adds to each wiped sample an
error of relative power ``2 / (12 S^2) = 5.2e-6`` (uncorrelated with the code), i.e. an SNR
loss of about ``2.3e-5 dB``; paired runs over 4 seeds: ``docs/notes/correlator.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ._numba_correlate_blocks import add_task_parts, code_wrap_split, rotate_block

#: Scale of the integer rotation table (products with int8 samples stay within 2^15).
ROT_SCALE = 127
#: Fractional bits of the fixed-point code index within a run.
FRAC_BITS = 23
#: Blocks between exact evaluations of the block phasor (advanced by a float64 rotation in
#: between: a relative error below 16 * 2^-52, 4e-15).
PHASOR_REFRESH = 16
#: Entries of the padded table one run may span (two 32-bit words, minus a safety margin).
_SPAN = 60.0


@njit(cache=True)
def run_length(spacing, dc):
    """Samples per run: the most whose E/P/L indices span at most ``_SPAN`` table entries
    (``(_SPAN - 2 d) / dchip``), rounded down to a multiple of 64 when at least 64, so the
    vectorized sum loop (16 float32 lanes, unrolled 4 times) leaves no scalar remainder in
    full runs (0.90 -> 0.80 ns per sample-channel at 25 MHz)."""
    run = max(int((_SPAN - 2.0 * spacing) / dc), 1)
    if run >= 64:
        run -= run % 64
    return run


def int_kernel_pays(spacing: float, dchip_max: float) -> bool:
    """Whether this kernel is faster than the float32 one for rows with code steps up to
    ``dchip_max`` [chips/sample] and E/L offset ``spacing`` [chips]: its runs (at most
    ``_SPAN = 60`` table entries, against the float kernel's 124) must hold at least 64
    samples. Shorter runs cost more in per-run set-up and sum reductions than the integer
    index saves: 7 channels, 1 ms rows, one thread, ``scripts/bench.py correlate``: 0.83 -
    1.03 against 1.12 - 1.29 ns per sample-channel at 25 MHz (runs of 128), but 3.7 against
    2.9 ns at 2.5 MHz (runs of 14)."""
    return run_length(spacing, dchip_max) >= 64


@njit(cache=True, fastmath={"reassoc", "contract"}, boundscheck=False)
def _run_sums_int(lo, hi, br, bi, e0, p0, l0, st):
    """E/P/L sums of one run: wiped samples ``br + j bi`` (integer values in float32),
    fixed-point table indices ``(x0 + q st) >> FRAC_BITS`` (int32) relative to the run's
    lowest entry, replica bits in the 32-bit words ``lo``, ``hi``; the sums are integers
    below 2^24, exact in float32."""
    one = np.float32(1.0)
    s1 = np.float32(0.0)
    s2 = np.float32(0.0)
    s3 = np.float32(0.0)
    s4 = np.float32(0.0)
    s5 = np.float32(0.0)
    s6 = np.float32(0.0)
    for q in range(br.size):
        dq = np.int32(np.int32(q) * st)
        ie = np.int32(np.int32(e0 + dq) >> FRAC_BITS)
        ip = np.int32(np.int32(p0 + dq) >> FRAC_BITS)
        il = np.int32(np.int32(l0 + dq) >> FRAC_BITS)
        we = lo if ie < 32 else hi
        wp = lo if ip < 32 else hi
        wl = lo if il < 32 else hi
        ce = -one if np.int32(we >> np.int32(ie & 31)) & 1 else one
        cp = -one if np.int32(wp >> np.int32(ip & 31)) & 1 else one
        cl = -one if np.int32(wl >> np.int32(il & 31)) & 1 else one
        wr = br[q]
        wi = bi[q]
        s1 += ce * wr
        s2 += ce * wi
        s3 += cp * wr
        s4 += cp * wi
        s5 += cl * wr
        s6 += cl * wi
    return s1, s2, s3, s4, s5, s6


@njit(cache=True, nogil=True, parallel=True, fastmath={"reassoc", "contract"},
      boundscheck=False)
def correlate_epl_int8(xs, n_comp, bits, tab_idx, pad, code_len, start, nsamp, theta0, dchip,
                       phi0, dphi, rot_re, rot_im, rot_idx, spacing, n_sub, out):
    """Fill ``out[r] = [[E.re, E.im], [P.re, P.im], [L.re, L.im]]`` for every row ``r`` from
    ``int8`` samples ``xs``; arguments as
    :func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_float` (module notes)."""
    n_rows = start.shape[0]
    blk = rot_re.shape[1]
    lf = float(code_len)
    part = np.zeros((n_rows * n_sub, 6))
    two_pi = 2.0 * math.pi
    fscale = float(1 << FRAC_BITS)
    a_e = pad + spacing
    a_p = float(pad)
    a_l = pad - spacing
    inv_s = 1.0 / ROT_SCALE
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
        qr = np.empty(blk, np.float32)
        qi = np.empty(blk, np.float32)
        for m in range(blk):
            qr[m] = np.float32(np.rint(ROT_SCALE * np.float64(rr[m])))
            qi[m] = np.float32(np.rint(ROT_SCALE * np.float64(ri[m])))
        st = np.int32(round(dc * fscale))
        run = run_length(spacing, dc)
        buf_r = np.empty(blk, np.float32)
        buf_i = np.empty(blk, np.float32)
        acc = np.zeros(6)
        # block phasor step exp(-j 2 pi B dphi); the phasor is recomputed exactly every
        # PHASOR_REFRESH blocks and advanced by this step in between
        sp = blk * dp
        sp -= math.floor(sp)
        sr = math.cos(two_pi * sp)
        si = -math.sin(two_pi * sp)
        cr = 1.0
        ci = 0.0
        for b in range(b0, b1):
            k0 = b * blk
            m_end = min(blk, n - k0)
            xo = x0 + k0
            if (b - b0) % PHASOR_REFRESH == 0:
                ph = p0 + k0 * dp
                ph -= math.floor(ph)
                cr = math.cos(two_pi * ph)
                ci = -math.sin(two_pi * ph)
            else:
                cr, ci = cr * sr - ci * si, cr * si + ci * sr
            rotate_block(xs, n_comp, xo, m_end, qr, qi, buf_r, buf_i)
            off, lim, mw = code_wrap_split(th0, k0, dc, lf, m_end)
            g1 = 0
            g2 = 0
            g3 = 0
            g4 = 0
            g5 = 0
            g6 = 0
            m = 0
            while m < m_end:
                seg_off = off if m < mw else lim
                m2 = min(m + run, mw if m < mw else m_end)
                th_first = (th0 + (k0 + m) * dc) - seg_off
                c0 = int(th_first + a_l)
                lo = np.int32(np.int64(bw[c0]))       # entries c0 .. c0 + 31
                hi = np.int32(np.int64(bw[c0 + 32]))  # entries c0 + 32 .. c0 + 63
                base = th_first - float(c0)
                e0 = np.int32(math.floor((base + a_e) * fscale))
                p0i = np.int32(math.floor((base + a_p) * fscale))
                l0 = np.int32(math.floor((base + a_l) * fscale))
                s1, s2, s3, s4, s5, s6 = _run_sums_int(lo, hi, buf_r[m:m2], buf_i[m:m2],
                                                       e0, p0i, l0, st)
                g1 += np.int64(s1)
                g2 += np.int64(s2)
                g3 += np.int64(s3)
                g4 += np.int64(s4)
                g5 += np.int64(s5)
                g6 += np.int64(s6)
                m = m2
            # block phasor (float64; the integer block sums are exact in float64)
            acc[0] += cr * float(g1) - ci * float(g2)
            acc[1] += cr * float(g2) + ci * float(g1)
            acc[2] += cr * float(g3) - ci * float(g4)
            acc[3] += cr * float(g4) + ci * float(g3)
            acc[4] += cr * float(g5) - ci * float(g6)
            acc[5] += cr * float(g6) + ci * float(g5)
        for j in range(6):
            part[t, j] = acc[j] * inv_s
    add_task_parts(part, n_sub, out)
