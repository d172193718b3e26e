"""Page-cache release behind a streamed IF file (``sdr_di.io.page_cache``)."""

import os

import numpy as np
import pytest

from sdr_di.io.page_cache import ReleaseBehind

pytestmark = pytest.mark.skipif(not hasattr(os, "posix_fadvise"),
                                reason="no posix_fadvise on this platform")


def test_release_behind_advises_the_trailing_window(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(os, "posix_fadvise", lambda fd, off, n, adv: calls.append((off, n, adv)))
    with open(tmp_path / "f.bin", "wb") as fh:
        r = ReleaseBehind(fh.fileno(), window_bytes=100)
        for pos in (0, 40, 130, 300):
            r.advance(pos)
    dn = os.POSIX_FADV_DONTNEED
    assert calls == [(0, 40, dn), (30, 100, dn), (200, 100, dn)]


def test_release_behind_stops_on_a_pipe():
    rd, wr = os.pipe()
    try:
        r = ReleaseBehind(wr)
        r.advance(4096)               # ESPIPE: disabled, no exception
        assert not r.enabled
    finally:
        os.close(rd)
        os.close(wr)


def test_generator_writes_the_same_bytes_and_advises_every_one(tmp_path, monkeypatch):
    """The writer's advice covers every byte it wrote, ends at the file's end, and leaves the
    file's content as written without it."""
    from sdr_di.io import page_cache
    from sdr_di.sim.generate import write_overlapped

    calls = []
    real = os.posix_fadvise

    def spy(fd, off, n, adv):
        calls.append((off, off + n))
        real(fd, off, n, adv)

    monkeypatch.setattr(page_cache, "WINDOW_BYTES", 3000)
    monkeypatch.setattr(page_cache.ReleaseBehind.__init__, "__defaults__", (3000,))
    monkeypatch.setattr(os, "posix_fadvise", spy)
    rng = np.random.default_rng(1)
    chunks = [rng.integers(-128, 128, 1000 + 7 * i, dtype=np.int8) for i in range(12)]
    with open(tmp_path / "x.bin", "wb") as fh:
        write_overlapped(fh, iter(chunks))
    data = (tmp_path / "x.bin").read_bytes()
    assert data == np.concatenate(chunks).tobytes()
    covered = np.zeros(len(data), bool)
    for a, b in calls:
        covered[a:b] = True
    assert covered.all() and max(b for _, b in calls) == len(data)


# ---- uncached (O_DIRECT) reads --------------------------------------------------------------
def _file_and_fd(tmp_path, size, seed=1):
    from sdr_di.io.page_cache import open_uncached

    data = np.random.default_rng(seed).integers(0, 256, size, dtype=np.uint8)
    path = tmp_path / "u.bin"
    path.write_bytes(data.tobytes())
    fd = open_uncached(path)
    if fd is None:
        pytest.skip("no O_DIRECT on this file system")
    return data, fd


@pytest.mark.parametrize("aligned", [True, False])
def test_uncached_reads_give_the_files_bytes(tmp_path, aligned):
    """Any offset and length, across the bounce buffer's size and the file's unaligned end:
    the file's bytes, and fewer only at its end."""
    from sdr_di.io.page_cache import BOUNCE_BYTES, DIRECT_ALIGN, aligned_empty, pread_uncached

    size = 3 * BOUNCE_BYTES + 1234
    data, fd = _file_and_fd(tmp_path, size)
    try:
        for off in (0, 1, DIRECT_ALIGN - 1, DIRECT_ALIGN, 5000, BOUNCE_BYTES - 3, size - 10):
            for n in (0, 1, DIRECT_ALIGN, 10_000, BOUNCE_BYTES + 5000, 2 * BOUNCE_BYTES):
                out = aligned_empty(n, off) if aligned else aligned_empty(n + 1, off)[1:]
                want = max(0, min(n, size - off))
                got = pread_uncached(fd, out, off)
                assert got == want, (off, n)
                np.testing.assert_array_equal(out[:got], data[off:off + got])
    finally:
        os.close(fd)


def test_uncached_read_into_an_aligned_array_goes_straight_into_it(tmp_path, monkeypatch):
    """Only the unaligned head and tail (less than one block each) pass the bounce buffer
    when the array is aligned with the file offset; all of it when it is not."""
    from sdr_di.io import page_cache

    data, fd = _file_and_fd(tmp_path, 1 << 20)
    bounced = []
    real = page_cache._pread_bounced

    def spy(fd_, out, off):
        bounced.append(out.size)
        return real(fd_, out, off)

    monkeypatch.setattr(page_cache, "_pread_bounced", spy)
    try:
        off, n = 1000, 600_000
        out = page_cache.aligned_empty(n, off)
        assert (out.ctypes.data - off) % page_cache.DIRECT_ALIGN == 0
        assert page_cache.pread_uncached(fd, out, off) == n
        np.testing.assert_array_equal(out, data[off:off + n])
        assert 0 < sum(bounced) < 2 * page_cache.DIRECT_ALIGN
        bounced.clear()
        out = page_cache.aligned_empty(n + 1, off)[1:]           # one byte off the alignment
        assert page_cache.pread_uncached(fd, out, off) == n
        np.testing.assert_array_equal(out, data[off:off + n])
        assert sum(bounced) == n
    finally:
        os.close(fd)
