"""Thread count of short numba kernel calls, and the row split that runs them on two cores.

Parallel regions of ~1 ms are cheap on idle cores but very slow when another process competes
for them (a worker thread descheduled at the barrier stalls the region for a time slice:
measured 5-10x slower than one thread on a loaded 2-core machine, for numba's ``omp`` layer
with its spinning workers). So the correlator kernels are not parallelized inside
(``prange`` over one thread): :meth:`KernelThreads.run_rows` splits a call's rows into
contiguous parts of equal sample counts and runs one part on the calling thread and each
other on a persistent worker thread (the kernels are ``nogil``), with no barrier to spin at.
Measured on the loaded 2-core machine (7 channels x 20 epochs at 25 MHz, load average 5):
one thread 17.1 ms wall, the split 9.4 ms, numba's ``prange`` on 2 threads 72.6 ms; the same
CPU time (6.0-6.1 ms) for the first two, 14.9 ms for ``prange``.

A row's sums never depend on which thread computes it (one task per row), so the results
are identical whatever the thread count or the split.

Small calls on one thread
-------------------------
A call of fewer than :data:`SPLIT_MIN_SAMPLES` samples (all rows together) runs on the
calling thread, whatever the measured costs say. The split's price is not all inside the
call that :meth:`RowsCall.wait` times: the worker's hand-off and its Python after the kernel
take the GIL from the caller's Python between the calls, and the futex wake-ups add system
time. Whole runs on the 2-core VM (2026-12-08, ``SDR_DI_KERNEL_THREADS`` 1 against 2,
two rounds each, default scenario; ``docs/notes/speed.md``, session 29), CPU-s (wall s):

=====================  ======================  ==========================  ======================
file, calls' samples   mode                    one thread                  split
=====================  ======================  ==========================  ======================
2.5 MHz 60 s, 2^17-18  scalar / deep           5.8, 5.6 (5.3, 5.1) /       8.1, 8.4 (6.5, 6.7) /
                                               6.5, 6.2 (6.0, 5.7)         7.8, 9.4 (6.0, 7.3)
5 MHz 40 s, 2^18-19    scalar / deep           6.8, 6.0 (6.2, 5.4) /       8.2, 8.3 (6.2, 6.3) /
                                               5.7, 5.9 (5.1, 5.3)         7.9, 9.1 (5.9, 6.9)
10 MHz 40 s, 2^19-20   scalar / deep           10.5, 9.4 (9.5, 8.5) /      11.6, 10.9 (8.2, 7.6) /
                                               10.6, 8.9 (9.7, 8.0)        10.7, 11.3 (7.4, 7.9)
25 MHz 40 s, 2^20-21   scalar / deep           12.7, 14.0 (11.5, 12.6) /   16.3, 13.2 (10.7, 8.6) /
                                               12.4, 13.2 (11.1, 11.7)     14.7, 12.9 (9.7, 8.4)
=====================  ======================  ==========================  ======================

Below 2^19 samples a call (2.5 and 5 MHz) the split cost 20-55 % more CPU and saved no
wall time (mostly it took more), though the adaptive choice below, which times each call
alone, took it. From 10 MHz up it saved 1-32 % of the wall time for -6 to +28 % of CPU.
The bound sits between: a 10 MHz scalar run's calls (2^19) now run on one thread, 11-14 %
slower in wall and as much cheaper in CPU; calls of 2^20 samples and more (10 MHz deep,
25 MHz) are left to the adaptive choice.

:class:`KernelThreads` measures both settings (1 thread and numba's thread count), re-explores
the other one for 1 call in every 256, and uses the split unless one thread costs less than 0.8
of it per sample. The first call of each setting
(thread start-up) is not counted. The costs are kept per size class of the call (its samples,
in powers of 2): a call's fixed costs (the worker's wake-up, the Python around the kernels)
weigh 20 times more per sample in the scalar receiver's 1 ms blocks before bit
synchronization than in its 20 ms blocks after it, and with one cost for both the 1 ms
blocks' verdict (one thread) stuck: re-explored once every 256 calls, the split's cost
hardly moved, and the deep start-up ran 1467 of its 1563 kernel calls on one thread
(2.4 s of kernel wall over the first 12.2 s of the 40 s default file). Used by the scalar
receiver's correlator bank and the deep vector loop.

Calls left running
------------------
:meth:`KernelThreads.run_rows` returns when every part is done, so the worker is idle while
the caller runs what must come between two calls. In the deep loop with the NCOs one
interval ahead that is the INS propagation and the NCO commands of the next interval (0.9
ms of the 4.7 ms an interval took on the 2-core machine), and the main thread, not the
kernel, bounded the run: over the 40 s default file it used 10.3 CPU-s of the 11.2 s wall
(its own kernel parts included), the worker 4.7 CPU-s. :meth:`KernelThreads.start_rows`
with ``detach=True`` returns once the caller's part and ``before`` are done; the worker's
part goes on while the caller prepares the next call, and the caller waits for it only
where it needs the rows (:meth:`RowsCall.wait`). The caller's part is then shortened by its
work between the calls as well as by ``before``, so the worker takes more of the kernel.
Seven interleaved pairs of 40 s deep runs (2026-12-04): the loop's paired change -0.49 s,
95 % interval [-0.88, -0.09] s (6.8-6.9 s to 5.8-5.9 s in a fast spell), the same output
bytes.
"""

