#!/usr/bin/env python
"""Deep receiver cost: real-time factor, time shares of its stages, peak memory.

Usage::

    python scripts/bench_deep.py [--duration 40] [--filter ff-aukf] [--if-file F.bin]
                                 [--filter-rate 50] [--keep] [--repeat 1]
                                 [--kernel-threads N] [--nco-latency 0 [1]]
                                 [--architectures prefilter [reset discriminator]]

Generates the default scenario (7 satellites, 25 MHz, 4-bit ``iq_int8``; ``--duration`` s)
unless ``--if-file`` names one with its sidecar, then runs the deep receiver (the pipeline of
``sdr-di run --mode deep``: scalar start-up and hand-over, vector loop with pre-filters and
the integration filter, CSV/JSON output) in a fresh process and prints:

* the wall and CPU (user + system, all threads) time of the whole process, the main thread's
  CPU time (``main``: the serial chain of the loop, which the kernels' worker thread and the
  IF read-ahead thread run beside; with the time it would wait for the worker's longer
  parts, :func:`~sdr_di.receiver.threads.split_stats`, it estimates the wall time on idle
  cores from a run on a loaded machine) and the real-time
  factor (file seconds per wall second), and a closing line with issue 17's target 3 (3x real
  time on a 40 s file, start-up included) for the best run;
* the start-up (scalar receiver until the hand-over) and the vector loop separately, with the
  loop's real-time factor over the seconds it processed;
* the share of the loop's time in correlation, pre-filters, integration filter, INS (and
  feedback), NCO commands and sample reading;
* where the main thread's wall time went (Linux ``/proc`` schedstat): on a core, waiting for
  a core (the load of other processes), sleeping (the GIL handed to the kernel worker, its
  longer parts, reads); and the CPU time of the other threads (kernel worker, IF read-ahead);
* the peak RSS of the process, and the load average (the machine is shared: repeat and report
  best and typical).

``--nco-latency 0 1`` runs the deep receiver with each setting in turn in every repeat
(interleaved, so that both see the same minutes of this shared machine; docs/deep.md, *NCOs
one interval ahead*) and closes with the best run of each.

``run(args)`` is the entry point of ``scripts/bench.py deep``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

_CHILD = """
import json, resource, sys, threading, time
from pathlib import Path
from sdr_di.integration.run_integrated import run_integrated
from sdr_di.integration.receiver import IntegrationConfig
from sdr_di.receiver.run_scalar import open_source

def sched(tid=None):
    # (on-CPU s, runnable-but-waiting-for-a-core s) of a thread; Linux schedstat, else None
    try:
        a = open(f"/proc/self/task/{tid or threading.get_native_id()}/schedstat").read().split()
        return int(a[0]) / 1e9, int(a[1]) / 1e9
    except OSError:
        return None

path, out, filt, rate = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
latency = int(sys.argv[5])
arch = sys.argv[6]
meta = json.loads(Path(path).with_suffix('.json').read_text())
prns = [s['prn'] for s in meta['satellites']]
s0 = sched()
t0 = time.perf_counter()
res = run_integrated(open_source(path), out, config=IntegrationConfig(
    filter=filt, filter_rate_hz=rate, nco_latency=latency, deep_measurements=arch),
    prns=prns, progress=False)
wall, cpu_main = time.perf_counter() - t0, time.thread_time()   # main thread, from start
s1 = sched()
main_sched = None if s0 is None or s1 is None else {
    'cpu': s1[0] - s0[0], 'runnable': s1[1] - s0[1], 'wall': wall}
threads = {}                     # CPU [s] of the threads alive at the end, by name
for t in threading.enumerate():
    st = None if t.native_id is None else sched(t.native_id)
    if st is not None and t is not threading.main_thread():
        name = t.name.rsplit('_', 1)[0]
        threads[name] = threads.get(name, 0.0) + st[0]
