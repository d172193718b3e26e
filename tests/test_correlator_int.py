"""Integer E/P/L kernel (``receiver._numba_correlate_int``) against a plain numpy
transcription of its integer arithmetic, on every integer sample format, and against the
float32 kernel within the rotation table's quantization."""

import math

import numpy as np
import pytest

from sdr_di.io.sample_formats import get_format, unpack_iq_int4
from sdr_di.receiver import _numba_correlate_bits as kb
from sdr_di.receiver._numba_correlate_int import (
    FRAC_BITS,
    ROT_SCALE,
    correlate_epl_int8,
    run_length,
)
from sdr_di.receiver.correlator import (
    CARRIER_BLOCK,
    CODE_PAD,
    bit_windows,
    carrier_rotation,
    padded_replicas,
)

L = 10230


def transcription(xs, n_comp, table, start, nsamp, theta0, dchip, phi0, dphi, rot_re, rot_im,
                  d):
    """The integer kernel's arithmetic in plain numpy/Python: rounded rotation table, int
    wipe-off, runs of the bit-window span, fixed-point code index, exact integer sums, float64
    block phasor, division by ROT_SCALE. ``table``: padded +/-1 replicas, one row per row."""
    x = xs.astype(np.int64)
    n_rows = start.size
    out = np.zeros((n_rows, 3), complex)
    fs = float(1 << FRAC_BITS)
    for r in range(n_rows):
        qr = np.array([round(ROT_SCALE * float(v)) for v in rot_re[r]], np.int64)
        qi = np.array([round(ROT_SCALE * float(v)) for v in rot_im[r]], np.int64)
        st = round(dchip[r] * fs)
        run = run_length(d, dchip[r])
        n = nsamp[r]
        th0, dc = theta0[r], dchip[r]
        acc = np.zeros(3, complex)
        for k0 in range(0, n, CARRIER_BLOCK):
            m_end = min(CARRIER_BLOCK, n - k0)
            s0 = start[r] + k0
            if n_comp == 2:
                xr = x[2 * s0:2 * (s0 + m_end):2]
                xi = x[2 * s0 + 1:2 * (s0 + m_end):2]
            else:
                xr = x[s0:s0 + m_end]
                xi = np.zeros_like(xr)
            wr = xr * qr[:m_end] - xi * qi[:m_end]
            wi = xr * qi[:m_end] + xi * qr[:m_end]
            assert np.abs(wr).max(initial=0) < 2 ** 15 and np.abs(wi).max(initial=0) < 2 ** 15
            tb = th0 + k0 * dc
            off = math.floor(tb / L) * L
            lim = off + L
            mw = min(max(math.ceil((lim - tb) / dc), 0), m_end)
            while mw > 0 and th0 + (k0 + mw - 1) * dc >= lim:
                mw -= 1
            while mw < m_end and th0 + (k0 + mw) * dc < lim:
                mw += 1
            g = np.zeros(3, complex)
            m = 0
            while m < m_end:
                seg = off if m < mw else lim
                m2 = min(m + run, mw if m < mw else m_end)
                th = (th0 + (k0 + m) * dc) - seg
                c0 = int(th + (CODE_PAD - d))
                base = th - c0
                q = np.arange(m2 - m)
                for j, a in enumerate((CODE_PAD + d, CODE_PAD, CODE_PAD - d)):
                    i = (math.floor((base + a) * fs) + q * st) >> FRAC_BITS
                    assert i.max() < 64  # inside the two 32-bit words
                    code = table[r, c0 + i].astype(np.int64)
                    g[j] += int(np.sum(code * wr[m:m2])) + 1j * int(np.sum(code * wi[m:m2]))
                m = m2
            ph = phi0[r] + k0 * dphi[r]
            ph -= math.floor(ph)
            acc += g * complex(math.cos(2 * math.pi * ph), -math.sin(2 * math.pi * ph))
        out[r] = acc / ROT_SCALE
    return out


