"""Multi-channel E/P/L correlator: numba kernel versus a plain numpy reference."""

import numpy as np
import pytest

from sdr_di.errors import UnknownPrnError
from sdr_di.receiver import _numba_correlate_bits
from sdr_di.receiver._numba_correlate_bits import correlate_epl_bits, mean_power
from sdr_di.receiver._numba_correlate_gather import correlate_epl_gather
from sdr_di.receiver._numba_correlate_int import ROT_SCALE
from sdr_di.receiver.correlator import (
    CARRIER_BLOCK,
    CODE_PAD,
    Correlator,
    bit_windows,
    carrier_rotation,
    correlate,
    padded_replicas,
)
from sdr_di.signal.codes import b3i_code

L = 10230
#: Relative tolerance of the kernel against the float64 reference. The kernel's products and
#: within-run sums are float32 (unit roundoff 6e-8; module notes of
#: ``receiver._numba_correlate_bits``): on these cases its error is about 2e-7 of ``scale``
#: (the sums' noise level, sqrt(n) for unit-variance samples). One sample on the wrong chip
#: or a wrong rotation entry moves a sum by about one sample's magnitude, ~4e-3 of ``scale``
#: at n = 50 000: 2000 times this tolerance.
TOL = 2e-6


@pytest.fixture(autouse=True)
def _float_kernel(monkeypatch):
    """These tests hold the float32 kernel to float64 references; int8 samples would take the
    integer kernel, which has its own tests (tests/test_correlator_int.py), and rows below
    about 10.6 MHz the low-rate kernel (its tests below: ``test_gather_kernel_*``)."""
    monkeypatch.setattr(_numba_correlate_bits, "INTEGER_PATH", False)
    monkeypatch.setattr(_numba_correlate_bits, "GATHER_PATH", False)


def reference_epl(x, codes, theta0, rate, phi0, fc, n, fs, d, start):
    """Plain numpy E/P/L: float64 phases recomputed from the interval start."""
    n_ch = codes.shape[0]
    out = np.zeros((n_ch, 3), complex)
    for c in range(n_ch):
        k = np.arange(n[c], dtype=np.float64)
        th = np.mod(theta0[c], L) + k * (rate[c] / fs)
        ph = (phi0[c] - np.floor(phi0[c])) + k * (fc[c] / fs)
        w = np.exp(-2j * np.pi * (ph - np.floor(ph)))
        seg = x[start[c]:start[c] + n[c]].astype(np.complex128) * w
        for j, delta in enumerate((d, 0.0, -d)):
            idx = np.floor(th + delta).astype(np.int64) % L
            out[c, j] = np.sum(codes[c, idx] * seg)
    return out


def _random_case(rng, n_ch, complex_input, n_block=60_000):
    codes = rng.choice(np.array([-1, 1], np.int8), size=(n_ch, L))
    if complex_input:
        x = (rng.normal(size=n_block) + 1j * rng.normal(size=n_block)).astype(np.complex64)
    else:
        x = rng.normal(size=n_block).astype(np.float32)
    fs = 25e6 if complex_input else 20e6
    theta0 = rng.uniform(-20000, 30000, n_ch)  # fractional, outside [0, L) too
    # code Doppler: rate != 10.23e6, up to +-50 ppm (larger than any real code Doppler)
    rate = 10.23e6 * (1.0 + rng.uniform(-5e-5, 5e-5, n_ch))
    phi0 = rng.uniform(-3, 3, n_ch)
    fc = rng.uniform(-6e3, 6e3, n_ch) + (0.0 if complex_input else 5e6)
    n = rng.integers(20_000, 50_000, n_ch)
    start = np.array([rng.integers(0, n_block - m + 1) for m in n])
    return x, codes, theta0, rate, phi0, fc, n, fs, start


@pytest.mark.parametrize("complex_input", [True, False])
@pytest.mark.parametrize("spacing", [0.5, 0.1, 1.0])
def test_kernel_matches_numpy_reference(complex_input, spacing):
    rng = np.random.default_rng(11 + int(complex_input) + int(10 * spacing))
    x, codes, theta0, rate, phi0, fc, n, fs, start = _random_case(rng, 5, complex_input)
    res = correlate(x, codes, theta0, rate, phi0, fc, n, fs, spacing_chips=spacing,
                    start_sample=start)
    ref = reference_epl(x, codes, theta0, rate, phi0, fc, n, fs, spacing, start)
    got = np.stack([res.early, res.prompt, res.late], axis=1)
    scale = np.sqrt(n.max())  # sums of n unit-variance terms are ~sqrt(n)
    np.testing.assert_allclose(got, ref, rtol=TOL, atol=TOL * scale)
    # early, prompt and late really differ (the test would not see a swapped offset otherwise)
    assert np.all(np.abs(res.early - res.late) > 1e-3 * scale)
    # NCO end states: exactly start + rate * n / fs, from the caller's unreduced values
    np.testing.assert_array_equal(res.code_phase_end, theta0 + rate * n / fs)
    np.testing.assert_array_equal(res.carrier_phase_end, phi0 + fc * n / fs)


