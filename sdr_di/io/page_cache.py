"""Streaming IF files through the operating system's page cache without filling it.

A generated or read IF file is gigabytes (25 MHz 8-bit I/Q: 50 MB per second of signal) and
is streamed once, front to back. Left to itself, the kernel keeps every page of it in its
page cache until memory runs short, which costs twice:

* the cache takes fresh memory for each new page. On a virtual machine whose free memory
  is handed back to the host, that memory must be faulted in again, page by page: measured
  on the 2-core development VM, writing 1 GB of new file data cost 4.9-5.4 s of system CPU
  time when the memory was cold, against 0.2-0.3 s when the pages of a file deleted just
  before were reused (``/tmp`` test, 4 MB writes);
* the file evicts what the user's other programs keep cached.

:class:`ReleaseBehind` therefore tells the kernel (``posix_fadvise(POSIX_FADV_DONTNEED)``)
that the pages behind the current position will not be needed again, over a trailing window
of ``window_bytes``: the first advice on a dirty page starts its write-back, a later one drops
it once clean, and the memory is reused for the next pages (same test, cold memory: 0.4-0.6 s
of system time per GB). The IF reader does the same behind its reads
(:func:`release_read_behind`): the 2 GB default test file read from disk cost 4.4 s of
system time into fresh cache pages, 0.3 s with the pages released behind (as much as
reading it from the cache), at 1.1 s of wall time (the read-ahead thread's). A file read
again later comes from the disk, not the cache; files shorter than the window keep every
page. Advice only: no byte of any file changes, and it is skipped where the platform has no
``posix_fadvise`` or the file does not support it (a pipe).

The IF reader's read-ahead goes further and reads past the cache altogether
(:func:`open_uncached`, :func:`pread_uncached`: ``O_DIRECT``), straight into buffers whose
address is aligned with the file offset (:func:`aligned_empty`); only the unaligned ends of a
range pass a small per-thread bounce buffer. On the same VM that took 0.58 s of system time
off a scalar run of the 40 s default file (1.07-1.26 s against 1.55-1.94 s, six interleaved
pairs; the outputs are the same bytes). Where the platform or file system refuses it, the
reader reads through the cache as above.
"""

from __future__ import annotations

import mmap
import os
import threading

import numpy as np

__all__ = ["ReleaseBehind", "aligned_empty", "open_uncached", "pread_uncached",
           "release_read_behind"]

#: Default trailing window [bytes]: about 1.3 s of a 25 MHz 8-bit I/Q file.
WINDOW_BYTES = 64 << 20


def _dont_need(fd: int, start: int, end: int) -> bool:
    """Advise ``[start, end)`` of ``fd`` as not needed; False where that cannot be done (no
    ``posix_fadvise`` on the platform, or not a regular file: a pipe)."""
    if not hasattr(os, "posix_fadvise"):
        return False
    if end > start:
        try:
            os.posix_fadvise(fd, start, end - start, os.POSIX_FADV_DONTNEED)
        except OSError:
            return False
    return True


class ReleaseBehind:
    """Drop a streamed file's pages from the page cache behind the current position.

    Parameters
    ----------
    fd : int
        Open file descriptor.
    window_bytes : int
        Length of the trailing window advised at each :meth:`advance` [bytes]: every page
        is advised about ``window_bytes / step`` times, so a dirty page whose write-back the
        first advice started is dropped by a later one.
    """

    def __init__(self, fd: int, window_bytes: int = WINDOW_BYTES) -> None:
        self.fd = fd
        self.window = int(window_bytes)
        self.enabled = hasattr(os, "posix_fadvise")

    def advance(self, pos: int) -> None:
        """The stream is at byte ``pos``: advise ``[pos - window, pos)`` as not needed."""
        if self.enabled and pos > 0:
            self.enabled = _dont_need(self.fd, max(0, pos - self.window), pos)


def release_read_behind(fd: int, offset: int, n: int, window_bytes: int = WINDOW_BYTES) -> None:
    """After reading ``n`` bytes at ``offset`` of a file streamed front to back: advise the
    ``n`` bytes ``window_bytes`` before them, ``[offset - window, offset + n - window)``, as
    not needed (stateless: reads that tile the file advise every byte but its last
    ``window_bytes``, which a reader going back a little, a chunk overlap, still finds
    cached)."""
    w = int(window_bytes)
    _dont_need(fd, max(0, offset - w), offset + int(n) - w)


