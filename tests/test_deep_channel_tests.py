"""The vector loop's channel tests and pre-filters of a pass in one kernel call each: the
same values, bit for bit, as the plain per-channel forms (BitPower, PostCorrelationNoise,
the tests' logic, PreFilterBank.process_blocks), and numpy's sums in the kernels."""

import math

import numpy as np
import pytest

from sdr_di.deep.bit_power import BitPower
from sdr_di.deep.channel_tests import CN0_MIN_MS, FAST_MS, LOSS_MS, ChannelTests
from sdr_di.deep.discriminators import DiscriminatorBank
from sdr_di.deep.prefilter import PreFilterBank, ResetPreFilterBank, coherent_blocks_of_channels
from sdr_di.receiver.pairwise_sums import (pairwise_sum, pairwise_sum_complex,
                                         pairwise_sum_squares, segment_sum,
                                         segment_sum_complex)
from sdr_di.receiver.lock import PostCorrelationNoise

LENGTHS = list(range(0, 140)) + [255, 256, 257, 999, 1000, 1001, 2049]


def _bits(x):
    return np.ascontiguousarray(np.atleast_1d(x)).view(np.uint8).tobytes()


def test_kernel_sums_are_numpys_bit_for_bit():
    rng = np.random.default_rng(7)
    for n in LENGTHS:
        a = rng.standard_normal(n + 3) * 10.0 ** rng.uniform(-4, 4, n + 3)
        c = (rng.standard_normal(n + 3) + 1j * rng.standard_normal(n + 3)) * 10.0 ** \
            rng.uniform(-4, 4, n + 3)
        lo = 2
        assert pairwise_sum(a, lo, n) == np.add.reduce(a[lo:lo + n]), n
        sq = a[lo:lo + n] * a[lo:lo + n]
        assert pairwise_sum_squares(a, lo, n) == np.add.reduce(sq), n
        assert pairwise_sum_complex(c, lo, n) == np.add.reduce(c[lo:lo + n]), n
        if n:
            assert segment_sum_complex(c, lo, n) == np.add.reduceat(c[lo:lo + n], [0])[0], n
            assert segment_sum(a, lo, n) == np.add.reduceat(a[lo:lo + n], [0])[0], n
    # signed zeros: reduce starts from its identity, a reduceat segment from its first value
    for n in (1, 2, 3, 9, 200):
        z = np.full(n, -0.0)
        zc = np.full(n, complex(-0.0, -0.0))
        assert _bits(pairwise_sum(z, 0, n)) == _bits(np.add.reduce(z))
        assert _bits(pairwise_sum_squares(z, 0, n)) == _bits(np.add.reduce(z * z))
        assert _bits(pairwise_sum_complex(zc, 0, n)) == _bits(np.add.reduce(zc))
        assert _bits(segment_sum_complex(zc, 0, n)) == _bits(np.add.reduceat(zc, [0]))
        assert _bits(segment_sum(z, 0, n)) == _bits(np.add.reduceat(z, [0]))
    # a plain left-to-right sum differs: the test can tell the orders apart
    a = rng.standard_normal(1000) * 10.0 ** rng.uniform(-4, 4, 1000)
    plain = 0.0
    for v in a:
        plain += v
    assert plain != pairwise_sum(a, 0, a.size) or plain != np.add.reduce(a)