def test_matched_signal_gives_full_prompt_and_symmetric_early_late():
    """A clean signal with the same NCO parameters: P = a n, E = L = a n (1 - d) (complex)."""
    rng = np.random.default_rng(3)
    code = rng.choice(np.array([-1, 1], np.int8), size=L)
    fs, n = 25e6, 25_000
    fd = 1234.5
    rate = 10.23e6 * (1 + fd / 1268.52e6)
    theta0, phi0 = 1234.37, 0.3
    k = np.arange(n)
    th = theta0 + k * rate / fs
    x = (code[np.floor(th).astype(int) % L] * np.exp(2j * np.pi * (phi0 + k * fd / fs))
         ).astype(np.complex64)
    r = correlate(x, code, theta0, rate, phi0, fd, n, fs)
    assert abs(r.prompt[0] - n) < 1e-3 * n
    # E/L of a rectangular-chip code at +-0.5 chip: about half of the prompt, symmetric
    assert abs(abs(r.early[0]) - abs(r.late[0])) < 0.02 * n
    assert 0.4 * n < abs(r.early[0]) < 0.6 * n
    # a quarter-cycle carrier phase error rotates P by -90 deg
    r2 = correlate(x, code, theta0, rate, phi0 + 0.25, fd, n, fs)
    assert abs(r2.prompt[0] - (-1j * n)) < 1e-3 * n
    # a code phase error of 0.3 chip: early (or late) power grows on the signal side
    r3 = correlate(x, code, theta0 - 0.3, rate, phi0, fd, n, fs)
    assert abs(r3.early[0]) > abs(r3.late[0])


def test_chained_intervals_equal_one_long_interval():
    """Feeding the end states back (as a tracking loop does) equals one long interval."""
    rng = np.random.default_rng(5)
    x, codes, *_ = _random_case(rng, 1, True, n_block=80_000)
    fs, rate, fc = 25e6, 10.23e6 * (1 + 2e-6), 2345.6
    whole = correlate(x, codes, 17.25, rate, 0.1, fc, 80_000, fs)
    a = correlate(x, codes, 17.25, rate, 0.1, fc, 30_001, fs)
    b = correlate(x, codes, a.code_phase_end, rate, a.carrier_phase_end, fc, 49_999, fs,
                  start_sample=30_001)
    scale = np.sqrt(80_000)
    np.testing.assert_allclose(a.prompt + b.prompt, whole.prompt, rtol=TOL, atol=TOL * scale)
    np.testing.assert_allclose(a.early + b.early, whole.early, rtol=TOL, atol=TOL * scale)


def test_result_independent_of_thread_count():
    import numba

    rng = np.random.default_rng(8)
    x, codes, theta0, rate, phi0, fc, n, fs, start = _random_case(rng, 7, True)
    r1 = correlate(x, codes, theta0, rate, phi0, fc, n, fs, start_sample=start)
    old = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        r2 = correlate(x, codes, theta0, rate, phi0, fc, n, fs, start_sample=start)
    finally:
        numba.set_num_threads(old)
    np.testing.assert_allclose(r1.prompt, r2.prompt, rtol=1e-12, atol=1e-9)


def test_correlator_bank_prns_and_errors():
    rng = np.random.default_rng(9)
    table = {p: rng.choice(np.array([-1, 1], np.int8), size=L) for p in (6, 9, 19)}
    bank = Correlator(25e6, spacing_chips=0.25, code_source=lambda p: table[p])
    x = (rng.normal(size=30_000) + 1j * rng.normal(size=30_000)).astype(np.complex64)
    r = bank.correlate(x, [6, 19], [10.0, 20.5], 10.23e6, 0.0, [100.0, -200.0], 25_000)
    ref = reference_epl(x, np.stack([table[6], table[19]]), np.array([10.0, 20.5]),
                        np.full(2, 10.23e6), np.zeros(2), np.array([100.0, -200.0]),
                        np.array([25_000, 25_000]), 25e6, 0.25, np.zeros(2, int))
    np.testing.assert_allclose(r.prompt, ref[:, 1], rtol=TOL, atol=TOL * np.sqrt(25_000))
    with pytest.raises(UnknownPrnError, match="64"):
        bank.correlate(x, [6, 64], 0.0, 10.23e6, 0.0, 0.0, 25_000)
    with pytest.raises(UnknownPrnError):
        bank.correlate(x, [0], 0.0, 10.23e6, 0.0, 0.0, 25_000)
    with pytest.raises(ValueError, match="inside"):
        bank.correlate(x, [6], 0.0, 10.23e6, 0.0, 0.0, 25_000, start_sample=10_000)
    with pytest.raises(ValueError, match="spacing"):
        correlate(x, table[6], 0.0, 10.23e6, 0.0, 0.0, 100, 25e6, spacing_chips=9.0)


