"""Plots and report page of one ``sdr-di run`` (any mode): ``run --plots`` and
``sdr-di report RUN_DIR``.

Plots (PNG beside the run's files, :func:`~sdr_di.experiments.plotting.time_series`):

``STEM_MODE_errors.png``  position and velocity error norms against the reference [m, m/s]
                          (only when a reference was available)
``STEM_MODE_cn0.png``     C/N0 of each channel [dB-Hz]
``STEM_MODE_sats.png``    satellites used in the solution (scalar: in the fix; deep, loose,
                          tight: in the measurement vector / fix)

:func:`render_run_report` writes ``RUN_DIR/report.html`` with the renderer pieces of
:mod:`~sdr_di.studies.campaign_report` (same page style, plots embedded): the run's summary
(``*_summary.json`` of an integrated mode, or the scalar channel table), then the plots.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from ..errors import ExperimentError
from ..io.atomic import atomic_open
from ..experiments.plotting import PLOTS_SKIPPED, matplotlib_missing, time_series
from .campaign_report import CSS, img_html, sig, table_html

__all__ = ["is_run_folder", "render_run_report", "write_run_plots"]


def write_run_plots(out_dir: Path, stem: str, *, t_s, n_used, cn0_by_prn: dict,
                    errors: tuple | None = None) -> list[Path] | str:
    """Write a run's plots (module notes).

    Parameters
    ----------
    out_dir : Path
        The run's output folder.
    stem : str
        ``STEM_MODE`` of the files.
    t_s, n_used : array
        Epoch times [s since the file start] and satellites used at each.
    cn0_by_prn : dict
        ``{prn: (t_s, cn0_dbhz)}`` arrays.
    errors : tuple, optional
        ``(t_s, pos_err (n, 3) [m], vel_err (n, 3) [m/s])`` against the reference.

    Returns
    -------
    list of Path, or str
        The PNGs written; the note :data:`~sdr_di.experiments.plotting.PLOTS_SKIPPED` when
        matplotlib is missing.
    """
    if matplotlib_missing():
        return PLOTS_SKIPPED
    out: list[Path] = []
    if errors is not None and len(errors[0]):
        t, dr, dv = (np.asarray(a, float) for a in errors)
        out.append(time_series(
            out_dir / f"{stem}_errors.png", {"error": t},
            [("position error [m]", {"error": np.linalg.norm(dr, axis=1)}),
             ("velocity error [m/s]", {"error": np.linalg.norm(dv, axis=1)})],
            title=f"{stem}: errors against the reference"))
    if cn0_by_prn:
        labels = {f"C{int(p):02d}": v for p, v in sorted(cn0_by_prn.items())}
        out.append(time_series(
            out_dir / f"{stem}_cn0.png", {k: np.asarray(v[0], float) for k, v in labels.items()},
            [("C/N0 [dB-Hz]", {k: np.asarray(v[1], float) for k, v in labels.items()})],
            title=f"{stem}: C/N0 per channel"))
    out.append(time_series(
        out_dir / f"{stem}_sats.png", {"used": np.asarray(t_s, float)},
        [("satellites used", {"used": np.asarray(n_used, float)})],
        title=f"{stem}: satellites used"))
    return out


def is_run_folder(folder: Path) -> bool:
    """True for an ``sdr-di run`` output folder (a scalar ``*_pvt.csv`` or an integrated
    mode's ``*_summary.json``)."""
    folder = Path(folder)
    return folder.is_dir() and (any(folder.glob("*_pvt.csv"))
                                or any(folder.glob("*_summary.json")))


def render_run_report(folder: str | Path) -> Path:
    """Write ``folder/report.html`` for one ``sdr-di run`` output folder (module notes).

    Raises
    ------
    ExperimentError
        Not a run folder, or a summary that is not JSON.
    """
    folder = Path(folder)
    if not is_run_folder(folder):
        raise ExperimentError(f"report {folder}: not a run output folder (no *_pvt.csv or "
                              "*_summary.json)")
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>sdr-di run "
             f"{html.escape(folder.name)}</title><style>{CSS}</style></head><body>",
             f"<h1>Run: {html.escape(folder.name)}</h1>"]
    for path in sorted(folder.glob("*_summary.json")):
        try:
            s = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise ExperimentError(f"report {path}: not JSON ({exc})") from None
        m = s.get("metrics") or {}
        parts.append(f"<h2>{html.escape(str(s.get('mode', '?')))}, filter "
                     f"{html.escape(str(s.get('filter', '?')))}</h2>")
        parts.append(f"<p>hand-over at {sig(s.get('handover_s'))} s with "
                     f"{html.escape(' '.join(f'C{int(p):02d}' for p in s.get('prns', [])))}; "
                     f"{s.get('rows')} rows</p>")
        rows = [("position [m]", "pos_m"), ("velocity [m/s]", "vel_mps"),
                ("attitude [deg]", "att_deg")]
        parts.append("<table><tr><th>error vs reference</th><th>RMSE</th><th>max</th></tr>"
                     + "".join(f"<tr><td>{q}</td><td>{sig(m.get(k + '_rmse'))}</td>"
                               f"<td>{sig(m.get(k + '_max'))}</td></tr>" for q, k in rows)
                     + "</table>")
        for w in s.get("warnings", []):
            parts.append(f"<p class='failed'>{html.escape(str(w))}</p>")
    for path in sorted(folder.glob("*_channels.csv")):
        parts.append(f"<h2>Scalar channels ({html.escape(path.name)})</h2>{table_html(path)}")
    parts.append("<h2>Plots</h2>")
    pngs = sorted(folder.glob("*.png"))
    if not pngs:
        parts.append("<p><em>no plots in this folder (<code>sdr-di run --plots</code> writes "
                     "them)</em></p>")
    parts += [img_html(p, p.name) for p in pngs]
    parts.append("</body></html>\n")
    out = folder / "report.html"
    with atomic_open(out, "w") as fh:
        fh.write("\n".join(parts))
    return out