def _reference_tests(power: BitPower, noise: PostCorrelationNoise, st: dict, prompts, nsamp,
                     bit_start, vals, input_power, fs, bit_ms, fast_thr, loss_thr) -> None:
    """The tests of one channel and interval in their plain form (the vector loop's
    ``_test_channel`` of session 26: BitPower, PostCorrelationNoise and the logic)."""
    noise.add_values(vals)
    npow = noise.noise_power(input_power)
    power.add(prompts, nsamp, bit_start)
    st["new"] = power.new
    if power.new:
        fast = power.cn0_dbhz(npow, fs, last=FAST_MS // bit_ms)
        st["ff"] = 0 if fast >= fast_thr else 1
        if st["ff"] and not power.cn0_dbhz(npow, fs, last=LOSS_MS // bit_ms) >= loss_thr:
            st["ff"] = 2
        st["tested"] = power.count
        if st["ff"] >= 2:
            power.clear()
            st["cn0"] = math.nan
            st["rej"] = True
        elif st["ff"] == 0 and power.count >= (
                power.p.size if st["rej"] else CN0_MIN_MS // bit_ms):
            st["rej"] = False
            st["cn0"] = power.cn0_dbhz(npow, fs)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_channel_tests_equal_the_plain_forms_bit_for_bit(seed):
    """Random passes over D1 and D2 channels through fades (the fast test fails, the loss
    test empties the window, the channel rejoins), a jammer (the noise rings replace the
    input power), epochs without a noise value, intervals without epochs, rings that wrap
    and a pass longer than a noise ring."""
    rng = np.random.default_rng(seed)
    fs, window = 2.5e6, 200
    bit_ms = [20, 2, 20, 2, 20]
    n = len(bit_ms)
    small = PostCorrelationNoise(n_values=40, z=6.0, min_values=20)
    bank = ChannelTests(bit_ms, window, fs, 17.0 - 3.0, 17.0 - 6.0, noise=small)
    powers = [BitPower(max(window // b, 2)) for b in bit_ms]
    noises = []
    for i in range(n):
        nz = PostCorrelationNoise(n_values=40, z=6.0, min_values=20)
        nz.add_values(rng.uniform(0.5, 1.5, int(rng.integers(0, 60))))
        bank.take_noise(i, nz)
        noises.append(nz)
    st = [{"cn0": 40.0, "rej": False, "ff": 0, "new": 0, "tested": 0} for _ in range(n)]
    cn0 = np.array([s["cn0"] for s in st])
    rej = np.zeros(n, bool)
    ff = np.zeros(n, np.int64)
    epoch = rng.integers(0, 40, n)
    lost = set()
    n_lost = n_jam = 0
    for k in range(400):
        jam = 150 <= k < 250
        counts = [int(rng.choice([0, 1, 19, 20, 21, 45])) if rng.random() < 0.9 else 0
                  for _ in range(n)]
        m = sum(counts)
        eps = np.concatenate([epoch[i] + np.arange(counts[i]) for i in range(n)]
                             ).astype(np.int64)
        for i in range(n):
            epoch[i] += counts[i]
        nsamp = rng.integers(2490, 2510, m).astype(np.int64)
        amp = []
        for i in range(n):
            fade = (k // 40 + i) % 4 == 3            # the signal goes, then comes back
            a = 0.0 if fade else 10.0 ** rng.uniform(-0.3, 0.6)
            amp += [a] * counts[i]
        sig = np.array(amp) * np.exp(1j * rng.uniform(0, 0.1, m)) * np.sqrt(nsamp)
        prompts = sig + (rng.standard_normal(m) + 1j * rng.standard_normal(m)) * \
            np.sqrt(nsamp / 2 * (4.0 if jam else 1.0) * 1e-3)
        bits = np.repeat(bit_ms, counts)
        bit_start = eps % bits == 0
        vals = rng.exponential(4.0 if jam else 1.0, m)
        ok = rng.random(m) > 0.05
        inp = float(rng.uniform(0.9, 1.1))
        if m >= 1 and k == 100:
            ok[:] = True                         # every value: a pass longer than a ring
        bank.run(0, np.array(counts), prompts, nsamp, bit_start, vals, ok, inp, cn0, rej, ff)
        s = 0
        for i in range(n):
            sl = slice(s, s + counts[i])
            if counts[i]:
                _reference_tests(powers[i], noises[i], st[i], prompts[sl], nsamp[sl],
                                 bit_start[sl], vals[sl][ok[sl]], inp, fs, bit_ms[i],
                                 17.0 - 3.0, 17.0 - 6.0)
                assert bank.new[i] == st[i]["new"]
                if st[i]["new"]:
                    assert bank.count_tested[i] == st[i]["tested"]
            else:
                assert bank.new[i] == 0
            s += counts[i]
            assert _bits(cn0[i]) == _bits(np.float64(st[i]["cn0"])), (k, i)
            assert ff[i] == st[i]["ff"] and rej[i] == st[i]["rej"], (k, i)
            size = powers[i].p.size
            cnt = powers[i].count
            assert bank.count[i] == cnt
            assert _bits(bank.p[i, size - cnt:size]) == _bits(powers[i].p[size - cnt:])
            assert _bits(bank.n[i, size - cnt:size]) == _bits(powers[i].n[size - cnt:])
            assert bank.acc_p[i] == powers[i]._acc_p and bank.acc_n[i] == powers[i]._acc_n
            values, next_slot = noises[i].ring()
            assert bank.nz_count[i] == noises[i].count and bank.nz_i[i] == next_slot
            assert _bits(bank.nz_v[i]) == _bits(values)
            if ff[i] == 2 and i not in lost:
                lost.add(i)
                n_lost += 1
            if jam and noises[i].noise_power(inp) != inp:
                n_jam += 1
    # the paths the test is for were taken
    assert n_lost >= 3 and n_jam > 0
    assert any(s["rej"] is False and math.isfinite(s["cn0"]) for s in st)


@pytest.mark.parametrize("bank_of", [
    lambda: PreFilterBank(4, 0.5),
    lambda: ResetPreFilterBank(4, 0.5),
    lambda: DiscriminatorBank(4, 0.5),
])
def test_prefilters_of_a_pass_equal_the_channel_by_channel_form(bank_of):
    rng = np.random.default_rng(5)
    a, b = bank_of(), bank_of()
    for k in range(60):
        counts = [int(v) for v in rng.choice([0, 20, 21, 40], 3)]
        m = sum(counts)
        E, P, L = ((rng.standard_normal(m) + 1j * rng.standard_normal(m)) * 30 + w
                   for w in (60, 100, 40))
        t = rng.uniform(0.9995e-3, 1.0005e-3, m)
        starts = rng.random(m) < 0.1
        cn0 = [float(10.0 ** (rng.uniform(2.5, 4.5))) for _ in counts]
        Eb, Pb, Lb, Tb, bounds = coherent_blocks_of_channels(E, P, L, t, starts, counts)
        a.process_channels(1, counts, bounds, Eb, Pb, Lb, Tb, cn0)
        for q, cnt in enumerate(counts):
            if cnt:
                bl = slice(bounds[q], bounds[q + 1])
                b.process_blocks(1 + q, Eb[bl], Pb[bl], Lb[bl], Tb[bl], cn0[q])
        for name in ("x", "P", "C", "nis", "nis_p", "out", "x_bar", "P_bar", "unfitted"):
            if hasattr(a, name):
                assert _bits(getattr(a, name)) == _bits(getattr(b, name)), (k, name)
        if k % 7 == 6:
            for bank in (a, b):
                bank.shift(2, 0.01, 0.5)
                if hasattr(bank, "decorrelate"):
                    bank.decorrelate(1)


@pytest.mark.parametrize("block_ms", [20, 10, 5, 1])
def test_pass_epochs_kernel_equals_the_numpy_form_bit_for_bit(block_ms):
    from sdr_di.deep.pass_epochs import pass_epochs_kernel_form, pass_epochs_numpy

    rng = np.random.default_rng(block_ms)
    for trial in range(30):
        bit_ms = [int(b) for b in rng.choice([20, 2], 5)]
        counts = [int(c) for c in rng.choice([0, 1, 19, 20, 21, 41], 5)]
        n_all = sum(counts) + 7
        out = rng.standard_normal((2 * n_all, 3, 2)) * 1e3
        out[3] = 0.0                              # a zero row
        epl = out.view(np.complex128)[..., 0]
        nh = rng.choice([-1.0, 1.0], n_all)
        n_noise = rng.integers(0, 3, n_all) * 400 if trial % 3 == 0 else \
            np.full(n_all, 1200, np.int64)
        nsamp = rng.integers(2490, 2510, n_all).astype(np.int64)
        epoch = np.concatenate([rng.integers(0, 10 ** 6) + np.arange(c) for c in counts]
                               + [np.arange(7)]).astype(np.int64)
        ms0 = [int(v) for v in rng.integers(0, 10 ** 8, 5) // 1000 * 1000]
        a0 = 3
        epoch = np.concatenate([np.arange(a0), epoch])[:n_all]
        a1 = a0 + sum(counts)
        got = pass_epochs_kernel_form(epl, a0, a1, nh, n_noise, nsamp, epoch, 2.5e6, counts,
                                      bit_ms, block_ms, ms0)
        ref = pass_epochs_numpy(epl, a0, a1, nh, n_noise, nsamp, epoch, 2.5e6, counts, bit_ms,
                                block_ms, ms0)
        for name in ("E", "P", "L", "ok", "bit_start", "nav_bits", "nav_sums", "nav_bounds"):
            assert _bits(getattr(got, name)) == _bits(getattr(ref, name)), (trial, name)
        assert _bits(got.noise[got.ok]) == _bits(ref.noise[ref.ok]), trial
        for q in range(4):
            assert _bits(got.blocks[q]) == _bits(ref.blocks[q]), (trial, q)
        assert list(got.blocks[4]) == list(ref.blocks[4]), trial