def test_b3i_codes_through_the_bank():
    bank = Correlator(25e6)  # default code source: sdr_di.signal.codes.b3i_code
    c6 = np.asarray(b3i_code(6))
    n, fs = 25_000, 25e6
    k = np.arange(n)
    x = c6[np.floor(100.5 + k * 10.23e6 / fs).astype(int) % L].astype(np.complex64)
    r = bank.correlate(x, [6, 7], 100.5, 10.23e6, 0.0, 0.0, n)
    assert abs(r.prompt[0] - n) < 1e-3 * n and abs(r.prompt[1]) < 0.05 * n


@pytest.mark.parametrize(("fs", "complex_input", "dtype", "spacing"), [
    (25e6, True, np.int8, 0.5),  # the default scenario's file
    (20e6, False, np.int16, 0.3),  # real IF
    (5e6, True, np.float32, 1.0),  # > 1 chip per sample: runs shorter than a block
    (25e6, False, np.int8, 0.0),
])
def test_receiver_kernel_on_stored_samples_matches_numpy_reference(fs, complex_input, dtype,
                                                                     spacing):
    """The receiver's bit-window kernel on stored (integer) samples equals the reference."""
    rng = np.random.default_rng(int(fs) % 1000 + int(10 * spacing))
    n_ch, n_block = 5, 60_000
    n_comp = 2 if complex_input else 1
    xs = rng.integers(-100, 100, n_block * n_comp).astype(dtype)
    x = xs.astype(np.float32)
    if complex_input:
        x = x.view(np.complex64)
    codes = rng.choice(np.array([-1, 1], np.int8), size=(n_ch, L))
    theta0 = rng.uniform(0, L, n_ch)
    rate = 10.23e6 * (1.0 + rng.uniform(-5e-5, 5e-5, n_ch))
    phi0 = rng.uniform(0, 1, n_ch)
    fc = rng.uniform(-6e3, 6e3, n_ch) + (0.0 if complex_input else 5e6)
    n = rng.integers(20_000, 50_000, n_ch)
    start = np.array([rng.integers(0, n_block - m + 1) for m in n])
    dphi = fc / fs
    arg = np.outer(dphi, np.arange(CARRIER_BLOCK))
    arg = 2 * np.pi * (arg - np.floor(arg))
    ref = reference_epl(x, codes, theta0, rate, phi0, fc, n, fs, spacing, start)
    scale = np.sqrt(n.max())
    for n_sub in (1, 3):
        out = np.empty((n_ch, 3, 2))
        # tables shared through the row indices: replica rows reversed, rotation rows as given
        idx = np.arange(n_ch, dtype=np.int64)
        correlate_epl_bits(xs, n_comp, bit_windows(padded_replicas(codes[::-1])), idx[::-1].copy(),
                           CODE_PAD, L, start.astype(np.int64), n.astype(np.int64), theta0,
                           rate / fs, phi0, dphi, np.cos(arg), -np.sin(arg), idx, spacing, n_sub,
                           out)
        got = out[..., 0] + 1j * out[..., 1]
        np.testing.assert_allclose(got, ref, rtol=TOL, atol=TOL * scale)
    assert mean_power(xs, n_comp) == pytest.approx(np.mean(np.abs(x.astype(complex)) ** 2),
                                                    rel=1e-12)


def _stored_case(rng, fs, complex_input, dtype, n_ch=5, n_block=60_000):
    """Stored samples (``dtype``, I/Q interleaved when complex) and random NCO rows for the
    receiver's kernel entry, with their float64 reference sums."""
    n_comp = 2 if complex_input else 1
    xs = rng.integers(-100, 100, n_block * n_comp).astype(dtype)
    x = xs.astype(np.float32)
    if complex_input:
        x = x.view(np.complex64)
    codes = rng.choice(np.array([-1, 1], np.int8), size=(n_ch, L))
    theta0 = rng.uniform(0, L, n_ch)
    rate = 10.23e6 * (1.0 + rng.uniform(-5e-5, 5e-5, n_ch))
    phi0 = rng.uniform(0, 1, n_ch)
    fc = rng.uniform(-6e3, 6e3, n_ch) + (0.0 if complex_input else fs / 4)
    n = rng.integers(20_000, 50_000, n_ch)
    start = np.array([rng.integers(0, n_block - m + 1) for m in n])
    rot_re, rot_im = carrier_rotation(fc / fs)
    idx = np.arange(n_ch, dtype=np.int64)
    args = (xs, n_comp, bit_windows(padded_replicas(codes)), idx, CODE_PAD, L,
            start.astype(np.int64), n.astype(np.int64), theta0, rate / fs, phi0, fc / fs,
            rot_re, rot_im, idx)
    return args, x, codes, theta0, rate, phi0, fc, n, start


