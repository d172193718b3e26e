"""The figures and tables of one run, from what its folder holds (``run --plots`` and
``sdr-di report`` both come here).

:func:`draw_run` reads a :class:`~sdr_di.report.run_files.RunFiles` and returns a
:class:`RunSection`: its figures (PNG beside the run's files, ``PLOTSTEM_NAME.png``, drawn
when missing or older than the data they show), its tables (HTML), the facts of the run,
what failed, and one line for each part left out with the reason.

Figures (``NAME``; ``PLOTSTEM`` = ``STEM_MODE``, ``STEM_scalar`` for a scalar run):

============== ======================================================================
integrated     ``pos-error``, ``vel-error``, ``att-error`` (per ENU axis with the filter's
(deep, loose,  +-3 sigma; with a reference), ``nis`` (per block against its band),
tight, lc)     ``trajectory`` (east-north, with the truth), ``channels`` (C/N0 and use
               per channel), ``innovations`` (deep, tight: per channel, normalized),
               ``sats-used``; table ``consistency``. ``lc`` has no position
               rows and no channels (its NIS is per row, all blocks together).
scalar         ``fix-pos-error``, ``fix-vel-error`` (per ENU axis against the reference
               file the IF file's sidecar names), ``channels`` (C/N0 and lock from the
               run's RINEX observation file), ``sky``, ``fix-status``, ``trajectory``;
               table ``navdata`` (per satellite: orbit, state, ephemeris decoded, toe,
               subframes, records in the navigation file written)
============== ======================================================================
"""

from __future__ import annotations

import csv
import dataclasses
import html
import math
import re
from pathlib import Path

import numpy as np

from ..constants import SECONDS_PER_WEEK, orbit_type
from ..errors import SdrDiError
from ..frames import C_e_n, llh_to_ecef, radii_of_curvature
from . import figures as F
from .consistency_table import consistency_table_html
from .run_files import RunFiles, read_csv_columns, read_obs_rinex, read_rows, scalar_sidecar

__all__ = ["FigureRef", "RunSection", "draw_run"]


@dataclasses.dataclass
class FigureRef:
    """A figure of a run: its id on the page (``PLOTSTEM-NAME``), caption and PNG."""

    fig_id: str
    caption: str
    path: Path


@dataclasses.dataclass
class RunSection:
    """What the page shows of one run (module notes)."""

    run: RunFiles
    title: str
    facts: list = dataclasses.field(default_factory=list)      # HTML
    failures: list = dataclasses.field(default_factory=list)   # plain text
    notes: list = dataclasses.field(default_factory=list)      # plain text: left out, why
    figures: list = dataclasses.field(default_factory=list)    # FigureRef
    tables: list = dataclasses.field(default_factory=list)     # (id, title, HTML)


class _Drawer:
    """Draws a figure only when its PNG is missing or older than the data it shows."""

    def __init__(self, folder: Path, plot_stem: str, newest_input: float, redraw: bool,
                 section: RunSection):
        self.folder, self.plot_stem = folder, plot_stem
        self.newest, self.redraw, self.section = newest_input, redraw, section

    def __call__(self, name: str, caption: str, draw) -> None:
        path = self.folder / f"{self.plot_stem}_{name}.png"
        if self.redraw or not path.is_file() or path.stat().st_mtime < self.newest:
            draw(path)
        self.section.figures.append(FigureRef(f"{self.plot_stem}-{name}", caption, path))


def _newest(paths) -> float:
    return max((Path(p).stat().st_mtime for p in paths if p is not None and Path(p).exists()),
               default=0.0)


def _east_north(lat_deg, lon_deg, h_m, lat0: float, lon0: float) -> np.ndarray:
    """East and north [m] of geodetic points from (lat0, lon0) [rad] (local tangent plane,
    radii of curvature at lat0: a run's few km)."""
    R_M, R_N = (float(r) for r in radii_of_curvature(lat0))
    h = np.nan_to_num(np.asarray(h_m, float))
    return np.column_stack([(np.radians(lon_deg) - lon0) * (R_N + h) * math.cos(lat0),
                            (np.radians(lat_deg) - lat0) * (R_M + h)])


def draw_run(folder: str | Path, run: RunFiles, redraw: bool = False) -> RunSection:
    """Figures, tables, facts and notes of one run of ``folder`` (module notes).

    ``redraw``: draw every figure even when its PNG is up to date (``run --plots``).
    """
    folder = Path(folder)
    if run.kind == "scalar":
        return _scalar(folder, run, redraw)
    return _integrated(folder, run, redraw)


# --- integrated modes and lc ------------------------------------------------------------

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


