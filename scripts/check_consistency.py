#!/usr/bin/env python
"""Filter consistency over a mode x C/N0 x filter grid and seeds (issue 25 item 1).

Usage::

    python scripts/check_consistency.py [--modes deep tight loose] [--cn0 40 30]
                                        [--filters ekf ukf] [--seeds 0 1] [--fs 2.5e6]
                                        [--filter-rates 50 10]
                                        [--architectures prefilter reset discriminator]
                                        [--duration 30] [--t-step 15] [--t0 17] [--csv FILE]
                                        [--ensemble]

For every seed and C/N0 the default scenario (``signals/default.toml``, or ``--scenario``; the
seed draws the IMU errors and the signal noise; truth IMU and oscillator equal to the assumed
ones unless the scenario says otherwise) is
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

``--architectures`` (deep mode's measurement architectures, ``--deep-measurements``;
default the receiver's) adds another dimension for deep runs.

Printed: one row per mode x C/N0 x filter (x filter rate x architecture) with the mean over
the seeds that ran and the seed count (``n``); a run that fails (no hand-over at a low C/N0,
a diverged filter) is counted in ``failed`` and named on stderr. ``--csv`` also writes one
row per run. Expected value of every figure: 1 (a consistent filter).

``--save`` keeps the runs' records, ``--load`` prints the tables of several saved sets
(seeds run in parallel processes).

``--ensemble`` (Bar-Shalom, Li and Kirubarajan 2001, section 5.4): also the ensemble
averages over the seeds, at every solution row (NEES of position, velocity, attitude) and
every filter update (NIS per block) from ``--t0`` on, at the epochs all runs of the cell
share (times in whole output or update periods: the runs hand over at different times): ANEES and ANIS per degree of freedom, their mean over time, the two-sided 95 %
chi-square band of an average of ``N`` runs
(:func:`~sdr_di.integration.consistency.ensemble_band`, dimension 3 for NEES and the
block's size for NIS) and the share of times inside it (95 % for a consistent filter;
consecutive times are correlated, so the share scatters more than a binomial would), and
the RMSE over the runs.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import math
import pickle
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
            sc = load_scenario(args.scenario or DEFAULT_SCENARIO).with_overrides(
                seed=seed, duration_s=args.duration, sampling_rate_hz=args.fs, cn0_dbhz=40.0)
            if cn0 < 40.0:
                sc = with_outages(sc, [{"prn": "all", "start_s": args.t_step,
                                        "end_s": args.duration + 1.0,
                                        "attenuation_db": 40.0 - cn0}])
            with generated_inputs(sc) as inp:
                for mode, f, rate, arch in itertools.product(
                        args.modes, args.filters, args.filter_rates, args.architectures):
                    if mode != "deep" and arch != args.architectures[0]:
                        continue            # loose and tight have no architecture
                    rec = {"mode": mode, "cn0_dbhz": cn0, "filter": f, "seed": seed,
                           "filter_rate_hz": rate,
                           "architecture": arch if mode == "deep" else ""}
                    t0 = time.perf_counter()
                    try:
                        kw = {"deep_measurements": arch} if arch else {}
                        dr = run_deep_variant(inp, f, mode=mode, filter_rate_hz=rate,
                                              assume=assume_dict(args.assume), **kw)
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
                        rec["att_deg_rmse"] = met["att_deg_rmse"]
                        if args.ensemble:
                            rec["series"] = run_series(dr.result, args.t0)
                    rec["wall_s"] = time.perf_counter() - t0
                    print(f"{mode:5s} {cn0:4.0f} dB-Hz {f:8s} {rate:g} Hz {arch or '-'} "
                          f"seed {seed}: "
                          + " ".join(f"{k} {rec[k]:.3g}" for k in FIGURES if k in rec)
                          + f" ({rec['wall_s']:.0f} s)", file=sys.stderr, flush=True)
                    recs.append(rec)
    return recs


def assume_dict(pairs: list[str] | None) -> dict | None:
    """``["imu.grade=tactical", "imu.bias_time_s=600"]`` -> the filter's assumptions as a
    study cell's ``assume`` (numbers where they parse as numbers)."""
    if not pairs:
        return None
    out: dict = {}
    for pair in pairs:
        key, _, text = pair.partition("=")
        try:
            out[key.strip()] = float(text)
        except ValueError:
            out[key.strip()] = text.strip()
    return out


def run_series(res, t0: float) -> dict:
    """A run's time series for the ensemble (module notes): per solution row from ``t0``
    the NEES per degree of freedom (position, velocity, attitude) and the squared error
    norms, per filter update the NIS per degree of freedom of each block and its size; keyed
    by the time rounded to the ms."""
    keep = res.t >= t0
    rows = {round(float(t), 3): (nees, (pe ** 2).sum(), (ve ** 2).sum(), (ae ** 2).sum())
            for t, nees, pe, ve, ae in zip(res.t[keep], res.nees[keep], res.pos_err[keep],
                                          res.vel_err[keep], res.att_err[keep])}
    up = res.updates or {}
    t_up = np.asarray(up.get("t", []), float)
    ups = {round(float(t), 3): (np.asarray(nis, float), int(d))
           for t, nis, d in zip(t_up, up.get("nis", []), up.get("dof", [])) if t >= t0}
    return {"rows": rows, "updates": ups}