@pytest.mark.parametrize(("fs", "complex_input", "dtype", "spacing"), [
    (2.5e6, True, np.int8, 0.5),    # the studies' files
    (2.5e6, True, np.float32, 0.0),
    (5e6, False, np.int16, 1.0),    # real IF
    (2.5e6, True, np.int8, 3.0),    # a wide spacing: E and L 6 chips apart in one word
])
def test_gather_kernel_matches_numpy_reference(fs, complex_input, dtype, spacing):
    """The low-rate kernel (one bit-window word per sample) equals the float64 reference
    within the float32 kernel's tolerance, for any task split."""
    rng = np.random.default_rng(int(fs) % 997 + int(10 * spacing))
    args, x, codes, theta0, rate, phi0, fc, n, start = _stored_case(rng, fs, complex_input,
                                                                     dtype)
    ref = reference_epl(x, codes, theta0, rate, phi0, fc, n, fs, spacing, start)
    scale = np.sqrt(n.max()) * 100
    for n_sub in (1, 3):
        out = np.empty((n.size, 3, 2))
        correlate_epl_gather(*args, spacing, n_sub, out)
        got = out[..., 0] + 1j * out[..., 1]
        np.testing.assert_allclose(got, ref, rtol=TOL, atol=TOL * scale)


def test_gather_kernel_dispatch_and_agreement_with_float_kernel(monkeypatch):
    """Below about 10.6 MHz the kernel entry takes the low-rate kernel (unless forced off),
    at 25 MHz the float32 one; at 2.5 MHz the two differ only by float32 rounding (their
    sums run over other spans), well within 2e-6 of the sums' noise level, and the low-rate
    kernel is not the float32 one by another name."""
    assert _numba_correlate_bits.gather_kernel_pays(0.5, 10.23e6 / 2.5e6)
    assert _numba_correlate_bits.gather_kernel_pays(0.5, 10.23e6 / 10e6)
    assert not _numba_correlate_bits.gather_kernel_pays(0.5, 10.23e6 / 12.5e6)
    assert not _numba_correlate_bits.gather_kernel_pays(0.5, 10.23e6 / 25e6)
    rng = np.random.default_rng(12)
    args, *_, n, _ = _stored_case(rng, 2.5e6, True, np.int8)
    o_gat, o_flt, o_disp, o_forced = (np.empty((n.size, 3, 2)) for _ in range(4))
    correlate_epl_gather(*args, 0.5, 1, o_gat)
    _numba_correlate_bits.correlate_epl_float(*args, 0.5, 1, o_flt)
    monkeypatch.setattr(_numba_correlate_bits, "GATHER_PATH", True)
    correlate_epl_bits(*args, 0.5, 1, o_disp)
    monkeypatch.setattr(_numba_correlate_bits, "GATHER_PATH", False)
    correlate_epl_bits(*args, 0.5, 1, o_forced)
    np.testing.assert_array_equal(o_disp, o_gat)
    np.testing.assert_array_equal(o_forced, o_flt)
    assert not np.array_equal(o_gat, o_flt)
    noise = 100 * np.sqrt(n)[:, None, None]
    assert np.abs(o_gat - o_flt).max() / noise.min() < TOL


@pytest.mark.parametrize("kind", ["complex128", "float64", "int16", "int8", "strided_complex64"])
def test_public_api_sample_types_match_numpy_reference(kind):
    """Every sample type of :func:`correlate` reaches the bit-window kernel correctly: float64
    and complex128 (float64 view), stored integers (read directly), a strided complex64 view
    (made contiguous)."""
    rng = np.random.default_rng(21)
    complex_input = kind.startswith(("complex", "strided"))
    x, codes, theta0, rate, phi0, fc, n, fs, start = _random_case(rng, 3, complex_input)
    n = np.minimum(n, 12_000)  # intervals stay inside the block
    if kind == "complex128":
        x = x.astype(np.complex128) + 1e-3j  # a value not representable in complex64
    elif kind == "float64":
        x = x.astype(np.float64) + 1e-9
    elif kind in ("int16", "int8"):
        x = np.clip(np.rint(x * 20), -127, 127).astype(kind)
    else:
        x = np.repeat(x, 2)[::2]
        assert not x.flags.c_contiguous
    res = correlate(x, codes, theta0, rate, phi0, fc, n, fs, start_sample=start)
    ref = reference_epl(x, codes, theta0, rate, phi0, fc, n, fs, 0.5, start)
    got = np.stack([res.early, res.prompt, res.late], axis=1)
    scale = np.sqrt(n.max()) * (20 if kind.startswith("int") else 1)
    np.testing.assert_allclose(got, ref, rtol=TOL, atol=TOL * scale)


