#!/usr/bin/env python
"""Throughput benchmarks (figures for the closing notes; tests check correctness only).

Usage::

    python scripts/bench.py generate [options of scripts/bench_generate.py]
    python scripts/bench.py run [--durations 30] [--bits 8] [--keep] [--if-file F]
        [--repeat N] [--search assisted|cold|both] [--gnss-sdr]
        [--mode scalar|deep|loose|tight|all] [--filter ekf] [--pocketsdr PATH]
    python scripts/bench.py acquire [options of scripts/bench_acquire.py]
    python scripts/bench.py correlate [options of scripts/bench_correlate.py]
    python scripts/bench.py filters [options of scripts/bench_filters.py]
    python scripts/bench.py deep [options of scripts/bench_deep.py]
    python scripts/bench.py study [--spec studies/smoke.toml] [--runs 2] [--workers 0 2]

``generate``: ``sdr-di generate`` on the default scenario per duration in a fresh process:
wall and CPU time, real-time factor, MB/s written, peak RSS, issue 17's target 1, and the
generator's stage profile (``scripts/bench_generate.py``; ``--oscillator PRESET`` and
``--impairments`` time those variants too).

``run``: runs the scalar receiver (``run_scalar``, the pipeline of ``sdr-di run --mode
scalar``: acquisition, tracking, decoding, PVT at 5 Hz, CSV/NMEA output) in a fresh process on
a default-scenario file per duration (default 30 s, 8-bit: issue 17's target 2) or ``--if-file``,
and prints the process wall time and CPU time, the
real-time factor (file seconds per wall second of the whole process, and of the tracking loop
alone), each stage's share of the wall time (``ScalarReceiver.profile``) and the peak RSS (10 s
vs 40 s shows that memory does not grow with the file length). The machine's load average is
printed: on a shared machine, repeat (``--repeat``) and report best and typical. So is the
machine's speed before and after the runs (``run`` and ``deep``:
``bench_correlate.speed_line``, a fixed kernel workload and a fixed filter-sized Python/NumPy
step): on the shared VM the same work takes up to 1.5 times longer from one hour, even one
minute, to the next, and a figure is only comparable beside the speed it was measured at. Each file
is run with the cold search of all 63 PRNs (``sdr-di run --cold``, the receiver before the
assisted search) and the assisted one (``sdr-di run``: the sidecar's satellites around their
Doppler). A closing line per file gives target 2 (best assisted run: x real time against 3x,
CPU seconds, stage shares); ``--gnss-sdr`` also runs GNSS-SDR 0.0.17 with the pinned
``scripts/gnss_sdr_b3i.conf`` on the same file (its process wall and CPU time, the channels
that started tracking) and prints the wall-time ratio against 0.5; ``--pocketsdr PATH``
runs PocketSDR's ``pocket_trk`` (built from its ``app/pocket_trk``, ``make USE_SOAPY=0``) on
the same file right after each assisted run (``-sig B3I -fmt CS8 -tscale T``: it replays the
file at ``T`` times real time, so its CPU time is the figure) and prints the CPU ratio of
each interleaved pair and their mean. ``T`` (``--pocketsdr-tscale``) is 8 for files at 5 MHz
or less and 2 above: while it waits for the replay, ``pocket_trk``'s reader sleeps and its
channel threads poll, CPU that grows with the replay's wall time and with idle cores. On
the 2.5 MHz default file (session 26, quiet VM) it took 5.5-10.0 CPU-s at ``-tscale 2``,
4.0-4.8 at 8 (every channel kept) and lost channels at 16; so 8 gives the steadier figure,
closer to its tracking work. A pair where ``pocket_trk`` lost a channel is flagged. Before
session 26 every pair ran at 2. The pairs are interleaved (issue 29's target: at most 1;
run one set after the other, the VM's speed changed between the two sets and moved the
ratio by 0.1-0.2). With ``--mode deep``
(or loose, tight, all) it also runs after each run of those modes, and pairs the run's
whole-process CPU with ``pocket_trk``'s (scalar: PocketSDR has no other) on the same file,
as issue 47's targets are stated; at any sample rate of the file (``-f`` from its sidecar,
e.g. the studies' 2.5 MHz files)::

    python scripts/bench.py run --if-file F60 --mode deep --repeat 3 --pocketsdr PATH

``run --mode deep|loose|tight|all`` (issue 13): the same file(s) through ``sdr-di run --mode
MODE`` (``run_integrated``: scalar start-up, hand-over, integration loop, solution files; the
sidecar's IMU, truth and ephemeris) in a fresh process per run, with ``--filter`` (default
ekf); prints per mode the process wall and CPU time, the real-time factor (file seconds per
wall second, and per CPU second), the scalar receiver's and the loop's share of the run
(loose and tight: the loop process's share of the CPU and the loop's tail after the
receiver), the hand-over time and the peak RSS. ``all`` = scalar (assisted), deep, loose
and tight, then issue 17's target 4 per file: loose and tight wall time against the
scalar run's (best of ``--repeat`` each; target at most 1.15), the CPU ratio and the CPU
shares (scalar receiver, loop process)::

    python scripts/bench.py run --mode all --durations 60 --bits 4 --repeat 2

Loose and tight run their integration loop in a child process
(``sdr_di.integration.loop_process``); ``SDR_DI_LOOP_THREAD=1`` in the environment runs it
on a thread of the receiver's process instead, as before session 7 (A/B on the same file).

``acquire``: acquisition time per PRN at 25 MHz, normal (40 x 1 ms) and long (400 x 1 ms)
searches, over +-5 kHz and +-1 kHz around a predicted Doppler.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def child_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """Environment of a benchmark's child process: this one's, without
    ``PYTHONDONTWRITEBYTECODE`` (with it, and no bytecode yet for the current sources, every
    child compiled the package's ~110 modules again, 0.2-0.3 s a run: a cost an installed
    package, whose bytecode exists, never has), plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(extra or {})
    return env


