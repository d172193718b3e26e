"""The integration loop of loose and tight mode in a child Python process.

Loose and tight run the loop behind the scalar receiver, which does not depend on the
filter (:mod:`~sdr_di.integration.gnss_epochs`). On a thread of the receiver's process
(:class:`~sdr_di.integration.loop.BackgroundLoop`) the loop's Python work (INS at 200 Hz,
filter at 50 Hz) needs the interpreter lock, which the receiver's own Python work holds
about half of the run: the loop then runs either in the receiver's place or beside the
correlation kernels on cores they use, and the run is longer by about the loop's CPU time
(issue 17 target 4, docs/coupling.md *Speed*). In a child process the loop has its own
interpreter and runs on the core the receiver leaves idle while it is in Python.

:class:`LoopProcess` has :class:`~sdr_di.integration.loop.BackgroundLoop`'s interface
(``join``, ``abort``, ``cpu_s``). It sends the child the loop and its measurement source
(pickled; the source's epoch list detached), then every epoch the
:class:`~sdr_di.integration.gnss_epochs.GnssEpochRecorder` records, as it records it (a
writer thread, so the receiver never waits on the pipe); ``join`` takes back the loop and
source as they ended (rows, filter, profile, navigation record); a child that died
without a result (killed, out of memory) is reported by a ``RuntimeWarning`` and replaced
by running the loop, which the parent still holds unrun, over the recorded epochs. The
child computes what the thread would have: the same objects, the same epochs in the same
order, the same code; the Klobuchar object of each epoch keeps its identity across the pipe (the source
marks an ionosphere change by identity), so the rows are the thread's bit for bit
(tested).

:func:`start_loop_behind` chooses: the child process unless the loop or its source cannot
be pickled (a filter holding a closure), or the caller is a daemonic
``multiprocessing`` worker (which may not have children), or ``SDR_DI_LOOP_THREAD=1``
is set; the thread otherwise. The child can be started before the loop exists
(:class:`LoopChild`: ``IntegratedReceiver.run`` starts it at the receiver's first output epoch,
after the acquisition, whose FFT search uses every core, so that its interpreter start
and imports run in the seconds before the hand-over on the core tracking leaves idle,
not beside the loop's first epochs).

Frames on the pipes: an 8-byte little-endian length, then a pickle. Parent to child: the
set-up ``(loop, source, epoch_source)``, then ``("epoch", GnssEpoch, iono_key, iono)`` per
epoch (``iono`` sent only with a new key) and ``("close",)``; child to parent: ``(loop,
source, epoch_source, cpu_s, error, warnings)`` (the warnings the loop issued, issued again
in the parent).
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import queue
import signal
import struct
import subprocess
import sys
import threading
import time
import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..errors import LoopProcessError  # noqa: F401  (defined in sdr_di.errors)
from ..settings import loop_on_thread
from .loop import BackgroundLoop, IntegrationLoop

if TYPE_CHECKING:
    from ..orbits.ephemeris import Klobuchar

__all__ = ["LoopChild", "LoopProcess", "LoopProcessError", "start_loop_behind"]

_LEN = struct.Struct("<Q")
#: Where the child's warnings, issued again here, are counted (once per place by default).
_WARNING_REGISTRY: dict = {}




def _write_frame(fh, data: bytes) -> None:
    fh.write(_LEN.pack(len(data)))
    fh.write(data)
    fh.flush()


def _read_frame(fh) -> bytes | None:
    head = fh.read(_LEN.size)
    if len(head) < _LEN.size:
        return None
    n = _LEN.unpack(head)[0]
    data = fh.read(n)
    if len(data) < n:
        return None
    return data


class LoopChild:
    """A started child process, its imports done or under way, waiting for a loop.

    Started early in a loose/tight run (:meth:`start`: at the receiver's first output
    epoch), its interpreter start and imports (0.6-0.7 s of CPU) run before the hand-over,
    while the receiver tracks, rather than at it.
    :meth:`close` ends one that gets no loop (no hand-over, or the thread runs it).
    """

    def __init__(self) -> None:
        # the child imports this very sdr_di, wherever the parent found it, and the folders
        # the parent added to sys.path (a plugin filter's module, found there or in the
        # current folder: unpickling the loop imports it; issue 49 item 2); the
        # interpreter's own folders it has already, in their order
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env = dict(os.environ)
        own = tuple(os.path.abspath(p) for p in {sys.prefix, sys.base_prefix, sys.exec_prefix})
        added = [p for p in sys.path if p and os.path.isdir(p)
                 and not os.path.abspath(p).startswith(own)]
        env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(
            p for p in (root, env.get("PYTHONPATH"), *added) if p))
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "sdr_di.integration.loop_process"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)

    @classmethod
    def start(cls) -> LoopChild | None:
        """A child, or None where the thread will run the loop (module notes)."""
        import multiprocessing

        if loop_on_thread() or multiprocessing.current_process().daemon:
            return None
        try:
            return cls()
        except OSError:            # no process to be had: the thread runs the loop
            return None

    def close(self) -> None:
        """End the child, which has run nothing (killed: it may still be importing)."""
        _end(self.proc)


class LoopProcess:
    """:meth:`IntegrationLoop.run` in a child process fed by a recorder (module notes).

    Parameters
    ----------
    loop : IntegrationLoop
    source : MeasurementSource
        What the loop runs with (``epoch_source`` or a wrapper of it).
    epoch_source : ScalarEpochSource
        The source reading the recorder's epochs.
    recorder : GnssEpochRecorder
        Its epochs so far are sent at once, later ones as they are recorded.
    payload : bytes, optional
        ``pickle.dumps((loop, source, epoch_source))`` with the epochs detached, when the
        caller has made it already.
    child : LoopChild, optional
        A child started earlier (default: one started now).

    Attributes
    ----------
    loop, source, epoch_source
        After :meth:`join`: the child's objects as the loop ended.
    cpu_s : float
        CPU time of the loop in the child [s] (its thread's, as ``BackgroundLoop``'s).
    """

    def __init__(self, loop: IntegrationLoop, source, epoch_source, recorder, *,
                 payload: bytes | None = None, child: LoopChild | None = None) -> None:
        self.loop, self.source, self.epoch_source = loop, source, epoch_source
        self.cpu_s = 0.0
        if payload is None:
            payload = _payload(loop, source, epoch_source)
        self._proc = (child or LoopChild()).proc
        self._q: queue.SimpleQueue = queue.SimpleQueue()
        self._q.put(payload)
        self._iono_keys: dict[int, object] = {}
        self._writer = threading.Thread(target=self._write, name="sdr-di loop feed",
                                        daemon=True)
        self._writer.start()
        self._done = False
        recorder.add_listener(self._on_epoch, self._on_close)

    # ---- parent side ---------------------------------------------------------------------
    def _on_epoch(self, ep) -> None:
        """Recorder listener: one epoch, its Klobuchar object by key (module notes)."""
        iono = ep.iono
        key = id(iono)
        new = key not in self._iono_keys
        if new:
            self._iono_keys[key] = iono     # held alive, so no other object gets its id
        self._q.put(pickle.dumps(("epoch", dataclasses.replace(ep, iono=None), key,
                                  iono if new else None), protocol=pickle.HIGHEST_PROTOCOL))

    def _on_close(self) -> None:
        self._q.put(pickle.dumps(("close",)))
        self._q.put(None)

    def _write(self) -> None:
        fh = self._proc.stdin
        assert fh is not None             # the child is started with stdin=PIPE
        try:
            while (data := self._q.get()) is not None:
                _write_frame(fh, data)
            fh.close()
        except (BrokenPipeError, OSError, ValueError):
            pass            # the child ended early (error or abort): join reports it

    def join(self) -> None:
        """Wait for the loop to end; take back its objects; re-raise its exception here.
        Call it after the recorder is closed (a child that died is replaced by running the
        loop here over the recorded epochs)."""
        assert self._proc.stdout is not None      # started with stdout=PIPE
        data = _read_frame(self._proc.stdout)
        self._proc.stdout.close()
        rc = self._proc.wait()
        self._writer.join()
        self._done = True
        if data is None:     # the child died (killed, out of memory, could not start):
            # the loop, never run here, runs now over the recorded epochs, the same rows
            warnings.warn(f"integration loop process ended (exit status {rc}) without a "
                          "result; running the loop in this process", RuntimeWarning,
                          stacklevel=2)
            c0 = time.thread_time()
            self.loop.run(self.source)
            self.cpu_s = time.thread_time() - c0
            return
        loop, source, epoch_source, cpu_s, error, notes = pickle.loads(data)
        self.loop, self.source, self.epoch_source, self.cpu_s = (loop, source, epoch_source,
                                                                 cpu_s)
        for message, category, filename, lineno in notes:    # as the thread would have
            warnings.warn_explicit(message, category, filename, lineno,
                                   registry=_WARNING_REGISTRY)
        if error is not None:
            raise error

    def abort(self) -> None:
        """End the child now (the caller failed)."""
        if self._done:
            return
        self._done = True

        def stop_writer() -> None:     # before the pipes close: it may be writing to stdin
            self._q.put(None)
            self._writer.join()

        _end(self._proc, before_close=stop_writer)


def _end(proc: subprocess.Popen, before_close: Callable[[], None] | None = None) -> None:
    """Kill the child ``proc``, wait for it, run ``before_close`` (if any), then close its
    pipes (a pipe already broken is ignored)."""
    proc.kill()
    proc.wait()
    if before_close is not None:
        before_close()
    for fh in (proc.stdin, proc.stdout):
        assert fh is not None             # LoopChild starts it with both pipes
        try:
            fh.close()
        except OSError:
            pass


def _payload(loop, source, epoch_source) -> bytes:
    """The set-up frame: the objects with the epoch list detached (restored after)."""
    saved = epoch_source.detach_epochs()
    try:
        return pickle.dumps((loop, source, epoch_source), protocol=pickle.HIGHEST_PROTOCOL)
    finally:
        epoch_source.attach_epochs(*saved)


def start_loop_behind(loop: IntegrationLoop, source, epoch_source, recorder,
                      child: LoopChild | None = None):
    """The loop behind the receiver: a :class:`LoopProcess` (in ``child``, a
    :class:`LoopChild` started earlier, else in a new one), else a
    :class:`~sdr_di.integration.loop.BackgroundLoop` (module notes)."""
    payload = None
    if child is None:
        child = LoopChild.start()
    if child is not None:
        try:
            payload = _payload(loop, source, epoch_source)
            pickle.loads(payload)          # what the child will do: fails here, not there
        except Exception:  # noqa: BLE001 - an unpicklable model: the thread runs it
            payload = None
            child.close()
    if payload is None:
        return BackgroundLoop(loop, source)
    return LoopProcess(loop, source, epoch_source, recorder, payload=payload, child=child)


# ---- child side --------------------------------------------------------------------------
class _EpochStream:
    """The child's view of the recorder: ``epochs`` and ``wait_for`` over the pipe."""

    def __init__(self, fh) -> None:
        self.fh = fh
        self.epochs: list = []
        self.closed = False
        self._iono: dict[int, Klobuchar] = {}

    def wait_for(self, i: int) -> bool:
        while i >= len(self.epochs) and not self.closed:
            data = _read_frame(self.fh)
            msg: tuple = pickle.loads(data) if data is not None else ("close",)
            if msg[0] == "close":
                self.closed = True
                break
            _, ep, key, iono = msg
            if iono is not None:
                self._iono[key] = iono
            self.epochs.append(dataclasses.replace(ep, iono=self._iono.get(key)))
        return i < len(self.epochs)


