"""Figures and tables of a scalar run, from ``STEM_pvt.csv``, ``STEM_channels.csv``, the
RINEX files it wrote and its record ``STEM_scalar_summary.json`` (the reference file and the
assistance ephemeris it used; :mod:`.run_figures` lists the figures)."""

from __future__ import annotations

import csv
import html
import math
import re
from pathlib import Path

import numpy as np

from ..constants import SECONDS_PER_WEEK, orbit_type
from ..errors import SdrDiError
from ..frames import C_e_n, llh_to_ecef
from . import figures as F
from .run_files import RunFiles, read_csv_columns, read_obs_rinex, scalar_sidecar
from .section import Drawer, RunSection, east_north, newest_mtime

__all__ = ["scalar_section"]


def scalar_section(folder: Path, run: RunFiles, redraw: bool) -> RunSection:
    """The section of a scalar run (:mod:`.run_figures`)."""
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
    newest = newest_mtime(list(run.files.values()) + [truth_path])
    draw = Drawer(folder, plot_stem, newest, redraw, sec)
    title = plot_stem
    truth = None
    if truth_path is not None and n_fix:
        from ..io.imu_files import read_truth
        from ..receiver.accuracy import solution_errors

        try:
            truth, t_week, t_sow = read_truth(truth_path)
            te, dr_e, dv_n = solution_errors(pvt_path, truth_path)
        except SdrDiError as exc:
            truth, te = None, np.zeros(0)
            sec.notes.append(f"reference file not used: {exc}")
        if te.size:
            # the PVT's formal 1-sigma of the same fixes (the times solution_errors uses)
            tf = (sol["week"][fix] - (t_week or 0)) * SECONDS_PER_WEEK + sol["sow"][fix] - (
                t_sow or 0.0)
            k = np.clip(np.searchsorted(tf, te), 0, max(tf.size - 1, 0))
            sd = {q: np.column_stack([sol[f"{q}_sd_{a}{u}"][fix][k] for a in "enu"])
                  for q, u in (("pos", "_m"), ("vel", ""))}
            # ECEF -> ENU at the first fix (a run spans a few km: the rotation differs by
            # less than 1e-3 rad over it)
            lat0, lon0 = math.radians(sol["lat_deg"][fix][0]), math.radians(
                sol["lon_deg"][fix][0])
            dr_n = dr_e @ C_e_n(lat0, lon0).T
            sp = F.Spans.of(te, None, cn0, xlabel="time since the IF start [s]")
            draw("fix-pos-error", "position error of each fix per axis (ENU) against the "
                                  "reference file, with the PVT's formal +-3 sigma",
                 lambda p: F.error_figure(p, te, dr_n, sd["pos"], quantity="position error",
                                          unit="m", spans=sp, title=title,
                                          envelope="PVT"))
            draw("fix-vel-error", "velocity error of each fix per axis (ENU) against the "
                                  "reference file, with the PVT's formal +-3 sigma",
                 lambda p: F.error_figure(p, te, dv_n, sd["vel"], quantity="velocity error",
                                          unit="m/s", spans=sp, title=title,
                                          envelope="PVT"))
            if not np.isfinite(sd["pos"]).any():
                sec.notes.append("the solution file has no sigma columns (written before "
                                 "they existed): the fix errors are drawn without an "
                                 "envelope")
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
        en = east_north(sol["lat_deg"][fix], sol["lon_deg"][fix], sol["h_m"][fix], lat0,
                         lon0)
        truth_en = None
        if truth is not None:
            truth_en = east_north(np.degrees(truth.llh[:, 0]), np.degrees(truth.llh[:, 1]),
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
