"""Tables, plots and the summary JSON of a finished campaign or single run.

Campaign folder::

    campaign.json         configuration, status, failed runs, aggregates, table/plot names
    aggregate.csv/.md     figure, n, mean, std, min, max over the successful runs
    runs.csv              one row per run: index, seed, status, elapsed_s, error, figures
    runs.md               index, seed, status, elapsed_s, error
    <table>.csv/.md       the experiment's tables (e.g. filters.csv)
    <plot>.png            the experiment's campaign plots (e.g. rmse_by_filter.png)
    runs/<i>.json         each run's record, written as it arrives
    runs/<i>/...          each run's own files (time series CSV, PNG)

Single-run folder: ``result.json``, ``figures.csv/.md``, the experiment's tables and plots,
and the run's own files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..experiments import plotting
from .aggregate import single_stats
from .execute import write_json
from ..experiments.registry import Experiment
from .tables import stats_rows, write_table

__all__ = ["write_campaign_outputs", "write_single_outputs"]


def _experiment_outputs(exp: Experiment, stats: dict, ok_records: list[dict],
                        out: Path) -> tuple[list[str], list[str], list[str]]:
    tables, plots, notes = [], [], []
    if exp.tables is not None:
        for name, rows in exp.tables(stats).items():
            write_table(out, name, rows)
            tables.append(name)
    if exp.plots is not None and ok_records:
        note = plotting.matplotlib_missing()
        if note:
            notes.append(note)
        else:
            plots = [Path(p).name for p in exp.plots(ok_records, out)]
    return tables, plots, notes


def write_campaign_outputs(exp: Experiment, result, config: dict) -> Path:
    """Write the campaign tables, plots and ``campaign.json`` (module docstring)."""
    out = Path(result.out_dir)
    write_table(out, "aggregate", stats_rows(result.stats),
                columns=["figure", "n", "mean", "std", "min", "max", "value"])
    rows = []
    for r in result.records:
        rows.append({"index": r["index"], "seed": r["seed"], "status": r["status"],
                     "elapsed_s": r.get("elapsed_s"), "error": r.get("error", ""),
                     **r.get("figures", {})})
    write_table(out, "runs", rows,
                md_columns=["index", "seed", "status", "elapsed_s", "error"])
    ok = [r for r in result.records if r["status"] == "ok"]
    tables, plots, notes = _experiment_outputs(exp, result.stats, ok, out)
    summary = {**config, "status": "done", "n_ok": len(ok),
               "n_failed": len(result.records) - len(ok),
               "failed": [{"index": r["index"], "seed": r["seed"], "error": r.get("error")}
                          for r in result.records if r["status"] != "ok"],
               "elapsed_s": result.elapsed_s, "tables": ["aggregate", *tables, "runs"],
               "plots": plots, "notes": notes, "stats": result.stats}
    return write_json(out / "campaign.json", summary)


def write_single_outputs(exp: Experiment, rec: dict, params: dict, out: Path) -> Path:
    """Write the tables, plots and ``result.json`` of one run (module docstring)."""
    out = Path(out)
    notes: list[str] = []
    tables: list[Any] = []
    plots: list[Any] = []
    if rec["status"] == "ok":
        stats = single_stats(rec["figures"])
        write_table(out, "figures", [{"figure": k, "value": v}
                                     for k, v in rec["figures"].items()])
        tables, plots, notes = _experiment_outputs(exp, stats, [rec], out)
        tables = ["figures", *tables]
    own_png = [f for f in rec.get("files", []) if f.endswith(".png")]
    summary = {"experiment": exp.name, "description": exp.description, "params": params,
               **{k: v for k, v in rec.items() if k != "files"},
               "files": rec.get("files", []), "tables": tables, "plots": plots + own_png,
               "notes": notes}
    return write_json(out / "result.json", summary)
