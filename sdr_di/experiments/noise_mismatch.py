"""``noise-mismatch``: every filter given the wrong Q or the wrong R (papers 000 and 003).

One run simulates the scenario's truth and IMU once (seeded) and runs the closed-loop loosely
coupled filter (:func:`sdr_di.integration.loose.run_loose`) once per filter on the same inputs
and the same GNSS noise draw, so the filters differ only in how they cope with the mismatch:

* ``case = "q"`` (paper 000): scenario ``signals/lc_paper000.toml``; the filters are given
  ``q_scale`` x the true process noise (the scenario says 16).
* ``case = "r"`` (paper 003): scenario ``signals/lc_paper003.toml``; the true GNSS noise
  variance is multiplied by the window factor during the window (the scenario says 16 x during
  500-700 s) while the filters keep ``r_scale`` x the nominal R (1).

Figures (per filter ``f``): ``f.att_deg_rmse``, ``f.att_deg_max``, ``f.vel_mps_rmse``,
``f.vel_mps_max``, ``f.pos_m_rmse``, ``f.pos_m_max`` over the run and, when the run has noise
windows, the same with ``f.win_`` over the epochs inside them; ``n_epochs``; a filter that
fails (e.g. loses positive definiteness) gets NaN figures and ``f.error``. Files: one error
CSV per filter (``errors_<f>.csv``) and ``error_norms.png`` (norms over time per filter).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from ..errors import ExperimentError, SdrDiError
from ..integration.loose import load_lc_scenario, run_loose
from ..sim.lc_inputs import make_inputs
from ..integration.noise import NoiseWindow
from ..scenario import REPO_ROOT
from . import plotting
from .entries import filter_list
from .filter_figures import QUANTITIES, STATS, filter_names_in
from .plotting import rmse_bar_plot
from .variants import nan_figures, plot_error_norms, variant_rows

__all__ = ["DESCRIPTION", "NAME", "check_params", "default_params", "plots", "run", "tables"]

NAME = "noise-mismatch"
DESCRIPTION = ("wrong Q (paper 000, q_scale) or wrong R (paper 003, noise window / r_scale) "
               "given to every filter in loosely coupled runs; RMSE/max per filter")

SCENARIOS = {"q": REPO_ROOT / "signals" / "lc_paper000.toml",
             "r": REPO_ROOT / "signals" / "lc_paper003.toml"}

#: ``None`` = the scenario's value; ``r_window``: ``"scenario"``, ``"none"`` or ``"t0,t1,f"``.
default_params: dict = {
    "case": "q",
    "scenario": None,
    "filters": "all",
    "duration_s": None,
    "q_scale": None,
    "r_scale": None,
    "r_window": "scenario",
    "plots": True,
}


def _window(text: str) -> tuple[NoiseWindow, ...] | None:
    t = str(text).strip().lower()
    if t == "scenario":
        return None
    if t == "none":
        return ()
    try:
        t0, t1, f = (float(v) for v in t.split(","))
        return (NoiseWindow(t0, t1, f),)
    except ValueError as exc:
        raise ExperimentError(f"noise-mismatch: r_window={text!r}: expected 'scenario', "
                              f"'none' or 't0,t1,factor' with t0 < t1, factor > 0 ({exc})") \
            from None


def check_params(params: dict) -> None:
    """Reject bad parameter values with :class:`~sdr_di.errors.ExperimentError`."""
    if params["case"] not in SCENARIOS:
        raise ExperimentError(f"noise-mismatch: case={params['case']!r}: expected 'q' "
                              "(wrong Q, paper 000) or 'r' (wrong R, paper 003)")
    if any(":" in f for f in filter_list(NAME, params["filters"])):
        raise ExperimentError(f"noise-mismatch: filters={params['filters']!r}: filter options "
                              "are not taken by the loosely coupled run")
    _window(params["r_window"])
    for key in ("duration_s", "q_scale", "r_scale"):
        v = params[key]
        if v is not None and (isinstance(v, (str, bool)) or not math.isfinite(v) or v <= 0):
            raise ExperimentError(f"noise-mismatch: {key}={v!r}: expected a number > 0")
    if params["scenario"] is not None and not Path(str(params["scenario"])).is_file():
        raise ExperimentError(f"noise-mismatch: scenario {params['scenario']}: no such file")


def run(params: dict, seed: int, out_dir: Path) -> dict:
    """One run: every filter on the same seeded inputs (module docstring).

    Parameters
    ----------
    params : dict
        :data:`default_params` updated by the caller.
    seed : int
        Seed of the IMU noise and the GNSS noise (replaces the scenario's seed).
    out_dir : Path
        Existing directory for ``errors_<filter>.csv`` and ``error_norms.png``.

    Returns
    -------
    dict
        Flat figures (module docstring).
    """
    check_params(params)
    path = Path(str(params["scenario"])) if params["scenario"] else SCENARIOS[params["case"]]
    sc, st = load_lc_scenario(path)
    sc = sc.with_overrides(seed=int(seed), duration_s=params["duration_s"])
    kw = {k: float(params[k]) for k in ("q_scale", "r_scale") if params[k] is not None}
    windows = _window(params["r_window"])
    if windows is not None:
        kw["noise"] = dataclasses.replace(st.noise, windows=windows)
    st = st.replace(**kw)
    truth, imu, model = make_inputs(sc, st)
    spans = [(w.t0, w.t1) for w in st.noise.windows]
    fig: dict = {"case": params["case"], "q_scale": st.q_scale, "r_scale": st.r_scale,
                 "duration_s": float(sc.duration_s)}
    series: dict = {}
    for name in filter_list(NAME, params["filters"]):
        try:
            res = run_loose(truth, imu, model, st.replace(filter=name), seed=int(seed))
        except SdrDiError as exc:
            fig.update(nan_figures(name))
            if spans:
                fig.update(nan_figures(name, "win_"))
            fig[f"{name}.error"] = f"{type(exc).__name__}: {exc}"
            continue
        m = res.metrics()
        fig["n_epochs"] = int(m["n"])
        for q, _ in QUANTITIES:
            for s in STATS:
                fig[f"{name}.{q}_{s}"] = float(m[f"{q}_{s}"])
        if spans:
            inside = np.zeros(res.t.size, bool)
            for t0, t1 in spans:
                inside |= (res.t >= t0) & (res.t <= t1)
            from ..integration.metrics import summarize

            mw = summarize(res.t[inside], res.att_err[inside], res.vel_err[inside],
                           res.pos_err[inside])
            for q, _ in QUANTITIES:
                for s in STATS:
                    fig[f"{name}.win_{q}_{s}"] = float(mw[f"{q}_{s}"])
        res.write_csv(Path(out_dir) / f"errors_{name}.csv")
        series[name] = res
    if params["plots"] and series:
        note = plotting.matplotlib_missing()
        if note is None:
            plot_error_norms(Path(out_dir) / "error_norms.png", series,
                             f"noise-mismatch case {params['case']}: error norms (seed {seed})",
                             spans)
        else:
            fig["plots_note"] = note
    return fig


def tables(stats: dict) -> dict[str, list[dict]]:
    """Table ``filters``: one row per filter, mean (and std over runs) of every figure."""
    keys = list(dict.fromkeys(k.partition(".")[2] for k, st in stats.items()
                              if k.partition(".")[0] in filter_names_in(stats)
                              and isinstance(st, dict) and "mean" in st))
    return {"filters": variant_rows(stats, keys)}


def plots(results: list[dict], out_dir: Path) -> list[Path]:
    """``rmse_by_filter.png``: mean RMSE per filter over the runs, std as error bars."""
    return rmse_bar_plot(results, out_dir, "noise-mismatch: RMSE per filter")