from __future__ import annotations

import math
import os
import sys
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import wait as futures_wait

import numba
import numpy as np

from ..settings import KERNEL_THREADS, kernel_threads

__all__ = ["SPLIT_MIN_SAMPLES", "KernelThreads", "RowsCall", "balanced_cuts", "split_stats",
           "wait_for_split_calls"]

#: Environment variable fixing the thread count of every automatic :class:`KernelThreads`
#: (benchmarks: ``scripts/bench_deep.py --kernel-threads``).
ENV_THREADS = KERNEL_THREADS
#: Fewest samples (all rows of a call together) for which :meth:`KernelThreads.pick` may
#: split a call; smaller calls run on the calling thread (module notes, *Small calls on one
#: thread*).
SPLIT_MIN_SAMPLES = 1 << 20
#: Interpreter switch interval while the caller runs ``before`` in :meth:`KernelThreads.
#: run_rows` [s] (default 5 ms: a worker that ends its part would wait that long for the
#: GIL to return).
_SWITCH_S = 1e-4
_POOL: ThreadPoolExecutor | None = None
_POOL_PID = 0
#: Process-wide CPU accounting of the split calls (:func:`split_stats`).
_STATS = {"calls": 0, "caller_cpu_s": 0.0, "worker_cpu_s": 0.0, "wait_cpu_s": 0.0}
_POOL_LOCK = threading.Lock()
#: Split calls of :meth:`KernelThreads.run_rows` in progress in the process, and the event
#: set while there is none (:func:`wait_for_split_calls`).
_SPLIT_LOCK = threading.Lock()
_SPLIT_RUNNING = 0
_NO_SPLIT_CALL = threading.Event()
_NO_SPLIT_CALL.set()


def _one_numba_thread() -> None:
    numba.set_num_threads(1)      # thread-local: the worker's kernel calls run serially


def _pool(workers: int) -> ThreadPoolExecutor:
    """The process's kernel worker threads (created on first use, kept for later calls)."""
    global _POOL, _POOL_PID
    with _POOL_LOCK:
        # a forked child inherits the pool object but not its threads: make its own
        if _POOL is None or _POOL._max_workers < workers or _POOL_PID != os.getpid():
            _POOL = ThreadPoolExecutor(max_workers=workers, initializer=_one_numba_thread,
                                       thread_name_prefix="sdr-di-kernel")
            _POOL_PID = os.getpid()
        return _POOL


def split_stats() -> dict:
    """CPU accounting of :meth:`KernelThreads.run_rows`' split calls in this process:
    ``calls``, ``caller_cpu_s`` (the caller's part and its ``before`` work), ``worker_cpu_s``
    (the workers' parts) and ``wait_cpu_s``, the sum over calls of the slowest worker's CPU
    time beyond the caller's from the call's start to its wait (a detached call's includes
    the caller's work between the calls): what the caller waits on idle cores. The main
    thread's CPU time plus ``wait_cpu_s`` estimates a run's wall time on idle cores, whatever
    the load it was measured under."""
    return dict(_STATS)


