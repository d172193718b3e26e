"""Figures and tables of an integrated run (deep, loose, tight) or an ``sdr-di lc`` run, from
its solution CSV, ``STEM_MODE_channels.csv``, ``STEM_MODE_nis.csv`` and summary
(:mod:`.run_figures` lists them)."""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from . import figures as F
from .consistency_table import consistency_table_html
from .run_files import RunFiles, read_csv_columns, read_rows
from .section import Drawer, RunSection, east_north, fmt, newest_mtime

__all__ = ["integrated_section"]


def _channel_series(path: Path | None):
    """``({prn: (t, cn0)}, {prn: (t, used)}, {block: {prn: (t, innovation)}})`` of
    ``STEM_MODE_channels.csv``."""
    if path is None:
        return {}, {}, {}
    c = read_csv_columns(path)
    t = c.get("t_s", np.zeros(0))
    cn0, used, innov = {}, {}, {}
    for k, v in c.items():
        if k.startswith("cn0_C"):
            cn0[int(k[5:])] = (t, v)
        elif k.startswith("used_C"):
            used[int(k[6:])] = (t, v > 0.5)
        elif k.startswith("innov_"):
            block, ch = k[6:].rsplit("_C", 1)
            innov.setdefault(block, {})[int(ch)] = (t, v)
    return cn0, used, innov


def integrated_section(folder: Path, run: RunFiles, redraw: bool) -> RunSection:
    """The section of an integrated or lc run (:mod:`.run_figures`)."""
    s = run.summary
    mode = run.mode
    sec = RunSection(run, f"{mode}, filter {s.get('filter', '?')}" if mode != "lc"
                     else f"lc (loosely coupled, simulated GNSS), filter {s.get('filter', '?')}")
    rows = read_rows(run)
    if mode != "lc":
        sec.facts.append(
            f"hand-over at {fmt(s.get('handover_s'))} s with "
            f"{html.escape(' '.join(f'C{int(p):02d}' for p in s.get('prns', [])))}; "
            f"{s.get('rows')} solution rows")
    for w in s.get("warnings", []) or []:
        sec.failures.append(f"warning of the run: {w}")
    if rows is None:
        sec.failures.append(f"the solution file {run.stem}.csv is missing: the run did not "
                            "complete (only its summary is shown)")
        _consistency(sec, s)
        return sec
    if rows["t_s"].size == 0:
        sec.failures.append(f"{run.stem}.csv has no rows: the run wrote no solution")
    handover = s.get("handover_s") if mode != "lc" else None
    cn0, used, innov = _channel_series(run.files.get("channels"))
    t = rows["t_s"]
    spans = F.Spans.of(t, rows.get("n_used"), cn0, handover,
                       xlabel="time since the scenario start [s]" if mode == "lc"
                       else "time since the IF start [s]")
    newest = newest_mtime(run.files.values())
    draw = Drawer(folder, run.stem, newest, redraw, sec)
    title = f"{run.stem}"
    has_truth = bool(np.isfinite(rows["pos_err"]).any())
    if has_truth:
        for name, key, q, unit, axes in (
                ("pos-error", "pos", "position error", "m", ("E", "N", "U")),
                ("vel-error", "vel", "velocity error", "m/s", ("E", "N", "U")),
                ("att-error", "att", "attitude error", "deg",
                 ("E (~pitch)", "N (~roll)", "U (heading)"))):
            draw(name, f"{q} per axis (ENU) against the reference, with the filter's "
                       "+-3 sigma envelope",
                 lambda p, key=key, q=q, unit=unit, axes=axes: F.error_figure(
                     p, t, rows[f"{key}_err"], rows[f"{key}_sd"], quantity=q, unit=unit,
                     spans=spans, title=title, axis_names=axes))
    else:
        sec.notes.append("no reference trajectory (truth) for this run: the error figures, "
                         "the NEES rows and the truth track are left out (the IF file's "
                         "sidecar names no truth file and none was given with --truth)")
    _nis(sec, run, rows, spans, draw, title)
    _consistency(sec, s)
    if "lat_deg" in rows and np.isfinite(rows["lat_deg"]).any():
        ok = np.isfinite(rows["lat_deg"])
        lat0, lon0 = (math.radians(float(rows[k][ok][0])) for k in ("lat_deg", "lon_deg"))
        en = east_north(rows["lat_deg"][ok], rows["lon_deg"][ok], rows["h_m"][ok], lat0, lon0)
        truth_en = en - rows["pos_err"][ok][:, :2] if has_truth else None
        draw("trajectory", "trajectory east-north" + (" with the truth (solution minus "
                                                      "its error)" if has_truth else ""),
             lambda p: F.trajectory_figure(p, en, truth_en, title=title,
                                           origin="the first solution row"))
    elif mode == "lc":
        sec.notes.append("lc writes errors only (no position rows): no trajectory figure")
    if cn0:
        draw("channels", "C/N0 per channel and whether it was in the measurement vector "
                         "(the filter's use of the channel)",
             lambda p: F.channel_figure(p, cn0, used, spans=spans, title=title,
                                        lock_label="in the measurement vector"))
        if innov:
            draw("innovations", "normalized innovation y/sqrt(S_ii) of each channel's "
                                "measurements at the last filter update of each row (within "
                                "+-3 for a consistent filter; S_ii holds the error common to "
                                "all channels, the clock, which the NIS whitens out)",
                 lambda p: F.innovation_figure(p, innov, spans=spans, title=title))
        elif mode in ("deep", "tight"):
            sec.notes.append(f"no innovation columns in {run.stem}_channels.csv (a run "
                             "written before they existed): no per-channel innovations")
        else:
            sec.notes.append("loose's measurement is a position/velocity fix, not channels: "
                             "no per-channel innovations (the NIS per block stands for them)")
    elif mode != "lc":
        sec.notes.append(f"no {run.stem}_channels.csv (a run written before it existed): "
                         "no C/N0 per channel")
    else:
        sec.notes.append("lc simulates its GNSS fixes: no channels")
    if "n_used" in rows:
        lab = "satellites in the fix" if mode == "loose" else "satellites used"
        draw("sats-used", lab, lambda p: F.sats_used_figure(p, t, rows["n_used"],
                                                             spans=spans, title=title,
                                                             label=lab))
    return sec


