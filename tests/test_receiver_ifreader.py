"""IF reader: every registry format round trip, chunking, memory mapping, error cases."""

import json
import os
import resource
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from sdr_di.errors import SampleFormatError
from sdr_di.io.sample_formats import FORMATS, get_format, pack_iq_int4, quantizer_levels
from sdr_di.receiver.ifreader import IfFileWarning, IfSource, check_format_statistics

#: Max (1960) quantizer step / sigma, as the generator uses (bits > 8: 4-sigma full scale).
MAX_STEP = {2: 0.9957, 3: 0.5860, 4: 0.3352, 5: 0.1881, 6: 0.1041, 7: 0.0568, 8: 0.0308}


def quantized_noise(rng, n, bits, is_complex):
    """Integer I, Q (or real) values as the generator writes them for ``bits`` bits."""
    lvl = quantizer_levels(bits)
    shape = (n, 2) if is_complex else (n, 1)
    x = rng.normal(size=shape)
    if bits == 1:
        q = np.where(x >= 0, 1, -1)
    else:
        step = MAX_STEP.get(bits, 4.0 / lvl)
        q = np.clip(np.floor(x / step + 0.5), -lvl, lvl)
    return q.astype(np.int64)


def encode(fmt_name, vals):
    """Bytes on disk of integer (n, 2) / (n, 1) values, or complex values for gr_complex."""
    f = get_format(fmt_name)
    if fmt_name == "iq_int4":
        return pack_iq_int4(vals[:, 0], vals[:, 1]).tobytes()
    if fmt_name == "gr_complex":
        return np.stack([vals.real, vals.imag], axis=1).astype("<f4").tobytes()
    return vals.astype(f.dtype).tobytes()


def expected(fmt_name, vals):
    f = get_format(fmt_name)
    if fmt_name == "gr_complex":
        return vals.astype(np.complex64)
    if f.is_complex:
        return (vals[:, 0] + 1j * vals[:, 1]).astype(np.complex64)
    return vals[:, 0].astype(np.float32)


def random_values(rng, fmt_name, n):
    f = get_format(fmt_name)
    if fmt_name == "gr_complex":
        return (rng.normal(size=n) + 1j * rng.normal(size=n)) * 0.01
    lo, hi = (-8, 8) if fmt_name == "iq_int4" else (np.iinfo(f.dtype).min,
                                                     np.iinfo(f.dtype).max + 1)
    return rng.integers(lo, hi, size=(n, 2 if f.is_complex else 1))


def write_sidecar(tmp_path, name, fmt, n, fs=25e6, if_hz=0.0, **extra):
    meta = {"schema": "sdr-di-if/1", "if_file": f"{name}.bin", "sampling_rate_hz": fs,
            "if_hz": if_hz, "sample_format": fmt, "n_samples": n,
            "start": {"week": 1234, "sow": 345600.5}, **extra}
    p = tmp_path / f"{name}.json"
    p.write_text(json.dumps(meta))
    return p


# peers' read-only formats: tests/test_io_peer_formats.py
@pytest.mark.parametrize("fmt", sorted(f for f in FORMATS if not FORMATS[f].peer))
def test_round_trip_every_format(tmp_path, fmt):
    rng = np.random.default_rng(abs(hash(fmt)) % 2**32)
    n = 10_007
    vals = random_values(rng, fmt, n)
    (tmp_path / "a.bin").write_bytes(encode(fmt, vals))
    src = IfSource.from_sidecar(write_sidecar(tmp_path, "a", fmt, n), check_format=False)
    exp = expected(fmt, vals)
    assert src.n_samples == n and src.is_complex == get_format(fmt).is_complex
    assert src.duration_s == pytest.approx(n / 25e6)
    got = src.read(0, n)
    assert got.dtype == (np.complex64 if src.is_complex else np.float32)
    np.testing.assert_array_equal(got, exp)
    np.testing.assert_array_equal(src.read(4321, 777), exp[4321:4321 + 777])
    assert src.read(n, 0).size == 0
    assert src.sample_time(25e6 * 10) == (1234, pytest.approx(345610.5))
    # explicit options (foreign file) give the same samples
    src2 = IfSource(tmp_path / "a.bin", 25e6, 0.0, fmt, check_format=False)
    np.testing.assert_array_equal(src2.read(100, 50), exp[100:150])
    with pytest.raises(ValueError, match="outside"):
        src.read(n - 10, 11)
    # stored values for the receiver's kernel: the same numbers, integer types kept
    st, n_comp = src.read_stored(4321, 777)
    assert n_comp == (2 if src.is_complex else 1) and st.size == 777 * n_comp
    assert st.dtype == {"iq_int8": np.int8, "real_int8": np.int8, "iq_int4": np.int8,
                        "iq_int16": np.int16, "real_int16": np.int16,
                        "gr_complex": np.float32}[fmt]
    want = exp[4321:4321 + 777]
    if src.is_complex:
        want = np.stack([want.real, want.imag], axis=1).ravel()
    np.testing.assert_array_equal(st.astype(np.float32), want)
    with pytest.raises(ValueError, match="outside"):
        src.read_stored(n - 10, 11)


