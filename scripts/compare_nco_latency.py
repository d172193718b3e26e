#!/usr/bin/env python
"""Deep mode with the NCOs one interval ahead against today's loop, paired over seeds.

Usage::

    python scripts/compare_nco_latency.py [--filter ekf] [--seeds 0 1 2 3 4 5] [--fs 25e6]
                                          [--duration 40] [--blockage T0 T1] [--out DIR]

For every seed the default scenario (``signals/default.toml``; the seed draws the IMU errors
and the signal noise; ``--blockage``: every satellite blocked over ``[T0, T1)`` s) is
generated once, the deep receiver's scalar start-up runs once and is kept
(``IntegratedReceiver.run(keep_start=True)``), and the vector loop runs from that same
hand-over twice: ``nco_latency = 0`` (the update of interval k steers interval k + 1) and
``nco_latency = 1`` (it steers k + 2; the correlation of k + 1 overlaps the update of k).
The two runs share the IF samples, the IMU record and the start-up, so each seed gives one
pair.

Criterion, fixed before any run (docs/deep.md, *NCOs one interval ahead*): latency 1 loses
nothing measurable when, for each of the position, velocity and attitude RMSE, the 95 %
t interval of the paired ratio (latency 1 / latency 0, from the mean log ratio) has its
upper end at most 1.05, and for each consistency figure (NIS of the code and rate blocks,
NEES of position, velocity and attitude) the interval lies within [0.9, 1.1].

Outputs in ``--out`` (default ``signals/out/compare_nco_latency``), each written under a
temporary name and renamed when complete: ``runs.csv`` (one row per seed and latency:
metrics, consistency, loop wall and CPU time) and ``table.md`` (the paired ratios with
their intervals, and the verdict; printed too).
"""

from __future__ import annotations

import argparse
import csv
import math
import time
from pathlib import Path

import numpy as np

from sdr_di.integration.receiver import IntegrationConfig, IntegratedReceiver
from sdr_di.io.atomic import atomic_open, ensure_output_dir
from sdr_di.studies.paired import t_interval

ROOT = Path(__file__).resolve().parents[1]

#: (key, label, lowest allowed ratio bound, highest allowed ratio bound)
ACCURACY = (("pos_m_rmse", "position RMSE", 0.0, 1.05),
            ("vel_mps_rmse", "velocity RMSE", 0.0, 1.05),
            ("att_deg_rmse", "attitude RMSE", 0.0, 1.05))
CONSISTENCY = (("nis_code", "NIS code", 0.9, 1.1), ("nis_rate", "NIS rate", 0.9, 1.1),
               ("nees_pos", "NEES position", 0.9, 1.1),
               ("nees_vel", "NEES velocity", 0.9, 1.1),
               ("nees_att", "NEES attitude", 0.9, 1.1))


def run_seed(seed: int, args: argparse.Namespace) -> list[dict]:
    """Generate one seed's files and run the vector loop with each latency from one kept
    start-up; one row per latency."""
    from sdr_di.experiments._deep import generated_inputs, with_outages
    from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario

    sc = load_scenario(DEFAULT_SCENARIO).with_overrides(
        seed=seed, duration_s=args.duration, sampling_rate_hz=args.fs)
    if args.blockage:
        sc = with_outages(sc, [{"prn": "all", "start_s": args.blockage[0],
                                "end_s": args.blockage[1], "blockage": True}])
    rows = []
    with generated_inputs(sc) as inp:
        kw = {"prns": inp.prns, "nav": inp.nav, "truth": inp.truth}
        first = IntegratedReceiver(IntegrationConfig(filter=args.filter))
        first.run(inp.source, inp.imu, keep_start=True, **kw)
        start = first.deep_start
        for latency in (0, 1):
            cfg = IntegrationConfig(filter=args.filter, nco_latency=latency)
            w0, c0 = time.perf_counter(), time.process_time()
            res = IntegratedReceiver(cfg).run(inp.source, inp.imu, start=start, **kw)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            m, c = res.metrics(), res.consistency()
            row = {"seed": seed, "nco_latency": latency, "handover_s": res.handover_s,
                   "rows": m["n"], **{k: m[k] for k, *_ in ACCURACY},
                   **{k: c[k]["value"] for k, *_ in CONSISTENCY},
                   "loop_wall_s": wall, "loop_cpu_s": cpu}
            rows.append(row)
            print(f"seed {seed} latency {latency}: position RMSE {m['pos_m_rmse']:.3f} m, "
                  f"velocity {m['vel_mps_rmse']:.4f} m/s, attitude {m['att_deg_rmse']:.4f} "
                  f"deg; NIS {c['nis_code']['value']:.3f} / {c['nis_rate']['value']:.3f}; "
                  f"loop {wall:.1f} s wall, {cpu:.1f} CPU s", flush=True)
    return rows