def stolen_s() -> float | None:
    """CPU seconds the hypervisor took from this virtual machine since boot, all cores
    together (the ``steal`` column of Linux's ``/proc/stat``); None elsewhere. A benchmark
    prints the difference over each run: on the shared 2-core VM it was 0.01-0.2 s in most
    40 s deep runs and up to 4.4 s in others (docs/notes/speed.md, session 17), and such runs
    are not comparable with the rest."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK") if fields[0] == "cpu" else None
    except (OSError, ValueError, IndexError):
        return None


def stolen_between(before: float | None) -> float | None:
    """:func:`stolen_s` now minus ``before`` (None when either is unknown)."""
    now = stolen_s()
    return None if before is None or now is None else now - before


def print_bytecode_note() -> None:
    """A line of a benchmark's header when ``PYTHONDONTWRITEBYTECODE`` is set here."""
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):
        print("PYTHONDONTWRITEBYTECODE is set here: the child processes run without it, so "
              "they use the package's bytecode as an installed copy does (child_env)")


def _run_generate(duration: float, out: Path, extra: tuple[str, ...] = ()) -> tuple[float, int]:
    """Run one generation in a child process (``extra``: more ``sdr-di generate`` options);
    return (wall s, peak RSS bytes of the child)."""
    code = (
        "import resource, sys; from sdr_di.cli import exit_program, main; "
        f"rc = main(['generate', '--duration', '{duration}', '--out', r'{out}', "
        f"'--name', 'bench', '--no-progress'] + {list(extra)!r}); "
        "print('MAXRSS', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss); "
        "exit_program(rc)"
    )
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=child_env())
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"generate failed: {res.stderr.strip()}")
    rss_kb = int(next(l for l in res.stdout.splitlines() if l.startswith("MAXRSS")).split()[1])
    return wall, rss_kb * 1024


_RUN_CHILD = """
import json, resource, sys, time
from sdr_di.receiver.run_scalar import open_source, run_scalar
from sdr_di.receiver.scalar import ScalarReceiver
from sdr_di.receiver.threads import split_stats
path, out, search = sys.argv[1], sys.argv[2], sys.argv[3]
import threading
def sched():   # main thread (on-CPU s, waiting-for-a-core s): Linux schedstat, else None
    try:
        a = open(f"/proc/self/task/{threading.get_native_id()}/schedstat").read().split()
        return int(a[0]) / 1e9, int(a[1]) / 1e9
    except OSError:
        return None
rx = ScalarReceiver(log=False)
s0, t0 = sched(), time.perf_counter()
res = run_scalar(open_source(path), out, progress=False, receiver=rx,
                 assist=search == "assisted")
s1, wall = sched(), time.perf_counter() - t0
prof = {k: v for k, v in res.profile.items() if isinstance(v, (int, float))}
print("RESULT", json.dumps({"profile": prof, "processed_s": res.processed_s,
      "main_sched": None if s0 is None or s1 is None else
      {"wall": wall, "cpu": s1[0] - s0[0], "runnable": s1[1] - s0[1]},
      "run_wall_s": res.wall_s, "cpu_main": time.thread_time(), "split": split_stats(),
      "maxrss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
from sdr_di.cli import exit_program   # the program's own exit (its teardown counted)
exit_program(0)
"""

