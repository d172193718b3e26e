#!/usr/bin/env python
"""Correlator throughput: sample-channels per second of the numba E/P/L kernel.

Usage::

    python scripts/bench_correlate.py [--channels 7] [--fs 25e6] [--ms 1] [--seconds 2]
                                      [--threads 1 2] [--real] [--noise-samples N]

For each kernel and thread count, correlates ``--channels`` channels (E/P/L) over 1-ms
coherent intervals at ``--fs`` for ``--seconds`` seconds of data (random samples, random code
phases and Dopplers, as in tracking) and prints the wall time, the thread CPU time, the
throughput in sample-channels per second (of wall time) and the real-time factor (data seconds
processed per wall second for all the channels). Numba compilation is excluded (warm-up call
first). Kernels:

* ``table``: :func:`~sdr_di.receiver.correlator.correlate_table`, the public correlator API
  (float replica table, ``complex64``/``float32`` samples, input checks, bit windows packed
  at each call, result object);
* ``receiver``: the kernel entry
  (:func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_bits`) called as the scalar
  receiver and the deep loop call it: stored 4-bit-in-int8 samples, bit windows packed
  once, one kernel call for all channels, NCO values given directly. On ``int8`` samples it
  runs the integer kernel (:mod:`~sdr_di.receiver._numba_correlate_int`) at 11 MHz or
  more, below about 10.6 MHz the low-rate kernel
  (:mod:`~sdr_di.receiver._numba_correlate_gather`);
* ``recv_f32``: the same calls on the float32 kernel
  (:func:`~sdr_di.receiver._numba_correlate_bits.correlate_epl_float`, the reference path,
  what ``receiver`` ran before the integer kernel).

``ns/s-ch`` is the CPU time per sample and channel [ns] (the three taps E, P, L and the
wipe-off of one sample for one channel).

``--noise-samples N`` (``receiver`` and ``recv_f32``): each interval's row of a channel is
followed by a noise-correlator row of its first ``N`` samples at another code phase, as the
receivers call the kernel (``rate``: :func:`~sdr_di.receiver.lock.noise_samples` of
``--fs``); ``ns/s-ch`` still divides by the interval's samples only, so it carries the noise
rows' cost.

``run(args)`` is the entry point for a later ``scripts/bench.py correlate`` dispatcher; ``args``
needs the attributes ``channels``, ``fs``, ``ms``, ``seconds``, ``threads`` and ``real``
(``noise_samples`` optional, default none).
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numba
import numpy as np

from sdr_di.receiver._numba_correlate_bits import correlate_epl_bits, correlate_epl_float
from sdr_di.receiver.correlator import (
    CODE_PAD,
    bit_windows,
    carrier_rotation,
    correlate_table,
    kernel_tasks,
    padded_replicas,
    reduce_code_phase,
)


def _one_rate(x: np.ndarray, table: np.ndarray, n_int: int, n_intervals: int, fs: float,
              rng: np.random.Generator) -> float:
    n_ch = table.shape[0]
    theta = rng.uniform(0, 10230, n_ch)
    rate = 10.23e6 * (1 + rng.uniform(-3e-6, 3e-6, n_ch))
    phi = rng.uniform(0, 1, n_ch)
    fc = rng.uniform(-5e3, 5e3, n_ch)
    t0 = time.perf_counter()
    for j in range(n_intervals):
        off = (j * n_int) % (x.size - n_int + 1)
        r = correlate_table(x[off:off + n_int], table, 10230, theta, rate, phi, fc, n_int, fs)
        theta, phi = r.code_phase_end, r.carrier_phase_end
    return time.perf_counter() - t0


def _one_rate_receiver(xs: np.ndarray, is_complex: bool, bits: np.ndarray, n_int: int,
                       n_intervals: int, fs: float, rng: np.random.Generator,
                       kernel=correlate_epl_bits, n_noise: int = 0) -> float:
    """The receiver's kernel on the same intervals (all channels in one call, as the bank;
    with ``n_noise`` > 0 each channel's row followed by its noise row of ``n_noise`` samples
    at a code phase 5000 chips away and the same carrier, as the receivers order them)."""
    n_ch = bits.shape[0]
    n_comp = 2 if is_complex else 1
    n_x = xs.size // n_comp
    theta = rng.uniform(0, 10230, n_ch)
    dchip = 10.23e6 * (1 + rng.uniform(-3e-6, 3e-6, n_ch)) / fs
    phi = rng.uniform(0, 1, n_ch)
    dphi = rng.uniform(-5e3, 5e3, n_ch) / fs
    rot_re, rot_im = carrier_rotation(dphi)
    k = 2 if n_noise > 0 else 1                      # rows per channel
    idx = np.repeat(np.arange(n_ch, dtype=np.int64), k)
    nsamp = np.full(k * n_ch, n_int, np.int64)
    if k == 2:
        nsamp[1::2] = min(n_noise, n_int)
    out = np.empty((k * n_ch, 3, 2))
    n_sub = kernel_tasks(n_ch, n_int) if k == 1 else 1
    dchip_k, dphi_k = np.repeat(dchip, k), np.repeat(dphi, k)
    t0 = time.perf_counter()
    for j in range(n_intervals):
        off = (j * n_int) % (n_x - n_int + 1)
        th, ph = theta, phi
        if k == 2:
            th, ph = np.repeat(theta, 2), np.repeat(phi, 2)
            th[1::2] = reduce_code_phase(theta + 5000.0, 10230)
        kernel(xs, n_comp, bits, idx, CODE_PAD, 10230, np.full(k * n_ch, off, np.int64), nsamp,
               th, dchip_k, ph, dphi_k, rot_re, rot_im, idx, 0.5, n_sub, out)
        theta = reduce_code_phase(theta + n_int * dchip, 10230)
        phi = phi + n_int * dphi
        phi -= np.floor(phi)
    return time.perf_counter() - t0


def _workload(rng: np.random.Generator, n_block: int, n_ch: int, real: bool = False):
    """Random samples (``float32`` real or ``complex64``), random +-1 code replicas (one
    row per channel), their bit windows, and the samples stored as the receivers store
    4-bit values (``int8``, interleaved I/Q for complex)."""
    if real:
        x = rng.normal(size=n_block).astype(np.float32)
    else:
        x = (rng.normal(size=n_block) + 1j * rng.normal(size=n_block)).astype(np.complex64)
    table = padded_replicas(rng.choice(np.array([-1, 1], np.int8), size=(n_ch, 10230)))
    xs = x.view(np.float32) if not real else x
    xs = np.clip(np.rint(xs * 2.5), -7, 7).astype(np.int8)
    return x, table, bit_windows(table), xs


def speed_reference(seconds: float = 1.0) -> float:
    """The machine's speed at this moment: CPU time per sample and channel [ns] of the
    receiver's kernel on one thread, on a fixed workload (7 channels, 25 MHz, 1 ms rows,
    ``seconds`` of stored 4-bit-in-int8 samples, the same random draw every time).

    The benchmarks print it before and after their runs: on the shared VM the same work
    takes up to 1.5 times longer in one hour than in another, and a figure without the
    machine's speed beside it cannot be compared with another session's."""
    rng = np.random.default_rng(1)
    fs, n_ch = 25e6, 7
    n_int = round(fs * 1e-3)
    _, _, bits, xs = _workload(rng, n_int * 50, n_ch)
    n_iv = max(1, round(seconds * 1e3))
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        _one_rate_receiver(xs, True, bits, n_int, 2, fs, rng)     # compile / warm up
        c0 = time.thread_time()
        _one_rate_receiver(xs, True, bits, n_int, n_iv, fs, rng)
        cpu = time.thread_time() - c0
    finally:
        numba.set_num_threads(old)
    return cpu / (n_iv * n_int * n_ch) * 1e9


def python_reference(iterations: int = 800) -> float:
    """The speed of the interpreter and small NumPy calls at this moment: CPU time of one
    step of a fixed filter-sized workload [us] (a 17-state covariance predict and a
    14-measurement update with ``np.linalg.solve``, plus scalar Python arithmetic), the kind
    of work the deep loop's main thread does between kernel calls."""
    rng = np.random.default_rng(2)
    F = np.eye(17) + 1e-3 * rng.normal(size=(17, 17))
    Q = 1e-6 * np.eye(17)
    H = rng.normal(size=(14, 17))
    R = np.eye(14)
    P0 = np.eye(17)
    acc = 0.0
    c0 = time.thread_time()
    for k in range(iterations):
        P = F @ P0 @ F.T + Q          # from the same P every step: the same values each time
        S = H @ P @ H.T + R
        K = np.linalg.solve(S, H @ P).T
        P = P - K @ H @ P
        for v in (0.1 * k, 0.2 * k, 0.3 * k):
            acc += math.sin(v) * math.cos(v) / (1.0 + v * v)
    return (time.thread_time() - c0) / iterations * 1e6


