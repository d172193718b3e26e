#!/usr/bin/env python
"""Loose, tight and deep coupling side by side on the default scenario (issue 13 item 5).

Usage::

    python scripts/compare_coupling.py [--filter ekf] [--seeds 0 1 2 3] [--fs 25e6]
                                       [--duration 60] [--gnss-rate 5] [--out DIR]
                                       [--modes loose tight deep] [--no-plot]

For every seed the default scenario (``signals/default.toml``: paper 004's motion, MEMS IMU,
7 satellites at 40 dB-Hz; the seed draws the IMU errors and the signal noise) is generated
once at ``--fs`` for ``--duration`` s into a temporary folder, and each mode runs on the same
IF, IMU and truth files with the same filter (``IntegrationConfig(mode=..., filter=...)``; the
ephemeris file as assistance, as ``sdr-di run`` does). The three modes hand over at the same
sample (the same scalar start-up and rule) and report over the same window: from the
hand-over to the end of the file.

Outputs in ``--out`` (default ``signals/out/compare_coupling``), each written under a
temporary name and renamed when complete:

``runs.csv``        one row per seed and mode: RMSE and max of the attitude [deg], velocity
                    [m/s] and position [m] error norms (RMSE = sqrt(mean ||e||^2)), hand-over
                    time, rows
``table.md``        per mode the mean and the spread (sample standard deviation over the
                    seeds, and min..max) of each figure; printed too
``error_norms.png`` attitude, velocity and position error norms over time, every seed (thin)
                    and the mean over seeds (thick) per mode
"""

from __future__ import annotations

import argparse
import csv
import io
import math
import time
from pathlib import Path

import numpy as np

from sdr_di.integration.receiver import IntegrationConfig, IntegratedReceiver
from sdr_di.integration.receiver import MODES
from sdr_di.io.atomic import atomic_open, ensure_output_dir

ROOT = Path(__file__).resolve().parents[1]

#: Figures of the table: (result key, label, unit).
FIGURES = (("pos_m_rmse", "position RMSE", "m"), ("pos_m_max", "position max", "m"),
           ("vel_mps_rmse", "velocity RMSE", "m/s"), ("vel_mps_max", "velocity max", "m/s"),
           ("att_deg_rmse", "attitude RMSE", "deg"), ("att_deg_max", "attitude max", "deg"))


def run_seed(seed: int, args: argparse.Namespace) -> dict:
    """Generate one seed's files and run every mode on them; ``{mode: IntegrationResult}``."""
    from sdr_di.experiments._deep import generated_inputs
    from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario

    sc = load_scenario(DEFAULT_SCENARIO).with_overrides(
        seed=seed, duration_s=args.duration, sampling_rate_hz=args.fs)
    out = {}
    with generated_inputs(sc) as inp:
        for mode in args.modes:
            cfg = IntegrationConfig(filter=args.filter, mode=mode, gnss_rate_hz=args.gnss_rate)
            t0 = time.process_time()
            res = IntegratedReceiver(cfg).run(inp.source, inp.imu, prns=inp.prns, nav=inp.nav,
                                        truth=inp.truth)
            cpu = time.process_time() - t0
            m = res.metrics()
            print(f"seed {seed} {mode:5s}: hand-over {res.handover_s:.2f} s, {m['n']} rows, "
                  f"position RMSE {m['pos_m_rmse']:.3f} m, velocity {m['vel_mps_rmse']:.4f} "
                  f"m/s, attitude {m['att_deg_rmse']:.4f} deg ({cpu:.0f} CPU s)", flush=True)
            out[mode] = res
    return out


def _spread(v: np.ndarray) -> tuple[float, float, float, float]:
    v = v[np.isfinite(v)]
    if not v.size:
        return (math.nan,) * 4
    return (float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else math.nan,
            float(v.min()), float(v.max()))