def _samples(fmt: str, rng, n: int) -> tuple[np.ndarray, int]:
    """Stored samples as the receiver gets them (int8), for each integer format."""
    if fmt == "iq_int8":
        return rng.integers(-128, 128, 2 * n).astype(np.int8), 2
    if fmt == "real_int8":
        return rng.integers(-128, 128, n).astype(np.int8), 1
    if fmt == "iq_int4":
        i, q = unpack_iq_int4(rng.integers(0, 256, n).astype(np.uint8))
        return np.stack([i, q], axis=1).ravel(), 2
    # 2-bit real (PocketSDR RAW8 real2) through the format's unpacking table
    from sdr_di.io.sample_formats import byte_layout

    _, tab = byte_layout(get_format(fmt), 1)
    return np.ascontiguousarray(tab[rng.integers(0, 256, n)].ravel()), 1


def _case(rng, n_comp, fs, n_rows=4, n_block=30_000):
    codes = rng.choice(np.array([-1, 1], np.int8), size=(n_rows, L))
    table = padded_replicas(codes)
    nsamp = rng.integers(5_000, 12_000, n_rows)
    start = np.array([rng.integers(0, n_block - m + 1) for m in nsamp])
    theta0 = rng.uniform(0, L, n_rows)
    theta0[0] = L - 3.3  # the code wraps inside the interval
    dchip = 10.23e6 * (1 + rng.uniform(-5e-5, 5e-5, n_rows)) / fs
    phi0 = rng.uniform(0, 1, n_rows)
    dphi = (rng.uniform(-6e3, 6e3, n_rows) + (0.0 if n_comp == 2 else 0.25 * fs)) / fs
    return table, start, nsamp, theta0, dchip, phi0, dphi


@pytest.mark.parametrize("fmt,fs,d", [("iq_int8", 25e6, 0.5), ("real_int8", 20e6, 0.5),
                                      ("iq_int4", 2.5e6, 1.0),
                                      ("pocket_raw8_real2", 25e6, 0.1)])
def test_int_kernel_matches_numpy_transcription(fmt, fs, d):
    rng = np.random.default_rng(sum(map(ord, fmt)))
    table, start, nsamp, theta0, dchip, phi0, dphi = _case(rng, 2 if "iq" in fmt else 1, fs)
    xs, n_comp = _samples(fmt, rng, 30_000)
    assert xs.dtype == np.int8
    rot_re, rot_im = carrier_rotation(dphi)
    idx = np.arange(start.size, dtype=np.int64)
    ref = transcription(xs, n_comp, table, start, nsamp, theta0, dchip, phi0, dphi, rot_re,
                        rot_im, d)
    for n_sub in (1, 3):
        out = np.empty((start.size, 3, 2))
        correlate_epl_int8(xs, n_comp, bit_windows(table), idx, CODE_PAD, L, start, nsamp,
                           theta0, dchip, phi0, dphi, rot_re, rot_im, idx, d, n_sub, out)
        got = out[..., 0] + 1j * out[..., 1]
        # integer sums exact; the kernel advances the block phasor by a float64 rotation
        # between exact evaluations (relative error < 4e-15) and associates the float64
        # block sums differently
        np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-9 * np.abs(ref).max())