#: Stages of ``ScalarReceiver.profile`` printed as shares of the receiver's wall time.
_STAGES = ("acquisition", "read", "correlate", "channels", "callback")


def stolen_note(r: dict) -> str:
    """The end of a run's line: the CPU the host took from the VM over the run (its
    ``stolen_s``, :func:`stolen_s`); empty when unknown."""
    st = r.get("stolen_s")
    return "" if st is None else f"; CPU the host took from the VM during the run: {st:.2f} s"


def run_result_child(code: str, argv: list[str], failed: str, env: dict | None = None,
                     err_tail: int | None = None) -> tuple[dict, float, float | None, float]:
    """``python -c code argv`` in a fresh process (:func:`child_env` unless ``env``): the
    JSON of its ``RESULT`` line, its wall time [s], the CPU the host took from the VM
    meanwhile (:func:`stolen_between`) and its user + system CPU time [s]. A failed child
    ends the benchmark with ``failed: <its stderr>`` (the last ``err_tail`` characters)."""
    import resource

    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    st0 = stolen_s()
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", code, *argv], check=False, capture_output=True,
                         text=True, env=child_env() if env is None else env)
    wall = time.perf_counter() - t0
    stolen = stolen_between(st0)
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if res.returncode != 0:
        err = res.stderr.strip()
        raise SystemExit(f"{failed}: {err if err_tail is None else err[-err_tail:]}")
    line = next(ln for ln in res.stdout.splitlines() if ln.startswith("RESULT "))
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    return json.loads(line[len("RESULT "):]), wall, stolen, cpu


def _run_receiver(path: Path, out: Path, search: str) -> dict:
    """``run_scalar`` (what ``sdr-di run --mode scalar`` runs) in a fresh process: the
    process wall time and peak RSS, the receiver's profile. ``search``: ``assisted`` (the
    sidecar's satellites around their Doppler: ``sdr-di run``) or ``cold`` (all 63 PRNs over
    +-5 kHz: ``sdr-di run --cold``)."""
    r, wall, stolen, cpu = run_result_child(
        _RUN_CHILD, [str(path), str(out), search], "run failed")
    r.update(process_wall_s=wall, stolen_s=stolen, cpu_s=cpu)
    return r


_MODE_CHILD = """
import json, resource, sys, time
from sdr_di.integration.receiver import IntegrationConfig
from sdr_di.integration.run_integrated import run_integrated
from sdr_di.receiver.run_scalar import open_source
from sdr_di.receiver.threads import split_stats
path, out, mode, filt = sys.argv[1:5]
c0 = time.thread_time()
res = run_integrated(open_source(path), out, config=IntegrationConfig(mode=mode, filter=filt),
               progress=False)
prof = {k: v for k, v in res.result.profile.items() if isinstance(v, (int, float))}
print("RESULT", json.dumps({"profile": prof, "handover_s": res.result.handover_s,
      "cpu_main": time.thread_time() - c0, "split": split_stats(),
      "maxrss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024}))
from sdr_di.cli import exit_program
exit_program(0)
"""


def _run_mode(path: Path, out: Path, mode: str, filt: str) -> dict:
    """``sdr-di run --mode MODE`` (``run_integrated``) in a fresh process: process wall and CPU
    time, the CPU the host took from the VM meanwhile (``stolen_s``), the receiver's
    profile, hand-over time, peak RSS."""
    r, wall, stolen, cpu = run_result_child(
        _MODE_CHILD, [str(path), str(out), mode, filt], f"run --mode {mode} failed")
    r.update(process_wall_s=wall, stolen_s=stolen, cpu_s=cpu)
    return r