def table(rows: list[dict], modes, args: argparse.Namespace) -> str:
    """Markdown table: per mode and figure, mean +- standard deviation (min..max)."""
    seeds = sorted({r["seed"] for r in rows})
    head = (f"Filter `{args.filter}`, {len(seeds)} seeds ({', '.join(map(str, seeds))}), "
            f"{args.duration:g} s at {args.fs / 1e6:g} MHz, GNSS rate {args.gnss_rate:g} Hz "
            "(loose, tight); errors from the hand-over to the end of the file; mean +- "
            "standard deviation over the seeds (min..max).\n\n")
    lines = ["| mode | " + " | ".join(f"{lab} [{u}]" for _, lab, u in FIGURES) + " |",
             "|---|" + "---|" * len(FIGURES)]
    for mode in modes:
        cells = []
        for key, _, _ in FIGURES:
            mean, sd, lo, hi = _spread(np.array([r[key] for r in rows if r["mode"] == mode]))
            cells.append(f"{mean:.4g} +- {sd:.2g} ({lo:.4g}..{hi:.4g})")
        lines.append(f"| {mode} | " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def plot(results: dict, modes, path: Path) -> None:
    """Error norms over time: every seed thin, the mean over seeds thick, per mode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
    colors = dict(zip(MODES, ("tab:red", "tab:blue", "tab:green")))
    styles = {"tight": "--"}            # loose and tight often overlap
    for ax, (attr, label) in zip(axes, (("att_err", "attitude error [deg]"),
                                        ("vel_err", "velocity error [m/s]"),
                                        ("pos_err", "position error [m]"))):
        for mode in modes:
            series = [(r[mode].t, np.linalg.norm(getattr(r[mode], attr), axis=1))
                      for r in results.values()]
            for t, e in series:
                ax.plot(t, e, color=colors[mode], lw=0.5, alpha=0.4)
            n = min(len(t) for t, _ in series)
            mean = np.mean([e[:n] for _, e in series], axis=0)
            ax.plot(series[0][0][:n], mean, color=colors[mode], lw=2.0,
                    ls=styles.get(mode, "-"), label=mode)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("time since the file start [s]")
    axes[0].set_title(f"error norms, {len(results)} seeds (thin: each seed, thick: mean)")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    with atomic_open(path, "wb") as fh:
        fh.write(buf.getvalue())


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--filter", default="ekf", help="integration filter of every mode")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    p.add_argument("--fs", type=float, default=25e6, help="sampling rate [Hz] (default 25e6)")
    p.add_argument("--duration", type=float, default=60.0, help="file length [s]")
    p.add_argument("--gnss-rate", type=float, default=5.0, help="loose/tight rate [Hz]")
    p.add_argument("--modes", nargs="+", choices=MODES, default=["loose", "tight", "deep"])
    p.add_argument("--out", type=Path, default=ROOT / "signals" / "out" / "compare_coupling")
    p.add_argument("--no-plot", action="store_true")
    args = p.parse_args(argv)
    if len(set(args.seeds)) != len(args.seeds):
        p.error("--seeds: repeated seed")
    out = ensure_output_dir(args.out)
    results, rows = {}, []
    for seed in args.seeds:
        results[seed] = run_seed(seed, args)
        for mode, res in results[seed].items():
            m = res.metrics()
            rows.append({"seed": seed, "mode": mode, "filter": res.filter_name,
                         "handover_s": res.handover_s, "rows": m["n"],
                         **{k: m[k] for k, _, _ in FIGURES}})
    with atomic_open(out / "runs.csv", "w") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    text = table(rows, args.modes, args)
    with atomic_open(out / "table.md", "w") as fh:
        fh.write(text)
    print()
    print(text)
    if not args.no_plot:
        plot(results, args.modes, out / "error_norms.png")
    for name in ("runs.csv", "table.md") + (() if args.no_plot else ("error_norms.png",)):
        print(f"wrote {out / name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
