"""Numba kernel of the IF generator (sample-rate loops on plain arrays).

The caller (:mod:`sdr_di.sim.ifgen`) describes each satellite's signal on a grid of *nodes*
every ``N`` samples (about 1 ms): code phase, code-epoch index, carrier phase and amplitude at
the node, and the per-sample code and carrier increments over the following interval (linear
interpolation between exactly computed node values: nothing accumulates across intervals).
A per-node term (a receiver-oscillator truth, say) enters through those node arrays only.

Synthesis (:func:`add_satellite`)
    Sample ``i`` of an interval has code position ``chip0 + i dchip`` in 32.32 fixed point
    (exact integer arithmetic, resolution 2^-32 chip) and carrier phase ``ph0 + i dph``
    [cycles]. The interval is cut at code-epoch boundaries (where the data x NH symbol
    changes) and then into *windows* of ``W`` samples that span at most 64 chips (``W`` a
    multiple of 16 when the rate allows: 144 at 25 MHz). Inside a window the code chips are
    one 64-bit word of the code's bits, the chip of a sample is a variable shift of that word,
    and the carrier is the window's start phasor ``exp(j 2 pi phi_w)`` (from the exact float64
    phase) times the rotation ``exp(j 2 pi i dph)``, ``i < W``, computed once per satellite and
    interval (cos and sin of 2 pi x, |x| <= 1/2, by their Taylor series to degree 16/17:
    truncation below 2e-7, float32 rounding about 1e-7 of the amplitude). The window loop has no table look-up by sample value
    (no gathers), so LLVM vectorizes it (AVX2/AVX-512).

Noise (:func:`noise_quantize`)
    Counter-based: the value of component ``c`` of sample ``m`` of the file is a function of
    the scenario's noise key and ``ncomp m + c`` only (SplitMix64's finalizer of
    ``key + counter * golden gamma``), so a file is the same whatever the chunking, the block
    split or the thread count. The 64 hash bits are four 16-bit uniforms; their standardized
    sum ``s`` (Irwin-Hall, n = 4) is mapped to a Gaussian by the odd polynomial
    :data:`NORMAL_POLY` (a density-weighted least-squares fit of ``Phi^-1(F_IH4(s))``,
    normalized to unit variance over the exact distribution of ``s``): excess kurtosis
    -0.001, P(|z| > 1, 2, 3, 4) = 0.3179, 0.0454, 0.00275, 4.9e-5 (Gaussian: 0.3173, 0.0455,
    0.00270, 6.3e-5), largest value 4.88. All arithmetic, no table: vectorized as well.

Jammers (:func:`add_cw`, :func:`add_noise_jammer`; models in :mod:`sdr_di.sim.interference`)
are added to the satellites' sum before the noise and the quantizer, whose gain ``g`` is given
per interval (the AGC). Quantization: ``q = clip(floor(g x + 1/2), -L, L)`` (1 bit: the
sign), fused with the noise.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

#: Chips of one B3I code period.
CODE_CHIPS = 10230
#: 64-bit words of a code's bit array (the last two are zero padding for the window reads).
CODE_WORDS = (CODE_CHIPS + 63) // 64 + 2

_TWO32 = 4294967296.0
_CHIPS_FX = np.int64(CODE_CHIPS) << 32

# Taylor coefficients of cos(2 pi x) (even powers) and sin(2 pi x) (odd powers), |x| <= 1/2.
_C = tuple(np.float32((-1) ** k * (2 * math.pi) ** (2 * k) / math.factorial(2 * k))
           for k in range(9))
_S = tuple(np.float32((-1) ** k * (2 * math.pi) ** (2 * k + 1) / math.factorial(2 * k + 1))
           for k in range(9))
_C0, _C1, _C2, _C3, _C4, _C5, _C6, _C7, _C8 = _C
_S0, _S1, _S2, _S3, _S4, _S5, _S6, _S7, _S8 = _S

#: Odd polynomial (coefficients of s, s^3, s^5, s^7) from the standardized Irwin-Hall(4) sum
#: of four 16-bit uniforms to a unit-variance near-Gaussian (see the module docstring).
NORMAL_POLY = (0.9590650944523564, 0.01632607915259235, -0.0019098554931083437,
               0.00030656939256050594)
_N1, _N3, _N5, _N7 = (np.float32(c) for c in NORMAL_POLY)
#: s = (u0 + u1 + u2 + u3 + 2 - 2^17) * _IH_SCALE: each (u + 1/2) / 2^16 uniform on (0, 1),
#: the sum minus its mean 2, over its standard deviation sqrt(4 / 12).
_IH_OFFSET = np.float32(2.0 - 131072.0)
_IH_SCALE = np.float32(1.0 / (65536.0 * math.sqrt(4.0 / 12.0)))

_GAMMA = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_U16 = np.uint64(0xFFFF)


def code_words(codes: np.ndarray) -> np.ndarray:
    """Pack +/-1 codes into 64-bit words, chip ``k`` at bit ``k % 64`` of word ``k // 64``.

    Parameters
    ----------
    codes : ndarray, shape (n_sat, 10230)
        Chips as +/-1 (bit 0 -> +1, bit 1 -> -1).

    Returns
    -------
    ndarray of int64, shape (n_sat, CODE_WORDS)
        The bits (1 = chip -1), zero-padded.
    """
    n_sat = codes.shape[0]
    bits = np.zeros((n_sat, CODE_WORDS * 64), np.uint8)
    bits[:, :CODE_CHIPS] = np.asarray(codes) < 0
    packed = np.packbits(bits.reshape(n_sat, CODE_WORDS, 64), axis=2, bitorder="little")
    return np.ascontiguousarray(packed).view("<u8").reshape(n_sat, CODE_WORDS).view(np.int64)


@njit(cache=True, inline="always")
def normal_from_counter(key, ctr):
    """Near-Gaussian (unit variance, float32) of a 64-bit key and counter (both uint64)."""
    z = key + ctr * _GAMMA
    z = (z ^ (z >> np.uint64(30))) * _M1
    z = (z ^ (z >> np.uint64(27))) * _M2
    z = z ^ (z >> np.uint64(31))
    u = ((z & _U16) + ((z >> np.uint64(16)) & _U16) + ((z >> np.uint64(32)) & _U16)
         + (z >> np.uint64(48)))
    s = (np.float32(u) + _IH_OFFSET) * _IH_SCALE
    y = s * s
    return s * (_N1 + y * (_N3 + y * (_N5 + y * _N7)))


@njit(cache=True, inline="always")
def _carrier(x):
    """cos and sin of 2 pi x for |x| <= 1/2 (float32 Taylor polynomials, degree 16/17)."""
    y = x * x
    co = _C8
    co = co * y + _C7
    co = co * y + _C6
    co = co * y + _C5
    co = co * y + _C4
    co = co * y + _C3
    co = co * y + _C2
    co = co * y + _C1
    co = co * y + _C0
    si = _S8
    si = si * y + _S7
    si = si * y + _S6
    si = si * y + _S5
    si = si * y + _S4
    si = si * y + _S3
    si = si * y + _S2
    si = si * y + _S1
    si = (si * y + _S0) * x
    return co, si


@njit(cache=True, inline="always")
def _phasor(ph):
    """cos and sin of 2 pi ph (float64 cycles), as float32."""
    return _carrier(np.float32(ph - np.floor(ph + 0.5)))


@njit(cache=True)
def _window_iq(sig, word, ar, ai, rel_fx, dc, rr, ri, n):
    """Add ``n`` complex samples of one satellite to interleaved ``sig`` (I, Q, I, ...):
    chips from the bits of ``word`` (the window's first chip at bit 0, sample 0 at ``rel_fx``
    32.32 chips from it); ``(ar + j ai)`` amplitude x symbol x carrier phasor at sample 0;
    ``rr + j ri`` the carrier's rotation from sample 0 to sample ``i``."""
    for i in range(n):
        k = (rel_fx + i * dc) >> 32
        c = np.float32(1 - 2 * ((word >> k) & 1))
        sig[2 * i] += c * (ar * rr[i] - ai * ri[i])
        sig[2 * i + 1] += c * (ar * ri[i] + ai * rr[i])


