"""Study throughput: runs per hour of a study spec, in one process and on a local Dask cluster.

``python scripts/bench.py study [--spec studies/smoke.toml] [--runs 2] [--workers 0 2]``
runs ``sdr-di study SPEC --runs N --workers W`` in a fresh process per ``W`` (0 = every task in
the process, no cluster; 2 = a two-worker local Dask cluster), each into a new folder (no
resumption), and prints per ``W``: wall time, CPU time (user + sys of the process and its
workers), (cell, seed) tasks and filter runs per wall hour and per CPU hour, and the load
average before and after. On a shared machine the wall figures depend on the load; the CPU
figures do not (much).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--spec", default=str(REPO / "studies" / "smoke.toml"),
                   help="study spec (default studies/smoke.toml)")
    p.add_argument("--runs", type=int, default=2, help="seeds per cell (default 2)")
    p.add_argument("--workers", type=int, nargs="+", default=[0, 2],
                   help="worker counts to compare (0: in process; default 0 2)")
    p.add_argument("--out", default=None, help="work folder (default: a temp dir, removed)")


def run(args: argparse.Namespace) -> None:
    sys.path.insert(0, str(REPO))
    from sdr_di.studies.spec import load_study

    spec = load_study(args.spec)
    tasks = len(spec.cells) * args.runs
    filter_runs = tasks * len(spec.filters)
    work = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_study_"))
    print(f"study {spec.name}: {len(spec.cells)} cells x {len(spec.filters)} filters x "
          f"{args.runs} seeds = {tasks} (cell, seed) tasks, {filter_runs} filter runs; "
          f"{os.cpu_count()} cores")
    try:
        for w in args.workers:
            out = work / f"w{w}"
            shutil.rmtree(out, ignore_errors=True)
            load0 = os.getloadavg()[0]
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            exe = shutil.which("sdr-di") or "sdr-di"
            proc = subprocess.run([exe, "study", args.spec, "--out",
                                   str(out), "--runs", str(args.runs), "--workers", str(w),
                                   "--no-report"], check=False, capture_output=True,
                                  text=True)
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            state = "ok" if proc.returncode == 0 else f"exit {proc.returncode}: " \
                f"{proc.stderr.strip().splitlines()[-1:]}"
            print(f"workers {w} ({'in process' if w == 0 else 'local Dask cluster'}): "
                  f"{state}; wall {wall:.1f} s, CPU {cpu:.1f} s (user+sys, workers included); "
                  f"{tasks / wall * 3600:.0f} tasks/h, {filter_runs / wall * 3600:.0f} filter "
                  f"runs/h per wall hour; {filter_runs / cpu * 3600:.0f} filter runs per CPU "
                  f"hour; load {load0:.2f} -> {os.getloadavg()[0]:.2f}")
    finally:
        if not args.out:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__)
    add_arguments(ap)
    run(ap.parse_args())