#: Modules a loop's set-up frame needs, imported before it arrives (:class:`LoopChild`).
_PRELOAD = ("sdr_di.integration.loose_fixes", "sdr_di.integration.tight_ranges",
            "sdr_di.integration.assumptions", "sdr_di.deep.vector_tracking")


def _warm_up_rules(kf) -> None:
    """Compile or load the adaptive rules' numba kernels before the loop runs. In the
    parent the rule did it when it was bound to the filter (outside its timed hooks); the
    unpickled rule's kernels are new to this interpreter, and the first hook call would
    otherwise count numba's start-up in ``adaptation_time_s`` (0.15 s from numba's cache,
    0.8 s and more when it compiles)."""
    if getattr(kf, "rule", None) is None:
        return
    for name, mod in list(sys.modules.items()):
        if name.startswith("sdr_di.filters.adaptive._numba_") and hasattr(mod, "warm_up"):
            mod.warm_up()


def _child_main() -> int:
    """Run the loop sent on stdin; write the result frame on stdout."""
    import importlib

    signal.signal(signal.SIGINT, signal.SIG_IGN)     # the parent ends the child
    inp = sys.stdin.buffer
    out = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    sys.stdout = sys.stderr                          # nothing else on the result pipe
    for name in _PRELOAD:
        importlib.import_module(name)
    data = _read_frame(inp)
    if data is None:
        return 1
    loop, source, epoch_source = pickle.loads(data)
    _warm_up_rules(loop.kf)
    stream = _EpochStream(inp)
    epoch_source.attach_epochs(stream.epochs, stream.wait_for)
    error = None
    c0 = time.thread_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")              # the parent's filters decide
        try:
            loop.run(source)
        except BaseException as e:  # noqa: BLE001 - handed to the parent
            error = e
    cpu_s = time.thread_time() - c0
    epoch_source.detach_epochs()
    # the whole child's CPU: interpreter start, imports, feed, loop (profile notes)
    loop.profile["loop_process_cpu"] = time.process_time()
    notes = [(w.message, w.category, w.filename, w.lineno) for w in caught]
    try:
        res = pickle.dumps((loop, source, epoch_source, cpu_s, error, notes),
                           protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # noqa: BLE001 - an unpicklable exception or warning: the text
        res = pickle.dumps((loop, source, epoch_source, cpu_s,
                            LoopProcessError(f"integration loop: {error!r}") if error
                            else None,
                            [(str(m), UserWarning, f, n) for m, _, f, n in notes]))
    _write_frame(out, res)
    out.close()
    return 0


if __name__ == "__main__":
    # run the module's own copy (not this ``__main__`` one), so that what the child pickles
    # (LoopProcessError) has the name the parent unpickles
    from sdr_di.integration.loop_process import _child_main as _main

    _rc = _main()
    sys.stderr.flush()
    os._exit(_rc)            # the result is written: no interpreter teardown on the tail
