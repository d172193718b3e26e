"""``DIR/report.html`` of a study: read top-down as a researcher reads.

1. The question and the design in two lines (cells, filters, baseline, seeds, correction).
2. The verdict of every claim per cell, with the numbers behind it.
3. Per cell, each filter's mean RMSE with its NEES beside it (ANEES with band and an
   in/out-of-band mark when cells.csv has them, and the number of runs averaged), its paired
   ratio to the baseline with the corrected interval,
   win count and Holm p (3 significant digits; the best mean per quantity in bold), and the
   NIS per measurement block.
4. Plots: paired ratios per cell (the factor levels) with their corrected intervals, on a
   log axis when they span a factor of 3 or more, else linear, labelled in plain decimals;
   error
   norms of a representative run (seed 0 of the first cell).
5. Failed or diverged runs, then the raw tables (cells, comparisons, runs, the spec),
   collapsed.

Self-contained: plots are embedded PNGs.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

from ..experiments import plotting
from ..integration.consistency import CONSISTENCY_KEYS, verdict
from ..io.atomic import atomic_open
from .campaign_report import CSS, img_html, sig, table_html
from .execute import read_json
from .paired import mean_ratio, ratio_of_log
from .spec import QUANTITY_KEYS
from .tables import read_csv_table

__all__ = ["render_study_report"]

_QLABEL = {"pos": "position", "vel": "velocity", "att": "attitude"}


def _rows(path: Path) -> list[dict]:
    head, rows = read_csv_table(path)
    return [dict(zip(head, r)) for r in rows]


def _num(text) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


#: Fewest paired seeds whose t interval the report prints (below it the t quantile at the
#: Bonferroni level makes the interval span orders of magnitude: [1.9e-08, 2.4e+08] at n = 2).
MIN_INTERVAL_N = 4


def _interval(lo, hi, n=None) -> str:
    """``[lo, hi]``, or a note when ``n`` paired seeds are too few to bound anything."""
    n = _num(n)
    if math.isfinite(n) and n < MIN_INTERVAL_N:
        return f"(interval not informative at n = {int(n)})"
    lo, hi = _num(lo), _num(hi)
    return f"[{sig(lo)}, {sig(hi)}]" if math.isfinite(lo) and math.isfinite(hi) else ""


#: The mark of an ensemble average against its band, by its verdict: inside (check mark),
#: outside (cross).
BAND_MARK = {"consistent": "&#10003;", "overconfident": "&#10007;",
             "pessimistic": "&#10007;"}

#: NIS columns of cells.csv (every mode's blocks; a mode fills its own).
_NIS_KEYS = tuple(k for k in CONSISTENCY_KEYS if k.startswith("nis_"))


def _consistency_cell(row: dict, key: str) -> str:
    """A cell's NEES or NIS per degree of freedom: ``anees_*``/``anis_*`` with its band
    (``_lo``, ``_hi``) and its mark (:data:`BAND_MARK`: in the band, or out of it and
    which way) where cells.csv has them (ensemble statistics,
    :mod:`.ensemble`), else the mean of the runs' own (``nees_*``, ``nis_*``)."""
    a = "a" + key
    if math.isfinite(_num(row.get(a))):
        v, lo, hi = _num(row[a]), _num(row.get(f"{a}_lo")), _num(row.get(f"{a}_hi"))
        if math.isfinite(lo) and math.isfinite(hi):
            vd = verdict(v, (lo, hi))
            cls = "v-holds" if vd == "consistent" else "v-reversed"
            return (f"{sig(v)} [{sig(lo)}, {sig(hi)}] <span class='{cls}'>{BAND_MARK[vd]} "
                    f"{vd}</span>")
        return sig(v)
    v = _num(row.get(key))
    return sig(v) if math.isfinite(v) else ""


def _n_pairs(comps: list[dict], cell: str, filt: str, against: str, q: str):
    c = next((c for c in comps if c["cell"] == cell and c["filter"] == filt
              and c["against"] == against and c["quantity"] == q), None)
    return c.get("n_pairs") if c else None


