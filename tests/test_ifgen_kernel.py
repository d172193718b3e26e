"""IF generator kernel (sdr_di/sim/_numba_ifgen.py) against plain NumPy transcriptions:
satellite synthesis across code-epoch boundaries, the counter-based noise (values and
statistics), quantization, and independence of the output from chunking and thread count."""

import functools
import math

import numba
import numpy as np
import pytest

from sdr_di.sim import _numba_ifgen as K

T32 = 2.0**32


def plain_satellite(n, code, chip0, ms, dchip, ph0, dph, a, sym, sym_base):
    """a d c exp(j 2 pi phi) sample by sample: chip from the exact 32.32 position."""
    pos0 = np.int64(chip0 * T32)
    dc = np.int64(np.round(dchip * T32))
    i = np.arange(n, dtype=np.int64)
    pos = pos0 + i * dc
    epoch = pos // (np.int64(10230) << 32)
    chip = (pos >> 32) - 10230 * epoch
    d = sym[ms + epoch - sym_base]
    phase = ph0 + i * dph
    return a * d * code[chip] * np.exp(2j * np.pi * phase)


@pytest.mark.parametrize("dchip,dph", [(10.23e6 * (1 + 2e-6) / 25e6, 3456.7 / 25e6),
                                       (10.23e6 * (1 - 3e-6) / 2.5e6, -1234.5 / 2.5e6),
                                       (10.23e6 / 4e6, 0.31)])
def test_add_satellite_matches_plain_transcription(dchip, dph):
    rng = np.random.default_rng(1)
    code = np.where(rng.random((1, 10230)) < 0.5, 1.0, -1.0).astype(np.float32)
    words = K.code_words(code)
    n = round(10230 / dchip * 1.02)  # over one code period: at least one epoch change
    sym = np.array([1, -1, -1, 1, -1], np.float32)
    a = np.float32(0.05)
    for chip0 in (0.0, 10229.7, 5000.123456):
        ref = plain_satellite(n, code[0], chip0, 7, dchip, 0.37, dph, a, sym, 6)
        sig = np.zeros(2 * n, np.float32)
        K.add_satellite(sig, 2, words[0], chip0, 7, dchip, 0.37, dph, a, sym, 6)
        got = sig[0::2] + 1j * sig[1::2]
        assert np.max(np.abs(got - ref)) < 2e-6 * a
        real = np.zeros(n, np.float32)
        K.add_satellite(real, 1, words[0], chip0, 7, dchip, 0.37, dph, a, sym, 6)
        assert np.max(np.abs(real - ref.real)) < 2e-6 * a


def plain_normal(key, ctr):
    """NumPy transcription of normal_from_counter (uint64 arithmetic wraps)."""
    with np.errstate(over="ignore"):
        z = np.uint64(key) + ctr.astype(np.uint64) * np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    m = np.uint64(0xFFFF)
    u = (z & m) + ((z >> np.uint64(16)) & m) + ((z >> np.uint64(32)) & m) + (z >> np.uint64(48))
    s = (u.astype(np.float32) + np.float32(2.0 - 131072.0)) * np.float32(
        1.0 / (65536.0 * math.sqrt(4.0 / 12.0)))
    c1, c3, c5, c7 = (np.float32(c) for c in K.NORMAL_POLY)
    y = s * s
    return s * (c1 + y * (c3 + y * (c5 + y * c7)))


def test_noise_values_and_quantizer_match_plain_transcription():
    n = 50_000
    sig = np.random.default_rng(2).normal(0, 0.3, 2 * n).astype(np.float32)
    key, ctr0, gain = np.uint64(0x1234_5678_9ABC_DEF0), np.uint64(10**12), np.float32(2.7)
    z = plain_normal(key, ctr0 + np.arange(2 * n, dtype=np.uint64))
    for level in (7, 1, 127):
        out = np.empty(2 * n, np.int8)
        K.noise_quantize(out, sig, key, ctr0, gain, level)
        if level == 1:
            ref = np.where(sig + z >= 0, 1, -1)
        else:
            ref = np.clip(np.floor((sig + z) * gain + np.float32(0.5)), -level, level)
        assert np.array_equal(out, ref.astype(np.int8))