def _bench_modes(files: list[Path], modes: tuple[str, ...], args: argparse.Namespace,
                 out: Path, pocket: dict[tuple[Path, str], list] | None = None
                 ) -> dict[Path, dict[str, dict]]:
    """Real-time factor of the integration modes on ``files`` (module notes); returns
    ``{file: {mode: best run}}`` (least wall time: ``wall``, ``cpu``, ``profile``). With
    ``args.pocketsdr``, PocketSDR's ``pocket_trk`` runs on the same file right after each
    run and the pair (the run's whole-process CPU s, ``pocket_trk``'s run) is appended to
    ``pocket[(file, mode)]``."""
    print(f"integration modes, filter {args.filter}: x real time = file seconds per process "
          "wall second; per CPU s = file seconds per CPU second (user + sys, all threads); "
          "scalar: share of the run's wall time in the scalar receiver (deep: start-up only; "
          "loose and tight: the whole file), loop: in the integration loop's stages (loose "
          "and tight: in a child process, overlapping the receiver); loop CPU: the loop's "
          "share of the run's CPU (loose and tight: the child's whole CPU, its start and "
          "imports included); tail: wall seconds the loop ran on after the receiver had "
          "finished")
    print(f"{'mode':>6} {'file s':>6} {'wall s':>7} {'CPU s':>6} {'x real time':>11} "
          f"{'per CPU s':>9} {'scalar':>7} {'loop':>6} {'loop CPU':>8} {'tail s':>6} "
          f"{'hand-over s':>11} {'peak RSS MiB':>12}")
    best: dict[Path, dict[str, dict]] = {}
    for f in files:
        for mode in modes:
            for _ in range(args.repeat):
                r = _run_mode(f, out / f"run_{mode}", mode, args.filter)
                p = r["profile"]
                wall, d, tot = r["process_wall_s"], p["processed_s"], max(p["total"], 1e-9)
                cpu = max(r["cpu_s"], 1e-9)
                lc = p.get("loop_process_cpu", p.get("loop_cpu"))
                lcpu = f"{100 * lc / cpu:7.1f}%" if lc is not None else f"{'-':>8}"
                tail = f"{p['loop_wait']:6.2f}" if "loop_wait" in p else f"{'-':>6}"
                print(f"{mode:>6} {d:6.1f} {wall:7.2f} {r['cpu_s']:6.1f} {d / wall:11.2f} "
                      f"{d / cpu:9.2f} {100 * p['scalar'] / tot:6.1f}% "
                      f"{100 * p['loop'] / tot:5.1f}% {lcpu} {tail} {r['handover_s']:11.2f} "
                      f"{r['maxrss'] / 2**20:12.1f}" + stolen_note(r))
                if args.pocketsdr and pocket is not None:
                    # right after each run, so that both see the same minutes of the VM
                    g = _run_pocketsdr(args.pocketsdr, f, _pocket_tscale(args, f),
                                       out / "pocketsdr")
                    pocket.setdefault((f, mode), []).append((r["cpu_s"], g, _load()))
                b = best.setdefault(f, {})
                if mode not in b or wall < b[mode]["wall"]:
                    b[mode] = {"wall": wall, "cpu": r["cpu_s"], "profile": p,
                               "idle": r["cpu_main"] + r["split"].get("wait_cpu_s", 0.0)}
    return best


#: Issue 17's target 4: the largest wall-time ratio of loose and tight to the scalar run.
_MODES_TARGET_RATIO = 1.15


def _print_target4(f: Path, scalar: dict, modes: dict[str, dict], repeat: int) -> None:
    """Target 4 for file ``f``: loose and tight against the scalar run (best of
    ``repeat`` each), wall and CPU ratios, and where their time goes."""
    print(f"target 4 ({f.name}, best of {repeat}; scalar {scalar['wall']:.2f} s wall, "
          f"{scalar['cpu']:.1f} s CPU, about {scalar.get('idle', float('nan')):.1f} s on idle "
          f"cores): ratio to scalar, target <= {_MODES_TARGET_RATIO:g}; on idle cores: the "
          "main thread's CPU + its waits for the kernel worker, a lower bound for loose and "
          "tight (it leaves out the loop's share of the cores; with the loop on a thread, "
          "SDR_DI_LOOP_THREAD=1, also its share of the GIL)")
    for mode in ("loose", "tight"):
        b = modes.get(mode)
        if b is None:
            continue
        p = b["profile"]
        ratio = b["wall"] / scalar["wall"]
        lcpu = p.get("loop_process_cpu", p.get("loop_cpu", 0.0))
        where = "process" if "loop_process_cpu" in p else "thread"
        idle = b["idle"] / max(scalar.get("idle", float("nan")), 1e-9)
        print(f"  {mode}: {b['wall']:.2f} s wall = {ratio:.3f} x scalar "
              f"({'met' if ratio <= _MODES_TARGET_RATIO else 'NOT met'}); on idle cores "
              f"about {b['idle']:.1f} s = {idle:.3f} x scalar; CPU "
              f"{b['cpu']:.1f} s = {b['cpu'] / max(scalar['cpu'], 1e-9):.3f} x scalar; CPU "
              f"shares: scalar receiver {100 * (b['cpu'] - lcpu) / max(b['cpu'], 1e-9):.0f}%, "
              f"loop {where} {100 * lcpu / max(b['cpu'], 1e-9):.0f}% (loop itself "
              f"{p.get('loop_cpu', 0.0):.2f} s CPU; " + ", ".join(
                  f"{k} {p.get(k, 0.0):.2f} s" for k in ("ins", "filter", "measure", "output"))
              + f" wall in the loop's {where}); loop tail {p.get('loop_wait', 0.0):.2f} s")


