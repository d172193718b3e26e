"""Process-wide switches from the environment, read here and nowhere else.

=========================  ===========================================================  =====================================
variable                   meaning                                                      used by
=========================  ===========================================================  =====================================
``SDR_DI_CORRELATOR``      ``int`` (default): the integer correlator kernel for int8      :data:`sdr_di.receiver._numba_correlate_bits.INTEGER_PATH`
                           samples, the low-rate kernel below ~10.6 MHz; ``float``:      and ``GATHER_PATH`` (read when that
                           the float32 reference kernel for every input                  module is imported)
                           (docs/notes/correlator.md)
``SDR_DI_KERNEL_THREADS``  threads of the correlation kernels (default: one for calls     :class:`sdr_di.receiver.threads.KernelThreads`
                           under 2^20 samples, else chosen from measured costs)
``SDR_DI_LOOP_THREAD``     ``1``: the integration loop runs on a thread of the run's     :meth:`sdr_di.integration.loop_process.LoopChild.start`
                           process instead of a child process
``OMP_WAIT_POLICY``        numba's OpenMP workers; the generator and the receivers ask   :func:`passive_kernel_workers` (``sim.ifgen.IfGenerator``,
                           for ``PASSIVE`` unless the user set it                        ``receiver.scalar.ScalarReceiver.run``,
                           (:func:`passive_kernel_workers`)                              ``receiver.acquisition.acquire``)
=========================  ===========================================================  =====================================

Each switch is read when its user asks (so a test may set it with ``monkeypatch.setenv``);
importing this module, or any module of sdr_di, sets nothing. A malformed value is a
:class:`~sdr_di.errors.OptionsError` naming the variable.
"""

from __future__ import annotations

import os

from .errors import OptionsError

__all__ = ["CORRELATOR", "KERNEL_THREADS", "LOOP_THREAD", "integer_correlator",
           "kernel_threads", "loop_on_thread", "passive_kernel_workers"]

CORRELATOR = "SDR_DI_CORRELATOR"
KERNEL_THREADS = "SDR_DI_KERNEL_THREADS"
LOOP_THREAD = "SDR_DI_LOOP_THREAD"


def integer_correlator() -> bool:
    """``SDR_DI_CORRELATOR``: True for the integer kernel (``int``, unset or empty), False
    for the float32 reference (``float``); any case, spaces ignored.

    Raises
    ------
    OptionsError
        Another value (a typo is an error, not a silent default).
    """
    v = os.environ.get(CORRELATOR, "int").strip().lower()
    if v not in ("int", "float", ""):
        raise OptionsError(f"{CORRELATOR} must be 'int' or 'float', got {v!r}")
    return v != "float"


def kernel_threads() -> int | None:
    """``SDR_DI_KERNEL_THREADS``: a fixed thread count for the correlation kernels, or None
    (unset or empty: chosen per call).

    Raises
    ------
    OptionsError
        Not a whole number >= 1.
    """
    v = os.environ.get(KERNEL_THREADS, "").strip()
    if not v:
        return None
    try:
        n = int(v)
    except ValueError:
        n = 0
    if n < 1:
        raise OptionsError(f"{KERNEL_THREADS} must be a whole number >= 1, got {v!r}")
    return n


def loop_on_thread() -> bool:
    """``SDR_DI_LOOP_THREAD``: True when set to anything but empty or ``0``."""
    return os.environ.get(LOOP_THREAD, "") not in ("", "0")


def passive_kernel_workers() -> None:
    """Ask numba's OpenMP layer to let its workers sleep between parallel regions
    (``OMP_WAIT_POLICY=PASSIVE``), unless the user set the variable.

    For the IF generator, before its first parallel kernel: otherwise the workers spin for
    milliseconds after each chunk (one region of about 0.2 s) and take CPU from the writer
    thread and from other processes (``sdr-di generate`` of the 60 s default file: 13.0 ->
    11.3 user CPU-s, docs/notes/speed.md). For the receivers, before their first parallel
    kernel (the scalar receiver's run, every acquisition): their tracking kernels run one
    numba thread each (:mod:`sdr_di.receiver.threads`), but the acquisition's refinement
    calls run numba's threads, and on a loaded machine a worker spinning at the barrier
    for a descheduled one took 0.2-0.6 CPU-s of a 0.5 s file's 1.5-2 CPU-s run (the same
    output: scheduling only; docs/notes/speed.md, session 24). libgomp reads the variable
    when numba first loads it, so a process whose parallel kernels already ran keeps its
    policy. Short parallel calls in a loop on idle cores wake sleeping workers more slowly
    (the public ``correlate_table`` with 2 numba threads: 2x the wall time), which no
    receiver makes.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