def _nis(sec: RunSection, run: RunFiles, rows: dict, spans: F.Spans, draw, title: str) -> None:
    cons = run.summary.get("consistency") or {}
    if run.files.get("nis") is not None:
        c = read_csv_columns(run.files["nis"])
        blocks = [k[4:] for k in c if k.startswith("nis_")]
        if c["t_s"].size:
            nb = np.column_stack([c[f"nis_{b}"] for b in blocks])
            draw("nis", "NIS per degree of freedom of each measurement block at each "
                        "filter update, against its chi-square band",
                 lambda p: F.nis_figure(p, c["t_s"], nb, blocks, c["dof"],
                                        [cons.get(f"nis_{b}") for b in blocks], spans=spans,
                                        title=title))
            return
    if "nis" in rows and np.isfinite(rows["nis"]).any():
        dof = 6                                  # lc: z = [velocity, position]
        draw("nis", "NIS per degree of freedom of the whole measurement (velocity and "
                    "position together, 6 dof) at each row; per block: the run's means in the "
                    "consistency table",
             lambda p: F.nis_figure(p, rows["t_s"], (rows["nis"] / dof)[:, None], ["all"],
                                    np.full(rows["t_s"].size, dof), [None], spans=spans,
                                    title=title))
        return
    sec.notes.append("the NIS per update is not in this folder (no "
                     f"{run.stem}_nis.csv): the consistency table gives the run's means")


def _consistency(sec: RunSection, s: dict) -> None:
    cons = s.get("consistency")
    if isinstance(cons, dict):
        sec.tables.append((f"{sec.run.stem}-consistency", "Consistency",
                           consistency_table_html(cons, f"{sec.run.stem}-consistency")))
    m = s.get("metrics") or {}
    if m:
        rows = [("position [m]", "pos_m"), ("velocity [m/s]", "vel_mps"),
                ("attitude [deg]", "att_deg")]
        body = "".join(
            f"<tr><td>{q}</td><td>{fmt(m.get(k + '_rmse'))}</td><td>{fmt(m.get(k + '_max'))}"
            "</td><td>" + " / ".join(fmt(v) for v in (m.get(k + "_rmse_axes") or [])) +
            "</td></tr>" for q, k in rows)
        sec.tables.insert(0, (f"{sec.run.stem}-errors", "Errors against the reference",
                              f'<table id="{sec.run.stem}-errors"><tr><th>error</th>'
                              "<th>RMSE</th><th>max</th><th>RMSE E / N / U</th></tr>"
                              f"{body}</table>"))