def test_aliases_and_generator_layout(tmp_path):
    # 4-bit values in iq_int8 as the generator writes them (-7..7 on the mid-tread grid)
    rng = np.random.default_rng(1)
    vals = quantized_noise(rng, 20_000, 4, True)
    (tmp_path / "g.bin").write_bytes(encode("iq_int8", vals))
    src = IfSource(tmp_path / "g.bin", 25e6, 0.0, "ibyte")
    assert src.format.name == "iq_int8"
    np.testing.assert_array_equal(src.read(0, 20_000), expected("iq_int8", vals))


@pytest.mark.parametrize("fmt", ["iq_int8", "real_int16", "iq_int4"])
def test_chunks_cover_the_file_exactly(tmp_path, fmt):
    rng = np.random.default_rng(2)
    n = 12_345
    vals = random_values(rng, fmt, n)
    (tmp_path / "c.bin").write_bytes(encode(fmt, vals))
    src = IfSource(tmp_path / "c.bin", 25e6, 0.0, fmt, check_format=False)
    exp = expected(fmt, vals)
    starts, parts = zip(*src.chunks(1000))
    assert starts == tuple(range(0, n, 1000))
    assert [p.size for p in parts] == [1000] * 12 + [345]
    np.testing.assert_array_equal(np.concatenate(parts), exp)
    parts = [p for _, p in src.chunks(999, start=17, stop=5000)]
    np.testing.assert_array_equal(np.concatenate(parts), exp[17:5000])
    assert list(src.chunks(10, start=n)) == []
    with pytest.raises(ValueError):
        next(src.chunks(0))