@functools.lru_cache(maxsize=1)
def _exact_noise_distribution():
    """Values and probabilities of the noise polynomial over the exact distribution of the
    sum of four 16-bit uniforms."""
    k = np.arange(2 * 65536 - 1)
    p2 = (65536.0 - np.abs(k - 65535.0)) / 65536.0**2  # sum of two: triangular, exact
    f = np.fft.rfft(p2, 1 << 18)
    p4 = np.clip(np.fft.irfft(f * f, 1 << 18)[: 4 * 65535 + 1], 0.0, None)
    s = (np.arange(p4.size) + 2.0 - 131072.0) / (65536.0 * math.sqrt(4.0 / 12.0))
    c1, c3, c5, c7 = K.NORMAL_POLY
    return s * (c1 + s**2 * (c3 + s**2 * (c5 + s**2 * c7))), p4


GAUSS_TAIL = {1: 0.3173105, 2: 0.0455003, 3: 0.0026998}


def test_noise_design_is_near_gaussian():
    """Over the exact distribution: unit variance, kurtosis 3, tail masses near Gaussian."""
    z, p = _exact_noise_distribution()
    assert abs(np.sum(p * z * z) - 1.0) < 1e-6
    assert abs(np.sum(p * z**4) - 3.0) < 0.005
    for k, tol in ((1, 0.003), (2, 0.004), (3, 0.025)):
        assert abs(np.sum(p[np.abs(z) > k]) / GAUSS_TAIL[k] - 1.0) < tol


def test_noise_is_white_with_the_designed_distribution():
    n = 2_000_000
    sig = np.zeros(n, np.float32)
    out = np.empty(n, np.int16)
    K.noise_quantize(out, sig, np.uint64(99), np.uint64(0), np.float32(4096.0), 30000)
    z = out / 4096.0
    assert abs(z.mean()) < 4 / math.sqrt(n)
    assert abs(z.var() - 1.0) < 4 * math.sqrt(2.0 / n)
    zd, p = _exact_noise_distribution()
    for k in (1, 2, 3):
        q = np.sum(p[np.abs(zd) > k])
        assert abs(np.mean(np.abs(z) > k) - q) < 4 * math.sqrt(q * (1 - q) / n)
    for lag in (1, 2, 25):  # white: I/Q pairs (lag 1) and samples independent
        assert abs(np.mean(z[:-lag] * z[lag:])) < 4 / math.sqrt(n)


def _chunk_args(n_nodes, n_per_node, n_sat=3, seed=3):
    rng = np.random.default_rng(seed)
    code = np.where(rng.random((n_sat, 10230)) < 0.5, 1.0, -1.0).astype(np.float32)
    dchip = np.full((n_sat, n_nodes), 10230.0 / n_per_node * (1 + 1e-6))
    chip0 = np.mod(rng.uniform(0, 10230, (n_sat, 1)) + np.arange(n_nodes) * 0.01, 10230)
    ms0 = np.tile(np.arange(n_nodes, dtype=np.int64) + 5, (n_sat, 1))
    ph0 = rng.uniform(0, 1, (n_sat, n_nodes))
    dph = np.full((n_sat, n_nodes), 1500.0 / (1000.0 * n_per_node))
    amp = np.full((n_sat, n_nodes), 0.2, np.float32)
    amp[1, 3] = 0.0  # an outage node
    sym = np.where(rng.random((n_sat, n_nodes + 10)) < 0.5, 1.0, -1.0).astype(np.float32)
    return K.code_words(code), chip0, ms0, dchip, ph0, dph, amp, sym, np.full(n_sat, 4)


def no_jammers(n_nodes):
    """Kernel jammer arguments for none."""
    return (np.zeros(0, np.int64), np.zeros((0, n_nodes), np.float32), np.zeros(0),
            np.zeros(0), np.zeros(0, np.uint64), np.zeros(0), np.zeros((4, 4), np.float32))