def wait_for_split_calls(timeout_s: float) -> bool:
    """Wait until no split call of :meth:`KernelThreads.run_rows` runs in the process, for
    at most ``timeout_s`` seconds; True when none runs. Background work that can wait (the
    IF read-ahead: :class:`~sdr_di.receiver.ifreader._ReadAhead`) calls it so as not to take
    a core from a kernel worker the caller will wait for (also while the caller waits:
    a read then shared the worker's core, and the caller's waits on the workers stayed as
    long as without the wait, 0.9-1.1 s per 40 s deep run)."""
    return _NO_SPLIT_CALL.wait(timeout_s)


def _no_split_call_in_child() -> None:
    # a fork copies the state of the parent's split calls, which are not the child's (and
    # the parent's lock may be held by a thread the child does not have)
    global _SPLIT_LOCK, _SPLIT_RUNNING, _NO_SPLIT_CALL
    _SPLIT_LOCK, _SPLIT_RUNNING, _NO_SPLIT_CALL = threading.Lock(), 0, threading.Event()
    _NO_SPLIT_CALL.set()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_no_split_call_in_child)


def _split_call(begin: bool) -> None:
    global _SPLIT_RUNNING
    with _SPLIT_LOCK:
        _SPLIT_RUNNING += 1 if begin else -1
        if _SPLIT_RUNNING == 0:
            _NO_SPLIT_CALL.set()
        else:
            _NO_SPLIT_CALL.clear()


def balanced_cuts(weights, parts: int) -> list[int]:
    """Row boundaries ``[0, c_1, .., n]`` splitting rows into ``parts`` contiguous runs of
    about equal total ``weights`` (samples per row)."""
    w = np.asarray(weights, dtype=np.float64)
    n = w.size
    if parts <= 1 or n <= 1:
        return [0, n]
    cum = np.cumsum(w)
    tot = float(cum[-1]) if n else 0.0
    cuts = [0]
    for j in range(1, parts):
        c = int(np.searchsorted(cum, tot * j / parts, side="left")) + 1
        cuts.append(min(max(c, cuts[-1]), n))
    cuts.append(n)
    return cuts