def test_memory_mapped_reading_of_a_large_sparse_file(tmp_path):
    """A 16 GiB (sparse) file: opening and reading a block near the end stays small/fast."""
    path = tmp_path / "big.bin"
    size = 16 << 30
    tail = np.arange(-50, 50, dtype=np.int8)
    with open(path, "wb") as fh:
        fh.truncate(size)
        fh.seek(size - tail.size)
        fh.write(tail.tobytes())
        fh.seek(1000)
        fh.write(b"\x05\xfb")
    st = os.stat(path)
    if st.st_blocks * 512 > 64 << 20:
        pytest.skip("file system without sparse files")
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    src = IfSource(path, 25e6, 0.0, "iq_int8")
    n = size // 2
    assert src.n_samples == n and src.duration_s == pytest.approx(n / 25e6)
    x = src.read(n - 50, 50)
    np.testing.assert_array_equal(x.real, tail[0::2])
    np.testing.assert_array_equal(x.imag, tail[1::2])
    assert src.read(500, 1)[0] == 5 - 5j
    it = src.chunks(250_000, start=n // 2)  # lazy: only the blocks asked for are read
    for _ in range(4):
        _k, blk = next(it)
        assert blk.size == 250_000 and not np.any(blk)
    wall = time.perf_counter() - t0
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    assert (rss1 - rss0) * 1024 < 64 << 20  # ru_maxrss in KiB on Linux
    assert wall < 5.0


def test_spectrum_inversion_complex_and_real(tmp_path):
    fs, n = 20e6, 4000
    k = np.arange(n)
    # complex: on disk the conjugate of a +1.5 MHz tone
    tone = np.exp(2j * np.pi * 1.5e6 * k / fs) * 60
    vals = np.rint(np.stack([tone.real, -tone.imag], axis=1))
    (tmp_path / "c.bin").write_bytes(vals.astype(np.int8).tobytes())
    src = IfSource(tmp_path / "c.bin", fs, 1.5e6, "iq_int8", spectrum_inverted=True,
                   check_format=False)
    x = src.read(0, n)
    np.testing.assert_array_equal(x, (vals[:, 0] + 1j * vals[:, 1]).conj().astype(np.complex64))
    assert src.if_hz == 1.5e6
    # real: IF 5 MHz declared, a carrier with Doppler +1 kHz sits at 5 MHz - 1 kHz on disk
    rec = np.rint(60 * np.cos(2 * np.pi * (5e6 - 1e3) * k / fs))
    (tmp_path / "r.bin").write_bytes(rec.astype(np.int8).tobytes())
    src = IfSource(tmp_path / "r.bin", fs, 5e6, "real_int8", spectrum_inverted=True,
                   check_format=False)
    assert src.declared_if_hz == 5e6 and src.if_hz == fs / 2 - 5e6
    x = src.read(0, n).astype(np.float64)
    f_true = src.if_hz + 1e3  # corrected stream: IF + Doppler
    for f, big in ((f_true, True), (src.if_hz - 1e3, False)):
        c = abs(np.sum(x * np.exp(-2j * np.pi * f * k / fs))) / n
        assert (c > 25) == big, (f, c)
    # odd start: the (-1)^k pattern follows the file index, not the block
    np.testing.assert_array_equal(src.read(3, 100), src.read(0, 103)[3:])
    # stored values for the kernel: the corrected samples
    st, n_comp = src.read_stored(3, 100)
    assert n_comp == 1
    np.testing.assert_array_equal(st, src.read(3, 100))


def test_error_cases(tmp_path: Path):
    (tmp_path / "empty.bin").write_bytes(b"")
    with pytest.raises(SampleFormatError, match=r"empty\.bin.*empty file"):
        IfSource(tmp_path / "empty.bin", 25e6, 0.0, "iq_int8")
    (tmp_path / "one.bin").write_bytes(b"\x01")
    with pytest.raises(SampleFormatError, match="shorter than one"):
        IfSource(tmp_path / "one.bin", 25e6, 0.0, "iq_int16")
    with pytest.raises(SampleFormatError, match=r"nothere\.bin.*not found"):
        IfSource(tmp_path / "nothere.bin", 25e6, 0.0, "iq_int8")
    (tmp_path / "a.bin").write_bytes(np.arange(1001, dtype=np.int8).tobytes())
    with pytest.raises(SampleFormatError, match=r"a\.bin.*unknown sample format 'int3'"):
        IfSource(tmp_path / "a.bin", 25e6, 0.0, "int3")
    with pytest.raises(SampleFormatError, match="sampling rate"):
        IfSource(tmp_path / "a.bin", 0.0, 0.0, "iq_int8")
    with pytest.raises(SampleFormatError, match="outside"):
        IfSource(tmp_path / "a.bin", 20e6, 12e6, "real_int8")
    with pytest.raises(SampleFormatError, match="outside"):
        IfSource(tmp_path / "a.bin", 20e6, -1e6, "real_int8")
    # partial trailing sample: warning with the count, whole samples read
    with pytest.warns(IfFileWarning, match=r"ignoring the 1 trailing byte"):
        src = IfSource(tmp_path / "a.bin", 25e6, 0.0, "iq_int8", check_format=False)
    assert src.n_samples == 500
    (tmp_path / "b.bin").write_bytes(np.arange(1003, dtype=np.int8).tobytes())
    with pytest.warns(IfFileWarning, match=r"ignoring the 3 trailing byte"):
        src = IfSource(tmp_path / "b.bin", 25e6, 0.0, "iq_int16", check_format=False)
    assert src.n_samples == 250
    last = np.frombuffer(np.arange(1003, dtype=np.int8).tobytes()[:1000], "<i2")[-2:]
    assert src.read(249, 1)[0] == last[0] + 1j * last[1]
    # sidecar: missing IF file, truncated IF file, longer IF file
    side = write_sidecar(tmp_path, "missing", "iq_int8", 10)
    with pytest.raises(SampleFormatError, match=r"missing\.json: IF file .*missing\.bin not "):
        IfSource.from_sidecar(side)
    (tmp_path / "t.bin").write_bytes(np.ones(2 * 400, np.int8).tobytes())
    with pytest.raises(SampleFormatError, match=r"t\.bin.*holds 400 samples.*says 500"):
        IfSource.from_sidecar(write_sidecar(tmp_path, "t", "iq_int8", 500), check_format=False)
    with pytest.warns(IfFileWarning, match="more than the sidecar's 300"):
        src = IfSource.from_sidecar(write_sidecar(tmp_path, "t", "iq_int8", 300),
                                    check_format=False)
    assert src.n_samples == 300
    with pytest.raises(SampleFormatError, match="unknown sample format"):
        IfSource.from_sidecar(write_sidecar(tmp_path, "t", "iq_int9", 400))
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(SampleFormatError, match="not JSON"):
        IfSource.from_sidecar(tmp_path / "bad.json")
    src = IfSource(tmp_path / "t.bin", 25e6, 0.0, "iq_int8", check_format=False)
    with pytest.raises(SampleFormatError, match="start time unknown"):
        src.sample_time(0)


# (actual data, bits, declared) that the heuristic must flag
WRONG = [
    ("iq_int8", 4, "iq_int16"), ("iq_int8", 8, "iq_int16"), ("real_int8", 1, "real_int16"),
    ("iq_int8", 2, "real_int16"),
    ("iq_int16", 16, "iq_int8"), ("iq_int16", 12, "real_int8"), ("iq_int16", 9, "iq_int8"),
    ("real_int16", 4, "iq_int8"),
    ("iq_int4", 4, "iq_int8"), ("iq_int4", 2, "real_int8"), ("iq_int4", 1, "iq_int8"),
    ("iq_int8", 4, "iq_int4"), ("real_int8", 3, "iq_int4"),
    ("gr_complex", 0, "iq_int16"), ("gr_complex", 0, "iq_int8"),
    ("iq_int8", 4, "gr_complex"), ("iq_int16", 16, "gr_complex"),
]
# genuine data of the declared format that it must not flag
RIGHT = [("iq_int8", b) for b in (1, 2, 3, 4, 5, 6, 8)] + \
        [("real_int8", b) for b in (1, 2, 4, 8)] + \
        [("iq_int16", b) for b in (1, 4, 8, 9, 10, 12, 16)] + \
        [("real_int16", b) for b in (2, 8, 11, 16)] + \
        [("iq_int4", b) for b in (1, 2, 3, 4)] + [("gr_complex", 0)]


def _genuine_bytes(rng, fmt, bits, n=60_000):
    if fmt == "gr_complex":
        return encode(fmt, (rng.normal(size=n) + 1j * rng.normal(size=n)) * 0.05)
    return encode(fmt, quantized_noise(rng, n, bits, get_format(fmt).is_complex))


@pytest.mark.parametrize("actual,bits,declared", WRONG)
def test_heuristic_flags_wrong_declared_format(tmp_path, actual, bits, declared):
    rng = np.random.default_rng(bits + len(actual) + 7 * len(declared))
    p = tmp_path / "w.bin"
    p.write_bytes(_genuine_bytes(rng, actual, bits))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IfFileWarning)
        with pytest.raises(SampleFormatError, match=rf"w\.bin: declared {declared} but"):
            IfSource(p, 25e6, 0.0, declared)
        IfSource(p, 25e6, 0.0, declared, check_format=False)  # the user can override