def _integrated(folder: Path, run: RunFiles, redraw: bool) -> RunSection:
    s = run.summary
    mode = run.mode
    sec = RunSection(run, f"{mode}, filter {s.get('filter', '?')}" if mode != "lc"
                     else f"lc (loosely coupled, simulated GNSS), filter {s.get('filter', '?')}")
    rows = read_rows(run)
    if mode != "lc":
        sec.facts.append(
            f"hand-over at {_g(s.get('handover_s'))} s with "
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
    spans = F.Spans.of(t, rows.get("n_used"), cn0, handover)
    newest = _newest(run.files.values())
    draw = _Drawer(folder, run.stem, newest, redraw, sec)
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
        en = _east_north(rows["lat_deg"][ok], rows["lon_deg"][ok], rows["h_m"][ok], lat0, lon0)
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
            f"<tr><td>{q}</td><td>{_g(m.get(k + '_rmse'))}</td><td>{_g(m.get(k + '_max'))}"
            "</td><td>" + " / ".join(_g(v) for v in (m.get(k + "_rmse_axes") or [])) +
            "</td></tr>" for q, k in rows)
        sec.tables.insert(0, (f"{sec.run.stem}-errors", "Errors against the reference",
                              f'<table id="{sec.run.stem}-errors"><tr><th>error</th>'
                              "<th>RMSE</th><th>max</th><th>RMSE E / N / U</th></tr>"
                              f"{body}</table>"))


def _g(v, digits: int = 3) -> str:
    if v is None:
        return "-"
    try:
        v = float(v)
    except (TypeError, ValueError):
        return html.escape(str(v))
    return "nan" if not math.isfinite(v) else f"{v:.{digits}g}"


# --- scalar -------------------------------------------------------------------------------

