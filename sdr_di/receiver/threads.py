"""Thread count of short numba kernel calls, chosen by measured speed.

Parallel regions of ~1 ms are cheap on idle cores but very slow when another process competes
for them (a worker thread descheduled at the barrier stalls the region for a time slice:
measured 5-10x slower than one thread on a loaded 2-core machine). :class:`KernelThreads`
measures both settings (1 thread and numba's thread count), re-explores the slower one for 1
call in every 256, and uses the faster. The first call of each setting (thread pool start-up)
is not counted. Used by the scalar receiver's correlator bank and the deep vector loop.
"""

from __future__ import annotations

import numba

__all__ = ["KernelThreads"]


class KernelThreads:
    """Per-call thread choice for a kernel (module notes).

    Parameters
    ----------
    threads : int, optional
        Fixed thread count (clipped to numba's); default None: automatic.

    Attributes
    ----------
    cost : dict
        ``{threads: smoothed seconds per unit of work}`` of the two settings (0: not measured).
    """

    def __init__(self, threads: int | None = None) -> None:
        self.max_threads = max(1, int(numba.config.NUMBA_NUM_THREADS))
        self.fixed = None if threads is None else max(1, min(int(threads), self.max_threads))
        self.cost = {1: 0.0, self.max_threads: 0.0}
        self._warm: set[int] = set()
        self._calls = 0

    def pick(self) -> int:
        """Thread count for the next call (also set as numba's current thread count)."""
        if self.fixed is not None:
            t = self.fixed
        elif self.max_threads == 1:
            t = 1
        else:
            c1, cm = self.cost[1], self.cost[self.max_threads]
            if c1 == 0.0:
                t = 1
            elif cm == 0.0:
                t = self.max_threads
            else:
                best = 1 if c1 <= cm else self.max_threads
                other = self.max_threads if best == 1 else 1
                t = other if self._calls % 256 == 255 else best
        self._calls += 1
        if numba.get_num_threads() != t:
            numba.set_num_threads(t)
        return t

    def record(self, threads: int, cost: float) -> None:
        """Measured cost of a call made with ``threads`` [s per unit of work]."""
        if threads not in self.cost:
            return
        if threads not in self._warm:
            self._warm.add(threads)
            return
        old = self.cost[threads]
        self.cost[threads] = cost if old == 0.0 else 0.7 * old + 0.3 * cost