@pytest.mark.parametrize("fmt,bits", RIGHT)
def test_heuristic_accepts_genuine_data(tmp_path, fmt, bits):
    rng = np.random.default_rng(100 + bits)
    p = tmp_path / "ok.bin"
    p.write_bytes(_genuine_bytes(rng, fmt, bits))
    assert check_format_statistics(p, fmt) is None
    IfSource(p, 25e6, 0.0, fmt)


def test_heuristic_with_strong_signal_and_small_files(tmp_path):
    # a strong CW on top of 4-bit noise in iq_int8 is still genuine 8-bit data
    rng = np.random.default_rng(4)
    n = 60_000
    k = np.arange(n)
    x = rng.normal(size=(n, 2)) + 2 * np.stack([np.cos(0.01 * k), np.sin(0.01 * k)], 1)
    q = np.clip(np.floor(x / 0.6 + 0.5), -7, 7).astype(np.int8)
    (tmp_path / "s.bin").write_bytes(q.tobytes())
    assert check_format_statistics(tmp_path / "s.bin", "iq_int8") is None
    # too little data: not judged
    (tmp_path / "tiny.bin").write_bytes(_genuine_bytes(rng, "iq_int8", 4, n=1000))
    assert check_format_statistics(tmp_path / "tiny.bin", "iq_int16") is None


