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
"""

from __future__ import annotations

import os

__all__ = ["ReleaseBehind", "release_read_behind"]

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
