#!/usr/bin/env python
"""Scalar and deep accuracy over seeds on generated default files (issue 17: a change of the
generator's algorithm must leave them within 2 sigma of before).

Usage::

    python scripts/check_generator_accuracy.py [--seeds 1 2 3 4] [--duration 60] [--fs 25e6]
                                               [--modes scalar deep] [--out DIR] [--keep]
                                               [--reuse] [--tag NAME] [--compare NAME]

For each seed: ``sdr-di generate`` (default scenario, the given duration and rate), then the
scalar receiver (``sdr-di run``, PVT at 5 Hz: position and velocity RMSE against the truth
file after the first fix) and the deep receiver (``run_integrated`` with the EKF: attitude,
velocity, position RMSE). Prints one row per seed and run, then the mean and standard
deviation over the seeds. Run it on the tree before and after a generator change (e.g.
``git worktree add /tmp/before <commit>`` and ``PYTHONPATH=/tmp/before``) and compare the
means with their spreads.

A receiver change is compared on the same files, paired: ``--out DIR --keep --tag before``
with the old tree, then ``--out DIR --reuse --tag after --compare before`` with the new one
(``--reuse``: a seed's file already in ``DIR`` is not generated again; ``--tag``: the runs'
folders are ``scalar_NAME``/``deep_NAME`` and their figures are kept in ``DIR/NAME.json``;
``--compare``: per figure, the mean paired difference (this run minus ``NAME``'s) with its
95 % t interval, next to ``NAME``'s standard deviation over the seeds).
"""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    p.add_argument("--duration", type=float, default=60.0)
    p.add_argument("--fs", type=float, default=25e6)
    p.add_argument("--modes", nargs="+", choices=("scalar", "deep"), default=["scalar", "deep"])
    p.add_argument("--out", default=None)
    p.add_argument("--keep", action="store_true")
    p.add_argument("--reuse", action="store_true", help="do not regenerate existing files")
    p.add_argument("--tag", default="", help="name of this tree's runs (paired comparisons)")
    p.add_argument("--compare", default=None, help="tag of earlier runs to pair with")
    args = p.parse_args(argv)
    if args.reuse or args.tag or args.compare:
        args.keep = True

    import sdr_di
    from sdr_di.cli import main as cli
    from sdr_di.integration.run_integrated import run_integrated
    from sdr_di.integration.receiver import IntegrationConfig
    from sdr_di.receiver.accuracy import solution_vs_truth
    from sdr_di.receiver.run_scalar import open_source

    out = Path(args.out) if args.out else Path(tempfile.mkdtemp(prefix="sdr-di-acc-"))
    print(f"package {sdr_di.__file__}; {args.duration:g} s at {args.fs / 1e6:g} MHz")
    rows: dict[str, list[tuple[float, ...]]] = {m: [] for m in args.modes}
    try:
        for seed in args.seeds:
            d = out / f"seed{seed}"
            sfx = f"_{args.tag}" if args.tag else ""
            if not (args.reuse and (d / "default.bin").exists()) and cli(["generate", "--duration", str(args.duration), "--fs", str(args.fs),
                        "--seed", str(seed), "--out", str(d), "--no-progress"]) != 0:
                raise SystemExit(f"generation of seed {seed} failed")
            meta = json.loads((d / "default.json").read_text())
            synth = meta.get("generator", {}).get("synthesis_version", 1)
            if "scalar" in args.modes:
                if cli(["run", str(d / "default.bin"), "--out", str(d / f"scalar{sfx}"),
                        "--no-progress"]) != 0:
                    raise SystemExit(f"scalar run of seed {seed} failed")
                acc = solution_vs_truth(d / f"scalar{sfx}" / "default_pvt.csv",
                                        d / "default_truth.csv")
                rows["scalar"].append((acc["pos_rmse_m"], acc["vel_rmse_mps"]))
                print(f"seed {seed} (synthesis v{synth}) scalar: pos {acc['pos_rmse_m']:.3f} m, "
                      f"vel {acc['vel_rmse_mps']:.4f} m/s, {acc['n_fixes']} fixes", flush=True)
            if "deep" in args.modes:
                prns = [s["prn"] for s in meta["satellites"]]
                res = run_integrated(open_source(d / "default.bin"), d / f"deep{sfx}",
                               config=IntegrationConfig(filter="ekf"), prns=prns, progress=False)
                m = res.metrics
                rows["deep"].append((m["pos_m_rmse"], m["vel_mps_rmse"], m["att_deg_rmse"]))
                print(f"seed {seed} (synthesis v{synth}) deep ekf: pos {m['pos_m_rmse']:.3f} m, "
                      f"vel {m['vel_mps_rmse']:.4f} m/s, att {m['att_deg_rmse']:.4f} deg",
                      flush=True)
        if args.tag:
            (out / f"{args.tag}.json").write_text(json.dumps(
                {"seeds": args.seeds, "rows": rows}))
        for mode, r in rows.items():
            a = np.array(r)
            if len(a):
                names = ("pos m", "vel m/s", "att deg")[: a.shape[1]]
                print(f"{mode}: " + ", ".join(
                    f"{n} {mu:.4f} +- {sd:.4f}" for n, mu, sd in
                    zip(names, a.mean(axis=0), a.std(axis=0, ddof=1) if len(a) > 1
                        else np.zeros(a.shape[1]))) + f" (mean +- sd over {len(a)} seeds)")
        if args.compare:
            _compare(rows, json.loads((out / f"{args.compare}.json").read_text()),
                     args.seeds, args.compare)
    finally:
        if not args.keep:
            shutil.rmtree(out, ignore_errors=True)


def _compare(rows: dict, before: dict, seeds: list[int], name: str) -> None:
    """Print per mode and figure the mean paired difference (these runs minus ``name``'s,
    same seeds) with its 95 % t interval, and ``name``'s mean and standard deviation."""
    from scipy import stats

    idx = [before["seeds"].index(s) for s in seeds]
    for mode, r in rows.items():
        if mode not in before["rows"] or not r:
            continue
        a = np.array(r)
        b = np.array(before["rows"][mode])[idx]
        dif = a - b
        n = len(dif)
        half = (stats.t.ppf(0.975, n - 1) * dif.std(axis=0, ddof=1) / np.sqrt(n)
                if n > 1 else np.full(a.shape[1], np.nan))
        names = ("pos m", "vel m/s", "att deg")[: a.shape[1]]
        for j, nm in enumerate(names):
            sd = b[:, j].std(ddof=1) if n > 1 else float("nan")
            print(f"{mode} {nm}: {name} {b[:, j].mean():.4f} +- {sd:.4f}; paired change "
                  f"{dif[:, j].mean():+.4f} [{dif[:, j].mean() - half[j]:+.4f}, "
                  f"{dif[:, j].mean() + half[j]:+.4f}] (95 %, {n} seeds)")


if __name__ == "__main__":
    main()