_PAIR_CHILD = """
import sys
sys.path.insert(0, {scripts!r})
from bench_correlate import speed_reference
speed_reference(0.02)            # load the kernel from numba's cache, warm up
print("ready", flush=True)
sys.stdin.readline()
print(speed_reference({seconds!r}), flush=True)
"""


def pair_reference(seconds: float = 1.0) -> list[float]:
    """:func:`speed_reference` in two processes at once, one per core [ns per sample-channel,
    each process's figure].

    The one-thread figure says nothing about how the VM's two cores share the host: a
    40 s deep run took 11.8 s at 19:27 and 9.5-10.1 s at 19:36 on 2026-12-04 with the same
    one-thread figures (0.885 and 0.868 ns). Each process loads and warms the kernel, then
    both start on one signal; equal figures here and on one thread mean two independent
    cores."""
    import subprocess
    import sys
    from pathlib import Path

    from bench import child_env

    code = _PAIR_CHILD.format(scripts=str(Path(__file__).resolve().parent), seconds=seconds)
    procs = [subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True, env=child_env())
             for _ in range(2)]
    try:
        for p in procs:
            if p.stdout.readline().strip() != "ready":
                raise RuntimeError("pair_reference: a child process failed to start")
        for p in procs:
            p.stdin.write("go\n")
            p.stdin.flush()
        return [float(p.stdout.readline()) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
            p.wait()


def speed_line(when: str) -> str:
    """One line with :func:`speed_reference`, :func:`pair_reference` and
    :func:`python_reference` for a benchmark's output."""
    py = sorted(python_reference() for _ in range(5))
    pair = pair_reference()
    return (f"machine speed {when}: the receiver's correlator at {speed_reference():.3f} ns "
            f"per sample-channel on one thread, {pair[0]:.3f} and {pair[1]:.3f} ns in two "
            f"processes at once (one per core), a filter-sized Python/NumPy step "
            f"{py[0]:.1f}-{py[-1]:.1f} us over 5 x 800 steps (scripts/bench_correlate.py "
            "speed_reference, pair_reference, python_reference; lower is faster; on the shared "
            "VM the step time varies from one second to the next)")


def run(args: argparse.Namespace) -> list[dict]:
    """Run the benchmark and print a table; returns the rows (dicts)."""
    rng = np.random.default_rng(1)
    fs = float(args.fs)
    n_int = round(fs * args.ms * 1e-3)
    n_ch = int(args.channels)
    x, table, bits, xs = _workload(rng, n_int * 50, n_ch, args.real)
    n_intervals = max(1, round(args.seconds * 1e3 / args.ms))
    max_threads = numba.config.NUMBA_NUM_THREADS
    threads = [t for t in args.threads if 1 <= t <= max_threads] or [numba.get_num_threads()]
    print(f"machine: {os.cpu_count()} cores, numba threads available: {max_threads}")
    n_noise = _noise_samples(args, fs)
    print(f"correlator: {n_ch} channels x E/P/L, {'real' if args.real else 'complex'} input, "
          f"fs = {fs / 1e6:g} MHz, {args.ms:g} ms intervals, {args.seconds:g} s of data"
          + (f", noise rows of {n_noise} samples" if n_noise else ""))
    print(f"{'kernel':>8} {'threads':>7} {'wall s':>8} {'CPU s':>7} {'Msample-ch/s':>13} "
          f"{'x real time':>12} {'ns/s-ch':>8}")
    rows = []
    old = numba.get_num_threads()
    try:
        for kernel in ("table", "receiver", "recv_f32"):
            for t in threads:
                numba.set_num_threads(t)
                if kernel == "table":
                    def one(n_iv):
                        return _one_rate(x, table, n_int, n_iv, fs, rng)
                else:
                    fn = correlate_epl_bits if kernel == "receiver" else correlate_epl_float

                    def one(n_iv, fn=fn):
                        return _one_rate_receiver(xs, not args.real, bits, n_int, n_iv, fs,
                                                  rng, fn, n_noise)
                one(2)  # compile / warm up
                c0 = time.thread_time() if t == 1 else time.process_time()
                wall = one(n_intervals)
                cpu = (time.thread_time() if t == 1 else time.process_time()) - c0
                sc = n_intervals * n_int * n_ch / wall
                rt = n_intervals * n_int / fs / wall
                ns = cpu / (n_intervals * n_int * n_ch) * 1e9
                rows.append({"kernel": kernel, "threads": t, "wall_s": wall, "cpu_s": cpu,
                             "sample_channels_per_s": sc, "real_time_factor": rt,
                             "cpu_ns_per_sample_channel": ns})
                print(f"{kernel:>8} {t:7d} {wall:8.3f} {cpu:7.3f} {sc / 1e6:13.1f} {rt:12.3f} "
                      f"{ns:8.3f}")
    finally:
        numba.set_num_threads(old)
    return rows


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of the correlator benchmark (shared with a ``bench.py`` sub-command)."""
    parser.add_argument("--channels", type=int, default=7)
    parser.add_argument("--fs", type=float, default=25e6, help="sample rate [Hz]")
    parser.add_argument("--ms", type=float, default=1.0, help="coherent interval [ms]")
    parser.add_argument("--seconds", type=float, default=2.0, help="data duration [s]")
    parser.add_argument("--threads", type=int, nargs="+",
                        default=sorted({1, numba.config.NUMBA_NUM_THREADS}))
    parser.add_argument("--real", action="store_true", help="real (float32) input")
    parser.add_argument("--noise-samples", default="0",
                        help="noise row after each row: samples, or 'rate' (the receivers' "
                             "count at --fs); 0: none")


def _noise_samples(args: argparse.Namespace, fs: float) -> int:
    """The noise rows' samples of ``--noise-samples`` (0: none)."""
    v = str(getattr(args, "noise_samples", "0"))
    if v == "rate":
        from sdr_di.receiver.lock import noise_samples
        return noise_samples(fs)
    return int(v)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    run(parser.parse_args(argv))


if __name__ == "__main__":
    main()