def _ratio_plot(path: Path, cells: list[dict], baseline: str, qs: list[str]) -> Path | None:
    if plotting.matplotlib_missing():
        return None
    from matplotlib.figure import Figure

    names = list(dict.fromkeys(r["cell"] for r in cells))
    filters = [f for f in dict.fromkeys(r["filter"] for r in cells) if f != baseline]
    if not filters:
        return None
    fig = Figure(figsize=(9, 2.4 * len(qs) + 0.8), layout="constrained")
    axes = fig.subplots(len(qs), 1, sharex=True, squeeze=False)[:, 0]
    width = 0.8 / max(1, len(filters))
    for ax, q in zip(axes, qs):
        shown: list[float] = [1.0]
        for k, f in enumerate(filters):
            xs, ys, lo, hi = [], [], [], []
            for j, cn in enumerate(names):
                r = next((r for r in cells if r["cell"] == cn and r["filter"] == f), None)
                if r is None:
                    continue
                y, a, b = (_num(r.get(f"{q}_ratio")), _num(r.get(f"{q}_ratio_ci_low")),
                           _num(r.get(f"{q}_ratio_ci_high")))
                if _num(r.get("n_ok")) < MIN_INTERVAL_N:      # no bar: not informative
                    a = b = math.nan
                if not math.isfinite(y):
                    continue
                xs.append(j - 0.4 + width * (k + 0.5))
                ys.append(y)
                lo.append(y - a if math.isfinite(a) else 0.0)
                hi.append(b - y if math.isfinite(b) else 0.0)
            ax.errorbar(xs, ys, yerr=[lo, hi], fmt="o", capsize=3, label=f)
            shown += [y - a for y, a in zip(ys, lo)] + [y + b for y, b in zip(ys, hi)]
        ax.axhline(1.0, color="0.4", lw=0.8, ls="--")
        plotting.ratio_axis(ax, shown)
        ax.set_ylabel(f"{_QLABEL[q]} RMSE\nratio to {baseline}")
        ax.grid(True, alpha=0.3, which="both")
    axes[-1].set_xticks(range(len(names)), names, rotation=25, ha="right")
    axes[-1].set_xlim(-0.6, len(names) - 0.4)
    axes[0].legend(fontsize="small", ncol=4)
    fig.suptitle("paired RMSE ratio to the baseline per cell: geometric mean over seeds,\n"
                 "corrected interval; below 1 = better than the baseline", fontsize="medium")
    return plotting.save_png(fig, path)