#: Issue 17's scalar target: file seconds per wall second of the whole process, and the
#: largest fraction of GNSS-SDR's wall time on the same file.
_RUN_TARGET_RT = 3.0
_RUN_TARGET_GNSS_SDR = 0.5
_GNSS_SDR_CONF = Path(__file__).resolve().parent / "gnss_sdr_b3i.conf"


def _run_gnss_sdr(path: Path, work: Path) -> dict | None:
    """GNSS-SDR's B3I receiver (``scripts/gnss_sdr_b3i.conf``, pinned for 0.0.17) on ``path``
    (an ``iq_int8`` file with its sidecar), the sidecar's satellites one per channel; the
    process wall and CPU time and the channels that started tracking. None when
    ``gnss-sdr`` is not installed."""
    import resource

    exe = shutil.which("gnss-sdr")
    if exe is None:
        return None
    meta = json.loads(Path(path).with_suffix(".json").read_text())
    prns = [s["prn"] for s in meta["satellites"]]
    work.mkdir(parents=True, exist_ok=True)
    conf = (_GNSS_SDR_CONF.read_text().replace("@FILE@", str(Path(path).resolve()))
            .replace("@N_CH@", str(len(prns)))
            .replace("@CHANNELS@", "\n".join(f"Channel{i}.satellite={p}"
                                             for i, p in enumerate(prns))))
    (work / "b3i.conf").write_text(conf)
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run([exe, "--config_file=b3i.conf", f"--log_dir={work}"], cwd=work,
                         check=False, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    ver = next((ln.split()[2] for ln in res.stdout.splitlines()
                if ln.startswith("Initializing GNSS-SDR")), "?")
    return {"wall_s": wall, "version": ver, "rc": res.returncode,
            "cpu_s": (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime),
            # satellites that started tracking (a re-acquired channel starts again)
            "tracked": len(set(re.findall(r"Tracking of Beidou B3I signal started on channel "
                                          r"\d+ for satellite Beidou PRN (\d+)", res.stdout))),
            "n_sat": len(prns)}


def _run_pocketsdr(exe: str, path: Path, tscale: float, work: Path) -> dict:
    """PocketSDR's ``pocket_trk`` on ``path`` (an ``iq_int8`` file with its sidecar: ``-fmt
    CS8``, ``-f`` the sample rate, ``-fo`` the carrier minus the IF), B3I, the sidecar's
    satellites (``-sig B3I -prn``), the file replayed at ``tscale`` times real time (its
    reader sleeps to keep that pace, so compare CPU, not wall), run in ``work`` (it writes a
    ``.pocket_navdata.csv`` there): the process wall and CPU time,
    the exit status, the locked channels of its last status screen and the end of its
    output."""
    import resource

    meta = json.loads(Path(path).with_suffix(".json").read_text())
    prns = [int(s["prn"]) for s in meta["satellites"]]
    fo = (float(meta["carrier_hz"]) - float(meta.get("if_hz", 0.0))) / 1e6
    cmd = [exe, "-sig", "B3I", "-prn", ",".join(map(str, prns)), "-fmt", "CS8",
           "-f", f"{float(meta['sampling_rate_hz']) / 1e6:g}", "-fo", f"{fo:.6f}",
           "-tscale", f"{tscale:g}", str(Path(path).resolve())]
    work.mkdir(parents=True, exist_ok=True)
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=work, check=False, capture_output=True, text=True,
                         errors="replace")
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    locks = re.findall(r"LOCK:\s*(\d+)/\s*(\d+)", res.stdout)  # status screens: locked/total
    return {"wall_s": wall, "rc": res.returncode, "cmd": " ".join(cmd[:-1]) + " FILE",
            "locked": f"{locks[-1][0]} of {locks[-1][1]}" if locks else "?",
            "cpu_s": (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime),
            "stdout_tail": res.stdout[-4000:], "n_sat": len(prns)}