def test_bit_windows_match_their_definition():
    rng = np.random.default_rng(4)
    tab = padded_replicas(rng.choice(np.array([-1, 1], np.int8), size=(2, 150)))
    bits = bit_windows(tab)
    assert bits.shape == (2, tab.shape[1] + 64) and bits.dtype == np.uint64
    neg = np.zeros((2, tab.shape[1] + 128), bool)
    neg[:, :tab.shape[1]] = tab < 0
    for j in (0, 1, 63, 100, tab.shape[1] - 1, tab.shape[1] + 63):
        want = sum(int(neg[0, j + b]) << b for b in range(64))
        assert int(bits[0, j]) == want
        assert int(bits[1, j]) == sum(int(neg[1, j + b]) << b for b in range(64))
    np.testing.assert_array_equal(bit_windows(tab[1]), bits[1:])


def test_carrier_rotation_tables_are_the_rounded_phasors():
    """The tables (angle addition of anchor and in-span phasors, each by float64 complex
    steps from two libm phasors a row) lie within half a float32 ulp of the phasors of the
    reduced phase, up to the float64 phase's own uncertainty (the reduction of ``m dphi``
    leaves ~256 * 0.5 * 2^-52 cycle, 2e-13 rad, which matters only where a value is near 0
    and its float32 ulp is smaller still) and the steps' rounding (about 1e-14), differ from
    their directly rounded values in at most a few entries in a million (values near 0 by
    at most 1e-14), and round to the integer kernel's tables ``rint(127 v)`` exactly as the
    directly rounded values do."""
    rng = np.random.default_rng(12)
    dphi = np.concatenate([rng.uniform(-0.5, 0.5, 1500), (1.5e6 + rng.normal(0, 5e3, 500)) / 25e6,
                           [0.0, 1e-9, -0.25, 0.125]])
    rot_re, rot_im = carrier_rotation(dphi)
    assert rot_re.shape == rot_im.shape == (dphi.size, CARRIER_BLOCK)
    assert rot_re.dtype == rot_im.dtype == np.float32
    arg = np.multiply.outer(dphi, np.arange(CARRIER_BLOCK, dtype=float))
    arg = 2 * np.pi * (arg - np.floor(arg))
    exact_re, exact_im = np.cos(arg), -np.sin(arg)
    for got, exact in ((rot_re, exact_re), (rot_im, exact_im)):
        half_ulp = 0.5 * np.spacing(np.abs(exact).astype(np.float32)).astype(float)
        assert np.all(np.abs(got - exact) <= half_ulp * (1 + 1e-6) + 2e-13)
        direct = exact.astype(np.float32)
        # the bits of values near 0 (quarter-cycle phases of the special steps) follow the
        # steps' rounding, ~1e-15 where libm's cos(pi / 2) gives 6e-17: equal to 1e-14 there
        tiny = np.abs(exact) < 1e-9
        assert np.all(np.abs(got[tiny] - direct[tiny]) <= 1e-14)
        assert np.count_nonzero(got[~tiny] != direct[~tiny]) <= 5e-6 * got.size
        np.testing.assert_array_equal(np.rint(ROT_SCALE * got.astype(float)),
                                      np.rint(ROT_SCALE * direct.astype(float)))
    assert rot_re[:, 0].tolist() == [1.0] * dphi.size and not np.any(rot_im[:, 0])


def test_correlator_keeps_bit_windows_per_prn_list():
    rng = np.random.default_rng(6)
    table = {p: rng.choice(np.array([-1, 1], np.int8), size=L) for p in (3, 5)}
    bank = Correlator(25e6, code_source=lambda p: table[p])
    x = (rng.normal(size=20_000) + 1j * rng.normal(size=20_000)).astype(np.complex64)
    args = (x, [3, 5], [10.0, 20.5], 10.23e6, 0.0, [100.0, -200.0], 20_000)
    r1 = bank.correlate(*args)
    bits = bank._bits
    r2 = bank.correlate(*args)
    assert bank._bits is bits  # same PRN list: not packed again
    np.testing.assert_array_equal(r1.prompt, r2.prompt)
    r3 = bank.correlate(x, [5, 3], [20.5, 10.0], 10.23e6, 0.0, [-200.0, 100.0], 20_000)
    assert bank._bits is not bits
    np.testing.assert_allclose(r3.prompt[::-1], r1.prompt, rtol=1e-12)
    ref = correlate(x, np.stack([table[3], table[5]]), [10.0, 20.5], 10.23e6, 0.0,
                    [100.0, -200.0], 20_000, 25e6)
    np.testing.assert_array_equal(r1.prompt, ref.prompt)