def render_study_report(folder: str | Path) -> Path:
    """Write ``folder/report.html`` for a study output folder (module docstring)."""
    folder = Path(folder)
    meta = read_json(folder / "study.json")
    cells = _rows(folder / "cells.csv") if (folder / "cells.csv").is_file() else []
    runs = _rows(folder / "runs.csv") if (folder / "runs.csv").is_file() else []
    comps = _rows(folder / "comparisons.csv") if (folder / "comparisons.csv").is_file() else []
    baseline = meta.get("baseline", "")
    qs = list(QUANTITY_KEYS)
    name = str(meta.get("name", "study"))
    n_cells = len(meta.get("cells", []))
    filters = meta.get("filters", [])
    m = len(comps)
    level = _num(comps[0]["level"]) if comps else math.nan
    parts = [(f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>sdr-di study "
              f"{html.escape(name)}</title><style>{CSS}</style></head><body>"),
             f"<h1>Study: {html.escape(name)}</h1>"]
    if meta.get("description"):
        parts.append(f"<p>{html.escape(meta['description'])}</p>")
    parts.append(
        f"<p>{n_cells} cell(s) x {len(filters)} filters ({html.escape(', '.join(filters))}) x "
        f"{meta.get('runs')} seeds, paired on the same files; baseline "
        f"<b>{html.escape(baseline)}</b>; experiment <code>{html.escape(meta.get('experiment', ''))}"
        f"</code>. Intervals: paired t on the per-seed "
        f"{'log RMSE ratios' if meta.get('interval') == 'log_ratio' else 'RMSE differences'} at "
        f"{sig(100 * level)} % (Bonferroni over the {m} comparisons, family-wise "
        f"{sig(100 * (1 - meta.get('alpha', 0.05)))} %); p-values Holm-adjusted over the same "
        f"family. Status: {html.escape(str(meta.get('status')))}.</p>")
    n_bad = sum(1 for r in runs if r.get("status") != "ok")
    if n_bad:
        parts.append(f"<p class='failed'>{n_bad} of {len(runs)} filter runs failed or diverged "
                     "(each counted as a loss for its filter, left out of the intervals; listed "
                     "below).</p>")

    claims = meta.get("claims", [])
    if claims:
        parts.append("<h2>Verdict</h2>")
        for j, cl in enumerate(claims, 1):
            crit = (f"wins in at least {cl['min_wins']} seeds, one-sided sign-test p &le; "
                    f"{sig(cl['max_sign_p'])}"
                    + (", corrected interval below 0" if cl["interval_excludes_zero"] else ""))
            parts.append(f"<h3>Claim {j}: {html.escape(cl['text'])}</h3><p>{cl['filter']} vs "
                         f"{cl['against']} in {', '.join(cl['quantities'])}; criterion: {crit}."
                         "</p>")
            head = ["cell", "verdict"] + [f"{q}: wins/n, ratio [interval]"
                                          for q in cl["quantities"]]
            out = ["<table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head)
                   + "</tr>"]
            for r in cells:
                v = r.get(f"claim{j}", "")
                if r["filter"] != cl["filter"] or not v:
                    continue
                tds = [html.escape(r["cell"]), f"<b class='v-{v.replace(' ', '-')}'>{v}</b>"]
                for q in cl["quantities"]:
                    c = next((c for c in comps if c["cell"] == r["cell"]
                              and c["filter"] == cl["filter"] and c["against"] == cl["against"]
                              and c["quantity"] == q), None)
                    if c is None:
                        tds.append("")
                        continue
                    ratio = mean_ratio(_num(c["log_mean"]))
                    lo, hi = _num(c["log_ci_low"]), _num(c["log_ci_high"])
                    iv = _interval(ratio_of_log(lo), ratio_of_log(hi), c.get("n_pairs")) \
                        if math.isfinite(lo) and math.isfinite(hi) else ""
                    tds.append(f"{c['wins']}/{c['n']}, {sig(ratio)} {iv}")
                out.append("<tr>" + "".join(f"<td>{t}</td>" for t in tds) + "</tr>")
            out.append("</table>")
            parts.append("".join(out))

    parts.append("<h2>Summary per cell</h2><p>Mean RMSE over the seeds (position m, velocity "
                 "m/s, attitude deg) and beside it the filter's NEES per degree of freedom "
                 "(ANEES, the mean over the N runs of each run's time-mean NEES, with the "
                 "two-sided 95 % chi-square band of an N-run ensemble average at one epoch "
                 "and its mark: &#10003; inside, &#10007; outside; where the study wrote no "
                 "ANEES, the mean over the seeds of each run's NEES; expected 1, below: "
                 "pessimistic, above: overconfident); for each other filter the paired ratio "
                 "to the baseline "
                 "with its corrected interval, wins/seeds and the Holm-adjusted sign-test p; "
                 "last, the NIS per measurement block the same way. "
                 "Bold: the best mean of the cell.</p>")
    for cn in dict.fromkeys(r["cell"] for r in cells):
        rows = [r for r in cells if r["cell"] == cn]
        facs = {k: v for k, v in rows[0].items() if "." in k or k in (
            "modes", "filter_rate_hz", "sampling_rate_hz", "cn0_dbhz", "duration_s")}
        facs = {k: v for k, v in facs.items() if v != ""}
        parts.append(f"<h3>{html.escape(cn)}</h3>"
                     + (f"<p><code>{html.escape(json.dumps(facs))}</code></p>" if facs else ""))
        nis_cols = [k for k in _NIS_KEYS if any(math.isfinite(_num(r.get(k))) for r in rows)]
        ens = any(r.get("n_ensemble", "") != "" for r in rows)
        head = ["filter", "ok/n"] + (["N (ensemble)"] if ens else [])
        for q in qs:
            head += [f"{q} RMSE", f"{q} NEES", f"{q} ratio [interval]", f"{q} wins",
                     f"{q} p (Holm)"]
        head += [f"NIS {k[4:]}" for k in nis_cols]
        out = ["<div class='scroll'><table><tr>"
               + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"]
        for r in rows:
            tds = [html.escape(r["filter"]), f"{r['n_ok']}/{r['n_runs']}"]
            if ens:
                tds.append(html.escape(r.get("n_ensemble", "")))
            for q in qs:
                col = next(k for k in r if k.startswith(f"{q}_rmse_") and k != f"{q}_rmse_sd")
                val = sig(_num(r[col]))
                tds.append(f"<b>{val}</b>" if r.get(f"{q}_best") == "1" else val)
                tds.append(_consistency_cell(r, f"nees_{q}"))
                if r["filter"] == baseline:
                    tds += ["(baseline)", "", ""]
                else:
                    iv = _interval(r[f"{q}_ratio_ci_low"], r[f"{q}_ratio_ci_high"],
                                   _n_pairs(comps, cn, r["filter"], baseline, q))
                    tds += [f"{sig(_num(r[f'{q}_ratio']))} {iv}",
                            f"{r[f'{q}_wins']}/{r['n_runs']}", sig(_num(r[f"{q}_sign_p_holm"]))]
            tds += [_consistency_cell(r, k) for k in nis_cols]
            out.append("<tr>" + "".join(f"<td>{t}</td>" for t in tds) + "</tr>")
        out.append("</table></div>")
        parts.append("".join(out))

    if (folder / "tuning.csv").is_file():
        from .tuning_report import tuning_html

        parts.append(tuning_html(folder / "tuning.csv"))
    parts.append("<h2>Plots</h2>")
    plot = _ratio_plot(folder / "paired_ratios.png", cells, baseline, qs) if cells else None
    if plot is not None:
        parts.append(img_html(plot, "paired RMSE ratios per cell"))
    rep = sorted((folder / "runs" / "0_0").glob("*.png")) if (folder / "runs").is_dir() else []
    for p in rep:
        parts.append(img_html(p, f"representative run: {cells[0]['cell'] if cells else ''}, "
                              f"seed 0 ({p.name}; shaded: before the scored window)"))
    if plot is None and not rep:
        parts.append("<p><em>no plots</em></p>")

    bad = [r for r in runs if r.get("status") != "ok"]
    if bad:
        parts.append("<h2>Failed or diverged runs</h2><ul class='failed'>")
        parts += [f"<li>{html.escape(r['cell'])}, seed {html.escape(r.get('seed', ''))} "
                  f"(index {r['seed_index']}), "
                  f"{html.escape(r['filter'])}: {html.escape(r['status'])} "
                  f"({html.escape(r.get('error', ''))})</li>" for r in bad]
        parts.append("</ul>")
    parts.append("<h2>Raw tables</h2>")
    for t in ("cells", "comparisons", "runs", "tuning"):
        path = folder / f"{t}.csv"
        if path.is_file():
            parts.append(f"<details><summary>{t}.csv</summary>{table_html(path)}</details>")
    spec = {k: meta.get(k) for k in ("source", "hash", "cells", "claims", "seeds")}
    parts.append("<details><summary>design (study.json)</summary><pre>"
                 f"{html.escape(json.dumps(spec, indent=1, default=str))}</pre></details>")
    parts.append("</body></html>\n")
    out_path = folder / "report.html"
    with atomic_open(out_path, "w") as fh:
        fh.write("\n".join(parts))
    return out_path