@njit(cache=True)
def _window_real(sig, word, ar, ai, rel_fx, dc, rr, ri, n):
    """As :func:`_window_iq` for real samples (the real part only)."""
    for i in range(n):
        k = (rel_fx + i * dc) >> 32
        c = np.float32(1 - 2 * ((word >> k) & 1))
        sig[i] += c * (ar * rr[i] - ai * ri[i])


@njit(cache=True)
def window_samples(dchip: float) -> int:
    """Samples per window: at most 64 chips spanned, a multiple of 16 when possible."""
    w = int(63.0 / dchip)
    if w >= 16:
        w = (w // 16) * 16
    return max(w, 1)


@njit(cache=True)
def add_satellite(sig, ncomp, words, chip0, ms, dchip, ph0, dph, a, sym, sym_base):
    """Add one satellite's ``a d c exp(+j 2 pi phi)`` over one node interval.

    Parameters
    ----------
    sig : float32 array (ncomp n,)
        Sum of the signals, interleaved I, Q (``ncomp`` 2) or real (``ncomp`` 1; updated).
    words : int64 array (CODE_WORDS,)
        The satellite's code bits (:func:`code_words`).
    chip0 : float
        Code phase [chips, 0..10230) at sample 0; ``ms`` its code-epoch index.
    dchip, ph0, dph : float
        Chips per sample (> 0), carrier phase [cycles] at sample 0, cycles per sample.
    a : float32
        Amplitude; ``sym[ms - sym_base]`` the data x NH symbol of epoch ``ms``.
    """
    n = sig.shape[0] // ncomp
    pos0 = np.int64(chip0 * _TWO32)  # 32.32 chips of sample 0 from the current epoch start
    dc = np.int64(np.round(dchip * _TWO32))
    w_len = window_samples(dchip)
    rr = np.empty(w_len, np.float32)  # carrier rotation over i samples: exp(j 2 pi i dph)
    ri = np.empty(w_len, np.float32)
    for i in range(w_len):
        rr[i], ri[i] = _phasor(i * dph)
    i = 0
    while i < n:
        seg_end = min(n, (_CHIPS_FX - pos0 + dc - 1) // dc)  # first sample of the next epoch
        cur = a * sym[ms - sym_base]
        while i < seg_end:
            j = min(i + w_len, seg_end)
            pos = pos0 + i * dc
            cst = pos >> 32
            w = cst >> 6
            o = cst & 63
            if o == 0:
                word = words[w]
            else:
                word = (np.int64(np.uint64(words[w]) >> np.uint64(o))
                        | (words[w + 1] << (64 - o)))
            er, ei = _phasor(ph0 + i * dph)
            if ncomp == 2:
                _window_iq(sig[2 * i:2 * j], word, cur * er, cur * ei, pos - (cst << 32), dc,
                           rr, ri, j - i)
            else:
                _window_real(sig[i:j], word, cur * er, cur * ei, pos - (cst << 32), dc, rr, ri,
                             j - i)
            i = j
        pos0 -= _CHIPS_FX
        ms += 1


@njit(cache=True)
def noise_quantize(out, sig, key, ctr0, gain, level):
    """``out[k] = Q(gain (sig[k] + n(ctr0 + k)))`` for the flat (interleaved) arrays: unit-
    variance noise from the counter (uint64), quantized to ``-level..level`` (1: the sign)."""
    if level == 1:
        for k in range(out.shape[0]):
            x = sig[k] + normal_from_counter(key, ctr0 + np.uint64(k))
            out[k] = 1 if x >= 0 else -1
    else:
        lv = np.float32(level)
        for k in range(out.shape[0]):
            x = (sig[k] + normal_from_counter(key, ctr0 + np.uint64(k))) * gain
            out[k] = min(max(np.floor(x + np.float32(0.5)), -lv), lv)


@njit(cache=True)
def add_cw(sig, ncomp, a, f, ph, m0):
    """Add ``a exp(j 2 pi (ph + f m))`` for file samples ``m = m0 ..`` (``f`` cycles per
    sample, ``ph`` cycles at sample 0); real output: the real part."""
    n = sig.shape[0] // ncomp
    b = ph + f * m0
    b -= np.floor(b)
    af = np.float32(a)
    if ncomp == 2:
        for i in range(n):
            p = b + i * f
            co, si = _carrier(np.float32(p - np.floor(p + 0.5)))
            sig[2 * i] += af * co
            sig[2 * i + 1] += af * si
    else:
        for i in range(n):
            p = b + i * f
            co, _ = _carrier(np.float32(p - np.floor(p + 0.5)))
            sig[i] += af * co


@njit(cache=True)
def add_noise_jammer(sig, ncomp, a, f, ph, key, r, taps, m0):
    """Add ``a`` times band-limited unit-power complex Gaussian noise, mixed to ``f``.

    Low-rate white samples ``w[k]`` (rate ``r`` per output sample; counter ``key``,
    ``2 (k + taps)`` and ``+1``, each component of variance 1/2) are interpolated by the
    polyphase table ``taps`` (phases, a power of 2, by n_taps; nearest phase) at ``u = m r``
    for file samples ``m = m0 ..``, then multiplied by ``exp(j 2 pi (ph + f m))`` (per
    :data:`MIX_WINDOW` samples: the exact start phasor times a rotation table). Inside
    the interval ``u`` runs in 32.32 fixed point from its exact float64 start (the rate's
    rounding, 2^-33 per sample, moves it by < 1e-5 low-rate sample over 25 000 samples)."""
    n = sig.shape[0] // ncomp
    n_ph, n_t = taps.shape
    ph_shift = 32
    while (1 << (32 - ph_shift)) < n_ph:
        ph_shift -= 1
    half = n_t // 2
    u0 = m0 * r
    k_start = np.int64(np.floor(u0))
    k_first = k_start - half + 1
    nw = np.int64(np.ceil(n * r)) + n_t + 2
    wr = np.empty(nw, np.float32)
    wi = np.empty(nw, np.float32)
    s = np.float32(math.sqrt(0.5))
    for k in range(nw):
        ctr = np.uint64(2 * (k + k_first + n_t))
        wr[k] = normal_from_counter(key, ctr) * s
        wi[k] = normal_from_counter(key, ctr + np.uint64(1)) * s
    flat = taps.reshape(n_ph * n_t)
    # u - k_start in 32.32, plus half a phase step: truncation picks the nearest phase (and
    # carries into the integer part at the top)
    pos = np.int64((u0 - k_start) * _TWO32) + (np.int64(1) << (ph_shift - 1))
    dr = np.int64(np.round(r * _TWO32))
    mask = n_ph - 1
    # mixing: per window of MIX_WINDOW samples, the exact start phasor times a rotation table
    w_len = min(MIX_WINDOW, n)
    rr = np.empty(w_len, np.float32)
    ri = np.empty(w_len, np.float32)
    for j in range(w_len):
        rr[j], ri[j] = _phasor(j * f)
    af = np.float32(a)
    i0 = 0
    while i0 < n:
        i1 = min(i0 + w_len, n)
        er, ei = _phasor(ph + f * (m0 + i0))
        ar = af * er
        ai = af * ei
        for i in range(i0, i1):
            base = pos >> 32  # k0 - half + 1 - k_first
            o = ((pos >> ph_shift) & mask) * n_t
            xr = np.float32(0.0)
            xi = np.float32(0.0)
            for t in range(n_t):
                h = flat[o + t]
                xr += wr[base + t] * h
                xi += wi[base + t] * h
            pos += dr
            cr = ar * rr[i - i0] - ai * ri[i - i0]
            ci = ar * ri[i - i0] + ai * rr[i - i0]
            if ncomp == 2:
                sig[2 * i] += cr * xr - ci * xi
                sig[2 * i + 1] += cr * xi + ci * xr
            else:
                sig[i] += cr * xr - ci * xi
        i0 = i1


#: Samples per mixing window of the noise jammer (one exact start phasor each).
MIX_WINDOW = 256


@njit(cache=True, parallel=True, nogil=True)
def synthesize_chunk(
    out,  # int8/int16 (n, 2) complex or (n, 1) real: quantized samples (written)
    key,  # uint64: noise key of the file
    sample0,  # int: file index of out[0]
    n_per_node,  # samples per node interval
    words,  # int64 (n_sat, CODE_WORDS): code bits (code_words)
    chip0,  # float64 (n_sat, n_nodes): chip phase in [0, 10230) at each node
    ms0,  # int64 (n_sat, n_nodes): code-epoch index at each node
    dchip,  # float64 (n_sat, n_nodes): chips per sample over the interval (> 0)
    ph0,  # float64 (n_sat, n_nodes): carrier phase [cycles] in [0, 1) at each node
    dph,  # float64 (n_sat, n_nodes): carrier cycles per sample over the interval
    amp,  # float32 (n_sat, n_nodes): amplitude over the interval (noise sigma = 1)
    sym,  # float32 (n_sat, n_sym): data x NH symbol (+/-1) of each code epoch
    sym_base,  # int64 (n_sat,): code-epoch index of sym[:, 0]
    gains,  # float32 (n_nodes,): quantizer input scale (LSB per unit) of each interval (AGC)
    level,  # int: largest quantizer magnitude L (1: sign only)
    jam_kind,  # int64 (n_jam,): 0 CW, 1 band-limited noise
    jam_amp,  # float32 (n_jam, n_nodes): jammer amplitude over the interval (0: off)
    jam_freq,  # float64 (n_jam,): jammer centre [cycles per sample]
    jam_phase,  # float64 (n_jam,): CW phase at sample 0 [cycles]
    jam_key,  # uint64 (n_jam,): noise jammer keys
    jam_rate,  # float64 (n_jam,): noise jammer low-rate samples per sample (its bandwidth)
    taps,  # float32 (phases, n_taps): the noise jammer's interpolator
):
    """Fill ``out`` with quantized signal + jammers + unit-variance noise for ``n_nodes``
    intervals.

    Complex output (``out.shape[1] == 2``) is ``sum a d c exp(+j 2 pi phi) + J + n``; real
    output is its real part plus real noise. The intervals are independent (one ``prange``
    iteration each: run it under ``numba.parallel_chunksize`` for load balancing); the
    result does not depend on the thread count or the schedule.
    """
    n_sat = words.shape[0]
    n_nodes = chip0.shape[1]
    ncomp = out.shape[1]
    flat = out.reshape(out.shape[0] * ncomp)
    m = n_per_node * ncomp
    for j in prange(n_nodes):
        sig = np.zeros(m, dtype=np.float32)
        for s in range(n_sat):
            a = amp[s, j]
            if a != 0.0:
                add_satellite(sig, ncomp, words[s], chip0[s, j], ms0[s, j], dchip[s, j],
                              ph0[s, j], dph[s, j], a, sym[s], sym_base[s])
        first = sample0 + j * n_per_node
        for q in range(jam_kind.shape[0]):
            if jam_amp[q, j] != 0.0:
                if jam_kind[q] == 0:
                    add_cw(sig, ncomp, jam_amp[q, j], jam_freq[q], jam_phase[q], first)
                else:
                    add_noise_jammer(sig, ncomp, jam_amp[q, j], jam_freq[q], 0.0, jam_key[q],
                                     jam_rate[q], taps, first)
        k0 = j * m
        noise_quantize(flat[k0:k0 + m], sig, key, np.uint64(ncomp * sample0 + k0), gains[j],
                       level)


@njit(cache=True, parallel=True, nogil=True)
def pack_iq_int4_kernel(out, iq):
    """``out[i] = (I << 4) | (Q & 0xF)`` of int8 pairs ``iq[i]`` (the ``iq_int4`` byte)."""
    for i in prange(out.shape[0]):
        out[i] = ((iq[i, 0] & 0xF) << 4) | (iq[i, 1] & 0xF)
