#!/usr/bin/env python
"""Filter consistency over a mode x C/N0 x filter grid and seeds (issue 25 item 1).

Usage::

    python scripts/check_consistency.py [--modes deep tight loose] [--cn0 40 30]
                                        [--filters ekf ukf] [--seeds 0 1] [--fs 2.5e6]
                                        [--filter-rates 50 10]
                                        [--duration 30] [--t-step 15] [--t0 17] [--csv FILE]

For every seed and C/N0 the default scenario (``signals/default.toml``; the seed draws the
IMU errors and the signal noise; truth IMU and oscillator equal to the assumed ones) is
generated once at ``--fs`` for ``--duration`` s
(:class:`~sdr_di.experiments._deep.generated_inputs`, the experiments' generator and file
cache), and every mode x filter runs on those files with
``IntegrationConfig(mode=..., filter=...)`` (the run of ``sdr-di run``, through the
experiments' ``run_deep_variant``). As in the weak-signal experiment, every satellite is at 40
dB-Hz until ``--t-step`` s (the start-up needs a strong signal: at 30 dB-Hz the default
scenario never hands over) and at ``--cn0`` from then to the end (an attenuation window of
the scenario schema, :func:`~sdr_di.experiments._deep.with_outages`). The figures are the
run's :meth:`~sdr_di.integration.receiver.IntegrationResult.consistency` (the summary JSON's
``consistency`` entry): mean NIS per degree of freedom of each measurement block and NEES
per degree of freedom of position, velocity and attitude, from ``--t0`` s of the file
(default: 2 s after the step) to its end.

``--filter-rates`` (default 50 Hz) adds the integration filter's rate as a dimension of the
grid. Deep runs of one file share the scalar start-up
(:class:`~sdr_di.integration.receiver.DeepStart`).

Printed: one row per mode x C/N0 x filter (x filter rate) with the mean over the seeds that ran and the
seed count (``n``); a run that fails (no hand-over at a low C/N0, a diverged filter) is
counted in ``failed`` and named on stderr. ``--csv`` also writes one row per run.
Expected value of every figure: 1 (a consistent filter).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import math
import sys
import time

import numpy as np

from sdr_di.integration.consistency import CONSISTENCY_KEYS, NIS_BLOCKS, flat

#: Figure columns of the table (a mode has two of the NIS ones).
FIGURES = CONSISTENCY_KEYS


def run_grid(args: argparse.Namespace) -> list[dict]:
    """One record per seed x C/N0 x mode x filter: the consistency figures or an error."""
    from sdr_di.experiments._deep import generated_inputs, run_deep_variant, with_outages
    from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario

    recs = []
    for cn0 in args.cn0:
        for seed in args.seeds:
            sc = load_scenario(DEFAULT_SCENARIO).with_overrides(
                seed=seed, duration_s=args.duration, sampling_rate_hz=args.fs, cn0_dbhz=40.0)
            if cn0 < 40.0:
                sc = with_outages(sc, [{"prn": "all", "start_s": args.t_step,
                                        "end_s": args.duration + 1.0,
                                        "attenuation_db": 40.0 - cn0}])
            with generated_inputs(sc) as inp:
                for mode, f, rate in itertools.product(args.modes, args.filters,
                                                       args.filter_rates):
                    rec = {"mode": mode, "cn0_dbhz": cn0, "filter": f, "seed": seed,
                           "filter_rate_hz": rate}
                    t0 = time.perf_counter()
                    try:
                        dr = run_deep_variant(inp, f, mode=mode, filter_rate_hz=rate)
                        rec["error"] = dr.error or ""
                    except Exception as exc:  # noqa: BLE001 - a failed cell, named
                        rec["error"] = f"{type(exc).__name__}: {exc}"
                    if rec["error"]:
                        print(f"sdr-di: warning: {mode} {f} {cn0:g} dB-Hz seed {seed}: "
                              f"{rec['error']}", file=sys.stderr)
                    else:
                        rec.update(flat(dr.result.consistency(args.t0, None)))
                        met = dr.result.metrics(args.t0, None)
                        rec["pos_m_rmse"] = met["pos_m_rmse"]
                        rec["vel_mps_rmse"] = met["vel_mps_rmse"]
                    rec["wall_s"] = time.perf_counter() - t0
                    print(f"{mode:5s} {cn0:4.0f} dB-Hz {f:8s} {rate:g} Hz seed {seed}: "
                          + " ".join(f"{k} {rec[k]:.3g}" for k in FIGURES if k in rec)
                          + f" ({rec['wall_s']:.0f} s)", file=sys.stderr, flush=True)
                    recs.append(rec)
    return recs


def table(recs: list[dict], args: argparse.Namespace) -> str:
    """Markdown table: mean over the seeds per mode x C/N0 x filter (module notes)."""
    lines = [f"{args.duration:g} s at {args.fs / 1e6:g} MHz, default scenario, 40 dB-Hz "
             f"then the level from {args.t_step:g} s; window {args.t0:g} s to the end; mean "
             "over the seeds that ran (n); expected value 1.", "",
             "| mode | C/N0 [dB-Hz] | filter | rate [Hz] | n | failed | NIS block 1 | "
             "NIS block 2 | NEES pos | NEES vel | NEES att |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for mode in args.modes:
        b1, b2 = NIS_BLOCKS[mode]
        for cn0 in args.cn0:
            for f, rate in itertools.product(args.filters, args.filter_rates):
                rs = [r for r in recs if (r["mode"], r["cn0_dbhz"], r["filter"],
                                          r["filter_rate_hz"]) == (mode, cn0, f, rate)]
                ok = [r for r in rs if not r["error"]]

                def m(key):
                    v = np.array([r.get(key, math.nan) for r in ok], float)
                    v = v[np.isfinite(v)]
                    return f"{v.mean():.3g}" if v.size else "-"

                lines.append(f"| {mode} | {cn0:g} | {f} | {rate:g} | {len(ok)} | {len(rs) - len(ok)} | "
                             f"{b1} {m('nis_' + b1)} | {b2} {m('nis_' + b2)} | "
                             f"{m('nees_pos')} | {m('nees_vel')} | {m('nees_att')} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--modes", nargs="+", default=["deep", "tight", "loose"],
                   choices=["deep", "tight", "loose"])
    p.add_argument("--cn0", nargs="+", type=float, default=[40.0, 30.0],
                   help="C/N0 after the step [dB-Hz], each <= 40")
    p.add_argument("--filters", nargs="+", default=["ekf", "ukf"])
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    p.add_argument("--filter-rates", nargs="+", type=float, default=[50.0],
                   help="integration filter rates [Hz] (default 50)")
    p.add_argument("--fs", type=float, default=2.5e6)
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--t-step", type=float, default=15.0,
                   help="time of the C/N0 step [s of file] (after the hand-over, ~12.2 s)")
    p.add_argument("--t0", type=float, default=None,
                   help="start of the window [s of file] (default: the step + 2 s)")
    p.add_argument("--csv", default=None, help="also write one row per run here")
    args = p.parse_args(argv)
    if any(c > 40.0 for c in args.cn0):
        p.error("--cn0: every level must be <= 40 dB-Hz (the start-up level)")
    if args.t0 is None:
        args.t0 = args.t_step + 2.0
    recs = run_grid(args)
    print(table(recs, args))
    if args.csv:
        keys = ["mode", "cn0_dbhz", "filter", "filter_rate_hz", "seed", *FIGURES, "pos_m_rmse",
                "vel_mps_rmse", "wall_s", "error"]
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, keys, restval="")
            w.writeheader()
            w.writerows(recs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