def test_dispatch_and_agreement_with_float_kernel(monkeypatch):
    """int8 input takes the integer kernel (unless forced off); it agrees with the float32
    kernel within the rotation table's quantization, ~3.2e-3 of the sums' noise level rms
    (module notes), on a random int8 IQ block with a strong signal on row 0."""
    rng = np.random.default_rng(5)
    fs = 25e6
    table, start, nsamp, theta0, dchip, phi0, dphi = _case(rng, 2, fs, n_rows=6)
    n = 30_000
    k = np.arange(n)
    # row 0's signal: code and carrier matching its NCO from sample start[0]
    kk = k - start[0]
    chips = table[0, CODE_PAD + np.floor(theta0[0] + kk * dchip[0]).astype(np.int64) % L]
    sig = 20.0 * chips * np.exp(2j * np.pi * (phi0[0] + kk * dphi[0]))
    z = sig + 25.0 * (rng.normal(size=n) + 1j * rng.normal(size=n))
    xs = np.clip(np.rint(np.stack([z.real, z.imag], axis=1).ravel()), -128, 127).astype(np.int8)
    rot_re, rot_im = carrier_rotation(dphi)
    idx = np.arange(start.size, dtype=np.int64)
    args = (xs, 2, bit_windows(table), idx, CODE_PAD, L, start, nsamp, theta0, dchip, phi0,
            dphi, rot_re, rot_im, idx, 0.5, 1)
    o_int, o_flt, o_disp, o_forced = (np.empty((start.size, 3, 2)) for _ in range(4))
    correlate_epl_int8(*args, o_int)
    kb.correlate_epl_float(*args, o_flt)
    kb.correlate_epl_bits(*args, o_disp)
    monkeypatch.setattr(kb, "INTEGER_PATH", False)
    kb.correlate_epl_bits(*args, o_forced)
    np.testing.assert_array_equal(o_disp, o_int)
    np.testing.assert_array_equal(o_forced, o_flt)
    assert not np.array_equal(o_int, o_flt)
    noise = 25.0 * np.sqrt(2 * nsamp)[:, None, None]  # |sum| noise level per component
    err = np.abs(o_int - o_flt) / noise
    assert err.max() < 0.02
    assert 1e-4 < np.sqrt(np.mean(err ** 2)) < 8e-3
    # the strong prompt keeps its magnitude to 1e-3
    p_i = np.hypot(*o_int[0, 1])
    p_f = np.hypot(*o_flt[0, 1])
    assert p_f > 0.9 * 20.0 * nsamp[0]
    assert abs(p_i / p_f - 1) < 1e-3


def test_low_rate_int8_stays_off_the_integer_kernel(monkeypatch):
    """At 2.5 MHz (code step 4.1 chips per sample) the integer kernel's runs are 14 samples
    and it is the slower one: the dispatcher takes the low-rate kernel
    (``receiver/_numba_correlate_gather.py``), or the float32 one when that is off."""
    rng = np.random.default_rng(9)
    fs = 2.5e6
    table, start, nsamp, theta0, dchip, phi0, dphi = _case(rng, 2, fs, n_rows=2)
    assert not kb.int_kernel_pays(0.5, float(dchip.max()))
    assert kb.int_kernel_pays(0.5, 10.23e6 / 25e6)
    xs, n_comp = _samples("iq_int4", rng, 30_000)
    rot_re, rot_im = carrier_rotation(dphi)
    idx = np.arange(start.size, dtype=np.int64)
    args = (xs, n_comp, bit_windows(table), idx, CODE_PAD, L, start, nsamp, theta0, dchip,
            phi0, dphi, rot_re, rot_im, idx, 0.5, 1)
    o_disp, o_gat, o_flt = (np.empty((2, 3, 2)) for _ in range(3))
    kb.correlate_epl_bits(*args, o_disp)
    kb.correlate_epl_gather(*args, o_gat)
    np.testing.assert_array_equal(o_disp, o_gat)
    monkeypatch.setattr(kb, "GATHER_PATH", False)
    kb.correlate_epl_bits(*args, o_disp)
    kb.correlate_epl_float(*args, o_flt)
    np.testing.assert_array_equal(o_disp, o_flt)


def test_environment_switch(monkeypatch):
    """SDR_DI_CORRELATOR=float (read at import, sdr_di.settings) selects the float32
    reference; a typo is an error, not a silent default."""
    from sdr_di.settings import integer_correlator

    for value, want in (("float", False), ("int", True), ("", True), (" Float ", False)):
        monkeypatch.setenv("SDR_DI_CORRELATOR", value)
        assert integer_correlator() is want
    monkeypatch.setenv("SDR_DI_CORRELATOR", "fp32")
    with pytest.raises(ValueError, match="SDR_DI_CORRELATOR"):
        integer_correlator()