class KernelThreads:
    """Per-call thread choice for a kernel (module notes).

    Parameters
    ----------
    threads : int, optional
        Fixed thread count (clipped to numba's); default None: automatic, unless the
        environment variable :data:`ENV_THREADS` gives one.

    Attributes
    ----------
    costs : dict
        ``{size class: {threads: smoothed seconds per unit of work}}`` of the two settings
        (0: not measured); the size class of ``work`` units is ``floor(log2(work))``.
    cost : dict
        The ``{threads: cost}`` of the last call's size class.
    """

    def __init__(self, threads: int | None = None) -> None:
        self.max_threads = max(1, int(numba.config.NUMBA_NUM_THREADS))
        if threads is None:
            threads = kernel_threads()     # SDR_DI_KERNEL_THREADS (sdr_di.settings)
        self.fixed = None if threads is None else max(1, min(int(threads), self.max_threads))
        self.costs: dict[int, dict[int, float]] = {}
        self.cost = {1: 0.0, self.max_threads: 0.0}
        self._warm: set[int] = set()
        self._calls: dict[int, int] = {}
        self._before_s = 0.0     # smoothed CPU time of run_rows' `before` [s]
        self._sample_s = 0.0     # smoothed kernel CPU time per sample on one thread [s]
        self._gap_s = 0.0        # smoothed CPU time between detached calls [s]
        self._detached_cpu: float | None = None   # thread time at a detached call's return

    def pick(self, work: float = 1.0) -> int:
        """Thread count for the next call, of ``work`` units (samples). Numba's own thread
        count of the calling thread is set to 1: :meth:`run_rows` parallelizes over rows, not
        inside the kernel."""
        size = int(math.log2(work)) if work >= 1.0 else 0
        cost = self.costs.get(size)
        if cost is None:
            cost = self.costs[size] = {1: 0.0, self.max_threads: 0.0}
        self.cost = cost              # what `record` updates
        calls = self._calls.get(size, 0)
        self._calls[size] = calls + 1
        if self.fixed is not None:
            t = self.fixed
        elif self.max_threads == 1 or work < SPLIT_MIN_SAMPLES:
            t = 1
        else:
            c1, cm = cost[1], cost[self.max_threads]
            if c1 == 0.0:
                t = 1
            elif cm == 0.0:
                t = self.max_threads
            else:
                # the split unless one thread is clearly cheaper: on a quiet 2-core machine
                # the per-call wall costs of the two settings differ by less than their
                # scatter, and picking by the smaller one chose one thread too often
                # (scalar 30 s file: 13.2 s wall against 11.3 s with the split always)
                best = 1 if c1 < 0.8 * cm else self.max_threads
                other = self.max_threads if best == 1 else 1
                t = other if calls % 256 == 255 else best
        if numba.get_num_threads() != 1:
            numba.set_num_threads(1)
        return t

    def record(self, threads: int, cost: float, costs: dict | None = None) -> None:
        """Measured cost of a call made with ``threads`` [s per unit of work], for the size
        class of the last :meth:`pick` (or the one of ``costs``, a value of :attr:`costs`)."""
        costs = self.cost if costs is None else costs
        if threads not in costs:
            return
        if threads not in self._warm:
            self._warm.add(threads)
            return
        old = costs[threads]
        costs[threads] = cost if old == 0.0 else 0.7 * old + 0.3 * cost

    def run_rows(self, call: Callable[[int, int], None], nsamp,
                 before: Callable[[int], None] | None = None) -> int:
        """Run ``call(a, b)`` (a ``nogil`` kernel on rows ``[a, b)``, writing its own rows'
        outputs) over all rows: on the calling thread alone, or split into contiguous parts
        between it and the worker threads (module notes). Records the cost per sample;
        returns the thread count used.

        ``before(rows_done)``: work for the calling thread that needs no results but those
        of the first ``rows_done`` rows, which are final when it runs (the deep loop's
        filter predict, and the channels whose epochs all lie there); it runs after the
        calling thread's part (rows ``[0, rows_done)``), while the workers are still in
        their kernels, and that part is shortened by its measured duration, so that all
        parts end together (one thread: after all rows). Run first, it held the GIL while the
        workers needed it for the Python steps before their kernels, and each of its GIL
        releases (a BLAS product) handed the GIL to a worker until that worker's kernel
        started: in a 40 s deep run on the shared 2-core machine the caller's ``before``
        took 0.1-2.2 s more wall than CPU (more under more load), 0.03-0.6 s with
        ``before`` after its part.
        """
        return self.start_rows(call, nsamp, before).wait()

    def start_rows(self, call: Callable[[int, int], None], nsamp,
                   before: Callable[[int], None] | None = None, *,
                   detach: bool = False) -> RowsCall:
        """:meth:`run_rows` that returns when the calling thread's part and ``before`` are
        done; :meth:`RowsCall.wait` (on the same thread) waits for the workers' parts.

        ``detach=True``: the caller goes on with other work while the workers end their
        parts (the deep loop's NCO commands of the next interval: module notes, *Calls
        left running*), and its part is shortened by that work too, measured from this
        call's return to the next ``start_rows`` of this object, so that the workers' parts
        end when the caller's next part does. Between two such calls the outputs of the
        first are final only after its ``wait``; its inputs must not change before.
        """
        ns = np.asarray(nsamp)
        n = ns.size
        threads = self.pick(float(ns.sum()))
        cost = self.cost
        cpu0 = time.thread_time()
        gap = self._detached_cpu
        self._detached_cpu = None
        if detach and gap is not None:
            dt = cpu0 - gap
            self._gap_s = dt if self._gap_s == 0.0 else 0.8 * self._gap_s + 0.2 * dt
        t0 = time.perf_counter()
        if threads == 1 or n < 2:
            call(0, n)
            if before is not None:
                before(n)
            rc = RowsCall(self, threads, cost, ns, cpu0, None)
        else:
            tot = max(float(ns.sum()), 1.0)
            # the caller's part: with `before` (T_b), the caller's work between detached
            # calls (T_g) and the kernel (K) shared so that all parts end together,
            # (K - T_b - T_g) / threads, in samples
            other_s = (0.0 if before is None else self._before_s) + \
                (self._gap_s if detach else 0.0)
            lead = 0.0 if self._sample_s <= 0.0 else min(other_s / self._sample_s, tot)
            cum = np.cumsum(ns, dtype=np.float64)
            share = (tot - lead) / threads
            c1 = min(int(np.searchsorted(cum, share, side="left")) + 1, n) if share > 0 else 0
            cuts = [0] + [c1 + c for c in balanced_cuts(ns[c1:], threads - 1)]
            pool = _pool(threads - 1)
            parts = [(cuts[j], cuts[j + 1]) for j in range(1, threads)
                     if cuts[j + 1] > cuts[j]]
            rc = RowsCall(self, threads, cost, ns, cpu0, len(parts) + 1)
            _split_call(True)
            try:
                rc.futures.extend(pool.submit(rc.worker_part, call, a, b) for a, b in parts)
                if cuts[1] > 0:
                    tc = time.thread_time()
                    call(0, cuts[1])
                    dt = time.thread_time() - tc
                    rc.main_cpu += dt
                    per = dt / float(cum[cuts[1] - 1])
                    self._sample_s = per if self._sample_s == 0.0 else \
                        0.8 * self._sample_s + 0.2 * per
                if before is not None:
                    # after the caller's part: the workers are inside their (nogil) kernels
                    # by then, so `before` has the GIL to itself (notes above); a short
                    # switch interval lets a worker that ends first return at once
                    switch = sys.getswitchinterval()
                    sys.setswitchinterval(min(switch, _SWITCH_S))
                    tb = time.thread_time()
                    try:
                        before(cuts[1])
                    finally:
                        sys.setswitchinterval(switch)
                    dt = time.thread_time() - tb
                    rc.main_cpu += dt
                    self._before_s = dt if self._before_s == 0.0 else \
                        0.8 * self._before_s + 0.2 * dt
            except BaseException:
                rc.wait()        # (the workers' parts end; the split call is released)
                raise
            rc.part_done()
        rc.start_wall = time.perf_counter() - t0
        if detach:
            self._detached_cpu = time.thread_time()
        return rc