def _read_ahead_and_plain(path, fmt: str, n: int, seed: int):
    """A file of ``n`` random values, opened twice: with the read-ahead (default) and
    without (synchronous reads, the reference)."""
    path.write_bytes(encode(fmt, random_values(np.random.default_rng(seed), fmt, n)))
    src = IfSource(path, 25e6, 0.0, fmt, check_format=False)
    ref = IfSource(path, 25e6, 0.0, fmt, check_format=False)
    ref.read_ahead = False
    return src, ref


@pytest.mark.parametrize("fmt", ["iq_int8", "iq_int16", "iq_int4"])
def test_read_ahead_serves_the_same_values(tmp_path, fmt):
    """Sequential chunk reads with overlaps (the receivers' pattern), a jump backwards and a
    pickled copy give what synchronous reads give; the read-ahead is actually used."""
    import pickle

    n = 50_000
    src, ref = _read_ahead_and_plain(tmp_path / "r.bin", fmt, n, seed=5)
    served = 0
    for s, m in [(0, 4000), (3500, 4000), (7500, 4000), (11000, 4000), (200, 300),
                 (500, 4000), (4400, 6000), (n - 3000, 3000)]:
        had = src._ahead is not None and src._ahead[0] <= s and s + m <= sum(src._ahead[:2])
        got, nc = src.read_stored(s, m)
        exp, nc_ref = ref.read_stored(s, m)
        assert nc == nc_ref and got.dtype == exp.dtype
        np.testing.assert_array_equal(got, exp)
        served += had
    assert served == 3
    copy = pickle.loads(pickle.dumps(src))
    np.testing.assert_array_equal(copy.read_stored(100, 900)[0], ref.read_stored(100, 900)[0])


def test_read_ahead_reads_an_overlapped_sequential_pass_about_once(tmp_path, monkeypatch):
    """The receivers' pattern (chunks of n re-reading an overlap of n / 20): every chunk after
    the first is served by the read-ahead, and the file is read once: each read-ahead copies
    in what the last read already holds (the overlap and the samples read past it), and
    reads only the rest (issue 29 item 3: the read-ahead started n / 2 before each chunk's
    end and read the file 1.58 times; reading from 2 overlaps back, 1.16 times)."""
    from sdr_di.receiver import ifreader

    n_file, n, ov = 200_000, 4000, 200
    src, ref = _read_ahead_and_plain(tmp_path / "s.bin", "iq_int8", n_file, seed=3)
    read = []
    real = ifreader.IfSource._read_stored_now

    real_into = ifreader.IfSource._read_stored_into

    def counting(self, s, m, c):
        if self is src:
            read.append(m)
        return real(self, s, m, c)

    def counting_into(self, out, s, m, c):    # the read-ahead's pieces
        if self is src:
            read.append(m)
        return real_into(self, out, s, m, c)

    monkeypatch.setattr(ifreader.IfSource, "_read_stored_now", counting)
    monkeypatch.setattr(ifreader.IfSource, "_read_stored_into", counting_into)
    s, served, calls = 0, 0, 0
    while s + n <= n_file:
        a = src._ahead
        served += a is not None and a[0] <= s and s + n <= a[0] + a[1]
        np.testing.assert_array_equal(src.read_stored(s, n)[0], ref.read_stored(s, n)[0])
        calls += 1
        s += n - ov
    assert served == calls - 1
    assert sum(read) / n_file <= 1.01   # was (n + 2 ov) / (n - ov) = 1.16