def _scalar(folder: Path, run: RunFiles, redraw: bool) -> RunSection:
    from ..io.sidecar import check_member, member_path, read_sidecar
    from ..io.solution_files import read_solution_csv

    sec = RunSection(run, "scalar receiver")
    plot_stem = f"{run.stem}_scalar"
    for name in run.partial:
        sec.failures.append(f"{name}: still under its temporary name, the run stopped before "
                            "it completed (what it wrote so far is shown)")
    pvt_path = run.files.get("pvt")
    try:
        sol = read_solution_csv(pvt_path) if pvt_path is not None else None
    except SdrDiError as exc:
        sol = None
        sec.failures.append(f"solution file not readable: {exc}")
    # the run's record (input files), else the IF file's sidecar beside the run folder:
    # start time, reference (truth) file, assistance ephemeris
    rec = run.summary
    side = Path(rec["sidecar"]) if rec.get("sidecar") else scalar_sidecar(folder, run.stem)
    meta, truth_path, eph_path = None, None, None
    if side is not None and side.is_file():
        try:
            meta = read_sidecar(side)
            eph_path = member_path(side, meta, "ephemeris_file")
            truth_path = check_member(side, meta, "truth_file")
        except SdrDiError as exc:
            sec.notes.append(f"sidecar {side.name} not used: {exc}")
    else:
        side = None
    for key in ("truth_file", "ephemeris_file"):
        p = Path(rec[key]) if rec.get(key) else None
        if p is not None and not p.is_file():
            sec.notes.append(f"the run's {key.replace('_', ' ')} {p} is no longer there")
        elif p is not None:
            truth_path, eph_path = (p, eph_path) if key == "truth_file" else (truth_path, p)
    if rec.get("start", {}).get("sow") is not None:
        meta = {**(meta or {}), "start": rec["start"]}
    start = (meta or {}).get("start") or {}
    obs = read_obs_rinex(run.files["rinex_obs"]) if "rinex_obs" in run.files else None
    if obs is None:
        obs_note = "no epochs in the RINEX observation file: no C/N0 and lock per channel"
    if start.get("week") is not None and start.get("sow") is not None:
        t0 = (int(start["week"]), float(start["sow"]))
        xlabel = "time since the IF start [s]"
    elif obs is not None:
        t0 = (obs.week, float(obs.sow[0]))
        xlabel = "time since the first epoch with a receiver time [s]"
    else:
        t0, xlabel = None, "time [s]"

    def rel(week, sow):
        return (np.asarray(week, float) - t0[0]) * SECONDS_PER_WEEK + np.asarray(sow,
                                                                                 float) - t0[1]

    if sol is None:
        return sec
    n_rows = sol["status"].size
    fix = sol["status"] == "fix"
    n_fix = int(fix.sum())
    sec.facts.append(f"{n_rows} epochs, {n_fix} with a fix"
                     + (f"; IF file {html.escape(str(rec['if_file']))}" if rec.get("if_file")
                        else f"; sidecar {html.escape(side.name)}" if side else
                        "; no run record and no sidecar beside the run folder"))
    if n_fix == 0:
        sec.failures.append(f"no fix in {n_rows} epochs: the run failed (what it wrote is "
                            "shown; 'sdr-di run' prints the likely causes)")
    timed = np.isfinite(sol["rx_sow"]) & (sol["rx_week"] > 0)
    rate = rec.get("rate_hz")
    if t0 and timed.any() and (~timed).any() and rate:
        # epochs before the receiver time was set: one every 1 / rate before the first
        # timed one (the run's epoch grid, STEM_scalar_summary.json)
        t_all = np.full(n_rows, np.nan)
        t_all[timed] = rel(sol["rx_week"][timed], sol["rx_sow"][timed])
        i0 = int(np.argmax(timed))
        t_all[:i0] = t_all[i0] - (i0 - np.arange(i0)) / float(rate)
        timed = np.isfinite(t_all)
        t_rows = t_all[timed]
    else:
        t_rows = rel(sol["rx_week"][timed], sol["rx_sow"][timed]) if t0 else np.zeros(0)
    if t0 and (~timed).any():
        sec.notes.append(f"{int((~timed).sum())} epochs before the receiver time was set are "
                         "left out of the time figures")
    cn0 = lock = weak = slips = None
    if obs is not None and t0:
        to = rel(obs.week, obs.sow)
        cn0 = {p: (to, v) for p, v in obs.cn0_dbhz.items()}
        lock = {p: (to, v) for p, v in obs.pseudorange.items()}
        weak = {p: (to, np.isfinite(obs.cn0_dbhz[p])) for p in obs.cn0_dbhz}
        slips = {p: (to, v) for p, v in obs.slip.items()}
    spans = F.Spans.of(t_rows, sol["n_sats"][timed], cn0, xlabel=xlabel)
    newest = _newest(list(run.files.values()) + [truth_path])
    draw = _Drawer(folder, plot_stem, newest, redraw, sec)
    title = plot_stem
    truth = None
    if truth_path is not None and n_fix:
        from ..io.imu_files import read_truth
        from ..receiver.accuracy import solution_errors

        try:
            truth = read_truth(truth_path)[0]
            te, dr_e, dv_n = solution_errors(pvt_path, truth_path)
        except SdrDiError as exc:
            truth, te = None, np.zeros(0)
            sec.notes.append(f"reference file not used: {exc}")
        if te.size:
            # ECEF -> ENU at the first fix (a run spans a few km: the rotation differs by
            # less than 1e-3 rad over it)
            lat0, lon0 = math.radians(sol["lat_deg"][fix][0]), math.radians(
                sol["lon_deg"][fix][0])
            dr_n = dr_e @ C_e_n(lat0, lon0).T
            nan = np.full_like(dr_n, np.nan)
            sp = F.Spans.of(te, None, cn0, xlabel="time since the IF start [s]")
            draw("fix-pos-error", "position error of each fix per axis (ENU) against the "
                                  "reference file",
                 lambda p: F.error_figure(p, te, dr_n, nan, quantity="position error",
                                          unit="m", spans=sp, title=title))
            draw("fix-vel-error", "velocity error of each fix per axis (ENU) against the "
                                  "reference file",
                 lambda p: F.error_figure(p, te, dv_n, nan, quantity="velocity error",
                                          unit="m/s", spans=sp, title=title))
            sec.notes.append("the solution file carries DOPs, not the PVT's covariance: the "
                             "fix errors are drawn without a sigma envelope (PDOP in the fix "
                             "status figure)")
    elif truth_path is not None:
        sec.notes.append("no fix: no fix errors against the reference file")
    else:
        sec.notes.append("no reference trajectory (truth): the fix-error figures and the "
                         "truth track are left out (the run had no --truth and the IF file's "
                         "sidecar names none)")
    if cn0:
        draw("channels", "C/N0 per channel (S6I) and its lock (from the run's RINEX "
                         "observation file)",
             lambda p: F.channel_figure(
                 p, cn0, lock, spans=spans, title=title, weak=weak, slips=slips,
                 lock_label="pseudorange (code lock, frame synchronized)",
                 weak_label="tracked (code lock, no transmit time yet)"))
    else:
        sec.notes.append(obs_note if obs is None else "no time reference: no channel figure")
    _sky(sec, run, sol, fix, eph_path, truth, draw, title)
    if t0:
        draw("fix-status", "fix status, satellites in the fix and PDOP of each epoch",
             lambda p: F.fix_status_figure(p, t_rows, sol["status"][timed],
                                           sol["n_sats"][timed], sol["pdop"][timed],
                                           spans=spans, title=title))
    if n_fix:
        lat0, lon0 = math.radians(sol["lat_deg"][fix][0]), math.radians(sol["lon_deg"][fix][0])
        en = _east_north(sol["lat_deg"][fix], sol["lon_deg"][fix], sol["h_m"][fix], lat0,
                         lon0)
        truth_en = None
        if truth is not None:
            truth_en = _east_north(np.degrees(truth.llh[:, 0]), np.degrees(truth.llh[:, 1]),
                                   truth.llh[:, 2], lat0, lon0)
        draw("trajectory", "fixes east-north" + (" with the truth" if truth is not None
                                                 else ""),
             lambda p: F.trajectory_figure(p, en, truth_en, title=title,
                                           origin="the first fix"))
    _navdata(sec, run)
    return sec