def _binned(series: dict) -> dict:
    """A run's series keyed by its time in whole periods (the median spacing of its times):
    the runs of a cell hand over at different times, so their rows and updates fall on
    grids offset by a fraction of a period; the same bin is the same epoch to within half
    a period."""
    t = np.array(sorted(series), float)
    if t.size < 2:
        return {}
    period = float(np.median(np.diff(t)))
    return {int(round(k / period)): v for k, v in series.items()}


def ensemble_rows(recs: list[dict], args: argparse.Namespace) -> list[dict]:
    """One record per cell (mode x C/N0 x filter x rate x architecture): ANEES and ANIS per
    degree of freedom averaged over the times all its runs share, their bands for the
    number of runs, the share of times inside, and the RMSE over the runs (module notes)."""
    from sdr_di.integration.consistency import ensemble_band

    out = []
    cells = sorted({(r["mode"], r["cn0_dbhz"], r["filter"], r["filter_rate_hz"],
                     r.get("architecture", "")) for r in recs}, key=str)
    for cell in cells:
        rs = [r for r in recs if (r["mode"], r["cn0_dbhz"], r["filter"], r["filter_rate_hz"],
                                  r.get("architecture", "")) == cell and "series" in r]
        n = len(rs)
        rec = {"mode": cell[0], "cn0_dbhz": cell[1], "filter": cell[2],
               "filter_rate_hz": cell[3], "architecture": cell[4], "n": n,
               "failed": sum(1 for r in recs if (r["mode"], r["cn0_dbhz"], r["filter"],
                                                 r["filter_rate_hz"],
                                                 r.get("architecture", "")) == cell
                             and "series" not in r)}
        if n < 2:
            out.append(rec)
            continue
        rows = [_binned(r["series"]["rows"]) for r in rs]
        times = sorted(set.intersection(*(set(b) for b in rows)))
        if times:
            nees = np.array([[b[t][0] for t in times] for b in rows])
            lo, hi = ensemble_band(n, 3)
            for j, q in enumerate(("pos", "vel", "att")):
                a = np.nanmean(nees[:, :, j], axis=0)        # ANEES at each time
                rec[f"anees_{q}"] = float(np.nanmean(a))
                rec[f"anees_{q}_band"] = (lo, hi)
                rec[f"anees_{q}_inside"] = float(np.mean((a >= lo) & (a <= hi)))
                sq = np.array([[b[t][1 + j] for t in times] for b in rows])
                rec[f"{q}_rmse"] = float(np.sqrt(np.nanmean(sq)))
        ups = [_binned(r["series"]["updates"]) for r in rs]
        t_up = sorted(set.intersection(*(set(u) for u in ups)))
        if t_up:
            for b, name in enumerate(NIS_BLOCKS[cell[0]]):
                vals = np.array([[u[t][0][b] for t in t_up] for u in ups])
                dof = int(np.median([ups[0][t][1] for t in t_up]))
                lo, hi = ensemble_band(n, dof)
                a = np.nanmean(vals, axis=0)
                rec[f"anis_{name}"] = float(np.nanmean(a))
                rec[f"anis_{name}_band"] = (lo, hi)
                rec[f"anis_{name}_inside"] = float(np.mean((a >= lo) & (a <= hi)))
        out.append(rec)
    return out


def ensemble_table(rows: list[dict], args: argparse.Namespace) -> str:
    """Markdown table of :func:`ensemble_rows`."""
    def f(rec, key):
        if key not in rec:
            return "-"
        lo, hi = rec[key + "_band"]
        return f"{rec[key]:.2f} [{lo:.2f}, {hi:.2f}] {100 * rec[key + '_inside']:.0f}%"

    lines = [f"Ensemble over seeds ({args.duration:g} s at {args.fs / 1e6:g} MHz, window "
             f"{args.t0:g} s to the end): time mean of ANEES / ANIS per degree of freedom "
             "[95 % band for N runs] share of times inside; RMSE over runs and times.", "",
             "| mode | C/N0 | filter | rate | architecture | N | failed | pos RMSE [m] | "
             "vel RMSE [m/s] | att RMSE [deg] | ANEES pos | ANEES vel | ANEES att | "
             "ANIS block 1 | ANIS block 2 |", "|" + "---|" * 15]
    for r in rows:
        b1, b2 = NIS_BLOCKS[r["mode"]]
        lines.append(
            f"| {r['mode']} | {r['cn0_dbhz']:g} | {r['filter']} | {r['filter_rate_hz']:g} | "
            f"{r['architecture'] or '-'} | {r['n']} | {r['failed']} | "
            f"{r.get('pos_rmse', math.nan):.3f} | {r.get('vel_rmse', math.nan):.4f} | "
            f"{r.get('att_rmse', math.nan):.3f} | {f(r, 'anees_pos')} | {f(r, 'anees_vel')} | "
            f"{f(r, 'anees_att')} | {b1} {f(r, 'anis_' + b1)} | {b2} {f(r, 'anis_' + b2)} |")
    return "\n".join(lines) + "\n"


