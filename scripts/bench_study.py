"""Study throughput: runs per hour of a study spec, in one process and on a local Dask cluster.

``python scripts/bench.py study [--spec studies/smoke.toml] [--runs 2] [--workers 0 2]``
runs ``sdr-di study SPEC --runs N --workers W`` in a fresh process per ``W`` (0 = every task in
the process, no cluster; 2 = a two-worker local Dask cluster), each into a new folder (no
resumption), and prints per ``W``: wall time, CPU time (user + sys of the process and its
workers), (cell, seed) tasks and filter runs per wall hour and per CPU hour, and the load
average before and after. On a shared machine the wall figures depend on the load; the CPU
figures do not (much).

``--tuning both`` runs a spec with a ``[tuning]`` table twice per ``W``: as written (training
tasks first) and with the table removed, so the cost of tuning shows as the difference.
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
    p.add_argument("--tuning", choices=("spec", "both"), default="spec",
                   help="'both': with the spec's [tuning] table and without it (default: "
                        "the spec as written)")


def _without_tuning(text: str) -> str:
    """The spec text with its ``[tuning]`` tables removed (a bench helper, not a parser)."""
    out, skip = [], False
    for line in text.splitlines(keepends=True):
        head = line.strip()
        if head.startswith("["):
            name = head.strip("[]").split("]")[0].strip()
            skip = name == "tuning" or name.startswith("tuning.")
        if not skip:
            out.append(line)
    return "".join(out)


def _counts(spec, runs: int) -> tuple[int, int]:
    """(cell, seed) tasks and filter runs of a study, its training stage included."""
    tasks, filter_runs = len(spec.cells) * runs, len(spec.cells) * runs * len(spec.filters)
    t = spec.tuning
    if t is not None:
        n_points = sum(len(p) for p in t.grids.values())
        tasks += len(t.cells) * t.runs
        filter_runs += len(t.cells) * t.runs * n_points
    return tasks, filter_runs


def run(args: argparse.Namespace) -> None:
    sys.path.insert(0, str(REPO))
    from sdr_di.studies.spec import load_study

    from sdr_di.studies.spec import parse_study

    spec = load_study(args.spec)
    work = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="bench_study_"))
    variants = [("", args.spec, spec)]
    if args.tuning == "both":
        if spec.tuning is None:
            raise SystemExit(f"bench study: {args.spec} has no [tuning] table")
        import tomllib

        text = _without_tuning(Path(args.spec).read_text(encoding="utf-8"))
        plain = work / f"{Path(args.spec).stem}_untuned.toml"
        work.mkdir(parents=True, exist_ok=True)
        plain.write_text(text, encoding="utf-8")
        variants = [(" with tuning", args.spec, spec),
                    (" without tuning", str(plain),
                     parse_study(tomllib.loads(text), source=Path(args.spec)))]
    for label, _, sp in variants:
        tasks, filter_runs = _counts(sp, args.runs)
        print(f"study {sp.name}{label}: {len(sp.cells)} cells x {len(sp.filters)} filters x "
              f"{args.runs} seeds{' + training' if sp.tuning else ''} = {tasks} (cell, seed) "
              f"tasks, {filter_runs} filter runs; {os.cpu_count()} cores")
    try:
        for (label, path, sp), w in ((v, w) for w in args.workers for v in variants):
            tasks, filter_runs = _counts(sp, args.runs)
            out = work / f"w{w}{label.replace(' ', '_')}"
            shutil.rmtree(out, ignore_errors=True)
            load0 = os.getloadavg()[0]
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            # the interpreter's own entry point (the venv need not be on PATH)
            exe = Path(sys.executable).with_name("sdr-di")
            exe = str(exe) if exe.exists() else shutil.which("sdr-di") or "sdr-di"
            proc = subprocess.run([exe, "study", path, "--out",
                                   str(out), "--runs", str(args.runs), "--workers", str(w),
                                   "--no-report"], check=False, capture_output=True,
                                  text=True)
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            state = "ok" if proc.returncode == 0 else f"exit {proc.returncode}: " \
                f"{proc.stderr.strip().splitlines()[-1:]}"
            print(f"workers {w} ({'in process' if w == 0 else 'local Dask cluster'}){label}: "
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
