"""Numba kernel of the receiver's multi-channel early/prompt/late correlator.

The scalar receiver's channel bank, acquisition refinement, the deep (vector) loop and the
public API of :mod:`~sdr_di.receiver.correlator` (:func:`~sdr_di.receiver.correlator.
correlate_table`, ``correlate``, ``Correlator``) all call :func:`correlate_epl_bits`, which
runs the float32 kernel :func:`correlate_epl_float` described here, or, for ``int8``
samples, its integer twin :func:`~sdr_di.receiver._numba_correlate_int.correlate_epl_int8`
(same blocks, runs, bit windows and block phasor; int16 wipe-off with a rounded rotation
table, sign-flip code, int32 sums: its module notes), and, at low sample rates (B3I below
about 10.6 MHz, whatever the sample type), its low-rate twin
:func:`~sdr_di.receiver._numba_correlate_gather.correlate_epl_gather` (one bit-window word
per sample instead of runs, which are about 30 samples long at 2.5 MHz: its module notes).
:data:`INTEGER_PATH` and :data:`GATHER_PATH` (environment ``SDR_DI_CORRELATOR=float``)
force the float32 kernel as the reference. Plain arrays in and out; the NCO values are given
per row.

For row ``r`` and sample ``k = 0 .. n_r - 1`` of its interval (sample ``start_r + k``):

* code phase ``theta_k = theta0_r + k * dchip_r`` [chips], ``theta0_r`` reduced to
  ``[0, L)`` by the caller, ``dchip_r = code rate / fs``; the replica chip is
  ``code[floor(theta_k + delta) mod L]`` for ``delta = +d`` (early), ``0`` (prompt),
  ``-d`` (late);
* carrier phase ``phi_k = phi0_r + k * dphi_r`` [cycles], ``dphi_r = f_carrier / fs``; the
  wipe-off multiplies by ``exp(-j 2 pi phi_k)``.

The interval is processed in blocks of ``B`` samples (``B = rot_re.shape[1]``, 256), each in
two passes:

1. **Rotation** into two float32 buffers (real, imaginary): the samples times the float32
   rotation table entries ``exp(-j 2 pi m dphi)``, ``m < B`` (one row per carrier step,
   computed in float64 and rounded by the caller). No table look-ups; this pass vectorizes.
   The block phasor ``exp(-j 2 pi (phi0 + k0 dphi))`` (float64 ``cos``/``sin`` of the exact
   phase at the block's first sample ``k0``) multiplies the block's six E/P/L sums after
   pass 2, in float64, so the carrier phase never accumulates an error from block to block.
2. **E/P/L sums** over the block. No phase is accumulated from sample to sample: the code
   phase is recomputed as ``theta0 + k * dchip`` (float64), minus an integer multiple ``w L``
   of the code length fixed per block segment. The block is split where the code wraps (at
   most once per block, since ``B dchip < L`` is checked by the caller): the first sample of
   the second segment is the first ``k`` with ``theta0 + k dchip >= (w + 1) L``, found from
   ``ceil(((w + 1) L - theta_k0) / dchip)`` and corrected by evaluating that comparison. The
   chip boundaries are placed to ~1e-12 chip (one ulp of a float64 below ``2 L``); a sample
   within that distance of a boundary may take either chip, and the periodic padding of the
   table keeps every index valid whichever segment such a sample falls in.

* **Input**: the samples as stored, 1-D ``int8``/``int16``/``float32``/``float64`` with
  ``n_comp = 2`` (interleaved I, Q) or ``n_comp = 1`` (real), read through per-block slices
  (contiguous loads the wipe-off loop vectorizes; ``int8``/``int16`` and float32 convert
  exactly to float32, float64 samples are rounded to float32). ``complex64`` / ``complex128``
  data are passed as their ``float32`` / ``float64`` view with ``n_comp = 2`` (no copy).
* **Replicas as bit windows** (:func:`pack_bit_windows`, through
  :func:`~sdr_di.receiver.correlator.bit_windows`): ``bits[c, j]`` holds, in bit ``b``,
  whether entry ``j + b`` of the channel's padded table (``codes[c, M + i] = code[i mod L]``)
  is ``-1``. For a run of samples whose E/P/L indices stay within 128 entries of the run's
  lowest index ``c0`` (runs of at most ``(124 - 2 d) / dchip`` samples: 256 at 25 MHz), the
  two words ``bits[c, c0]`` and ``bits[c, c0 + 64]`` hold every chip the run needs, and the
  replica value of index ``j`` is a shift and a select on them: no per-sample memory gather,
  and the loop vectorizes. The window can never read outside the table whatever the phase
  (``& 63`` and the select keep every shift in range). The index of the early replica is
  ``int(theta + (M + d - c0))``, i.e. ``M + floor(theta + d) - c0`` on a non-negative
  argument (``theta >= 0``, ``M > d + 1``) without a ``floor`` call.
* **Shared tables**: each row names its replica row (``tab_idx``) and rotation-table row
  (``rot_idx``), so the epochs of one channel share one of each (no repeated copies).

**Precision.** The code phase and the chip indices are float64 arithmetic (chip boundaries
to ~1e-12 chip, as above); the wipe-off products, the replica signs and the sums over a run
(at most ``B`` samples) are float32, and the run sums are added in float64 (block sums, block
phasor, interval sums). A float32 product or run sum has a relative rounding of at most
``2^-24`` (6e-8) per operation, so a row's sums carry a rounding error of about 2e-7 of their
noise level (``sqrt(n)`` times the sample's standard deviation; measured on random data,
``tests/test_receiver_correlator.py``), millions of times below the thermal noise that every
tracking loop, C/N0 estimator and discriminator already sees. float32 doubles the vector lanes
of the wipe-off and the sums: 1.27 against 1.70 ns per sample and channel on one thread of
an Intel Xeon (AVX-512; session 8, same run shape as below), where the kernel was float64
throughout before. The kernel is compiled with the ``reassoc`` fast-math flag only (no
``nnan``/``ninf``/``arcp``), which lets LLVM vectorize the loops; :func:`_run_sums` also has
``contract`` (fused multiply-adds). The kernel itself had ``contract`` too, until it turned
out that LLVM then fused differently in the code numba runs after compiling and in the code
it writes to its cache: a run that compiled the kernel (the first after an install or a
change) gave other sums in the last float32 bits than every later run, and the deep
receiver's outputs on the 40 s default file differed from the second row on
(``tests/test_receiver_correlator.py::test_kernels_compiled_here_equal_the_cached_ones``;
the int8 kernel gives the same sums either way and keeps the flag; :func:`mean_power` dropped
it too, for float64 samples). Without it the kernel is 0-7 % slower (25 MHz, one thread;
no difference at 2.5 MHz). The work is split into ``n_rows * n_sub`` tasks (row x
contiguous range of whole blocks) run with ``prange``; each task writes its partial sums,
which are added in a fixed order, so results depend on the thread count only through the
float64 association of whole-block sums (~1e-16 relative), not on scheduling.

Speed of the float64 kernel (development machine, AMD EPYC with AVX-512; 7 channels at
25 MHz, one thread, thread CPU time on the shared machine): 1.35-1.5 ns per sample and
channel, about 2x faster than the
earlier kernel that indexed a float32 replica table per sample and wiped ``complex64`` samples
(~3.1 ns; removed). Measured alternatives that were not faster: a half-chip bit table (one
index per sample instead of three), single-word windows (runs of ~60 chips, no word select),
float64 replica tables indexed per sample (1.6-1.9 ns for the sums alone).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from ..settings import integer_correlator
from ._numba_correlate_blocks import add_task_parts, code_wrap_split, rotate_block
from ._numba_correlate_gather import correlate_epl_gather, gather_kernel_pays
from ._numba_correlate_int import correlate_epl_int8, int_kernel_pays


#: Use the integer kernel (:mod:`~sdr_di.receiver._numba_correlate_int`) for ``int8``
#: samples. Environment ``SDR_DI_CORRELATOR=float`` (read at import,
#: :func:`sdr_di.settings.integer_correlator`) or setting this and :data:`GATHER_PATH` to
#: False forces the float32 kernel for every input (the reference path).
INTEGER_PATH = integer_correlator()
#: Use the low-rate kernel (:mod:`~sdr_di.receiver._numba_correlate_gather`) where its
#: runs would be short (:func:`~sdr_di.receiver._numba_correlate_gather.
#: gather_kernel_pays`); ``SDR_DI_CORRELATOR=float`` sets it False, as it does
#: :data:`INTEGER_PATH`.
GATHER_PATH = INTEGER_PATH

#: Entries of the padded table one run may span (two 64-bit words, minus a safety margin).
_SPAN = 124.0


@njit(cache=True, fastmath={"reassoc", "contract"}, boundscheck=False)
def _run_sums(lo, hi, br, bi, k, th0, dc, off, ae, ap, al):
    """E/P/L sums of one run: wiped samples ``br + j bi`` at interval samples ``k, k + 1, ..``
    (code phase ``th0 + k dc - off``), replica bits in the words ``lo``, ``hi``; indices
    relative to the run's lowest table index (offsets ``ae``, ``ap``, ``al``). The indices
    are float64 arithmetic; the replica signs, products and sums are float32."""
    one = np.float32(1.0)
    s1 = np.float32(0.0)
    s2 = np.float32(0.0)
    s3 = np.float32(0.0)
    s4 = np.float32(0.0)
    s5 = np.float32(0.0)
    s6 = np.float32(0.0)
    for q in range(br.size):
        th = (th0 + (k + q) * dc) - off
        ie = np.int64(th + ae)
        ip = np.int64(th + ap)
        il = np.int64(th + al)
        we = lo if ie < 64 else hi
        wp = lo if ip < 64 else hi
        wl = lo if il < 64 else hi
        ce = -one if (we >> (ie & 63)) & 1 else one
        cp = -one if (wp >> (ip & 63)) & 1 else one
        cl = -one if (wl >> (il & 63)) & 1 else one
        wr = br[q]
        wi = bi[q]
        s1 += ce * wr
        s2 += ce * wi
        s3 += cp * wr
        s4 += cp * wi
        s5 += cl * wr
        s6 += cl * wi
    return s1, s2, s3, s4, s5, s6


def correlate_epl_bits(xs, n_comp, bits, tab_idx, pad, code_len, start, nsamp, theta0, dchip,
                       phi0, dphi, rot_re, rot_im, rot_idx, spacing, n_sub, out) -> None:
    """E/P/L sums of every row into ``out`` (arguments: :func:`correlate_epl_float`).

    Runs the integer kernel :func:`~sdr_di.receiver._numba_correlate_int.correlate_epl_int8`
    for ``int8`` samples when :data:`INTEGER_PATH` is set (the default) and every row's runs
    are long enough for it to be the faster one (:func:`~sdr_di.receiver.
    _numba_correlate_int.int_kernel_pays`: code step at most about 0.9 chip per sample, i.e.
    B3I sampled at 11 MHz or more), the low-rate kernel :func:`~sdr_di.receiver.
    _numba_correlate_gather.correlate_epl_gather` for any samples when :data:`GATHER_PATH`
    is set and some row's code step is above about 0.96 chip per sample (B3I below about
    10.6 MHz: :func:`~sdr_di.receiver._numba_correlate_gather.gather_kernel_pays`), else the
    float32 kernel :func:`correlate_epl_float`."""
    dchip_max = float(dchip.max()) if dchip.size else 0.0
    if INTEGER_PATH and xs.dtype == np.int8 and dchip.size and int_kernel_pays(spacing,
                                                                               dchip_max):
        correlate_epl_int8(xs, n_comp, bits, tab_idx, pad, code_len, start, nsamp, theta0,
                           dchip, phi0, dphi, rot_re, rot_im, rot_idx, spacing, n_sub, out)
    elif GATHER_PATH and gather_kernel_pays(spacing, dchip_max):
        correlate_epl_gather(xs, n_comp, bits, tab_idx, pad, code_len, start, nsamp, theta0,
                             dchip, phi0, dphi, rot_re, rot_im, rot_idx, spacing, n_sub, out)
    else:
        correlate_epl_float(xs, n_comp, bits, tab_idx, pad, code_len, start, nsamp, theta0,
                            dchip, phi0, dphi, rot_re, rot_im, rot_idx, spacing, n_sub, out)


@njit(cache=True, nogil=True, parallel=True, fastmath={"reassoc"},
      boundscheck=False)
def correlate_epl_float(
    xs,  # int8/int16/float32/float64 (n * n_comp,): stored samples, I/Q interleaved when n_comp == 2
    n_comp,  # int: 2 (complex, interleaved I, Q) or 1 (real)
    bits,  # uint64 (n_tab, >= L + 2 M + 64): bit windows of the padded tables (module notes)
    tab_idx,  # int64 (n_rows,): row of `bits` (the PRN) of each row
    pad,  # int: M, the table padding (M > spacing + 1)
    code_len,  # int: L, chips per code period
    start,  # int64 (n_rows,): first sample of each row's interval (index into the samples)
    nsamp,  # int64 (n_rows,): samples of each interval
    theta0,  # float64 (n_rows,): code phase at the first sample [chips], in [0, L)
    dchip,  # float64 (n_rows,): code phase step [chips/sample], > 0, B * dchip < L
    phi0,  # float64 (n_rows,): carrier phase at the first sample [cycles], in [0, 1)
    dphi,  # float64 (n_rows,): carrier phase step [cycles/sample]
    rot_re,  # float32 (n_rot, B): cos(2 pi m dphi)
    rot_im,  # float32 (n_rot, B): -sin(2 pi m dphi)
    rot_idx,  # int64 (n_rows,): row of rot_re/rot_im of each row (one with its dphi)
    spacing,  # float64: early/late offset d [chips], 0 <= d < M - 1
    n_sub,  # int: tasks per row
    out,  # float64 (n_rows, 3, 2): E, P, L real/imag (written)
):
    """Fill ``out[r] = [[E.re, E.im], [P.re, P.im], [L.re, L.im]]`` for every row ``r``."""
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
        run = max(int((_SPAN - 2.0 * spacing) / dc), 1)
        buf_r = np.empty(blk, np.float32)
        buf_i = np.empty(blk, np.float32)
        acc = np.zeros(6)
        for b in range(b0, b1):
            k0 = b * blk
            m_end = min(blk, n - k0)
            xo = x0 + k0
            # pass 1: rotation by the table entry exp(-j 2 pi m dphi); the block phasor
            # exp(-j 2 pi (phi0 + k0 dphi)) multiplies the block's sums (after pass 2)
            ph = p0 + k0 * dp
            ph -= math.floor(ph)
            cr = math.cos(two_pi * ph)
            ci = -math.sin(two_pi * ph)
            rotate_block(xs, n_comp, xo, m_end, rr, ri, buf_r, buf_i)
            # code phase at the block start in [w L, (w + 1) L); split at (w + 1) L
            off, lim, mw = code_wrap_split(th0, k0, dc, lf, m_end)
            # pass 2: E/P/L sums in runs of at most `run` samples, each within one segment
            g1 = 0.0
            g2 = 0.0
            g3 = 0.0
            g4 = 0.0
            g5 = 0.0
            g6 = 0.0
            m = 0
            while m < m_end:
                seg_off = off if m < mw else lim
                m2 = min(m + run, mw if m < mw else m_end)
                th_first = (th0 + (k0 + m) * dc) - seg_off
                c0 = int(th_first + a_l)
                lo = np.int64(bw[c0])
                hi = np.int64(bw[c0 + 64])
                base = float(c0)
                ae = a_e - base
                ap = a_p - base
                al = a_l - base
                s1, s2, s3, s4, s5, s6 = _run_sums(lo, hi, buf_r[m:m2], buf_i[m:m2], k0 + m,
                                                   th0, dc, seg_off, ae, ap, al)
                g1 += s1
                g2 += s2
                g3 += s3
                g4 += s4
                g5 += s5
                g6 += s6
                m = m2
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


@njit(cache=True, boundscheck=False)
def pack_bit_windows(neg, out):
    """Pack sign flags into bit windows: bit ``b`` of ``out[c, j]`` is ``neg[c, j + b]``.

    Parameters
    ----------
    neg : numpy.ndarray
        bool (n_ch, W): table entry negative (``-1`` chip).
    out : numpy.ndarray
        uint64 (n_ch, W + 64), written; entries past ``W - 1`` count as 0 (positive).

    Notes
    -----
    One pass per row from the end: ``out[j] = neg[j] | (out[j + 1] << 1)`` (bit 63 of
    ``out[j + 1]``, entry ``j + 64``, is shifted out), O(W) per row.
    """
    n_ch, width = neg.shape
    one = np.uint64(1)
    zero = np.uint64(0)
    for c in range(n_ch):
        for j in range(width, out.shape[1]):
            out[c, j] = zero
        w = zero
        for j in range(width - 1, -1, -1):
            w = (w << one) | (one if neg[c, j] else zero)
            out[c, j] = w


@njit(cache=True, nogil=True, fastmath={"reassoc"}, boundscheck=False)
def mean_power(xs, n_comp):
    """Mean ``|x|^2`` per sample of stored samples (I/Q interleaved when ``n_comp == 2``).

    Returns
    -------
    float
        ``sum(xs**2) / (xs.size / n_comp)`` [stored units^2], float64 accumulation.
    """
    acc = 0.0
    for k in range(xs.size):
        v = float(xs[k])
        acc += v * v
    n = xs.size // n_comp
    return acc / n if n > 0 else 0.0


@njit(cache=True, nogil=True, boundscheck=False)
def block_sum_squares(xs, block, out):
    """Sums of ``xs**2`` over consecutive blocks of ``block`` values (the last block may be
    shorter) of integer samples (``int8``/``int16``), into ``out`` (float64,
    ``ceil(xs.size / block)``,). Summed in int64, exact: every partial sum of 8-bit values
    is an integer below 2**53, so sums of these sums equal :func:`mean_power`'s float64
    accumulator bit for bit. (Integer sums over a slice per block vectorize: 0.62 against
    2.6 ms per 5e6 values of the earlier float64 loop, one core of the development
    machine.)"""
    nb = (xs.size + block - 1) // block
    for b in range(nb):
        a = xs[b * block:min((b + 1) * block, xs.size)]
        acc = np.int64(0)
        for k in range(a.size):
            v = np.int64(a[k])
            acc += v * v
        out[b] = float(acc)