def paired_table(rows: list[dict], args: argparse.Namespace) -> tuple[str, bool]:
    """Markdown table of the paired ratios (latency 1 / latency 0) and the verdict."""
    seeds = sorted({r["seed"] for r in rows})
    by = {(r["seed"], r["nco_latency"]): r for r in rows}
    lines = [f"Filter `{args.filter}`, {len(seeds)} seeds ({', '.join(map(str, seeds))}), "
             f"{args.duration:g} s at {args.fs / 1e6:g} MHz"
             + (f", every satellite blocked over {args.blockage[0]:g}-{args.blockage[1]:g} s"
                if args.blockage else "")
             + "; errors and consistency from the hand-over to the end of the file. Ratio: "
             "latency 1 / latency 0, geometric mean over the seeds with its 95 % t interval "
             "(paired, on the log ratio).", "",
             "| figure | latency 0 (mean) | latency 1 (mean) | ratio | 95 % interval | "
             "allowed | |", "|---|---|---|---|---|---|---|"]
    ok_all = True
    for key, label, lo_ok, hi_ok in ACCURACY + CONSISTENCY + (
            ("loop_wall_s", "loop wall time [s]", None, None),
            ("loop_cpu_s", "loop CPU time [s]", None, None)):
        a = np.array([by[s, 0][key] for s in seeds], float)
        b = np.array([by[s, 1][key] for s in seeds], float)
        good = np.isfinite(a) & np.isfinite(b) & (a > 0) & (b > 0)
        mean, lo, hi, _ = t_interval(np.log(b[good] / a[good]), 0.95)
        r, rlo, rhi = (math.exp(v) if math.isfinite(v) else math.nan for v in (mean, lo, hi))
        if lo_ok is None:
            verdict, allowed = "", "(speed)"
        else:
            passed = math.isfinite(rlo) and rlo >= lo_ok and rhi <= hi_ok
            ok_all &= passed
            verdict = "pass" if passed else "FAIL"
            allowed = f"<= {hi_ok:g}" if lo_ok == 0.0 else f"{lo_ok:g}..{hi_ok:g}"
        lines.append(f"| {label} | {np.mean(a):.4g} | {np.mean(b):.4g} | {r:.4f} | "
                     f"{rlo:.4f}..{rhi:.4f} | {allowed} | {verdict} |")
    lines += ["", "Verdict: latency 1 " + ("loses nothing measurable (every figure within "
                                           "its bound)." if ok_all else
                                           "misses a bound (FAIL rows).")]
    return "\n".join(lines) + "\n", ok_all


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--filter", default="ekf", help="integration filter (default ekf)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    p.add_argument("--fs", type=float, default=25e6, help="sampling rate [Hz] (default 25e6)")
    p.add_argument("--duration", type=float, default=40.0, help="file length [s]")
    p.add_argument("--blockage", type=float, nargs=2, metavar=("T0", "T1"), default=None,
                   help="block every satellite over [T0, T1) s of the file")
    p.add_argument("--out", type=Path, default=ROOT / "signals" / "out" / "compare_nco_latency")
    args = p.parse_args(argv)
    if len(set(args.seeds)) < 2 or len(set(args.seeds)) != len(args.seeds):
        p.error("--seeds: at least two seeds, none repeated")
    out = ensure_output_dir(args.out)
    rows = [r for seed in args.seeds for r in run_seed(seed, args)]
    with atomic_open(out / "runs.csv", "w") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    text, ok = paired_table(rows, args)
    with atomic_open(out / "table.md", "w") as fh:
        fh.write(text)
    print()
    print(text)
    for name in ("runs.csv", "table.md"):
        print(f"wrote {out / name}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
