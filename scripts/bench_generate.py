#!/usr/bin/env python
"""IF generation cost: real-time factor, CPU time, write rate, memory and stage profile.

Usage::

    python scripts/bench.py generate [--durations 10 60] [--repeat 1] [--profile-s 4]
                                     [--oscillator PRESET] [--impairments] [--out DIR] [--keep]

Runs ``sdr-di generate`` on the default scenario (7 satellites, 25 MHz, 4-bit ``iq_int8``)
for each duration in a fresh process (after a 0.2 s warm-up run that fills the numba cache)
and prints, per run: wall and CPU (user + system, all threads) time of the whole process,
the real-time factor (data seconds per wall second), the write rate (IF file bytes per wall
second), the peak RSS (10 s vs 60 s: memory flat in the duration) and the file size; then
issue 17's target 1 for the best 60 s run: at least 4x real time.

The stage profile (``--profile-s`` seconds of data, in a fresh process) gives each stage's
CPU seconds per data second and share: set-up (truth, IMU, satellites), geometry
(``IfGenerator.node_state``), satellite synthesis and noise + quantization (each timed alone
on one thread over the same node intervals: the kernel fuses them), iq_int4 packing where
used, and writing (the chunks written to a file), with the synthesis rate in M
sample-satellites per CPU second (target: at least 443, gps-sdr-sim's rate on this machine)
and the fused kernel's wall and CPU time on all threads.

``--oscillator PRESET`` times each duration also with a truth ``[oscillator]`` of that preset
(issue 14); ``--impairments`` also with each impairment of issue 15 on (a CW and a noise
jammer, multipath on every satellite), one at a time.

The machine is shared: CPU time and rates per CPU second are the load-independent figures;
repeat (``--repeat``) and report the best and the load average printed.

``run(args)`` is the entry point of ``scripts/bench.py generate``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "signals" / "default.toml"

#: Issue 17 target 1: data seconds per wall second on the 60 s default file.
#: Issue 29's generation target [x real time] on the same file.
TARGET_29_X_REALTIME = 6.0
TARGET_X_REALTIME = 4.0
#: gps-sdr-sim's satellite synthesis rate on the reference machine [M sample-sats / CPU s].
TARGET_SYNTH_MSPS = 443.0

#: Impairment variants of ``--impairments``: label -> TOML appended to the default scenario.
IMPAIRMENTS = {
    "cw": '\n[[interference]]\ntype = "cw"\noffset_hz = 1.2e6\njs_db = 30.0\n',
    "noise jam": ('\n[[interference]]\ntype = "noise"\noffset_hz = 0.0\nbandwidth_hz = 2.0e6\n'
                  'js_db = 30.0\n'),
    "multipath": ('\n[[multipath]]\nprn = "all"\nalpha = 0.5\ndelay_chips = 0.25\n'
                  'phase_deg = 0.0\n'),
}


def _scenario_with(out: Path, name: str, extra: str) -> Path:
    """The default scenario plus ``extra`` TOML, written under ``out``."""
    text = DEFAULT.read_text().replace('ephemeris = "', 'ephemeris = "' + str(DEFAULT.parent)
                                       + "/")
    path = out / f"{name}.toml"
    path.write_text(text + extra)
    return path


def _timed_generate(duration: float, out: Path, extra: tuple[str, ...]) -> dict:
    """One ``sdr-di generate`` in a child: wall, CPU (user + sys) and peak RSS, file size."""
    from bench import _run_generate

    # untimed: the previous run's files are deleted (replacing a 3 GB file would charge its
    # deletion to this run) and flushed (3 GB are still being written back at a few hundred
    # MB/s), so each run pays for its own generation and writing only, as one
    # `sdr-di generate` into a fresh folder does
    for f in out.glob("bench*"):
        f.unlink()
    os.sync()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    wall, rss = _run_generate(duration, out, extra)
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = ru1.ru_utime + ru1.ru_stime - ru0.ru_utime - ru0.ru_stime
    return {"wall": wall, "cpu": cpu, "rss": rss, "size": (out / "bench.bin").stat().st_size}


_PROFILE_CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1])
import bench_generate
print('RESULT', json.dumps(bench_generate.profile_stages(float(sys.argv[2]), sys.argv[3])))
"""