from sdr_di.receiver.threads import split_stats
print('RESULT', json.dumps({'wall': wall, 'cpu_main': cpu_main, 'split': split_stats(),
      'profile': res.result.profile, 'main_sched': main_sched, 'threads': threads,
      'maxrss_kb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
      'metrics': {k: v for k, v in res.metrics.items() if not k.endswith('axes')}}))
from sdr_di.cli import exit_program   # the program's own exit (its teardown counted)
exit_program(0)
"""


#: Issue 17's deep target: file seconds per wall second of the whole process (start-up and
#: hand-over included) on a 40 s 25 MHz file.
TARGET_RT = 3.0


def _one(path: Path, out: Path, filt: str, rate: float, threads: int | None = None,
         latency: int = 0, arch: str = "prefilter") -> dict:
    from bench import child_env, run_result_child

    # SDR_DI_KERNEL_THREADS: receiver.threads.ENV_THREADS
    env = child_env({"SDR_DI_KERNEL_THREADS": str(threads)} if threads else None)
    d, wall, stolen, cpu = run_result_child(
        _CHILD, [str(path), str(out), filt, str(rate), str(latency), arch], "deep run failed",
        env=env, err_tail=2000)
    d.update(process_wall=wall, stolen_s=stolen, cpu_s=cpu)
    return d


def run(args: argparse.Namespace) -> list[dict]:
    tmp = Path(tempfile.mkdtemp(prefix="sdr-di-bench-deep-"))
    rows = []
    try:
        if args.if_file:
            path = Path(args.if_file)
        else:
            from bench import _run_generate  # the generator benchmark child process

            _run_generate(args.duration, tmp)
            path = tmp / "bench.bin"
        from bench_correlate import speed_line

        print(f"machine: {os.cpu_count()} cores, load average "
              f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}; file {path.name}; filter "
              f"{args.filter} at {args.filter_rate:g} Hz; NCO latency "
              f"{' and '.join(map(str, args.nco_latency))}; measurements "
              f"{' and '.join(args.architectures)} (run column: repeat.latency.architecture)")
        print(speed_line("at start"))
        from bench import print_bytecode_note, stolen_note

        print_bytecode_note()
        print(f"{'run':>3} {'file s':>7} {'wall s':>7} {'CPU s':>6} {'main':>5} {'x RT':>6} {'start-up s':>10} "
              f"{'loop s':>7} {'loop xRT':>8} {'corr%':>6} {'pref%':>6} {'filt%':>6} "
              f"{'ins%':>5} {'nco%':>5} {'read%':>6} {'RSS MiB':>8}")
        for i, lat, arch in ((i, lat, a) for i in range(args.repeat)
                             for lat in args.nco_latency for a in args.architectures):
            d = _one(path, tmp / f"out{i}_{lat}_{arch}", args.filter, args.filter_rate,
                     args.kernel_threads, lat, arch)
            d["latency"], d["architecture"] = lat, arch
            p = d["profile"]
            loop = max(p["loop"], 1e-9)
            sh = {k: 100 * p[k] / loop for k in ("correlate", "prefilter", "filter", "ins",
                                                 "nco", "read")}
            print(f"{f'{i}.{lat}.{arch[0]}':>3} {p['processed_s']:7.1f} {d['process_wall']:7.1f} {d['cpu_s']:6.1f} "
                  f"{d['cpu_main']:5.1f} "
                  f"{p['processed_s'] / d['process_wall']:6.2f} {p['scalar']:10.1f} "
                  f"{loop:7.1f} {p['deep_s'] / loop:8.2f} {sh['correlate']:6.0f} "
                  f"{sh['prefilter']:6.0f} {sh['filter']:6.0f} {sh['ins']:5.0f} "
                  f"{sh['nco']:5.0f} {sh['read']:6.0f} {d['maxrss_kb'] / 1024:8.0f}")
            m = d["metrics"]
            print(f"    errors: pos {m['pos_m_rmse']:.3f} m, vel {m['vel_mps_rmse']:.4f} m/s, "
                  f"att {m['att_deg_rmse']:.4f} deg RMSE over {m['n']} rows")
            ms = d.get("main_sched")
            if ms is not None:
                # where the main thread's wall time went (Linux schedstat): on a quiet
                # machine 'waiting for a core' is ~0 and 'sleeping' is the chain's waits
                sleep = ms["wall"] - ms["cpu"] - ms["runnable"]
                print(f"    main thread over run_integrated: {ms['wall']:.2f} s wall = {ms['cpu']:.2f} s "
                      f"on a core + {ms['runnable']:.2f} s waiting for a core (load) + "
                      f"{sleep:.2f} s sleeping (GIL hand-overs, kernel worker, reads); other "
                      "threads' CPU: " + ", ".join(f"{k} {v:.2f} s" for k, v in sorted(
                          d.get("threads", {}).items()) if v >= 0.05)
                      + f", the rest (IF read-ahead, ended threads) "
                      f"{d['cpu_s'] - d['cpu_main'] - sum(d.get('threads', {}).values()):.2f} s"
                      + stolen_note(d))
            rows.append(d)
        for lat in args.nco_latency:
            for arch in args.architectures:
                _best_line([r for r in rows if (r["latency"], r["architecture"]) == (lat, arch)],
                           lat, arch)
        print(speed_line("at the end"))
    finally:
        if not args.keep:
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            print(f"kept {tmp}")
    return rows


def _best_line(rows: list[dict], latency: int, arch: str = "prefilter") -> None:
    """The closing line of the best run of one NCO latency and measurement architecture."""
    b = min(rows, key=lambda r: r["process_wall"])
    p = b["profile"]
    loop = max(p["loop"], 1e-9)
    # wall time on idle cores (receiver.threads.split_stats): the main thread's chain
    idle = b["cpu_main"] + b["split"]["wait_cpu_s"]
    print(f"target 3 (deep, NCO latency {latency}, {arch}, best of {len(rows)}): "
          f"{p['processed_s']:.0f} s file in "
          f"{b['process_wall']:.2f} s wall = {p['processed_s'] / b['process_wall']:.2f}x "
          f"real time (target >= {TARGET_RT:g}x, start-up and hand-over included), CPU "
          f"{b['cpu_s']:.1f} s, {p['processed_s'] / b['cpu_s']:.2f} file s per CPU s; on "
          f"idle cores about {idle:.1f} s = {p['processed_s'] / idle:.2f}x (main thread "
          f"{b['cpu_main']:.1f} s CPU + {b['split']['wait_cpu_s']:.1f} s waiting for the "
          f"kernel worker's longer parts); start-up "
          f"{100 * p['scalar'] / b['process_wall']:.0f}% of "
          f"the wall time, loop {100 * loop / b['process_wall']:.0f}% (" + ", ".join(
              f"{k} {100 * p[k] / loop:.0f}%" for k in ("correlate", "read", "nco",
                                                       "filter", "prefilter", "ins"))
          + f"); load average {os.getloadavg()[0]:.2f} at the end")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, default=40.0,
                   help="generated file length [s] (default 40: issue 17's target 3)")
    p.add_argument("--filter", default="ff-aukf")
    p.add_argument("--filter-rate", type=float, default=50.0)
    p.add_argument("--if-file", default=None, help="existing IF file (with its sidecar)")
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--keep", action="store_true", help="keep the temporary folder")
    p.add_argument("--kernel-threads", type=int, default=None,
                   help="fix the correlator kernels' thread count (default: chosen by "
                        "measured speed); 2 on a loaded machine makes the idle-core "
                        "estimate that of the split the kernels use on idle cores")
    p.add_argument("--nco-latency", type=int, nargs="+", choices=(0, 1), default=[0],
                   help="deep's NCO latency [filter intervals] (default 0); several: each "
                        "in turn in every repeat (interleaved)")
    p.add_argument("--architectures", nargs="+", default=["prefilter"],
                   choices=("prefilter", "reset", "discriminator"),
                   help="deep measurement architectures (--deep-measurements; default the "
                        "cascade); several: each in turn in every repeat (interleaved)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_arguments(ap)
    run(ap.parse_args(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())