@pytest.mark.parametrize("fmt", ["iq_int8", "real_int16"])
def test_read_ahead_copies_what_it_reuses_before_the_caller_owns_it(tmp_path, fmt):
    """The read-ahead takes the samples the last read already holds from its values, before
    they are returned: a caller that overwrites every array it gets still reads the file's
    values from the next calls (read_stored's contract: a fresh array)."""
    src, ref = _read_ahead_and_plain(tmp_path / "o.bin", fmt, 60_000, seed=17)
    n, ov, s = 4000, 300, 0
    while s + n <= 60_000:
        got, _ = src.read_stored(s, n)
        np.testing.assert_array_equal(got, ref.read_stored(s, n)[0])
        got[:] = 1                               # (the caller's own array to change)
        s += n - ov
    assert src._ahead is not None and src._ahead[2].copied > 0


@pytest.mark.parametrize("fmt", ["iq_int8", "real_int16", "iq_int4"])
def test_read_stored_power_equals_mean_power_of_the_values(tmp_path, fmt, monkeypatch):
    """read_stored_power: the values of read_stored and mean_power's value bit for bit,
    whether the read-ahead's block sums serve it (8-bit) or not; blocks of 64 values so
    that the ranges start and end inside blocks and across them."""
    from sdr_di.receiver import ifreader
    from sdr_di.receiver._numba_correlate_bits import mean_power

    monkeypatch.setattr(ifreader, "_POWER_BLOCK", 64)
    n = 20_000
    src, ref = _read_ahead_and_plain(tmp_path / "p.bin", fmt, n, seed=7)
    summed_ahead = 0
    for s, m in [(0, 3000), (2601, 3000), (4901, 3001), (6600, 10), (6603, 4000),
                 (300, 50), (n - 700, 700)]:
        ahead = src._ahead
        got, nc, pw = src.read_stored_power(s, m)
        exp, nc_ref = ref.read_stored(s, m)
        np.testing.assert_array_equal(got, exp)
        assert nc == nc_ref and pw == float(mean_power(exp, nc_ref))
        if ahead is not None and ahead[0] <= s and s + m <= sum(ahead[:2]):
            summed_ahead += ahead[2].result()[1] is not None
    assert summed_ahead == (3 if get_format(fmt).name in ("iq_int8", "iq_int4") else 0)


def _small_pieces_with_readers(tmp_path, monkeypatch):
    """A 6000-sample ``iq_int8`` file read with the read-ahead (``src``) and without
    (``ref``), in pieces of 64 samples that wait up to 30 s for split calls, and the list
    that records, per ``_read_stored_into`` call, whether the main thread made it."""
    import threading

    from sdr_di.receiver import ifreader

    monkeypatch.setattr(ifreader, "_POWER_BLOCK", 64)
    monkeypatch.setattr(ifreader, "_PIECE_BLOCKS", 2)        # pieces of 64 samples
    monkeypatch.setattr(ifreader, "_SPLIT_WAIT_S", 30.0)
    src, ref = _read_ahead_and_plain(tmp_path / "w.bin", "iq_int8", 6000, seed=11)
    readers = []
    real = ifreader.IfSource._read_stored_into

    def recording(self, out, s, m, c):
        readers.append(threading.current_thread() is threading.main_thread())
        return real(self, out, s, m, c)

    monkeypatch.setattr(ifreader.IfSource, "_read_stored_into", recording)
    return src, ref, readers


