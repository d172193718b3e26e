#!/usr/bin/env python
"""Markdown tables of a finished study for ``docs/studies.md``.

Usage::

    python scripts/study_table.py DIR [--quantities pos vel att]

Reads ``DIR/cells.csv`` and ``DIR/comparisons.csv`` (``sdr-di study``) and prints, per
quantity, one table: a row per cell, each filter's mean RMSE over the seeds, and for every
filter other than the baseline its RMSE ratio to the baseline (geometric mean over the
seeds, with the corrected interval of ``comparisons.csv``) and its wins out of the pairs;
then a consistency table (mean NIS per measurement block and NEES per quantity of each cell
and filter, expected value 1) and the ensemble one (ANEES and ANIS with their chi-square
bands, ``sdr_di.studies.ensemble``); ``--no-consistency`` leaves both out, and each is left
out for a study written before its columns existed; then each claim's verdict per cell. Nothing
is computed here that the study did not write: the table is a view of its outputs.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from pathlib import Path

UNITS = {"pos": ("pos_rmse_m", "m"), "vel": ("vel_rmse_mps", "m/s"),
         "att": ("att_rmse_deg", "deg")}


#: NIS / NEES columns of cells.csv (sdr_di.integration.consistency.CONSISTENCY_KEYS).
CONSISTENCY = ("nis_code", "nis_range", "nis_rate", "nis_vel", "nis_pos", "nees_pos",
               "nees_vel", "nees_att")


def _read(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _f(x: str) -> float:
    try:
        return float(x)
    except (TypeError, ValueError):
        return math.nan


def _g(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.3g}"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("study_dir", type=Path)
    p.add_argument("--quantities", nargs="+", default=["pos", "vel", "att"],
                   choices=sorted(UNITS))
    p.add_argument("--no-consistency", action="store_true",
                   help="leave out the NIS / NEES table")
    args = p.parse_args(argv)
    cells = _read(args.study_dir / "cells.csv")
    comps = _read(args.study_dir / "comparisons.csv")
    meta = json.loads((args.study_dir / "study.json").read_text())
    filters, base = meta["filters"], meta["baseline"]
    names = list(dict.fromkeys(r["cell"] for r in cells))
    by = {(r["cell"], r["filter"]): r for r in cells}
    cmp_ = {(r["cell"], r["filter"], r["against"], r["quantity"]): r for r in comps}
    print(f"Study `{meta['name']}` ({meta.get('runs')} seeds, baseline {base}, "
          f"{meta.get('interval')} intervals at family level {meta.get('alpha')}).\n")
    for q in args.quantities:
        col, unit = UNITS[q]
        print(f"**{q} RMSE [{unit}]**: mean over the seeds; for the others, ratio to {base} "
              "[corrected interval], wins/pairs\n")
        print("| cell | " + " | ".join(filters) + " |")
        print("|---" * (len(filters) + 1) + "|")
        for c in names:
            out = []
            for f in filters:
                r = by.get((c, f))
                if r is None:
                    out.append("-")
                    continue
                m = _g(_f(r[col]))
                k = cmp_.get((c, f, base, q))
                if f != base and k is not None:
                    m += (f" ({_g(_f(k['ratio']))} [{_g(math.exp(_f(k['log_ci_low'])))}, "
                          f"{_g(math.exp(_f(k['log_ci_high'])))}], {k['wins']}/{k['n_pairs']})")
                failed = int(_f(r.get("n_failed", "0")) or 0)
                out.append(m + (f", {failed} failed" if failed else ""))
            print(f"| {c} | " + " | ".join(out) + " |")
        print()
    keys = [k for k in CONSISTENCY if cells and k in cells[0]
            and any(math.isfinite(_f(r[k])) for r in cells)]
    if keys and not args.no_consistency:
        print("**consistency**: mean over the seeds of NIS per degree of freedom per "
              "measurement block and NEES per degree of freedom (expected 1; bands in each "
              "run's summary JSON)\n")
        print("| cell | filter | " + " | ".join(keys) + " |")
        print("|---" * (len(keys) + 2) + "|")
        for c in names:
            for f in filters:
                r = by.get((c, f))
                if r is not None:
                    print(f"| {c} | {f} | " + " | ".join(_g(_f(r[k])) for k in keys) + " |")
        print()
    ens = [k for k in (cells[0] if cells else {}) if k.startswith(("anees_", "anis_"))
           and not k.endswith(("_lo", "_hi")) and any(math.isfinite(_f(r[k])) for r in cells)]
    if ens and not args.no_consistency:
        print("**ensemble consistency** (Bar-Shalom et al. 5.4): average NEES and NIS per "
              "degree of freedom over the cell's runs, [the two-sided 95 % chi-square band "
              "for that many runs]; * outside the band\n")
        print("| cell | filter | " + " | ".join(ens) + " |")
        print("|---" * (len(ens) + 2) + "|")
        for c in names:
            for f in filters:
                r = by.get((c, f))
                if r is None:
                    continue
                out = []
                for k in ens:
                    v, lo, hi = _f(r[k]), _f(r.get(k + "_lo")), _f(r.get(k + "_hi"))
                    star = "*" if math.isfinite(v) and not lo <= v <= hi else ""
                    out.append(f"{_g(v)}{star} [{_g(lo)}, {_g(hi)}]")
                print(f"| {c} | {f} | " + " | ".join(out) + " |")
        print()
    claims = meta.get("claims") or []
    if claims:
        print("| cell | " + " | ".join(f"claim {j}" for j in range(1, len(claims) + 1))
              + " |")
        print("|---" * (len(claims) + 1) + "|")
        for c in names:
            v = []
            for j, cl in enumerate(claims, 1):
                r = by.get((c, cl["filter"]), {})
                v.append(r.get(f"claim{j}") or "-")
            print(f"| {c} | " + " | ".join(v) + " |")
        print()
        for j, cl in enumerate(claims, 1):
            print(f"{j}. {cl['text']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
