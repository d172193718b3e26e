"""``outage``: every satellite blocked (tunnel) for 5 s and 10 s after the deep loop took over.

One run generates the scenario once (default ``signals/default.toml``) with one full blockage
of every satellite (``[[outage]] prn = "all", blockage = true``) per entry of ``outages``
(default ``5,10`` s): the first starts at ``t_first_s`` (after the hand-over, about 12 s of
file for the default scenario), each is followed by ``gap_s`` of open sky, and the file ends
``gap_s`` after the last one. Then the receiver runs on the same files once per filter
(``filters``, default ``ff-aukf``) and coupling mode (``modes``, default ``deep``; ``loose``
and ``tight`` are labelled ``f@loose``, ``f@tight``, :mod:`.variants`). In deep mode, during a blockage the INS coasts (no channel passes the
C/N0 test, the filter only predicts) and the NCOs stay driven by the INS prediction; when the
signal returns a channel rejoins the measurement vector as soon as its C/N0 estimate and
pre-filter innovations pass again, without an acquisition search. In loose and tight mode
the scalar loops lose the signal and must find it again (the scalar receiver's recovery
from a total blockage) before the filter gets a fix or a range; ``first_good_s`` compares
the modes on that.

Figures per outage ``k``: ``o<k>.start_s``, ``o<k>.duration_s``; per filter ``f`` and
outage ``k``:

``f.o<k>.pos_m_start``
    Position error norm at the last output row before the blockage [m].
``f.o<k>.pos_m_max``, ``f.o<k>.vel_mps_max``, ``f.o<k>.att_deg_max``
    Max error norms during the blockage (the INS coasting).
``f.o<k>.pos_growth_m``
    ``pos_m_max - pos_m_start``.
``f.o<k>.all_left``
    1 when every channel was out of the measurement vector at the end of the blockage
    (the loop saw the blockage).
``f.o<k>.rejoin_s.Cxx``, ``f.o<k>.rejoin_s_max``, ``f.o<k>.rejoin_s_mean``
    Time from the signal's return to the first output row with the channel in the
    measurement vector [s] (NaN: not back before the next blockage or the end; resolution
    ``1 / output_rate_hz``).
``f.o<k>.n_rejoined``, ``f.o<k>.all_rejoined``
    Channels back within ``rejoin_limit_s``; 1 when all are.
``f.o<k>.first_good_s``
    Time to the first good solution after the tunnel: from the signal's return to the first
    output row with measurements (``n_used > 0``) and a position error norm below
    ``good_pos_m`` (default 5 m) [s] (NaN: none before the next blockage or the end).
``f.o<k>.{pos_m,vel_mps,att_deg}_{rmse,max}_after``
    Error RMSE and max from the signal's return to the next blockage (or the end).
``f.o<k>.used_after``
    Fraction of channel-rows in the measurement vector from ``rejoin_limit_s`` after the
    return to the next blockage.

and per filter ``f.completed``, ``f.error``, ``f.handover_s``, ``f.acq_after_handover``
(acquisition searches after the hand-over, from the start-up receiver's own record; 0 means
every rejoin was without an acquisition search), ``f.{q}_{rmse,max}`` over the whole run
after the hand-over.

Files: ``errors_<f>.csv`` (t, channels used, error columns), ``error_norms.png`` (error norms
over time per filter, blockages shaded) and ``channels_<f>.png`` (channels in the vector and
per-channel C/N0 estimate over time).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import ExperimentError
from . import plotting
from ._deep import (
    base_scenario,
    check_number,
    generated_inputs,
    has_mean,
    parse_list,
    segment_metrics,
    with_outages,
)
from .filter_figures import QUANTITIES, STATS
from .plotting import rmse_bar_plot
from .variants import (
    check_deep_options,
    loop_config,
    plot_error_norms,
    run_variants,
    variant_list,
    variant_rows,
)

__all__ = ["DESCRIPTION", "NAME", "check_params", "default_params", "first_good_s",
           "outage_windows", "plots", "rejoin_times", "run", "tables"]

NAME = "outage"
DESCRIPTION = ("every satellite blocked for 5 s and 10 s (tunnel) after the hand-over; INS "
               "coasting; per-channel rejoin time, error growth during and RMSE after")

default_params: dict = {
    "scenario": None,
    "filters": "ff-aukf",
    "modes": "deep",
    "outages": "5,10",
    "t_first_s": 15.0,
    "gap_s": 15.0,
    "rejoin_limit_s": 1.0,
    "good_pos_m": 5.0,
    "sampling_rate_hz": None,
    "cn0_dbhz": None,
    "filter_rate_hz": 50.0,
    "nco_latency": None,
    "deep_measurements": None,
    "fusion_rate_hz": None,
    "output_rate_hz": 50.0,
    "plots": True,
}


def check_params(params: dict) -> None:
    """Reject bad parameter values with :class:`~sdr_di.errors.ExperimentError`."""
    check_deep_options(NAME, params)
    variant_list(NAME, params["filters"], params["modes"])
    d = parse_list(f"{NAME}: outages", params["outages"], float)
    if min(d) <= 0:
        raise ExperimentError(f"{NAME}: outages={params['outages']!r}: durations must be > 0")
    for key in ("t_first_s", "gap_s", "rejoin_limit_s", "good_pos_m", "filter_rate_hz",
                "output_rate_hz"):
        check_number(NAME, params, key)
    for key in ("sampling_rate_hz", "cn0_dbhz"):
        check_number(NAME, params, key, allow_none=True)
    if params["rejoin_limit_s"] > params["gap_s"]:
        raise ExperimentError(f"{NAME}: rejoin_limit_s must not exceed gap_s")
    if params["scenario"] is not None and not Path(str(params["scenario"])).is_file():
        raise ExperimentError(f"{NAME}: scenario {params['scenario']}: no such file")


def outage_windows(durations: list[float], t_first: float, gap: float
                   ) -> tuple[list[tuple[float, float]], float]:
    """Blockage windows ``(t0, t1)`` and the file duration (``gap`` after the last one)."""
    wins, t = [], float(t_first)
    for d in durations:
        wins.append((t, t + float(d)))
        t += float(d) + gap
    return wins, wins[-1][1] + gap


def rejoin_times(t: np.ndarray, used: np.ndarray, t_back: float, t_next: float) -> np.ndarray:
    """Per channel: first ``t >= t_back`` (and ``< t_next``) with the channel used, minus
    ``t_back`` [s]; NaN when it never is.

    Parameters
    ----------
    t : (n,) output times [s];  used : (n, n_ch) bool
    t_back : signal return time;  t_next : end of the search window
    """
    sel = (t >= t_back) & (t < t_next)
    ts, us = t[sel], used[sel]
    out = np.full(used.shape[1], math.nan)
    for i in range(used.shape[1]):
        hit = np.flatnonzero(us[:, i])
        if hit.size:
            out[i] = ts[hit[0]] - t_back
    return out


def run(params: dict, seed: int, out_dir: Path) -> dict:
    """One run: every filter on the same generated files (module docstring).

    Parameters
    ----------
    params : dict
        :data:`default_params` updated by the caller.
    seed : int
        Scenario seed (IF noise, IMU errors).
    out_dir : Path
        Existing directory for the run's CSV and PNG files.

    Returns
    -------
    dict
        Flat figures (module docstring).
    """
    check_params(params)
    durs = parse_list("outages", params["outages"], float)
    wins, duration = outage_windows(durs, float(params["t_first_s"]), float(params["gap_s"]))
    limit = float(params["rejoin_limit_s"])
    sc = base_scenario(params, seed, duration)
    sc = with_outages(sc, [{"prn": "all", "start_s": t0, "end_s": t1, "blockage": True}
                           for t0, t1 in wins])
    fig: dict = {"duration_s": duration}
    for k, (t0, t1) in enumerate(wins):
        fig[f"o{k}.start_s"] = t0
        fig[f"o{k}.duration_s"] = t1 - t0
    with generated_inputs(sc) as inp:
        fig["sampling_rate_hz"] = float(inp.source.sampling_rate_hz)
        series = run_variants(
            inp, variant_list(NAME, params["filters"], params["modes"]), loop_config(params),
            fig, out_dir,
            figures=lambda name, res: _outage_figures(name, res, wins, duration, limit,
                                                      float(params["good_pos_m"])),
            failed=lambda name: {f"{name}.o{k}.all_rejoined": 0 for k in range(len(wins))})
    if params["plots"] and series:
        note = plotting.matplotlib_missing()
        if note is None:
            _plot_run(Path(out_dir), series, wins, seed)
        else:
            fig["plots_note"] = note
    return fig


def first_good_s(t: np.ndarray, n_used: np.ndarray, pos_err_m: np.ndarray, t_back: float,
                 t_next: float, good_pos_m: float) -> float:
    """Time from the signal's return ``t_back`` to the first output row (before ``t_next``)
    with measurements (``n_used > 0``) and a position error norm below ``good_pos_m`` [s];
    NaN when there is none."""
    sel = (t >= t_back) & (t < t_next) & (n_used > 0) & (pos_err_m < good_pos_m)
    hit = np.flatnonzero(sel)
    return float(t[hit[0]] - t_back) if hit.size else math.nan


def _outage_figures(name: str, res, wins: list, duration: float, limit: float,
                    good_pos_m: float) -> dict:
    fig: dict = {}
    t = res.t
    pos = np.linalg.norm(res.pos_err, axis=1)
    for k, (t0, t1) in enumerate(wins):
        p = f"{name}.o{k}."
        t_next = wins[k + 1][0] if k + 1 < len(wins) else duration + 1.0
        before = np.flatnonzero(t < t0)
        fig[p + "pos_m_start"] = float(pos[before[-1]]) if before.size else math.nan
        m = segment_metrics(res, t0, t1, "")
        for q, _ in QUANTITIES:
            fig[p + f"{q}_max"] = m[f"{q}_max"]
        fig[p + "pos_growth_m"] = fig[p + "pos_m_max"] - fig[p + "pos_m_start"]
        inside = np.flatnonzero((t >= t0) & (t < t1))
        fig[p + "all_left"] = int(inside.size > 0 and not res.used[inside[-1]].any())
        rj = rejoin_times(t, res.used, t1, t_next)
        for prn, r in zip(res.prns, rj):
            fig[p + f"rejoin_s.C{prn:02d}"] = float(r)
        fig[p + "rejoin_s_max"] = float(np.max(rj)) if np.all(np.isfinite(rj)) else math.nan
        fig[p + "rejoin_s_mean"] = (float(np.mean(rj[np.isfinite(rj)]))
                                    if np.isfinite(rj).any() else math.nan)
        ok = np.isfinite(rj) & (rj <= limit + 1e-9)
        fig[p + "n_rejoined"] = int(ok.sum())
        fig[p + "all_rejoined"] = int(ok.all())
        after = segment_metrics(res, t1, t_next, "")
        for q, _ in QUANTITIES:
            for s in STATS:
                fig[p + f"{q}_{s}_after"] = after[f"{q}_{s}"]
        fig[p + "first_good_s"] = first_good_s(t, np.asarray(res.n_used), pos, t1, t_next,
                                               good_pos_m)
        sel = (t >= t1 + limit) & (t < t_next)
        fig[p + "used_after"] = float(res.used[sel].mean()) if sel.any() else math.nan
    return fig


def _plot_run(out_dir: Path, series: dict, wins: list, seed: int) -> None:
    plot_error_norms(out_dir / "error_norms.png", series,
                     f"outage: error norms (seed {seed}; shaded: all satellites blocked)", wins)
    for n, r in series.items():
        labels = [f"C{p:02d}" for p in r.prns]
        plotting.time_series(
            out_dir / f"channels_{n}.png", {"in vector": r.t, **{lb: r.t for lb in labels}},
            [("channels in the vector", {"in vector": r.n_used}),
             ("C/N0 estimate [dB-Hz]", {lb: r.cn0_dbhz[:, i] for i, lb in enumerate(labels)})],
            title=f"outage: {n} channels (seed {seed})", spans=wins)


def tables(stats: dict) -> dict[str, list[dict]]:
    """``outages``: one row per filter and outage (mean over runs; ``*_std`` with several)."""
    rows = []
    n_out = sum(1 for k in stats if k.startswith("o") and k.endswith(".duration_s"))
    keys = ("pos_m_start", "pos_m_max", "pos_growth_m", "vel_mps_max", "att_deg_max",
            "all_left", "rejoin_s_max", "rejoin_s_mean", "n_rejoined", "all_rejoined",
            "first_good_s", "pos_m_rmse_after", "pos_m_max_after", "vel_mps_rmse_after",
            "att_deg_rmse_after", "used_after")
    for k in range(n_out):
        d = stats.get(f"o{k}.duration_s")
        for row in variant_rows(stats, keys, infix=f"o{k}.", outage=k,
                                duration_s=d["mean"] if has_mean(d) else ""):
            acq = stats.get(f"{row['filter']}.acq_after_handover")
            row["acq_after_handover"] = acq["mean"] if has_mean(acq) else ""
            rows.append(row)
    order = list(dict.fromkeys(r["filter"] for r in rows))
    rows.sort(key=lambda r: order.index(r["filter"]))
    return {"outages": rows}


def plots(results: list[dict], out_dir: Path) -> list[Path]:
    """Campaign plots: mean RMSE per filter (``rmse_by_filter.png``)."""
    return rmse_bar_plot(results, out_dir, "outage: RMSE per filter over the run")
