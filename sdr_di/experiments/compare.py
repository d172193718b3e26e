"""``compare``: every filter (and coupling mode) on the same generated files of one scenario.

The run of a study cell (``sdr-di study``, ``docs/studies.md``): the scenario (default
``signals/default.toml``) with the cell's truth keys (``truth``, :func:`~._deep.with_truth`)
is generated once per seed, and the receiver runs on those files once per variant
(``filters`` x ``modes``, :mod:`.variants`) with the cell's filter assumptions (``assume``:
dotted keys of the assumptions file, ``imu.accel_random_walk_mps_sqrth``,
``initial_errors.att_deg``; :func:`~._deep.parse_assume`, applied as ``--assume`` is). All variants are scored over one window, from the
latest hand-over of the run plus ``settle_s`` to the end, so their figures pair.

Figures (per variant ``f``): ``f.completed``, ``f.error`` (when it failed), ``f.handover_s``,
``f.acq_after_handover``, ``f.{att_deg,vel_mps,pos_m}_{rmse,max}`` over the window (NaN when
the variant failed), ``f.nis_<block>``, ``f.nis_dof`` (one block's size) and
``f.nees_{pos,vel,att}`` over the window (the run's consistency,
:func:`~._deep.consistency_figures`; absent when the variant failed);
``t_eval_s`` (window start), ``sampling_rate_hz``. Files:
``errors_<f>.csv`` and ``error_norms.png``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from ..errors import ExperimentError
from . import plotting
from ._deep import (
    base_scenario,
    check_number,
    consistency_figures,
    generated_inputs,
    parse_assume,
    segment_metrics,
)
from .plotting import rmse_bar_plot
from .variants import (
    check_deep_options,
    loop_config,
    plot_error_norms,
    run_variants,
    variant_list,
    variant_rows,
)

__all__ = ["DESCRIPTION", "NAME", "check_params", "default_params", "plots", "run", "tables"]

NAME = "compare"
DESCRIPTION = ("every filter (and mode) on the same generated files of a scenario; RMSE/max "
               "from the hand-over + settle_s to the end")

default_params: dict = {
    "scenario": None,
    "filters": "ekf,ff-aukf",
    "modes": "deep",
    "duration_s": 30.0,
    "settle_s": 2.0,
    "sampling_rate_hz": None,
    "cn0_dbhz": None,
    "filter_rate_hz": 50.0,
    "nco_latency": None,
    "deep_measurements": None,
    "fusion_rate_hz": None,
    "output_rate_hz": 10.0,
    "gnss_rate_hz": None,
    "handover_wait_s": None,
    "truth": {},
    "assume": {},
    "plots": True,
}


def check_params(params: dict) -> None:
    """Reject bad parameter values with :class:`~sdr_di.errors.ExperimentError`."""
    check_deep_options(NAME, params)
    variant_list(NAME, params["filters"], params["modes"])
    for key in ("duration_s", "filter_rate_hz", "output_rate_hz"):
        check_number(NAME, params, key)
    check_number(NAME, params, "settle_s", lo=0.0, lo_open=False)
    check_number(NAME, params, "handover_wait_s", lo=0.0, lo_open=False, allow_none=True)
    for key in ("sampling_rate_hz", "cn0_dbhz", "gnss_rate_hz"):
        check_number(NAME, params, key, allow_none=True)
    for key in ("truth", "assume"):
        if not isinstance(params[key], dict):
            raise ExperimentError(f"{NAME}: {key}={params[key]!r}: expected a table of keys "
                                  "(a study spec's cell, or JSON)")
    parse_assume(params["assume"], f"{NAME}: assume")
    if params["settle_s"] >= params["duration_s"]:
        raise ExperimentError(f"{NAME}: settle_s must be shorter than duration_s")
    if params["scenario"] is not None and not Path(str(params["scenario"])).is_file():
        raise ExperimentError(f"{NAME}: scenario {params['scenario']}: no such file")


def run(params: dict, seed: int, out_dir: Path) -> dict:
    """One run: every variant on the same generated files (module docstring).

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
    duration = float(params["duration_s"])
    sc = base_scenario(params, seed, duration)
    fig: dict = {"duration_s": duration,
                 "truth": json.dumps(params["truth"], sort_keys=True),
                 "assume": json.dumps(params["assume"], sort_keys=True)}
    cfg = {**loop_config(params), "assume": params["assume"]}
    with generated_inputs(sc) as inp:
        fig["sampling_rate_hz"] = float(inp.source.sampling_rate_hz)
        series = run_variants(inp, variant_list(NAME, params["filters"], params["modes"]),
                              cfg, fig, out_dir)
    # one window for every variant, so that their figures pair
    t_eval = (max(r.handover_s for r in series.values()) if series else math.nan) \
        + float(params["settle_s"])
    fig["t_eval_s"] = t_eval
    for name, res in series.items():
        fig.update(segment_metrics(res, t_eval, None, f"{name}."))
        fig.update(consistency_figures(res, t_eval, None, f"{name}."))
    if params["plots"] and series:
        note = plotting.matplotlib_missing()
        if note is None:
            plot_error_norms(Path(out_dir) / "error_norms.png", series,
                             f"compare: error norms (seed {seed})",
                             [(0.0, t_eval)])
        else:
            fig["plots_note"] = note
    return fig


def tables(stats: dict) -> dict[str, list[dict]]:
    """``filters``: one row per variant (mean and std over runs)."""
    keys = ("completed", "handover_s") + tuple(f"{q}_{s}" for q in ("att_deg", "vel_mps",
                                                                    "pos_m")
                                               for s in ("rmse", "max"))
    return {"filters": variant_rows(stats, keys, std=lambda k: k.endswith(("rmse", "max")))}


def plots(results: list[dict], out_dir: Path) -> list[Path]:
    """``rmse_by_filter.png``: mean RMSE per variant over the runs, std as error bars."""
    return rmse_bar_plot(results, out_dir, "compare: RMSE per variant")
