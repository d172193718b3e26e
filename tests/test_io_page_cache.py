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