def profile_stages(duration: float, work: str) -> dict:
    """Stage CPU times [s] of generating ``duration`` s of the default scenario (in-process;
    run by :func:`run` in a fresh process). See the module docstring for the stages."""
    import time

    import numba
    import numpy as np

    from sdr_di.scenario.schema import load_scenario
    from sdr_di.sim import _numba_ifgen as K
    from sdr_di.sim.generate import imu_model, make_generator, simulate_truth

    def cpu() -> float:
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    prof: dict = {"duration_s": duration}
    c0 = cpu()
    sc = load_scenario(DEFAULT).with_overrides(duration_s=duration)
    truth = simulate_truth(sc)
    gen = make_generator(sc, truth)
    imu_model(sc).apply(truth, np.random.default_rng(0))
    prof["setup"] = cpu() - c0
    gen.synthesize(0, 2)  # numba cache load, outside the stages
    n_total = gen.n_nodes_total
    c0 = cpu()
    states = [(j0, gen.node_state(j0, min(1000, n_total - j0)))
              for j0 in range(0, n_total, 1000)]
    prof["geometry"] = cpu() - c0

    @numba.njit
    def synth_only(sig, ncomp, words, st_chip0, st_ms0, st_dchip, st_ph0, st_dph, st_amp,
                   st_sym, st_base):
        for j in range(st_chip0.shape[1]):
            sig[:] = 0.0
            for s in range(words.shape[0]):
                K.add_satellite(sig, ncomp, words[s], st_chip0[s, j], st_ms0[s, j],
                                st_dchip[s, j], st_ph0[s, j], st_dph[s, j], st_amp[s, j],
                                st_sym[s], st_base[s])

    @numba.njit
    def noise_only(out, sig, key, n_nodes, gain, level):
        m = sig.shape[0]
        for j in range(n_nodes):
            K.noise_quantize(out, sig, key, np.uint64(j * m), gain, level)

    m = gen.n_per_node * gen.ncomp
    sig = np.zeros(m, np.float32)
    q = np.empty(m, np.int16 if gen.fmt.dtype.itemsize == 2 else np.int8)
    st = states[0][1]
    args = [st[k] for k in ("chip0", "ms0", "dchip", "ph0", "dph", "amp", "sym", "sym_base")]
    synth_only(sig, gen.ncomp, gen.code_words,  # compile (C-contiguous, as timed below)
               *(np.ascontiguousarray(a[:, :1]) if k < 6 else a for k, a in enumerate(args)))
    noise_only(q, sig, gen.noise_key, 1, np.float32(gen.gain), gen.level)  # compile
    c0 = cpu()
    for _, st in states:
        synth_only(sig, gen.ncomp, gen.code_words, st["chip0"], st["ms0"], st["dchip"],
                   st["ph0"], st["dph"], st["amp"], st["sym"], st["sym_base"])
    prof["synthesis"] = cpu() - c0
    c0 = cpu()
    noise_only(q, sig, gen.noise_key, n_total, np.float32(gen.gain), gen.level)
    prof["noise_quantization"] = cpu() - c0
    # the fused kernel on all threads, and the writing of its chunks
    c0, t0 = cpu(), time.perf_counter()
    chunks = []
    for j0, st in states:
        for a in range(0, st["chip0"].shape[1], gen.chunk_nodes):
            b = min(a + gen.chunk_nodes, st["chip0"].shape[1])
            sub = {k: (np.ascontiguousarray(v[:, a:b]) if v.ndim == 2 and k != "sym" else v)
                   for k, v in st.items()}
            out = gen.synthesize(j0 + a, b - a, None, sub)
            if len(chunks) < 2:
                chunks.append(out)
    prof["kernel_cpu"] = cpu() - c0
    prof["kernel_wall"] = time.perf_counter() - t0
    prof["threads"] = numba.get_num_threads()
    if gen.fmt.name == "iq_int4":
        p = np.empty(chunks[0].shape[0], np.uint8)
        c0 = cpu()
        for _ in range(n_total // gen.chunk_nodes):
            K.pack_iq_int4_kernel(p, chunks[0])
        prof["packing"] = cpu() - c0
    path = Path(work) / "profile_write.bin"
    c0 = cpu()
    from sdr_di.sim.generate import write_overlapped     # the generator's writer

    with open(path, "wb") as fh:
        write_overlapped(fh, (chunks[k % len(chunks)] for k in range(n_total // gen.chunk_nodes)))
    prof["write"] = cpu() - c0
    path.unlink()
    prof["samples"] = gen.n_samples
    prof["n_sat"] = len(gen.sats)
    prof["bytes"] = gen.n_samples * gen.fmt.bytes_per_sample
    return prof


def print_profile(p: dict) -> None:
    d = p["duration_s"]
    stages = ["setup", "geometry", "synthesis", "noise_quantization", "packing", "write"]
    stages = [s for s in stages if s in p]
    total = sum(p[s] for s in stages)
    print(f"\nstage profile, {d:g} s of data in one process ({p['threads']} kernel threads); "
          "CPU s per data second and share of the stages' CPU:")
    for s in stages:
        print(f"  {s:20s} {p[s] / d:7.3f} CPU-s/s {100 * p[s] / total:6.1f} %")
    synth = p["samples"] * p["n_sat"] / p["synthesis"] / 1e6
    print(f"  satellite synthesis: {synth:.0f} M sample-satellites per CPU second "
          f"(target >= {TARGET_SYNTH_MSPS:.0f}: {'met' if synth >= TARGET_SYNTH_MSPS else 'NOT met'})")
    print(f"  noise + quantization: {p['samples'] / p['noise_quantization'] / 1e6:.0f} M samples "
          f"per CPU second ({p['noise_quantization'] / d:.3f} CPU-s per data second)")
    print(f"  fused kernel on {p['threads']} threads: {p['kernel_cpu'] / d:.3f} CPU-s and "
          f"{p['kernel_wall'] / d:.3f} wall-s per data second "
          f"({p['samples'] * p['n_sat'] / p['kernel_cpu'] / 1e6:.0f} M sample-satellites per "
          "CPU second, noise and quantization included)")


def run(args: argparse.Namespace) -> None:
    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="sdr-di-bench-"))
    out.mkdir(parents=True, exist_ok=True)
    try:
        _timed_generate(0.2, out, ())  # warm numba cache
        load = os.getloadavg()[0]
        print(f"machine: {os.cpu_count()} cores, load average {load:.2f} at start; default "
              "scenario, 7 satellites, 25 MHz, 4-bit iq_int8")
        from bench import print_bytecode_note

        print_bytecode_note()
        print(f"{'variant':>12} {'data s':>6} {'wall s':>7} {'CPU s':>6} {'x real time':>11} "
              f"{'MB/s':>6} {'peak RSS MiB':>12} {'file MiB':>8}")
        variants: list[tuple[str, tuple[str, ...]]] = [("default", ())]
        if args.oscillator:  # the default scenario plus a truth [oscillator] table
            sc = _scenario_with(out, "oscillator", f'\n[oscillator]\npreset = "{args.oscillator}"\n')
            variants.append((f"osc {args.oscillator}", ("--scenario", str(sc))))
        if args.impairments:
            for label, extra in IMPAIRMENTS.items():
                sc = _scenario_with(out, label.replace(" ", "_"), extra)
                variants.append((label, ("--scenario", str(sc))))
        best60 = None
        for d in args.durations:
            for label, extra in variants:
                runs = [_timed_generate(d, out, extra) for _ in range(args.repeat)]
                for r in runs:
                    print(f"{label:>12} {d:6.1f} {r['wall']:7.2f} {r['cpu']:6.2f} "
                          f"{d / r['wall']:11.2f} {r['size'] / r['wall'] / 1e6:6.1f} "
                          f"{r['rss'] / 2**20:12.1f} {r['size'] / 2**20:8.1f}")
                if d == 60.0 and label == "default":
                    best60 = min(runs, key=lambda r: r["wall"])
        if best60 is not None:
            x = 60.0 / best60["wall"]
            print(f"target 1 (issue 17): >= {TARGET_X_REALTIME:g}x real time on the 60 s file: "
                  f"best {x:.2f}x (wall {best60['wall']:.2f} s, CPU {best60['cpu']:.2f} s, "
                  f"{best60['size'] / best60['wall'] / 1e6:.0f} MB/s written) -> "
                  + ("met" if x >= TARGET_X_REALTIME else "NOT met")
                  + f"; load average now {os.getloadavg()[0]:.2f}")
            print(f"issue 29's target: >= {TARGET_29_X_REALTIME:g}x -> "
                  + ("met" if x >= TARGET_29_X_REALTIME else "NOT met"))
        if args.profile_s > 0:
            res = subprocess.run([sys.executable, "-c", _PROFILE_CHILD,
                                  str(Path(__file__).resolve().parent), str(args.profile_s),
                                  str(out)], capture_output=True, text=True, check=False)
            if res.returncode != 0:
                raise SystemExit(f"profile failed: {res.stderr.strip()}")
            line = next(ln for ln in res.stdout.splitlines() if ln.startswith("RESULT "))
            print_profile(json.loads(line[len("RESULT "):]))
    finally:
        if not args.keep:
            shutil.rmtree(out, ignore_errors=True)


def add_arguments(g: argparse.ArgumentParser) -> None:
    g.add_argument("--durations", type=float, nargs="+", default=[10.0, 60.0])
    g.add_argument("--repeat", type=int, default=1, help="runs per duration and variant")
    g.add_argument("--profile-s", type=float, default=4.0,
                   help="data seconds of the stage profile (0: none)")
    g.add_argument("--out", default=None, help="output directory (default: a temp dir)")
    g.add_argument("--keep", action="store_true", help="keep the generated files")
    g.add_argument("--oscillator", default=None, metavar="PRESET",
                   help="also time each duration with a truth [oscillator] of this preset "
                        "(issue 14)")
    g.add_argument("--impairments", action="store_true",
                   help="also time each duration with each impairment on (issue 15)")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(parser)
    run(parser.parse_args(argv))


if __name__ == "__main__":
    main()