def _pocket_tscale(args: argparse.Namespace, path: Path) -> float:
    """``pocket_trk``'s replay speed for ``path``: ``--pocketsdr-tscale``, else 8 for files
    at 5 MHz or less and 2 above (module notes: its reader sleeps and its channel threads
    poll while it waits for data, CPU that grows with the replay's wall time and falls with
    the load; 8 is the fastest replay that keeps every channel of the 2.5 MHz default file
    on the development VM, 16 loses some)."""
    if args.pocketsdr_tscale is not None:
        return float(args.pocketsdr_tscale)
    mhz = _file_rate_mhz(path)
    return 8.0 if mhz is not None and mhz <= 5.0 else 2.0


def _load() -> float:
    """The machine's 1-minute load average now (NaN where unknown)."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def _file_rate_mhz(path: Path) -> float | None:
    """Sample rate of a default-scenario IF file from its sidecar [MHz]; None without one."""
    try:
        meta = json.loads(Path(path).with_suffix(".json").read_text())
        return float(meta["sampling_rate_hz"]) / 1e6
    except (OSError, KeyError, ValueError):
        return None


#: Issue 47's targets of the CPU ratio to ``pocket_trk``'s (scalar) CPU on the same file:
#: ``{mode: ((MHz at or below which the first applies, target), (else, target))}``.
_POCKET_TARGETS = {"scalar": ((2.5, 1.0), (None, 0.85)), "deep": ((2.5, 1.0), (None, 1.1))}


def _print_pocket_pairs(f: Path, mode: str, pairs: list) -> None:
    """The interleaved pairs of one file and mode (an sdr-di run's whole-process CPU s,
    ``pocket_trk``'s run right after it, the load average then) and their mean ratio, with
    issue 47's target for the file's rate."""
    what = "sdr-di run" if mode == "scalar" else f"sdr-di run --mode {mode}"
    lost = False
    for cpu, g, load in pairs:
        print(f"  PocketSDR pocket_trk ({g['cmd']}) on {f.name}, right after {what} of "
              f"{cpu:.1f} CPU s: {g['wall_s']:.2f} s wall, CPU {g['cpu_s']:.1f} s, "
              f"{g['locked']} channels locked at the end, exit {g['rc']}; load average "
              f"{load:.2f}; sdr-di / pocket_trk CPU = {cpu / g['cpu_s']:.2f}")
        lost = lost or g["locked"] != f"{g['n_sat']} of {g['n_sat']}"
    if lost:
        print("  WARNING: pocket_trk did not end with every channel locked in some pairs "
              "(above): at its -tscale it may not have followed the replay, so its CPU may "
              "not be the whole tracking work; rerun with a lower --pocketsdr-tscale")
    ratios = [cpu / g["cpu_s"] for cpu, g, _ in pairs]
    mhz = _file_rate_mhz(f)
    target = ""
    if mode in _POCKET_TARGETS and mhz is not None:
        (lim, t_low), (_, t_high) = _POCKET_TARGETS[mode]
        target = f" (issue 47 target at {mhz:g} MHz: <= {t_low if mhz <= lim else t_high:g})"
    print(f"  {what} / pocket_trk (scalar) CPU, {f.name}, {len(ratios)} interleaved pairs: "
          f"mean {sum(ratios) / len(ratios):.2f}, {min(ratios):.2f}-{max(ratios):.2f}"
          + target)


def bench_run(args: argparse.Namespace) -> None:
    """Scalar receiver real-time factor, per-stage shares and peak memory on default-scenario
    files (generated for each duration, or ``--if-file``); issue 17's target 2 per file, with
    GNSS-SDR's time on the same file when ``--gnss-sdr``."""
    if args.pocketsdr and not (Path(args.pocketsdr).is_file()
                               and os.access(args.pocketsdr, os.X_OK)):
        raise SystemExit(f"bench.py: error: --pocketsdr {args.pocketsdr}: not an executable "
                         "file")
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="sdr-di-bench-"))
    try:
        rate = (f"{_file_rate_mhz(Path(args.if_file)) or float('nan'):g} MHz "
                f"({Path(args.if_file).name})" if args.if_file else f"25 MHz, {args.bits}-bit")
        print(f"machine: {os.cpu_count()} cores, load average {_load():.2f} at start; scalar "
              f"receiver, default scenario, 7 satellites, {rate} iq_int8, PVT at 5 Hz")
        print_bytecode_note()
        print("x real time: file seconds per wall second of the whole process (imports, "
              "acquisition, tracking, PVT, output); tracking: of the tracking loop alone; "
              "CPU s: the process's user + system time (all threads; on a shared machine the "
              "load-independent cost: below half the file length = 2x real time on one free "
              "core)")
        from bench_correlate import speed_line

        print(speed_line("at start"))
        scalar_head = (f"{'search':>8} {'file s':>6} {'wall s':>7} {'CPU s':>6} "
                       f"{'x real time':>11} {'tracking':>8} "
                       + " ".join(f"{s[:7]:>7}" for s in _STAGES)
                       + f" {'other':>6} {'peak RSS MiB':>12}")
        if args.if_file:
            files = [Path(args.if_file)]
        else:
            files = []
            for d in args.durations:
                sub = out / f"d{d:g}"
                _run_generate(d, sub, ("--bits", str(args.bits)))
                files.append(sub / "bench.bin")
        modes = ("deep", "loose", "tight") if args.mode == "all" else (
            () if args.mode == "scalar" else (args.mode,))
        pocket: dict[tuple[Path, str], list] = {}   # {(file, mode): [(CPU s, run, load)]}
        mode_best = _bench_modes(files, modes, args, out, pocket) if modes else {}
        searches = () if args.mode not in ("scalar", "all") else (
            ("cold", "assisted") if args.search == "both" else (args.search,))
        if args.mode == "all":
            searches = ("assisted",)
        if searches:
            print(scalar_head)
        best: dict[Path, dict] = {}
        for f, search in ((f, s) for f in files for s in searches):
            for _ in range(args.repeat):
                r = _run_receiver(f, out / "run", search)
                p = r["profile"]
                wall = r["process_wall_s"]
                d = r["processed_s"]
                shares = [100.0 * p[s] / wall for s in _STAGES]
                print(f"{search:>8} {d:6.1f} {wall:7.2f} {r['cpu_s']:6.1f} {d / wall:11.2f} "
                      f"{p['realtime_factor']:8.2f} "
                      + " ".join(f"{v:6.1f}%" for v in shares)
                      + f" {100.0 - sum(shares):5.1f}% {r['maxrss'] / 2**20:12.1f}")
                ms = r.get("main_sched")
                if ms is not None:   # where the main thread's time went (bench_deep notes)
                    print(f"{'':>8} main thread over run_scalar: {ms['wall']:.2f} s wall = "
                          f"{ms['cpu']:.2f} s on a core + {ms['runnable']:.2f} s waiting for "
                          f"a core (load) + {ms['wall'] - ms['cpu'] - ms['runnable']:.2f} s "
                          "sleeping (kernel worker, GIL, reads)" + stolen_note(r))
                if search == "assisted" and (f not in best or wall < best[f]["wall"]):
                    best[f] = {"wall": wall, "cpu": r["cpu_s"], "d": d, "shares": shares,
                               "idle": r["cpu_main"] + r["split"]["wait_cpu_s"]}
                if search == "assisted" and args.pocketsdr:
                    # right after each run, so that both see the same minutes of the VM
                    g = _run_pocketsdr(args.pocketsdr, f, _pocket_tscale(args, f),
                                       out / "pocketsdr")
                    pocket.setdefault((f, "scalar"), []).append((r["cpu_s"], g, _load()))
        if searches:
            print("stage shares: % of the process wall time (other: imports, numba cache "
                  "loading, setup, output files)")
        for f, b in best.items():
            print(f"target 2 (scalar, sdr-di run, best of {args.repeat}): {b['d']:.0f} s file "
                  f"in {b['wall']:.2f} s wall = {b['d'] / b['wall']:.2f}x real time (target >= "
                  f"{_RUN_TARGET_RT:g}x), CPU {b['cpu']:.1f} s = {b['d'] / b['cpu']:.2f} file "
                  f"s per CPU s; on idle cores about {b['idle']:.1f} s = "
                  f"{b['d'] / b['idle']:.2f}x (main thread's CPU + its waits for the kernel "
                  "worker, receiver.threads.split_stats); shares " + ", ".join(
                      f"{s} {v:.0f}%" for s, v in zip(_STAGES, b["shares"])))
            if args.gnss_sdr:
                g = _run_gnss_sdr(f, out / "gnss-sdr")
                if g is None:
                    print("  GNSS-SDR: not installed (apt-get install gnss-sdr)")
                    continue
                print(f"  GNSS-SDR {g['version']} (scripts/gnss_sdr_b3i.conf) on the same file: "
                      f"{g['wall_s']:.2f} s wall, CPU {g['cpu_s']:.1f} s, {g['tracked']} of "
                      f"{g['n_sat']} channels tracking, exit {g['rc']}; sdr-di / GNSS-SDR wall "
                      f"= {b['wall'] / g['wall_s']:.2f} (target <= {_RUN_TARGET_GNSS_SDR:g})")
        for (f, mode), pairs in pocket.items():
            _print_pocket_pairs(f, mode, pairs)
            if args.pocketsdr_show:
                print(pairs[-1][1]["stdout_tail"])
        if args.mode == "all":
            for f, b in best.items():
                _print_target4(f, b, mode_best.get(f, {}), args.repeat)
        print(speed_line("at the end"))
        print(f"load average {_load():.2f} at the end")
    finally:
        if not args.keep:
            shutil.rmtree(out, ignore_errors=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="what", required=True)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_generate

    g = sub.add_parser("generate", help="IF generation throughput, CPU, memory, stage profile")
    bench_generate.add_arguments(g)
    g.set_defaults(func=bench_generate.run)
    r = sub.add_parser("run", help="scalar receiver real-time factor and memory")
    r.add_argument("--durations", type=float, nargs="+", default=[30.0],
                   help="generated file lengths [s] (default 30: issue 17's target 2)")
    r.add_argument("--bits", type=int, default=8,
                   help="quantization bits of the generated iq_int8 files (default 8)")
    r.add_argument("--gnss-sdr", action="store_true",
                   help="also time GNSS-SDR (scripts/gnss_sdr_b3i.conf) on each file")
    r.add_argument("--pocketsdr", default=None, metavar="PATH",
                   help="also run PocketSDR's pocket_trk (PATH) on the same file after each "
                   "assisted scalar run and each --mode deep/loose/tight run (CPU time in "
                   "interleaved pairs; issues 29 and 47)")
    r.add_argument("--pocketsdr-tscale", type=float, default=None,
                   help="pocket_trk's -tscale (replay speed, x real time; default 8 for "
                   "files at 5 MHz or less, 2 above: module notes)")
    r.add_argument("--pocketsdr-show", action="store_true",
                   help="print the end of pocket_trk's last status screen")
    r.add_argument("--out", default=None, help="work directory (default: a temp dir)")
    r.add_argument("--keep", action="store_true", help="keep the files")
    r.add_argument("--if-file", default=None,
                   help="benchmark this default-scenario IF file (with its sidecar) instead "
                        "of generating one per duration")
    r.add_argument("--repeat", type=int, default=1, help="runs per file (timings are noisy "
                                                          "on a shared machine)")
    r.add_argument("--search", choices=("assisted", "cold", "both"), default="both",
                   help="initial search: the sidecar's satellites around their Doppler "
                   "(sdr-di run), all 63 PRNs cold (sdr-di run --cold), or both (default)")
    r.add_argument("--mode", choices=("scalar", "deep", "loose", "tight", "all"),
                   default="scalar", help="receiver mode (default scalar; all: scalar "
                   "assisted, deep, loose and tight on the same file)")
    r.add_argument("--filter", default="ekf",
                   help="integration filter of deep, loose and tight (default ekf)")
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
    import bench_acquire

    a = sub.add_parser("acquire", help="acquisition time per PRN, normal and long search")
    bench_acquire.add_arguments(a)
    a.set_defaults(func=bench_acquire.run)
    import bench_deep

    dp = sub.add_parser("deep", help="deep receiver real-time factor, stage shares, memory")
    bench_deep.add_arguments(dp)
    dp.set_defaults(func=bench_deep.run)
    import bench_study

    st = sub.add_parser("study", help="study runs per hour, in process vs local Dask cluster")
    bench_study.add_arguments(st)
    st.set_defaults(func=bench_study.run)
    args = parser.parse_args(argv)
    args.func(args)


if __name__ == "__main__":
    main()
