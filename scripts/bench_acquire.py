#!/usr/bin/env python
"""Acquisition time per PRN at 25 MHz: the normal search and the long one (``bench.py
acquire``).

Usage::

    python scripts/bench.py acquire [--fs 25e6] [--prns 7] [--repeat 2]

On 0.5 s of the default scenario (generated once into a temp dir), times
:func:`~sdr_di.receiver.acquisition.acquire` (input cleaning, FFT search, refinement) for:

* ``normal``: 40 x 1 ms, +-5 kHz in 500 Hz bins (21): the cold search of ``sdr-di run``;
* ``assisted``: 40 x 1 ms around each PRN's predicted Doppler (the receiver's window: the
  cold grid's bins covering +-1 kHz, 7 per PRN), one call whose PRNs share their bins;
* ``long``: 400 x 1 ms, +-5 kHz in 250 Hz bins (41): the long search of a listed PRN
  without a Doppler;
* ``long assisted``: 400 x 1 ms in 250 Hz bins around each PRN's predicted Doppler (11 per
  PRN), one call.

Wall and CPU time (user + system of this process, all threads) per PRN; the FFT of the
input blocks is shared by the PRNs of one call, so the per-PRN cost falls with more PRNs.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import tempfile
import time
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fs", type=float, default=25e6, help="sampling rate [Hz] (default 25e6)")
    p.add_argument("--prns", type=int, default=7, help="PRNs per search (default 7: the "
                   "default scenario's satellites)")
    p.add_argument("--repeat", type=int, default=2, help="timed repeats (best is printed)")


def _cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def run(args: argparse.Namespace) -> None:
    from sdr_di.cli import main as cli
    from sdr_di.receiver.acquisition import acquire, doppler_offsets
    from sdr_di.receiver.run_scalar import open_source, sidecar_assistance
    from sdr_di.receiver.scalar import ScalarReceiver

    tmp = Path(tempfile.mkdtemp(prefix="sdr-di-bench-acq-"))
    try:
        rc = cli(["generate", "--no-progress", "--duration", "0.5", "--fs", f"{args.fs:g}",
                  "--out", str(tmp)])
        if rc:
            raise SystemExit(rc)
        src = open_source(tmp / "default.bin")
        aid = sidecar_assistance(src)
        prns = (list(aid) + [p for p in range(1, 64) if p not in aid])[:args.prns]
        fs = src.sampling_rate_hz
        x = src.read(0, round(0.4 * fs))
        acquire(x[:round(0.005 * fs)], fs, src.if_hz, prns=prns[:1], noncoherent=5)  # warm-up
        print(f"machine: {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; "
              f"{fs / 1e6:g} MHz complex, {len(prns)} PRNs per search")
        print(f"{'search':>14} {'K x M ms':>9} {'bins':>5} {'wall s':>7} {'CPU s':>6} "
              f"{'wall s/PRN':>10} {'CPU s/PRN':>9}")
        rx = ScalarReceiver()
        cases = (("normal", 40, 500.0, False), ("assisted", 40, 500.0, True),
                 ("long", 400, 250.0, False), ("long assisted", 400, 250.0, True))
        for name, k, step, assisted in cases:
            best = None
            for _ in range(args.repeat):
                t0, c0 = time.perf_counter(), _cpu()
                if assisted:  # one call, each PRN around its own Doppler (shared bins)
                    win = rx._assisted_windows(prns, {p: aid.get(p) or 0.0 for p in prns}, fs)
                    acquire(x, fs, src.if_hz, prns=prns, noncoherent=k, doppler_step_hz=step,
                            **win)
                else:
                    win = {"doppler_center_hz": 0.0, "doppler_range_hz": 5000.0}
                    acquire(x, fs, src.if_hz, prns=prns, noncoherent=k, doppler_step_hz=step,
                            **win)
                w, c = time.perf_counter() - t0, _cpu() - c0
                best = (w, c) if best is None or w < best[0] else best
            bins = doppler_offsets(win["doppler_range_hz"], step).size
            w, c = best
            print(f"{name:>14} {k:>5} x 1 {bins:5d} {w:7.2f} {c:6.2f} {w / len(prns):10.3f} "
                  f"{c / len(prns):9.3f}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(ap)
    run(ap.parse_args())