def table(recs: list[dict], args: argparse.Namespace) -> str:
    """Markdown table: mean over the seeds per mode x C/N0 x filter (module notes)."""
    scen = getattr(args, "scenario", None) or "default scenario"
    lines = [f"{args.duration:g} s at {args.fs / 1e6:g} MHz, {scen}, 40 dB-Hz "
             f"then the level from {args.t_step:g} s; window {args.t0:g} s to the end; mean "
             "over the seeds that ran (n); expected value 1.", "",
             "| mode | C/N0 [dB-Hz] | filter | rate [Hz] | architecture | n | failed | "
             "NIS block 1 | NIS block 2 | NEES pos | NEES vel | NEES att |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for mode in args.modes:
        b1, b2 = NIS_BLOCKS[mode]
        for cn0 in args.cn0:
            archs = getattr(args, "architectures", [""])
            for f, rate, arch in itertools.product(args.filters, args.filter_rates, archs):
                if mode != "deep" and arch != archs[0]:
                    continue                # one row: loose and tight have no architecture
                arch = arch if mode == "deep" else ""
                rs = [r for r in recs if (r["mode"], r["cn0_dbhz"], r["filter"],
                                          r["filter_rate_hz"], r.get("architecture", "")) == (
                    mode, cn0, f, rate, arch)]
                ok = [r for r in rs if not r["error"]]

                def m(key):
                    v = np.array([r.get(key, math.nan) for r in ok], float)
                    v = v[np.isfinite(v)]
                    return f"{v.mean():.3g}" if v.size else "-"

                lines.append(f"| {mode} | {cn0:g} | {f} | {rate:g} | {arch or '-'} | {len(ok)} | "
                             f"{len(rs) - len(ok)} | "
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
    p.add_argument("--scenario", default=None, metavar="FILE.toml",
                   help="the base scenario (default signals/default.toml), e.g. one whose "
                   "[imu] names a grade, so that each seed draws its own unit")
    p.add_argument("--assume", nargs="+", default=None, metavar="KEY=VALUE",
                   help="the filter's assumptions as a study cell's assume keys, e.g. "
                   "imu.grade=tactical (docs/assumptions.md)")
    p.add_argument("--duration", type=float, default=30.0)
    p.add_argument("--t-step", type=float, default=15.0,
                   help="time of the C/N0 step [s of file] (after the hand-over, ~12.2 s)")
    p.add_argument("--t0", type=float, default=None,
                   help="start of the window [s of file] (default: the step + 2 s)")
    p.add_argument("--architectures", nargs="+", default=[""],
                   choices=["", "prefilter", "reset", "discriminator"],
                   help="deep measurement architectures (default: the receiver's)")
    p.add_argument("--ensemble", action="store_true",
                   help="also the ensemble averages over the seeds (module notes)")
    p.add_argument("--csv", default=None, help="also write one row per run here")
    p.add_argument("--save", default=None, metavar="FILE.pkl",
                   help="also keep every run's record (with its series) in this file")
    p.add_argument("--load", nargs="+", default=None, metavar="FILE.pkl",
                   help="run nothing: the tables of the records saved in these files (runs "
                   "split over processes; the other options must match theirs)")
    args = p.parse_args(argv)
    if any(c > 40.0 for c in args.cn0):
        p.error("--cn0: every level must be <= 40 dB-Hz (the start-up level)")
    if args.t0 is None:
        args.t0 = args.t_step + 2.0
    if args.load:
        recs = []
        for path in args.load:
            with open(path, "rb") as fh:
                recs += pickle.load(fh)
    else:
        recs = run_grid(args)
    if args.save:
        with open(args.save, "wb") as fh:
            pickle.dump(recs, fh)
    print(table(recs, args))
    if args.ensemble:
        print(ensemble_table(ensemble_rows(recs, args), args))
    if args.csv:
        keys = ["mode", "cn0_dbhz", "filter", "filter_rate_hz", "architecture", "seed",
                *FIGURES, "pos_m_rmse", "vel_mps_rmse", "att_deg_rmse", "wall_s", "error"]
        with open(args.csv, "w", newline="") as fh:
            w = csv.DictWriter(fh, keys, restval="", extrasaction="ignore")
            w.writeheader()
            w.writerows(recs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