def test_read_ahead_pieces_wait_for_split_calls_and_the_caller_reads_the_rest(tmp_path,
                                                                               monkeypatch):
    """Through the page cache, the read-ahead reads a piece at a time and only while no
    split kernel call runs (receiver.threads.wait_for_split_calls): with a split call in
    progress and no timeout, the caller that needs the values reads every piece itself, and
    gets the values and block sums of a synchronous read; the background thread then finds
    nothing left."""
    from sdr_di.receiver import threads
    from sdr_di.receiver._numba_correlate_bits import mean_power

    src, ref, readers = _small_pieces_with_readers(tmp_path, monkeypatch)
    src.uncached = False                         # (uncached reads are not held back)
    threads._split_call(True)
    try:
        src.read_stored(0, 1000)                 # schedules [500, 2000)
        ahead = src._ahead
        got, nc, pw = src.read_stored_power(1000, 900)     # and then [1900, 2800)
        during = list(readers)
    finally:
        threads._split_call(False)
    exp, _ = ref.read_stored(1000, 900)
    np.testing.assert_array_equal(got, exp)
    assert pw == float(mean_power(exp, 2))
    job = ahead[2]
    assert ahead[0] == 500 and len(job.pieces) == 24
    assert job.copied == 500                     # [500, 1000): the first read's, copied in
    n_read = sum(b > job.copied for _, b in job.pieces)
    assert n_read == 17
    assert during == [True] * n_read             # every piece read on the caller's thread
    job.result()                                 # nothing left to read
    assert readers.count(True) == n_read
    nxt = src._ahead[2]
    nxt.result()                                 # read in the background once allowed
    assert len(nxt.pieces) == 15 and nxt.copied == 100     # [1900, 2000) copied
    assert len(readers) == n_read + sum(b > nxt.copied for _, b in nxt.pieces)


