"""``count-change``: the visible-satellite count follows a schedule (paper 004 Fig. 9).

One run generates the scenario once (default ``signals/default.toml``, 7 satellites) with a
blockage schedule that makes the number of visible satellites follow ``counts`` (default
``7,6,5,4,5,6,7``): from ``t_start_s`` on, segment ``i`` lasts ``segment_s`` (the last one to
the end of the file) and shows the ``counts[i]`` satellites of highest elevation at the start;
the others are blocked (``[[outage]] blockage = true`` per PRN, so a satellite leaves and
comes back as a whole signal, as behind a building). Then the receiver runs on the same
files once per filter (``filters``, default ``ekf,rae-aukf,ff-aukf``) and coupling mode
(``modes``, default ``deep``; ``loose``, ``tight``: :mod:`.variants` for the labels,
``ekf@tight``): the variants differ only in how they cope with the changing measurement
dimension ``N_k``. A schedule below 4 (``counts = "7,5,3,2,3,5,7"``) separates the
couplings: with 3 satellites the WLS fix of ``loose`` is gone (no update, the INS coasts)
while ``tight`` and ``deep`` keep updating with the ranges they have (``f.seg<i>.updating``).

``t_start_s`` must be after the deep receiver's hand-over (about 12 s of file for the default
scenario: scalar acquisition, tracking and the first decoded D1 subframe); a run whose
hand-over comes later reports ``f.through_all`` = 0.

Figures (per filter ``f``):

``f.completed``
    1 when the run ended without an exception and with finite errors at every output row.
``f.through_all``
    1 when it also took over before the schedule and has output rows with finite errors in
    every count segment: the filter ran through every count change without error.
``f.error``
    The exception text (only when it failed).
``f.handover_s``
    Hand-over time [s].
``f.{att_deg,vel_mps,pos_m}_{rmse,max}``
    RMSE (sqrt of mean squared norm) and max of the error norms over the schedule
    (``t_start_s`` to the end).
``f.seg<i>.{...}_{rmse,max}``
    The same over count segment ``i`` (its count is the figure ``seg<i>.count``).
``f.seg<i>.updating``
    Fraction of the segment's output rows at which the filter had measurements
    (``n_used > 0``).
``f.count_match``
    Fraction of output rows in the schedule where the filter's measurement vector held
    exactly the scheduled count of channels (the deep loop's channel management following
    the blockage; a channel is dropped once its C/N0 estimate falls, so the first rows after
    a change may differ).
``f.acq_after_handover``
    Acquisition searches run after the hand-over (expected 0: blocked channels stay driven
    by the INS).

Files: ``errors_<f>.csv`` (t, n_used, scheduled count, error columns), ``error_norms.png``
(error norms over time per filter, blocked segments shaded) and ``satellite_count.png``
(scheduled count and channels in each filter's measurement vector over time).
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
    ranked_prns,
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

__all__ = ["DESCRIPTION", "NAME", "check_params", "default_params", "plots", "run",
           "schedule", "tables"]

NAME = "count-change"
DESCRIPTION = ("visible-satellite count following a schedule (7-6-5-4-5-6-7, paper 004 "
               "Fig. 9) by blockage; deep receiver per filter; RMSE/max overall and per "
               "count segment")

#: ``None`` = the scenario's value (``duration_s``: ``t_start_s + len(counts) * segment_s``).
default_params: dict = {
    "scenario": None,
    "filters": "ekf,rae-aukf,ff-aukf",
    "modes": "deep",
    "counts": "7,6,5,4,5,6,7",
    "t_start_s": 15.0,
    "segment_s": 10.0,
    "duration_s": None,
    "sampling_rate_hz": None,
    "cn0_dbhz": None,
    "filter_rate_hz": 50.0,
    "nco_latency": None,
    "deep_measurements": None,
    "fusion_rate_hz": None,
    "output_rate_hz": 10.0,
    "plots": True,
}


def _duration(params: dict, n_seg: int) -> float:
    if params["duration_s"] is not None:
        return float(params["duration_s"])
    return float(params["t_start_s"]) + n_seg * float(params["segment_s"])


def check_params(params: dict) -> None:
    """Reject bad parameter values with :class:`~sdr_di.errors.ExperimentError`."""
    check_deep_options(NAME, params)
    variant_list(NAME, params["filters"], params["modes"])
    counts = parse_list(f"{NAME}: counts", params["counts"], int)
    if min(counts) < 1:
        raise ExperimentError(f"{NAME}: counts={params['counts']!r}: every count must be >= 1")
    for key in ("t_start_s", "segment_s", "filter_rate_hz", "output_rate_hz"):
        check_number(NAME, params, key)
    for key in ("duration_s", "sampling_rate_hz", "cn0_dbhz"):
        check_number(NAME, params, key, allow_none=True)
    if params["duration_s"] is not None and params["duration_s"] <= (
            params["t_start_s"] + (len(counts) - 1) * params["segment_s"]):
        raise ExperimentError(f"{NAME}: duration_s={params['duration_s']:g} ends before the "
                              "last count segment starts")
    if params["scenario"] is not None and not Path(str(params["scenario"])).is_file():
        raise ExperimentError(f"{NAME}: scenario {params['scenario']}: no such file")


def schedule(prns: list[int], counts: list[int], t_start: float, segment: float,
             duration: float) -> tuple[list[tuple[float, float, int]], list[dict]]:
    """Count segments and the blockage entries that realize them.

    Parameters
    ----------
    prns : list of int
        Simulated PRNs, the ones to keep longest first (highest elevation).
    counts : list of int
        Visible count per segment.
    t_start, segment, duration : float
        Schedule start, segment length and file length [s]; the last segment runs to the end.

    Returns
    -------
    segments : list of (t0, t1, count)
    outages : list of dict
        ``[[outage]]`` tables (``prn``, ``start_s``, ``end_s``, ``blockage``), one per
        contiguous blocked window of each PRN.

    Raises
    ------
    ExperimentError
        A count above the number of simulated satellites.
    """
    if max(counts) > len(prns):
        raise ExperimentError(f"{NAME}: counts go up to {max(counts)} but the scenario "
                              f"simulates {len(prns)} satellites")
    segs = []
    for i, c in enumerate(counts):
        t0 = t_start + i * segment
        t1 = duration if i == len(counts) - 1 else t0 + segment
        segs.append((t0, t1, c))
    outages = []
    for rank, prn in enumerate(prns):
        open_t0 = None
        for t0, t1, c in segs:
            blocked = rank >= c
            if blocked and open_t0 is None:
                open_t0 = t0
            if not blocked and open_t0 is not None:
                outages.append({"prn": prn, "start_s": open_t0, "end_s": t0, "blockage": True})
                open_t0 = None
        if open_t0 is not None:
            outages.append({"prn": prn, "start_s": open_t0, "end_s": max(duration, open_t0 + 1),
                            "blockage": True})
    return segs, outages


def _scheduled_count(t: np.ndarray, segs: list, n_all: int) -> np.ndarray:
    out = np.full(t.size, n_all, int)
    for t0, t1, c in segs:
        out[(t >= t0) & (t < t1)] = c
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
    counts = parse_list("counts", params["counts"], int)
    t_start, seg_len = float(params["t_start_s"]), float(params["segment_s"])
    duration = _duration(params, len(counts))
    sc = base_scenario(params, seed, duration)
    prns = ranked_prns(sc)
    segs, outages = schedule(prns, counts, t_start, seg_len, duration)
    sc = with_outages(sc, outages)
    fig: dict = {"duration_s": duration, "n_satellites": len(prns),
                 "counts": ",".join(str(c) for c in counts),
                 "blocked_first": ",".join(f"C{p:02d}" for p in prns[::-1])}
    for i, (t0, t1, c) in enumerate(segs):
        fig[f"seg{i}.count"] = c
        fig[f"seg{i}.t0_s"] = t0
    cfg = loop_config(params)

    def seg_figures(name: str, res) -> dict:
        out: dict = {}
        through = bool(fig[f"{name}.completed"]) and res.handover_s < t_start
        for i, (t0, t1, _) in enumerate(segs):
            m = segment_metrics(res, t0, t1, f"{name}.seg{i}.")
            out.update(m)
            through = through and all(math.isfinite(v) for v in m.values())
            sel = (res.t >= t0) & (res.t < t1)
            out[f"{name}.seg{i}.updating"] = (float(np.mean(res.n_used[sel] > 0))
                                              if sel.any() else math.nan)
        out[f"{name}.through_all"] = int(through)
        sched = _scheduled_count(res.t, segs, len(res.prns))
        inside = res.t >= t_start
        out[f"{name}.count_match"] = (float(np.mean(res.n_used[inside] == sched[inside]))
                                      if inside.any() else math.nan)
        return out

    with generated_inputs(sc) as inp:
        fig["sampling_rate_hz"] = float(inp.source.sampling_rate_hz)
        series = run_variants(
            inp, variant_list(NAME, params["filters"], params["modes"]), cfg, fig, out_dir,
            window=(t_start, None), figures=seg_figures,
            failed=lambda name: {f"{name}.through_all": 0},
            csv_extra=lambda res: {"scheduled_count": _scheduled_count(res.t, segs,
                                                                       len(res.prns))})
    if params["plots"] and series:
        note = plotting.matplotlib_missing()
        if note is None:
            _plot_run(Path(out_dir), series, segs, len(prns), seed)
        else:
            fig["plots_note"] = note
    return fig


def _plot_run(out_dir: Path, series: dict, segs: list, n_all: int, seed: int) -> None:
    spans = [(t0, t1) for t0, t1, c in segs if c < n_all]
    plot_error_norms(out_dir / "error_norms.png", series,
                     f"count-change: error norms (seed {seed}; shaded: fewer satellites)",
                     spans)
    t_any = next(iter(series.values())).t
    t_by = {"scheduled": t_any, **{n: r.t for n, r in series.items()}}
    counts = {"scheduled": _scheduled_count(t_any, segs, n_all),
              **{n: r.n_used for n, r in series.items()}}
    plotting.time_series(out_dir / "satellite_count.png", t_by,
                         [("satellites (visible / in the vector)", counts)],
                         title=f"count-change: satellite count (seed {seed})", spans=spans)


def tables(stats: dict) -> dict[str, list[dict]]:
    """``filters``: one row per filter (overall figures, flags); ``segments``: one row per
    filter and count segment (mean over runs)."""
    n_seg = sum(1 for k in stats if k.startswith("seg") and k.endswith(".count"))
    rows = variant_rows(stats, ("completed", "through_all", "handover_s", "count_match",
                                "acq_after_handover")
                        + tuple(f"{q}_{s}" for q, _ in QUANTITIES for s in STATS),
                        std=lambda k: k.endswith(("rmse", "max")))
    seg_rows = []
    for i in range(n_seg):
        c = stats.get(f"seg{i}.count")
        seg_rows += variant_rows(stats, tuple(f"{q}_{s}" for q, _ in QUANTITIES for s in STATS)
                                 + ("updating",), infix=f"seg{i}.", std=lambda k: False,
                                 segment=i, count=c["mean"] if has_mean(c) else "")
    order = [r["filter"] for r in rows]
    seg_rows.sort(key=lambda r: order.index(r["filter"]))
    return {"filters": rows, "segments": seg_rows}


def plots(results: list[dict], out_dir: Path) -> list[Path]:
    """``rmse_by_filter.png``: mean RMSE per filter over the runs, std as error bars."""
    return rmse_bar_plot(results, out_dir, "count-change: RMSE per filter over the schedule")
