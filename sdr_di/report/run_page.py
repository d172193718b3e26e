"""``RUN_DIR/report.html``: one self-contained page for an ``sdr-di run`` / ``sdr-di lc``
folder, and the figures ``run --plots`` writes.

The page has one section per run in the folder (:func:`~sdr_di.report.run_files.find_runs`):
what ran (mode, filter, hand-over, channels), what failed (a file left under its ``.part``
name, no fix, the run's warnings), the error table and the consistency table, the figures
(:mod:`~sdr_di.report.run_figures`, drawn from the folder's files when missing), and one
line for each part left out with the reason. Figures are embedded as base64 PNG: the page
reads offline and can be mailed alone (about 0.7 MB per 60 s run).
"""

from __future__ import annotations

import base64
import html
from pathlib import Path

from ..errors import ExperimentError
from ..experiments.plotting import PLOTS_SKIPPED, matplotlib_missing
from ..io.atomic import atomic_open
from ..studies.campaign_report import CSS
from .run_figures import RunSection, draw_run
from .run_files import find_runs, is_run_folder

__all__ = ["render_run_report", "write_run_plots"]

_PAGE_CSS = CSS + """
.note{color:#555;font-size:0.9em} figure{margin:0.8em 0} figcaption{font-size:0.9em;color:#333}
section.run{border-top:2px solid #ccc;margin-top:1.5em}
"""


def write_run_plots(folder: str | Path, stem: str | None = None) -> list[Path] | str:
    """Draw the figures of the runs in ``folder`` (``run --plots``): all of them, or those
    of the run whose figure prefix is ``stem`` (``STEM_MODE``, ``STEM`` for scalar).

    Returns
    -------
    list of Path, or str
        The PNGs written; :data:`~sdr_di.experiments.plotting.PLOTS_SKIPPED` when matplotlib
        is missing.
    """
    if matplotlib_missing():
        return PLOTS_SKIPPED
    out: list[Path] = []
    for run in find_runs(folder):
        if stem is None or run.stem == stem:
            out += [f.path for f in draw_run(folder, run, redraw=True).figures]
    return out


def _img(path: Path, fig_id: str, caption: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (f'<figure id="{html.escape(fig_id)}"><img alt="{html.escape(caption)}" '
            f'src="data:image/png;base64,{data}"><figcaption>{html.escape(caption)}'
            "</figcaption></figure>")


def _section(sec: RunSection) -> str:
    run = sec.run
    parts = [f'<section class="run" id="run-{html.escape(run.stem)}">'
             f"<h2>{html.escape(run.stem)}: {html.escape(sec.title)}</h2>"]
    parts += [f"<p>{f}</p>" for f in sec.facts]
    parts += [f"<p class='failed'>{html.escape(f)}</p>" for f in sec.failures]
    for _tid, title, body in sec.tables:
        parts.append(f"<h3>{html.escape(title)}</h3>{body}")
    if sec.figures:
        parts.append("<h3>Figures</h3>")
        parts += [_img(f.path, f.fig_id, f.caption) for f in sec.figures if f.path.is_file()]
    if sec.notes:
        parts.append("<h3>Left out</h3><ul class='note'>"
                     + "".join(f"<li class='left-out'>{html.escape(n)}</li>"
                               for n in sec.notes) + "</ul>")
    parts.append("</section>")
    return "\n".join(parts)


def render_run_report(folder: str | Path) -> Path:
    """Write ``folder/report.html`` for an ``sdr-di run`` or ``sdr-di lc`` output folder
    (module notes), drawing the figures its files allow that are not there yet.

    Returns
    -------
    Path
        The HTML file.

    Raises
    ------
    ExperimentError
        Not a run folder, or a summary that is not a JSON object.
    """
    folder = Path(folder)
    if not is_run_folder(folder):
        raise ExperimentError(f"report {folder}: not a run output folder (no *_pvt.csv or "
                              "*_summary.json)")
    runs = find_runs(folder)
    no_mpl = matplotlib_missing()
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>sdr-di run "
             f"{html.escape(folder.name)}</title><style>{_PAGE_CSS}</style></head><body>",
             f"<h1>Run: {html.escape(folder.name)}</h1>",
             "<p class='note'>Times in seconds since the IF file's start; errors and sigmas "
             "in the navigation frame (east, north, up). Runs in this folder: "
             + ", ".join(f"<a href='#run-{html.escape(r.stem)}'>{html.escape(r.stem)}</a>"
                         for r in runs) + ".</p>"]
    if no_mpl:
        parts.append(f"<p class='failed'>{html.escape(no_mpl)}</p>")
    for run in runs:
        if no_mpl:
            sec = RunSection(run, run.mode)
        else:
            sec = draw_run(folder, run)
        parts.append(_section(sec))
    parts.append("</body></html>\n")
    out = folder / "report.html"
    with atomic_open(out, "w") as fh:
        fh.write("\n".join(parts))
    return out