@pytest.mark.parametrize("fmt", ["iq_int8", "iq_int4", "real_int16"])
def test_read_ahead_of_a_file_cut_short_falls_back_to_the_reads_error(tmp_path, fmt,
                                                                       monkeypatch):
    """A file that loses its end after it was opened, before the read-ahead read it (held
    back by a split call): the read-ahead's short read is not served, and the synchronous
    read raises SampleFormatError (no garbage values)."""
    from sdr_di.errors import SampleFormatError
    from sdr_di.receiver import ifreader, threads

    monkeypatch.setattr(ifreader, "_SPLIT_WAIT_S", 30.0)
    path = tmp_path / "cut.bin"
    src, _ = _read_ahead_and_plain(path, fmt, 20_000, seed=13)
    src.uncached = False                         # held back: read through the cache
    threads._split_call(True)
    try:
        src.read_stored(0, 4000)
        data = path.read_bytes()
        path.write_bytes(data[:len(data) // 4])
        with pytest.raises(SampleFormatError, match="short read"):
            src.read_stored(4000, 4000)
    finally:
        threads._split_call(False)


@pytest.mark.skipif(not hasattr(os, "posix_fadvise"), reason="no posix_fadvise here")
@pytest.mark.parametrize("fmt", ["iq_int8", "iq_int4"])   # preadv, tables
def test_sequential_reads_release_the_pages_a_window_behind(tmp_path, monkeypatch, fmt):
    """A front-to-back pass (with the read-ahead, and without) advises every byte but the
    last window's as not needed, and reads the same values as without the advice."""
    from sdr_di.io import page_cache

    n, window = 40_000, 20_000
    size = n * get_format(fmt).bytes_per_sample
    monkeypatch.setattr(page_cache.release_read_behind, "__defaults__", (window,))
    advised = []
    real = os.posix_fadvise

    def spy(fd, off, length, adv):
        assert adv == os.POSIX_FADV_DONTNEED
        advised.append((off, off + length))
        real(fd, off, length, adv)

    monkeypatch.setattr(os, "posix_fadvise", spy)
    src, ref = _read_ahead_and_plain(tmp_path / "r.bin", fmt, n, seed=3)
    for s in range(0, n, 4000):
        np.testing.assert_array_equal(src.read_stored(s, 4000)[0], ref.read_stored(s, 4000)[0])
    covered = np.zeros(size, bool)
    for a, b in advised:
        covered[a:b] = True
    assert covered[:size - window].all() and not covered[size - window:].any()


def test_read_ahead_kernel_is_compiled_on_the_callers_thread(tmp_path):
    """The read-ahead thread's numba kernel is compiled (or loaded) by the thread that
    schedules it, never on the read-ahead thread, where numba's ``catch_warnings`` could
    take the caller's warnings: in a fresh process (a kernel has no signature before its
    first call, compiled or loaded from the cache) with a read-ahead thread that does
    nothing, the kernel has its int8 signature after a read."""
    import subprocess
    import sys

    path = tmp_path / "r.bin"
    path.write_bytes(np.zeros(2 * 100_000, np.int8).tobytes())
    code = f"""
from sdr_di.receiver import ifreader
from sdr_di.receiver._numba_correlate_bits import block_sum_squares
ifreader._ReadAhead.run = lambda self: None        # the thread compiles nothing
src = ifreader.IfSource({str(path)!r}, 25e6, 0.0, "iq_int8", check_format=False)
src.read_stored_power(0, 10_000)                   # schedules the read-ahead of the rest
print(len(block_sum_squares.signatures))
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert int(res.stdout.split()[-1]) >= 1


@pytest.mark.parametrize("fmt", ["iq_int8", "iq_int16"])
def test_read_ahead_reads_past_the_page_cache_or_falls_back(tmp_path, monkeypatch, fmt):
    """The read-ahead's straight reads bypass the page cache where the file system allows
    it (``uncached`` stays set), and fall back to reads through the cache, with the same
    values, where the file cannot be opened so (``open_uncached`` None) or a read is
    refused (``EINVAL``)."""
    import errno

    from sdr_di.io.page_cache import open_uncached
    from sdr_di.receiver import ifreader

    def chunks(src):
        return [src.read_stored(s, 4000)[0] for s in range(0, 36_000, 3500)]

    src, ref = _read_ahead_and_plain(tmp_path / "r.bin", fmt, 40_000, seed=8)
    want = chunks(ref)
    calls = []
    real = ifreader.pread_uncached
    with monkeypatch.context() as mp:
        mp.setattr(ifreader, "pread_uncached", lambda *a: calls.append(1) or real(*a))
        for got, exp in zip(chunks(src), want):
            np.testing.assert_array_equal(got, exp)
    fd = open_uncached(src.path)
    if fd is not None:
        os.close(fd)
        assert calls and src.uncached           # used, and not silently dropped

    def refused(*a):
        raise OSError(errno.EINVAL, "Invalid argument")

    for name, fake in (("open_uncached", lambda path: None), ("pread_uncached", refused)):
        with monkeypatch.context() as mp:
            mp.setattr(ifreader, name, fake)
            src = IfSource(tmp_path / "r.bin", 25e6, 0.0, fmt, check_format=False)
            for got, exp in zip(chunks(src), want):
                np.testing.assert_array_equal(got, exp)
            assert not src.uncached


def test_uncached_read_ahead_is_not_held_back_by_split_calls(tmp_path, monkeypatch):
    """Uncached reads cost next to no CPU: the read-ahead thread reads every piece while a
    split kernel call runs, and the caller reads none itself."""
    from sdr_di.io.page_cache import open_uncached
    from sdr_di.receiver import threads

    src, ref, readers = _small_pieces_with_readers(tmp_path, monkeypatch)
    fd = open_uncached(src.path)
    if fd is None:
        pytest.skip("no O_DIRECT on this file system")
    os.close(fd)
    threads._split_call(True)
    try:
        src.read_stored(0, 1000)                 # schedules [500, 2000)
        ahead = src._ahead[2]
        with ahead._cond:                        # the background thread reads them all
            ahead._cond.wait_for(lambda: not ahead._left() and ahead._busy == 0, 30.0)
        got, _ = src.read_stored(1000, 900)
    finally:
        threads._split_call(False)
    np.testing.assert_array_equal(got, ref.read_stored(1000, 900)[0])
    assert src.uncached and readers[:17] == [False] * 17   # (the 17 pieces not copied in)