def test_output_independent_of_chunking_and_threads():
    n_nodes, npn = 12, 2500
    words, chip0, ms0, dchip, ph0, dph, amp, sym, base = _chunk_args(n_nodes, npn)
    key = np.uint64(7)

    def run(parts, threads):
        old = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            outs = []
            for a, b in parts:
                out = np.empty(((b - a) * npn, 2), np.int8)
                sub = [np.ascontiguousarray(x[:, a:b]) for x in (chip0, ms0, dchip, ph0, dph, amp)]
                K.synthesize_chunk(out, key, a * npn, npn, words, *sub, sym, base,
                                   np.full(b - a, 3.0, np.float32), 7, *no_jammers(b - a))
                outs.append(out)
            return np.concatenate(outs)
        finally:
            numba.set_num_threads(old)

    whole = run([(0, n_nodes)], 1)
    assert np.array_equal(whole, run([(0, 5), (5, 6), (6, n_nodes)], numba.config.NUMBA_NUM_THREADS))
    assert np.array_equal(whole, run([(0, n_nodes)], numba.config.NUMBA_NUM_THREADS))
    # the satellites are in it: removing them changes the samples
    amp0 = np.zeros_like(amp)
    out = np.empty_like(whole)
    K.synthesize_chunk(out, key, 0, npn, words, chip0, ms0, dchip, ph0, dph, amp0, sym, base,
                       np.full(n_nodes, 3.0, np.float32), 7, *no_jammers(n_nodes))
    assert not np.array_equal(out, whole)


def test_code_words_round_trip():
    rng = np.random.default_rng(4)
    code = np.where(rng.random((2, 10230)) < 0.5, 1.0, -1.0).astype(np.float32)
    w = K.code_words(code).view(np.uint64)
    k = np.arange(10230)
    bits = (w[:, k // 64] >> (k % 64).astype(np.uint64)) & np.uint64(1)
    assert np.array_equal(1.0 - 2.0 * bits, code)
    assert not w[:, -2:].any()


def test_int4_packing_kernel_matches_the_format_registry():
    from sdr_di.io.sample_formats import pack_iq_int4, unpack_iq_int4

    v = np.arange(-8, 8, dtype=np.int8)
    iq = np.stack(np.meshgrid(v, v), axis=-1).reshape(-1, 2).copy()
    out = np.empty(iq.shape[0], np.uint8)
    K.pack_iq_int4_kernel(out, iq)
    assert np.array_equal(out, pack_iq_int4(iq[:, 0], iq[:, 1]))
    i, q = unpack_iq_int4(out)
    assert np.array_equal(i, iq[:, 0]) and np.array_equal(q, iq[:, 1])


def test_noise_jammer_matches_plain_transcription():
    """add_noise_jammer against NumPy: low-rate counter noise, nearest-phase polyphase
    interpolation at u = m r, mixing to f (a neighbouring phase moves a sample by at most
    1/512 of a low-rate sample: < 1 % of the jammer's RMS)."""
    from sdr_di.sim.interference import interpolator_taps

    taps = interpolator_taps()
    n_ph, n_t = taps.shape
    n, m0, r, f, ph, key, a = 3000, 987_654_321, 0.137, 0.0211, 0.3, np.uint64(77), 1.7
    sig = np.zeros(2 * n, np.float32)
    K.add_noise_jammer(sig, 2, a, f, ph, key, r, taps, m0)
    got = sig[0::2] + 1j * sig[1::2]
    u = (m0 + np.arange(n)) * r
    k0 = np.floor(u).astype(np.int64)
    p = np.round((u - k0) * n_ph).astype(np.int64)
    k0 += p == n_ph
    p %= n_ph
    ks = k0[:, None] - n_t // 2 + 1 + np.arange(n_t)[None, :]
    ctr = (2 * (ks + n_t)).astype(np.uint64)
    w = (plain_normal(key, ctr) + 1j * plain_normal(key, ctr + np.uint64(1))) * math.sqrt(0.5)
    x = np.sum(w * taps[p], axis=1)
    ref = a * x * np.exp(2j * np.pi * (ph + f * (m0 + np.arange(n))))
    err = np.abs(got - ref) / (a * np.sqrt(np.mean(np.abs(x) ** 2)))
    assert np.mean(err < 1e-4) > 0.99 and err.max() < 0.01
    assert abs(np.mean(np.abs(got) ** 2) / a**2 - 1.0) < 0.1  # unit power (3000 samples)
