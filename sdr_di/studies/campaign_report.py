"""``render_report(dir)``: one self-contained HTML page for a campaign or single-run folder.

The page reads top-down as a researcher reads (the same order as a study's report,
:mod:`.study_report`): what ran and how many runs completed, the failed runs, the
experiment's own summary tables (numbers at 3 significant digits), the plots (the folder's
and those of the first few runs), and last, collapsed, the raw tables (``aggregate``,
``runs``, ``figures``, at 6 digits) and the parameters. Plots are embedded as base64
``data:`` URIs: the page can be mailed or archived alone.
"""

from __future__ import annotations

import base64
import html
import json
import warnings
from pathlib import Path

from ..errors import ExperimentError
from ..io.atomic import atomic_open
from .aggregate import aggregate
from .execute import read_json, restore_floats
from .tables import format_cell, read_csv_table, stats_rows

__all__ = ["CSS", "ReportWarning", "img_html", "render_report", "sig", "table_html"]

CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.85em}
th,td{border:1px solid #ccc;padding:2px 6px;text-align:right}
th{background:#eee} td:first-child,th:first-child{text-align:left}
.scroll{overflow-x:auto} img{max-width:100%;border:1px solid #ddd;margin:0.5em 0}
.failed{color:#a00} code{background:#f4f4f4;padding:0 3px}
details{margin:0.5em 0} summary{cursor:pointer;font-weight:600}
.v-holds{color:#070} .v-reversed{color:#a00} .v-not-shown{color:#666}
"""

#: Significant digits of numbers a person reads in a report (CSV files keep full precision).
REPORT_DIGITS = 3


def sig(v, digits: int = REPORT_DIGITS) -> str:
    """``v`` with ``digits`` significant digits (``nan`` for NaN, empty for None)."""
    return format_cell(float(v) if isinstance(v, int) and not isinstance(v, bool) else v,
                       digits)


def _cell(text: str, digits: int) -> str:
    try:
        return sig(float(text), digits) if text not in ("", "True", "False") else text
    except ValueError:
        return text


#: Columns that name something (a seed, an index, a count) and are shown exactly as written.
VERBATIM_COLUMNS = frozenset({"seed", "seed_index", "index", "n", "n_pairs", "n_runs",
                              "n_ok", "n_failed"})


def table_html(path: Path, digits: int = REPORT_DIGITS) -> str:
    """A CSV table as HTML, numbers at ``digits`` significant digits (the identifiers of
    :data:`VERBATIM_COLUMNS` as written: a seed is a name, not a measurement)."""
    head, rows = read_csv_table(path)
    out = ['<div class="scroll"><table><tr>']
    out += [f"<th>{html.escape(h)}</th>" for h in head]
    out.append("</tr>")
    for row in rows:
        out.append("<tr>" + "".join(
            f"<td>{html.escape(c if h in VERBATIM_COLUMNS else _cell(c, digits))}</td>"
            for h, c in zip(head, row)) + "</tr>")
    out.append("</table></div>")
    return "".join(out)


def _rows_html(head: list[str], rows: list[dict]) -> str:
    out = ['<div class="scroll"><table><tr>']
    out += [f"<th>{html.escape(h)}</th>" for h in head]
    out.append("</tr>")
    for row in rows:
        out.append("<tr>" + "".join(f"<td>{html.escape(sig(row.get(h)))}</td>"
                                    for h in head) + "</tr>")
    out.append("</table></div>")
    return "".join(out)


#: Tables of every campaign/run folder that are raw data (collapsed at the end of a report).
_RAW_TABLES = ("aggregate", "runs", "figures")


class ReportWarning(UserWarning):
    """A run record the report could not read (named in the message; the report goes on)."""


#: Keys of ``campaign.json`` / ``result.json`` the report uses, and the type each must have.
_META_TYPES: dict[str, tuple[type, ...]] = {
    "experiment": (str,), "description": (str,), "status": (str,), "error": (str, type(None)),
    "params": (dict,), "notes": (list,), "tables": (list,), "failed": (list,),
}


def _read_meta(path: Path) -> dict:
    """``campaign.json`` / ``result.json``, checked; :class:`ExperimentError` naming the file."""
    try:
        meta = read_json(path)
    except OSError as exc:
        raise ExperimentError(f"report {path}: cannot read ({exc.strerror or exc})") from None
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise ExperimentError(f"report {path}: not JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise ExperimentError(f"report {path}: not a JSON object (top level is "
                              f"{type(meta).__name__})")
    for key, types in _META_TYPES.items():
        if key in meta and not isinstance(meta[key], types):
            raise ExperimentError(f"report {path}: {key} must be "
                                  f"{' or '.join(t.__name__ for t in types)}, got "
                                  f"{meta[key]!r:.60}")
    if not all(isinstance(t, str) for t in meta.get("tables", [])):
        raise ExperimentError(f"report {path}: tables must be a list of names")
    if not all(isinstance(f, dict) for f in meta.get("failed", [])):
        raise ExperimentError(f"report {path}: failed must be a list of run records")
    return meta


def _partial_campaign(folder: Path) -> dict:
    """Counts, failures and aggregate from ``runs/<i>.json`` of an unfinished campaign.

    A record that cannot be read (truncated by a kill, edited by hand) is skipped with a
    :class:`ReportWarning` naming it; the list is also kept under ``"unreadable"``.
    """
    recs, unreadable = [], []
    for p in sorted((folder / "runs").glob("*.json")):
        try:
            rec = read_json(p)
            if not isinstance(rec, dict) or not isinstance(rec.get("figures", {}), dict):
                raise ValueError("not a run record")
            rec["index"] = int(rec.get("index", 0))
        except (OSError, ValueError, TypeError, RecursionError) as exc:
            warnings.warn(ReportWarning(f"run record {p} could not be read ({exc}); "
                                        "left out of the report"), stacklevel=2)
            unreadable.append(p.name)
            continue
        recs.append(rec)
    recs.sort(key=lambda r: r.get("index", 0))
    ok = [r for r in recs if r.get("status") == "ok"]
    return {"n_ok": len(ok), "n_failed": len(recs) - len(ok), "unreadable": unreadable,
            "failed": [r for r in recs if r.get("status") != "ok"],
            "stats": aggregate(restore_floats(r.get("figures", {})) for r in ok)}


def img_html(path: Path, caption: str) -> str:
    """A PNG embedded as a ``data:`` URI with its caption."""
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure><img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def render_report(folder: str | Path, max_run_plots: int = 3) -> Path:
    """Write ``folder/report.html`` for a campaign or single-run folder.

    Parameters
    ----------
    folder : path
        Output folder of ``sdr-di campaign`` (``campaign.json``) or ``sdr-di robustness``
        (``result.json``).
    max_run_plots : int
        Per-run PNGs are included for this many runs of a campaign (the first ones).

    Returns
    -------
    Path
        The HTML file.

    Raises
    ------
    ExperimentError
        Not a folder written by a campaign or a run, or its ``campaign.json`` /
        ``result.json`` is not JSON, not an object, or has a key of the wrong type.

    Warns
    -----
    ReportWarning
        For each run record (``runs/<i>.json``) of an unfinished campaign that cannot be read.
    """
    folder = Path(folder)
    if (folder / "campaign.json").is_file():
        meta = _read_meta(folder / "campaign.json")
        kind = "campaign"
    elif (folder / "result.json").is_file():
        meta = _read_meta(folder / "result.json")
        kind = "run"
    else:
        raise ExperimentError(f"report {folder}: not an experiment output folder (no "
                              "campaign.json or result.json)")
    name = meta.get("experiment", "?")
    parts = [(f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>sdr-di {kind} "
             f"{html.escape(name)}</title><style>{CSS}</style></head><body>")]
    raw: list[str] = []          # raw tables and settings: last, collapsed
    if kind == "campaign":
        status = meta.get("status")
        parts.append(f"<h1>Campaign: {html.escape(name)}</h1>")
        parts.append(f"<p>{html.escape(meta.get('description', ''))}</p>")
        if status != "done":
            parts.append(f"<p class='failed'>Campaign status: {html.escape(str(status))} "
                         f"{html.escape(str(meta.get('error', '')))} (incomplete: the "
                         "aggregate comes from the run records so far)</p>")
            partial = _partial_campaign(folder)
            meta.update(partial)
            if partial["unreadable"]:
                parts.append("<p class='failed'>Run records that could not be read: "
                             f"{html.escape(', '.join(partial['unreadable']))}</p>")
            raw.append("<details open><summary>Aggregate of the runs so far</summary>"
                       + _rows_html(["figure", "n", "mean", "std", "min", "max", "value"],
                                    stats_rows(partial["stats"])) + "</details>")
        parts.append(f"<p>{meta.get('n_ok', '?')} of {meta.get('runs')} runs completed, "
                     f"{meta.get('n_failed', '?')} failed; base seed {meta.get('base_seed')}; "
                     f"scheduler <code>{html.escape(str(meta.get('scheduler')))}</code>. "
                     f"Numbers: mean over the runs (std beside it), {REPORT_DIGITS} significant "
                     "digits.</p>")
    else:
        parts.append(f"<h1>Run: {html.escape(name)}</h1>")
        parts.append(f"<p>{html.escape(meta.get('description', ''))}</p>")
        parts.append(f"<p>seed {meta.get('seed')}, status {html.escape(str(meta.get('status')))}"
                     "</p>")
        if meta.get("status") != "ok":
            parts.append(f"<p class='failed'>{html.escape(str(meta.get('error')))}</p>")
    for note in meta.get("notes", []):
        parts.append(f"<p><em>{html.escape(str(note))}</em></p>")
    failed = meta.get("failed") or []
    if failed:
        parts.append("<h2>Failed runs</h2><ul class='failed'>")
        parts += [f"<li>run {html.escape(str(f.get('index')))} (seed "
                  f"{html.escape(str(f.get('seed')))}): {html.escape(str(f.get('error')))}"
                  "</li>" for f in failed]
        parts.append("</ul>")
    summary = [t for t in meta.get("tables", []) if t not in _RAW_TABLES]
    if summary:
        parts.append("<h2>Summary</h2>")
    for t in summary:
        path = folder / f"{t}.csv"
        if path.is_file():
            parts.append(f"<h3>{html.escape(t)}</h3>{table_html(path)}")
    parts.append("<h2>Plots</h2>")
    pngs = sorted(folder.glob("*.png"))
    if kind == "campaign":
        runs = sorted((p for p in (folder / "runs").glob("*") if p.is_dir()),
                      key=lambda p: int(p.name) if p.name.isdigit() else 1 << 30)
        for run_dir in runs[:max_run_plots]:
            pngs += sorted(run_dir.rglob("*.png"))
    if not pngs:
        parts.append("<p><em>no plots in this folder</em></p>")
    for p in pngs:
        parts.append(img_html(p, p.relative_to(folder).as_posix()))
    parts.append("<h2>Raw tables</h2>")
    parts += raw
    for t in meta.get("tables", []):
        path = folder / f"{t}.csv"
        if t in _RAW_TABLES and path.is_file():
            parts.append(f"<details><summary>{html.escape(t)}</summary>"
                         f"{table_html(path, 6)}</details>")
    params = json.dumps(meta.get("params", {}), indent=1)
    parts.append(f"<details><summary>Parameters</summary><pre>{html.escape(params)}</pre>"
                 "</details>")
    parts.append("</body></html>\n")
    out = folder / "report.html"
    with atomic_open(out, "w") as fh:
        fh.write("\n".join(parts))
    return out