def _sky(sec: RunSection, run: RunFiles, sol: dict, fix: np.ndarray, eph_path, truth, draw,
         title: str) -> None:
    from .sky import load_navigation, sky_tracks

    tracked = []
    if "channels" in run.files:
        try:
            tracked = [int(v) for v in read_csv_columns(run.files["channels"])["prn"]]
        except (SdrDiError, KeyError, ValueError):
            tracked = []
    # the assistance file first; the records the run decoded only for satellites it lacks
    # (reading them also imports georinex for its header check: about 1 s)
    nav = load_navigation([eph_path])
    if nav is None or not set(tracked) <= set(nav.prns):
        nav = load_navigation([eph_path, run.files.get("rinex_nav")])
    if nav is None:
        sec.notes.append("no navigation data (no record decoded and no assistance file "
                         "found): no sky plot")
        return
    if fix.any():
        week = int(sol["week"][fix][0])
        sow = (sol["week"][fix] - week) * SECONDS_PER_WEEK + sol["sow"][fix]
        r = np.column_stack([sol["x_m"], sol["y_m"], sol["z_m"]])[fix]
    elif truth is not None and sol["rx_week"].max() > 0:
        ok = np.isfinite(sol["rx_sow"]) & (sol["rx_week"] > 0)
        week = int(sol["rx_week"][ok][0])
        sow = sol["rx_sow"][ok]
        r = llh_to_ecef(*truth.llh[0])
    else:
        sec.notes.append("no fix and no time reference: no sky plot")
        return
    tracks = sky_tracks(nav, week, sow, r, prns=sorted(set(nav.prns) | set(tracked)))
    tracks = {p: v for p, v in tracks.items() if np.nanmax(v[1]) > 0}
    if not tracks:
        sec.notes.append("no satellite above the horizon in the navigation data: no sky plot")
        return
    draw("sky", "sky plot: azimuth and elevation of each satellite with a broadcast record "
                "(GEO squares, IGSO triangles, MEO circles; hollow: not tracked)",
         lambda p: F.sky_figure(p, tracks, title=title, used=tracked))


def _nav_records(path: Path | None) -> dict[int, int]:
    """Records per PRN of the RINEX 3 navigation file a run wrote (its ``SV / EPOCH / SV
    CLK`` lines, ``Cnn yyyy mm dd ...``), counted from the text."""
    out: dict[int, int] = {}
    if path is None:
        return out
    try:
        lines = Path(path).read_text(encoding="ascii", errors="replace").splitlines()
    except OSError:
        return out
    body = next((i for i, ln in enumerate(lines) if "END OF HEADER" in ln), len(lines))
    for ln in lines[body + 1:]:
        if re.match(r"C\d\d \d{4} \d\d \d\d", ln):
            out[int(ln[1:3])] = out.get(int(ln[1:3]), 0) + 1
    return out


def _navdata(sec: RunSection, run: RunFiles) -> None:
    """Navigation data decoded per satellite: the channels table and the navigation file."""
    path = run.files.get("channels")
    if path is None:
        sec.notes.append(f"no {run.stem}_channels.csv: no navigation data table")
        return
    from ..studies.tables import read_csv_table

    try:
        head, rows = read_csv_table(path)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        sec.notes.append(f"{path.name} not readable ({exc}): no navigation data table")
        return
    recs = _nav_records(run.files.get("rinex_nav"))
    cols = ["prn", "orbit", "state", "cn0_dbhz", "ephemeris_decoded", "toe", "subframes",
            "records in the navigation file"]
    out = [f'<table id="{run.stem}_scalar-navdata"><tr>'
           + "".join(f"<th>{html.escape(c)}</th>" for c in cols) + "</tr>"]
    for r in rows:
        d = dict(zip(head, r))
        try:
            prn = int(d.get("prn", ""))
        except ValueError:
            continue
        cells = [f"C{prn:02d}", orbit_type(prn), d.get("state", ""), d.get("cn0_dbhz", ""),
                 "yes" if d.get("ephemeris_decoded") == "True" else "no", d.get("toe", ""),
                 d.get("subframes", ""), str(recs.get(prn, 0))]
        out.append("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in cells)
                   + "</tr>")
    out.append("</table>")
    sec.tables.append((f"{run.stem}_scalar-navdata", "Navigation data decoded per satellite",
                       "".join(out)))