def test_row_split_on_two_threads_is_identical_to_one_call():
    """KernelThreads.run_rows: rows split between the caller and a worker thread give the
    same bytes as one call on one thread, whatever the split (receiver.threads notes)."""
    from sdr_di.receiver.threads import KernelThreads, balanced_cuts

    assert balanced_cuts([1, 1, 1, 1], 2) == [0, 2, 4]
    assert balanced_cuts([10, 1, 1, 1], 2) == [0, 1, 4]
    assert balanced_cuts([5], 2) == [0, 1]
    rng = np.random.default_rng(12)
    n_rows, n_block = 9, 40_000
    xs = rng.integers(-8, 8, 2 * n_block).astype(np.int8)
    bits = bit_windows(padded_replicas(rng.choice(np.array([-1, 1], np.int8), size=(3, L))))
    tab = rng.integers(0, 3, n_rows).astype(np.int64)
    n = rng.integers(1_000, 30_000, n_rows).astype(np.int64)
    start = np.array([rng.integers(0, n_block - m) for m in n], np.int64)
    theta0, phi0 = rng.uniform(0, L, n_rows), rng.uniform(0, 1, n_rows)
    dchip = np.full(n_rows, 10.23e6 / 25e6)
    dphi = rng.uniform(-6e3, 6e3, n_rows) / 25e6
    arg = np.outer(dphi, np.arange(CARRIER_BLOCK))
    rot_re, rot_im = np.cos(2 * np.pi * (arg - np.floor(arg))), -np.sin(2 * np.pi * (arg - np.floor(arg)))
    ridx = np.arange(n_rows, dtype=np.int64)

    def run(threads):
        out = np.full((n_rows, 3, 2), np.nan)

        def rows_ab(a, b):
            correlate_epl_bits(xs, 2, bits, tab[a:b], CODE_PAD, L, start[a:b], n[a:b],
                               theta0[a:b], dchip[a:b], phi0[a:b], dphi[a:b], rot_re, rot_im,
                               ridx[a:b], 0.5, 1, out[a:b])

        kt = KernelThreads(threads)
        calls = []
        used = [kt.run_rows(rows_ab, n, before=b) for b in (None, calls.append)]
        assert len(calls) == 1       # `before` runs once, on the caller
        return out, used

    one, used1 = run(1)
    two, used2 = run(2)
    assert used1 == [1, 1] and used2 == [min(2, KernelThreads().max_threads)] * 2
    assert np.all(np.isfinite(one))
    np.testing.assert_array_equal(two, one)


def test_row_split_runs_before_after_the_callers_part():
    """run_rows' `before` runs on the caller after its own part of the rows, while the worker
    is in its kernel (receiver.threads: run first, it held the GIL the worker needed to
    start), and is given the end of that part; the worker takes the rest."""
    import threading

    import numba

    from sdr_di.receiver.threads import KernelThreads

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two numba threads")
    me = threading.get_ident()
    events = []
    kt = KernelThreads(2)
    kt.run_rows(lambda a, b: events.append(("part", a, b, threading.get_ident() == me)),
                np.ones(10),
                before=lambda done: events.append(("before", done, threading.get_ident() == me)))
    mine = [e for e in events if e[-1]]
    assert [e[0] for e in mine] == ["part", "before"]
    # `before` is told the rows of the caller's part, all final by then
    assert mine[0][1] == 0 and mine[1][1] == mine[0][2]
    assert ("part", mine[0][2], 10, False) in events


def test_split_call_holds_background_work_until_its_workers_end():
    """While a split call runs (the caller's part and `before`, the worker's part, up to the
    caller's collecting it), wait_for_split_calls waits; a one-thread call does not hold it
    (the other core is free); after the call it returns at once. Background work (the IF
    read-ahead) waits on it."""
    import numba

    from sdr_di.receiver.threads import KernelThreads, wait_for_split_calls

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two numba threads")
    seen = []

    def part(a, b):
        seen.append(("part", wait_for_split_calls(0.0)))

    KernelThreads(2).run_rows(part, np.ones(10),
                              before=lambda done: seen.append(("before", wait_for_split_calls(0.0))))
    assert seen and not any(free for _, free in seen)
    assert wait_for_split_calls(0.0)
    seen.clear()
    KernelThreads(1).run_rows(part, np.ones(10))
    assert seen == [("part", True)]

    def failing(a, b):
        raise RuntimeError("kernel failed")

    with pytest.raises(RuntimeError):
        KernelThreads(2).run_rows(failing, np.ones(10))
    assert wait_for_split_calls(0.0)        # released on failure too


def _burn(seconds: float) -> None:
    """Spend ``seconds`` of this thread's CPU time."""
    import time

    t = time.thread_time()
    while time.thread_time() - t < seconds:
        pass