#: Alignment of uncached (``O_DIRECT``) transfers: file offset, length and buffer address
#: [bytes] (the largest logical block size of common disks).
DIRECT_ALIGN = 4096
#: Bounce buffer of each thread [bytes]: the parts of an uncached read that cannot go
#: straight into the caller's array go through it, in pieces of at most this size.
BOUNCE_BYTES = 1 << 20

_bounce = threading.local()


def _bounce_buffer() -> np.ndarray:
    """This thread's page-aligned bounce buffer (made once: fresh pages cost system time
    on the VM, module notes)."""
    buf = getattr(_bounce, "buf", None)
    if buf is None:
        buf = _bounce.buf = np.frombuffer(mmap.mmap(-1, BOUNCE_BYTES), np.uint8)
    return buf


def open_uncached(path) -> int | None:
    """A read-only descriptor of ``path`` whose reads bypass the page cache (``O_DIRECT``),
    or None where that is not available (the platform, or a file system without it, such
    as tmpfs)."""
    flag = getattr(os, "O_DIRECT", 0)
    if not flag or not hasattr(os, "preadv"):
        return None
    try:
        return os.open(path, os.O_RDONLY | flag)
    except OSError:
        return None


def aligned_empty(n_bytes: int, file_offset: int) -> np.ndarray:
    """An uninitialized ``uint8`` array of ``n_bytes`` whose address is congruent to
    ``file_offset`` modulo :data:`DIRECT_ALIGN`: :func:`pread_uncached` of that offset
    into it (or of any offset into the same place of it) goes straight into its memory."""
    raw = np.empty(n_bytes + DIRECT_ALIGN, np.uint8)
    skip = (file_offset - raw.ctypes.data) % DIRECT_ALIGN
    return raw[skip:skip + n_bytes]


def _pread_all(fd: int, out: np.ndarray, offset: int) -> int:
    """``preadv`` until ``out`` is full or the file ends; the bytes read."""
    done, n = 0, out.size
    while done < n:
        got = os.preadv(fd, [out[done:]], offset + done)
        if got <= 0:
            break
        done += got
    return done


def _pread_bounced(fd: int, out: np.ndarray, offset: int) -> int:
    """Uncached read of ``out.size`` bytes at any ``offset`` into any ``out``, through this
    thread's bounce buffer (aligned transfers covering the range, the range copied out)."""
    buf = _bounce_buffer()
    done, n = 0, out.size
    while done < n:
        pos = offset + done
        a0 = pos - pos % DIRECT_ALIGN
        a1 = min(-(-(offset + n) // DIRECT_ALIGN) * DIRECT_ALIGN, a0 + BOUNCE_BYTES)
        got = _pread_all(fd, buf[:a1 - a0], a0)
        take = min(got - (pos - a0), n - done)
        if take <= 0:
            break
        out[done:done + take] = buf[pos - a0:pos - a0 + take]
        done += take
        if got < a1 - a0:
            break                                    # the end of the file
    return done


def pread_uncached(fd: int, out: np.ndarray, offset: int) -> int:
    """Read ``out.size`` bytes at ``offset`` of the file open as ``fd`` (:func:`open_uncached`)
    into the contiguous ``uint8`` array ``out``; returns the bytes read (fewer only at the end
    of the file).

    The aligned middle of the range goes straight from the disk into ``out`` when ``out``'s
    address is congruent to ``offset`` modulo :data:`DIRECT_ALIGN` (:func:`aligned_empty`),
    the unaligned head and tail, or the whole range otherwise, through this thread's bounce
    buffer. No page of the file enters the page cache: on the 2-core VM, reading the 40 s
    default file (2 GB) this way cost 0.58 s less system time per run than through the
    cache with its pages released behind (:func:`release_read_behind`). Raises ``OSError``
    as the read does (``EINVAL``: the file system refuses uncached reads)."""
    n = out.size
    head = (-offset) % DIRECT_ALIGN
    end = offset + n
    mid = (end - end % DIRECT_ALIGN) - (offset + head)
    if (out.ctypes.data - offset) % DIRECT_ALIGN or mid <= 0:
        return _pread_bounced(fd, out, offset)
    done = _pread_bounced(fd, out[:head], offset) if head else 0
    if done < head:
        return done
    got = _pread_all(fd, out[head:head + mid], offset + head)
    if got < mid:
        return head + got
    return head + mid + (_pread_bounced(fd, out[head + mid:], offset + head + mid)
                         if head + mid < n else 0)
