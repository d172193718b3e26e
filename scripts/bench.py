#!/usr/bin/env python
"""Throughput benchmarks (figures for the closing notes; tests check correctness only).

Usage::

    python scripts/bench.py generate [--durations 10 60] [--out DIR] [--keep]
    python scripts/bench.py run [--durations 10 40] [--keep]
    python scripts/bench.py correlate [options of scripts/bench_correlate.py]
    python scripts/bench.py filters [options of scripts/bench_filters.py]

``generate``: runs ``sdr-di generate`` on the default scenario (7 satellites, 25 MHz, 4-bit)
for each duration in a fresh process, and prints wall time, samples per second, real-time
factor (data seconds per wall second) and the process's peak resident memory, so 10 s vs 60 s
shows whether memory grows with the file length. The first run also pays numba compilation
unless the cache is warm; a warm-up run of 0.2 s is made first.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _run_generate(duration: float, out: Path) -> tuple[float, int]:
    """Run one generation in a child process; return (wall s, peak RSS bytes of the child)."""
    code = (
        "import resource, sys; from sdr_di.cli import main; "
        f"rc = main(['generate', '--duration', '{duration}', '--out', r'{out}', "
        f"'--name', 'bench', '--no-progress']); "
        "print('MAXRSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); sys.exit(rc)"
    )
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"generate failed: {res.stderr.strip()}")
    rss_kb = int(next(l for l in res.stdout.splitlines() if l.startswith("MAXRSS")).split()[1])
    return wall, rss_kb * 1024


def bench_generate(args: argparse.Namespace) -> None:
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="sdr-di-bench-"))
    try:
        _run_generate(0.2, out)  # warm numba cache
        print(f"machine: {os.cpu_count()} cores; default scenario, 7 satellites, 25 MHz, "
              "4-bit iq_int8")
        print(f"{'duration s':>10} {'wall s':>8} {'Msamples/s':>11} {'x real time':>12} "
              f"{'peak RSS MiB':>13} {'file MiB':>9}")
        for d in args.durations:
            wall, rss = _run_generate(d, out)
            size = (out / "bench.bin").stat().st_size
            n = d * 25e6
            print(f"{d:10.1f} {wall:8.2f} {n / wall / 1e6:11.2f} {d / wall:12.2f} "
                  f"{rss / 2**20:13.1f} {size / 2**20:9.1f}")
    finally:
        if not args.keep:
            shutil.rmtree(out, ignore_errors=True)


def bench_run(args: argparse.Namespace) -> None:
    """Scalar receiver real-time factor and peak memory on default-scenario files."""
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="sdr-di-bench-"))
    try:
        print(f"machine: {os.cpu_count()} cores; scalar receiver, default scenario, "
              "7 satellites, 25 MHz, 4-bit iq_int8, PVT at 5 Hz")
        print(f"{'duration s':>10} {'wall s':>8} {'x real time':>12} {'peak RSS MiB':>13}")
        for d in args.durations:
            _run_generate(d, out)
            meta = json.loads((out / "bench.json").read_text())
            prns = ",".join(str(s["prn"]) for s in meta["satellites"])
            code = (
                "import resource, sys; from sdr_di.cli import main; "
                f"rc = main(['run', r'{out / 'bench.bin'}', '--prn', '{prns}', '--out', "
                f"r'{out / 'run'}', '--no-progress']); "
                "print('MAXRSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); "
                "sys.exit(rc)")
            t0 = time.perf_counter()
            res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
            wall = time.perf_counter() - t0
            if res.returncode != 0:
                raise SystemExit(f"run failed: {res.stderr.strip()}")
            rss = int(next(l for l in res.stdout.splitlines()
                           if l.startswith("MAXRSS")).split()[1]) * 1024
            print(f"{d:10.1f} {wall:8.2f} {d / wall:12.2f} {rss / 2**20:13.1f}")
            print("           " + next(l for l in res.stdout.splitlines()
                                        if l.startswith("processed")))
    finally:
        if not args.keep:
            shutil.rmtree(out, ignore_errors=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    g = sub.add_parser("generate", help="IF generation throughput and memory")
    g.add_argument("--durations", type=float, nargs="+", default=[10.0, 60.0])
    g.add_argument("--out", default=None, help="output directory (default: a temp dir)")
    g.add_argument("--keep", action="store_true", help="keep the generated files")
    g.set_defaults(func=bench_generate)
    r = sub.add_parser("run", help="scalar receiver real-time factor and memory")
    r.add_argument("--durations", type=float, nargs="+", default=[10.0, 40.0])
    r.add_argument("--out", default=None, help="work directory (default: a temp dir)")
    r.add_argument("--keep", action="store_true", help="keep the files")
    r.set_defaults(func=bench_run)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_correlate

    c = sub.add_parser("correlate", help="E/P/L correlator throughput (sample-channels/s)")
    bench_correlate.add_arguments(c)
    c.set_defaults(func=bench_correlate.run)
    import bench_filters

    f = sub.add_parser("filters", help="filter step time, 17 states, 2N measurements")
    bench_filters.add_arguments(f)
    f.set_defaults(func=bench_filters.run)
    args = parser.parse_args(argv)
    args.func(args)


if __name__ == "__main__":
    main()