def test_detached_call_leaves_the_workers_part_running_until_waited():
    """start_rows(detach=True) returns when the caller's part and `before` are done, the
    worker's part still running (held here until released); the split call counts as
    running until the worker ends, and wait() gives the thread count once its rows are
    final (receiver.threads, *Calls left running*). A worker's exception is raised by
    wait()."""
    import threading

    import numba

    from sdr_di.receiver.threads import KernelThreads, wait_for_split_calls

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two numba threads")
    me = threading.get_ident()
    release = threading.Event()
    done = np.zeros(10, bool)

    def part(a, b):
        if threading.get_ident() != me:
            assert release.wait(30)
        done[a:b] = True

    rc = KernelThreads(2).start_rows(part, np.ones(10), before=lambda n: None, detach=True)
    assert 0 < done.sum() < 10          # the caller's part only
    assert not wait_for_split_calls(0.0)
    release.set()
    assert rc.wait() == 2 and rc.wait() == 2
    assert done.all() and wait_for_split_calls(0.0)

    def failing(a, b):
        if threading.get_ident() != me:
            raise RuntimeError("kernel failed")

    rc = KernelThreads(2).start_rows(failing, np.ones(10), detach=True)
    with pytest.raises(RuntimeError, match="kernel failed"):
        rc.wait()
    assert wait_for_split_calls(0.0)


def test_detached_calls_give_the_worker_the_callers_work_between_them(monkeypatch):
    """Between detached calls the caller's CPU time (here the time of 10 of the 40 rows)
    shortens its next part (K - T_g) / 2, from 20 rows to 15, so the worker's part ends
    with it; a call that is not detached splits evenly again. The CPU clock KernelThreads
    reads (``time.thread_time``) is the test's own per-thread clock, advanced by the work
    it stands for: with the real clock, two Python threads burning CPU under a loaded
    machine's GIL hand-offs made the part 11 rows once in a CI run."""
    import threading
    import time

    import numba

    from sdr_di.receiver.threads import KernelThreads

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("needs two numba threads")
    clock = threading.local()

    def spend(seconds: float) -> None:
        clock.t = getattr(clock, "t", 0.0) + seconds

    monkeypatch.setattr(time, "thread_time", lambda: getattr(clock, "t", 0.0))
    row_s = 2.0 ** -13                  # CPU of one row (binary fractions: exact sums)
    me = threading.get_ident()
    mine = []

    def part(a, b):
        if threading.get_ident() == me:
            mine.append(b - a)
        spend(row_s * (b - a))

    kt = KernelThreads(2)
    for _ in range(5):
        rc = kt.start_rows(part, np.ones(40), detach=True)
        spend(10 * row_s)               # the caller's work between the calls
        rc.wait()
    kt.run_rows(part, np.ones(40))
    assert mine == [20, 15, 15, 15, 15, 20]


def test_thread_choice_is_made_per_call_size(monkeypatch):
    """KernelThreads keeps its costs per size class of the call: one thread measured cheaper
    on small calls (a worker's wake-up weighs on 1 ms blocks) does not decide the large
    ones, where the split was measured cheaper (receiver.threads notes: with one cost for
    all sizes, the deep start-up ran most of its 20 ms blocks on one thread)."""
    from sdr_di.receiver.threads import ENV_THREADS, KernelThreads

    monkeypatch.delenv(ENV_THREADS, raising=False)
    kt = KernelThreads()
    m = kt.max_threads
    if m < 2:
        pytest.skip("needs two numba threads")
    small, large = 1.5 * 2**20, 2**23    # samples per call, both large enough to split
    cost = {(small, 1): 1e-9, (small, m): 5e-9, (large, 1): 2e-9, (large, m): 1e-9}

    def call(work):
        t = kt.pick(work)
        kt.record(t, cost[(work, t)])
        return t

    # each size class measures one thread, then the split (the first call of a setting
    # starts its thread and is not counted)
    assert [call(small) for _ in range(4)] == [1, 1, m, m]
    assert [call(large) for _ in range(2)] == [1, m]
    assert call(large) == m and call(small) == 1 and call(large) == m
    assert kt.costs[int(np.log2(small))] == pytest.approx({1: 1e-9, m: 5e-9})
    assert kt.costs[int(np.log2(large))] == pytest.approx({1: 2e-9, m: 1e-9})


def test_small_calls_run_on_one_thread(monkeypatch):
    """A call of fewer than SPLIT_MIN_SAMPLES samples runs on the caller, even where the
    split measured cheaper per call (receiver.threads, *Small calls on one thread*: whole
    2.5 and 5 MHz runs took 20-55 % more CPU split); a call of that many samples may still
    split; a fixed thread count (SDR_DI_KERNEL_THREADS) is kept for every size."""
    from sdr_di.receiver.threads import ENV_THREADS, SPLIT_MIN_SAMPLES, KernelThreads

    monkeypatch.delenv(ENV_THREADS, raising=False)
    kt = KernelThreads()
    m = kt.max_threads
    if m < 2:
        pytest.skip("needs two numba threads")
    for work in (SPLIT_MIN_SAMPLES - 1, float(SPLIT_MIN_SAMPLES)):
        kt.costs[int(np.log2(work))] = {1: 3e-9, m: 1e-9}     # the split cheaper
    assert {kt.pick(SPLIT_MIN_SAMPLES - 1) for _ in range(600)} == {1}
    assert kt.pick(float(SPLIT_MIN_SAMPLES)) == m
    assert KernelThreads(2).pick(1e3) == min(2, m)