class RowsCall:
    """A call of :meth:`KernelThreads.start_rows` whose workers' parts may still run.

    Attributes
    ----------
    threads : int
        Thread count used.
    futures : list
        The workers' parts (each returns its CPU time [s]).
    main_cpu : float
        CPU time of the caller's part and its ``before`` [s].
    start_wall : float
        Wall time of ``start_rows`` [s].
    """

    def __init__(self, kt: KernelThreads, threads: int, costs: dict, nsamp: np.ndarray,
                 cpu0: float, parts: int | None) -> None:
        self.kt, self.threads, self.costs = kt, threads, costs   # costs: the size class's
        self.work = max(float(nsamp.sum()), 1.0)
        self.cpu0 = cpu0                 # the caller's thread time at the call's start [s]
        self.futures: list = []
        self.main_cpu = 0.0
        self.start_wall = 0.0
        self._parts = parts            # parts still running, the caller's counted (None: no split)
        self._lock = threading.Lock()
        self._waited: int | None = None

    def worker_part(self, call: Callable[[int, int], None], a: int, b: int) -> float:
        """A worker's part: ``call(a, b)``; returns its CPU time [s]."""
        tc = time.thread_time()
        try:
            call(a, b)
        finally:
            self.part_done()
        return time.thread_time() - tc

    def part_done(self) -> None:
        """One part ended (the caller's includes ``before``): the split call counts as running
        (:func:`wait_for_split_calls`) until every part has."""
        with self._lock:
            if self._parts is None or self._parts <= 0:
                return
            self._parts -= 1
            last = self._parts == 0
        if last:
            _split_call(False)

    def wait(self) -> int:
        """Wait for the workers' parts (a part's exception is raised here), record the call's
        cost and CPU accounting once; returns the thread count used."""
        if self._waited is not None:
            return self._waited
        tw = time.perf_counter()
        cpu = time.thread_time() - self.cpu0
        worker_cpu = []
        try:
            worker_cpu = [f.result() for f in self.futures]
        except BaseException:
            futures_wait(self.futures)      # the other parts end before the release below
            raise
        finally:
            self._waited = self.threads
            # every part submitted has ended: release what a part never submitted holds
            with self._lock:
                left, self._parts = self._parts, 0 if self._parts is not None else None
            if left:
                _split_call(False)
            if left is not None:
                _STATS["calls"] += 1
                _STATS["caller_cpu_s"] += self.main_cpu
                _STATS["worker_cpu_s"] += sum(worker_cpu)
                # the caller's CPU time since the call began ran beside the workers' parts
                _STATS["wait_cpu_s"] += max(0.0, max(worker_cpu, default=0.0) - cpu)
        wall = self.start_wall + time.perf_counter() - tw
        self.kt.record(self.threads, wall / self.work, self.costs)
        return self.threads