def _split_in_child():
    from sdr_di.receiver.threads import KernelThreads

    parts = []
    KernelThreads(2).run_rows(lambda a, b: parts.append((a, b)), np.ones(10))
    return sorted(parts)


def test_row_split_works_in_a_forked_child():
    """A child forked after the parent started the kernel worker makes its own worker (the
    inherited pool has no threads: submitting to it would wait forever)."""
    import multiprocessing as mp

    import numba

    from sdr_di.receiver.threads import _pool

    if numba.config.NUMBA_NUM_THREADS < 2 or "fork" not in mp.get_all_start_methods():
        pytest.skip("needs two numba threads and fork")
    _pool(1).submit(lambda: None).result()
    with mp.get_context("fork").Pool(1) as p:
        assert p.apply_async(_split_in_child).get(timeout=30) == [(0, 5), (5, 10)]


def _split_calls_free_in_child():
    from sdr_di.receiver.threads import wait_for_split_calls

    return wait_for_split_calls(0.0)


def test_forked_child_does_not_inherit_the_parents_split_call():
    """A child forked while the parent is inside a split call starts with none running (its
    read-ahead would otherwise wait on a call that never ends in the child)."""
    import multiprocessing as mp

    from sdr_di.receiver import threads

    if "fork" not in mp.get_all_start_methods():
        pytest.skip("needs fork")
    threads._split_call(True)
    try:
        assert not threads.wait_for_split_calls(0.0)
        with mp.get_context("fork").Pool(1) as p:
            assert p.apply_async(_split_calls_free_in_child).get(timeout=30)
    finally:
        threads._split_call(False)
    assert threads.wait_for_split_calls(0.0)


def test_block_sum_squares_equals_plain_sums():
    """block_sum_squares (int64 sums): the float64 sums of squares of each block, short last
    block included, with the extreme 8-bit values."""
    from sdr_di.receiver._numba_correlate_bits import block_sum_squares

    rng = np.random.default_rng(7)
    x = rng.integers(-128, 128, 3 * 4096 + 123).astype(np.int8)
    x[:4096] = -128                       # a full block at the largest square
    out = np.empty(4)
    block_sum_squares(x, 4096, out)
    want = [float(np.sum(x[i:i + 4096].astype(np.float64) ** 2)) for i in range(0, x.size, 4096)]
    np.testing.assert_array_equal(out, want)


#: Sums of one correlator kernel (``sys.argv[1]``: float32 samples, or int8) on fixed random
#: data, printed as a digest: run by :func:`test_kernels_compiled_here_equal_the_cached_ones`.
_KERNEL_DIGEST = """
import hashlib, sys
import numpy as np
from sdr_di.receiver.correlator import correlate_table, padded_replicas
rng = np.random.default_rng(3)
codes = padded_replicas(np.where(rng.random((5, 10230)) < 0.5, -1.0, 1.0))
z = (rng.normal(size=40000) + 1j * rng.normal(size=40000)) * 20
x = z.astype(np.complex64) if sys.argv[1] == "float32" else \\
    np.clip(z.real, -127, 127).astype(np.int8)
fs = float(sys.argv[2])
h = hashlib.sha1()
for k in range(3):
    r = correlate_table(x, codes, 10230, rng.uniform(0, 10230, 5), 10.23e6 + rng.normal(size=5),
                        rng.random(5), rng.normal(size=5) * 3000, round(fs / 1e3), fs, 0.5,
                        start_sample=rng.integers(0, 15000, 5))
    for v in (r.early, r.prompt, r.late):
        h.update(np.ascontiguousarray(v).tobytes())
print(h.hexdigest())
"""


@pytest.mark.parametrize("kind, kernel, fs", [("float32", "correlate_epl_float", 25e6),
                                              ("int8", "correlate_epl_int8", 25e6),
                                              ("int8", "correlate_epl_gather", 2.5e6)])
def test_kernels_compiled_here_equal_the_cached_ones(tmp_path, kind, kernel, fs):
    """A kernel compiled in this process and the same kernel loaded from numba's cache by the
    next one give the same sums bit for bit, so a run's outputs do not depend on whether it
    is the first after an install (module notes of ``receiver._numba_correlate_bits``:
    the ``contract`` fast-math flag made the float32 kernel's first run differ)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def digest() -> str:
        res = subprocess.run([sys.executable, "-c", _KERNEL_DIGEST, kind, str(fs)],
                             capture_output=True,
                             text=True, env=env, timeout=300)
        assert res.returncode == 0, res.stderr
        return res.stdout.strip()

    compiled = digest()
    assert list((tmp_path / "cache").rglob(f"*{kernel}*.nbi")), "nothing cached"
    assert digest() == compiled
