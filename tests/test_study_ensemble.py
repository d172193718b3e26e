"""Ensemble verdicts of a study (issue 46 item 5): ANEES and ANIS per cell and filter with
the two-sided 95 % chi-square band for the number of runs, the report's in/out-of-band
marks, at least 4 training seeds, and the grid-edge flag of a tuned choice."""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
from scipy.stats import chi2

from sdr_di.errors import StudyError
from sdr_di.experiments import Experiment, register_experiment
from sdr_di.studies.ensemble import ENSEMBLE_COLUMNS, ensemble_consistency
from sdr_di.studies.spec import parse_study
from sdr_di.studies.study import run_study

cloudpickle.register_pickle_by_value(sys.modules[__name__])


def _band(n: int, dim: int) -> tuple[float, float]:
    """scipy's quantiles of the average of n chi-square(dim) samples, per dof."""
    lo, hi = chi2.ppf([0.025, 0.975], n * dim)
    return lo / (n * dim), hi / (n * dim)


def _row(status="ok", nees=(math.nan,) * 3, dof=math.nan, **nis):
    """A runs.csv row: NEES of position, velocity, attitude, NIS block size, NIS per block."""
    r = {"status": status, "nis_dof": dof,
         **{f"nees_{q}": v for q, v in zip(("pos", "vel", "att"), nees)}}
    r.update({f"nis_{b}": nis.get(b, math.nan) for b in ("code", "range", "rate", "vel",
                                                         "pos")})
    return r


def test_ensemble_of_known_runs_by_hand():
    """Deep runs: the ok runs with every value finite are averaged; the NIS band takes the
    median block size of those runs."""
    rows = [_row(nees=(1.0, 2.0, 0.5), dof=7, code=1.2, rate=0.8),
            _row(nees=(1.4, 2.2, 0.7), dof=7, code=0.9, rate=1.0),
            _row(nees=(1.3, 1.6, 0.6), dof=5, code=1.5, rate=0.9),
            _row(nees=(1.1, 2.0, 0.4), dof=7, code=math.nan, rate=1.1),  # no code NIS
            _row("failed"), _row("diverged", nees=(50.0, 9.0, 3.0), dof=7, code=9.0,
                                 rate=9.0)]
    got = ensemble_consistency(rows)
    assert list(got) == list(ENSEMBLE_COLUMNS)
    assert got["n_ensemble"] == 3
    assert got["anees_pos"] == pytest.approx((1.0 + 1.4 + 1.3) / 3)
    assert got["anees_vel"] == pytest.approx((2.0 + 2.2 + 1.6) / 3)
    assert got["anees_att"] == pytest.approx((0.5 + 0.7 + 0.6) / 3)
    assert got["anis_code"] == pytest.approx((1.2 + 0.9 + 1.5) / 3)
    assert got["anis_rate"] == pytest.approx((0.8 + 1.0 + 0.9) / 3)
    for q in ("pos", "vel", "att"):                      # 3 runs of a 3-dof NEES
        assert (got[f"anees_{q}_lo"], got[f"anees_{q}_hi"]) == pytest.approx(_band(3, 3),
                                                                           rel=1e-10)
    for b in ("code", "rate"):                           # median of 7, 7, 5 channels
        assert (got[f"anis_{b}_lo"], got[f"anis_{b}_hi"]) == pytest.approx(_band(3, 7),
                                                                         rel=1e-10)
    for b in ("range", "vel", "pos"):                    # not deep's blocks
        assert all(math.isnan(got[f"anis_{b}{s}"]) for s in ("", "_lo", "_hi"))


def test_ensemble_of_loose_runs_and_of_none():
    rows = [_row(nees=(0.9, 1.1, 1.0), dof=3, vel=1.3, pos=0.7),
            _row(nees=(1.1, 0.9, 1.2), dof=3, vel=0.7, pos=1.1)]
    got = ensemble_consistency(rows)
    assert got["n_ensemble"] == 2 and got["anis_vel"] == pytest.approx(1.0)
    assert (got["anis_pos_lo"], got["anis_pos_hi"]) == pytest.approx(_band(2, 3), rel=1e-10)
    assert math.isnan(got["anis_code"]) and math.isnan(got["anis_rate_lo"])
    none = ensemble_consistency([_row("failed")])
    assert none["n_ensemble"] == 0
    assert all(math.isnan(v) for k, v in none.items() if k != "n_ensemble")
    old = ensemble_consistency([{k: v for k, v in r.items() if k != "nis_dof"}
                                for r in rows])          # records without nis_dof
    assert old["anis_vel"] == pytest.approx(1.0) and math.isnan(old["anis_vel_lo"])
    assert math.isfinite(old["anees_pos_lo"])


# ---- a study on a stand-in experiment --------------------------------------------------------
def _ens_run(params: dict, seed: int, out_dir) -> dict:
    """Stand-in for ``compare`` with consistency figures: ekf consistent in position and
    velocity, pessimistic in attitude; ukf overconfident, diverging on ``div_seed``."""
    rng = np.random.default_rng(seed)
    fig = {}
    for f in ("ekf", "ukf"):
        fig[f"{f}.completed"] = int(not (f == "ukf" and seed == params["div_seed"]))
        fig[f"{f}.handover_s"] = 12.0
        for q in ("pos_m", "vel_mps", "att_deg"):
            fig[f"{f}.{q}_rmse"] = 1.0 + rng.random()
        k = 1.0 if f == "ekf" else 4.0
        fig[f"{f}.nees_pos"] = k * (0.9 + 0.2 * rng.random())
        fig[f"{f}.nees_vel"] = k * (0.9 + 0.2 * rng.random())
        fig[f"{f}.nees_att"] = 0.05 if f == "ekf" else 4.0
        fig[f"{f}.nis_code"] = k * (0.9 + 0.2 * rng.random())
        fig[f"{f}.nis_rate"] = 0.95
        fig[f"{f}.nis_dof"] = 6.0
    if seed == params["div_seed"]:
        fig["ukf.pos_m_rmse"] = math.nan
    return fig


register_experiment(Experiment(name="test-ensemble-toy", run=_ens_run,
                               default_params={"filters": "", "modes": "deep",
                                               "div_seed": -1}))


def _csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_cells_csv_and_the_report_carry_the_ensemble(tmp_path):
    from sdr_di.studies.campaign import run_seed

    spec = parse_study({"study": {"name": "ens", "experiment": "test-ensemble-toy",
                                  "runs": 5, "filters": ["ekf", "ukf"], "baseline": "ekf"},
                        "base": {"div_seed": run_seed(0, 2)},
                        "cells": [{"name": "c"}]})
    out = tmp_path / "ens"
    run_study(spec, out, workers=0)
    runs = _csv(out / "runs.csv")
    cells = {r["filter"]: r for r in _csv(out / "cells.csv")}
    for f, n in (("ekf", 5), ("ukf", 4)):                 # ukf's diverged run left out
        ok = [r for r in runs if r["filter"] == f and r["status"] == "ok"]
        assert len(ok) == n and cells[f]["n_ensemble"] == str(n)
        for k, dim in (("nees_pos", 3), ("nees_vel", 3), ("nees_att", 3), ("nis_code", 6),
                       ("nis_rate", 6)):
            assert float(cells[f]["a" + k]) == pytest.approx(
                sum(float(r[k]) for r in ok) / n)
            lo, hi = _band(n, dim)
            assert float(cells[f][f"a{k}_lo"]) == pytest.approx(lo, rel=1e-10)
            assert float(cells[f][f"a{k}_hi"]) == pytest.approx(hi, rel=1e-10)
        for k in ("anis_range", "anis_vel", "anis_pos_lo"):
            assert cells[f][k] == "nan"
    page = (out / "report.html").read_text()
    summary = page[page.index("Summary per cell"):page.index("Plots")]
    assert "<th>N (ensemble)</th>" in summary and "<td>5</td>" in summary
    assert summary.count("&#10003; consistent</span>") == 5      # ekf pos, vel, code, rate;
    #                                                              both filters' rate NIS
    assert "&#10007; pessimistic</span>" in summary              # ekf attitude
    assert summary.count("&#10007; overconfident</span>") == 4   # ukf pos, vel, att, code


# ---- tuning: 4 training seeds at least, the grid-edge flag ------------------------------------
def _tuned(**tuning) -> dict:
    return {"study": {"name": "t", "experiment": "test-ensemble-toy", "runs": 2,
                      "filters": ["ekf", "ukf"], "baseline": "ekf"},
            "tuning": {"base_seed": 7, "criterion": "mean_log_pos_rmse",
                       "grid": {"ekf": {"q_scale": [0.5, 1.0, 2.0], "r_scale": [1.0]}},
                       **tuning}}


def test_fewer_than_four_training_seeds_are_refused_and_four_is_the_default():
    with pytest.raises(StudyError, match=r"\[tuning\] runs must be an integer >= 4") as info:
        parse_study(_tuned(runs=3))
    assert "\n" not in str(info.value)
    assert parse_study(_tuned()).tuning.runs == 4
    assert parse_study(_tuned(runs=4)).tuning.runs == 4


def test_grid_edges():
    from sdr_di.studies.tuning import grid_edges

    pts = [(("q_scale", q), ("r_scale", r), ("flag", b), ("fixed", 3))
           for q in (2.0, 0.5, 1.0) for r in (1.0, 4.0, 2.0) for b in (True, False)]
    assert grid_edges((("q_scale", 1.0), ("r_scale", 2.0), ("flag", True), ("fixed", 3)),
                      pts) == ()                         # interior; bool and fixed ignored
    assert grid_edges((("q_scale", 2.0), ("r_scale", 2.0), ("flag", False), ("fixed", 3)),
                      pts) == ("q_scale (highest)",)    # by value, not written order
    assert grid_edges((("q_scale", 0.5), ("r_scale", 4.0), ("flag", True), ("fixed", 3)),
                      pts) == ("q_scale (lowest)", "r_scale (highest)")


def _train_rows(best_q: float) -> list[dict]:
    from sdr_di.studies.tuning_spec import grid_entry

    return [{"cell": "baseline", "seed_index": i, "seed": 100 + i, "status": "ok",
             "filter": grid_entry("ekf", (("q_scale", q), ("r_scale", 1.0))),
             "pos_rmse_m": 1.0 + abs(math.log(q / best_q)) + 0.01 * i}
            for q in (0.5, 1.0, 2.0) for i in range(4)]


@pytest.mark.parametrize("best_q, edge, opts", [(1.0, "0", ""),
                                                 (2.0, "1", "q_scale (highest)"),
                                                 (0.5, "1", "q_scale (lowest)")])
def test_tuning_csv_flags_a_choice_on_the_grids_edge(tmp_path, best_q, edge, opts):
    from sdr_di.studies.tables import write_table
    from sdr_di.studies.tuning import choose
    from sdr_di.studies.tuning_report import tuning_html

    t = parse_study(_tuned()).tuning
    choices, table = choose(t, _train_rows(best_q))
    assert choices[(None, "ekf")].options["q_scale"] == best_q
    assert choices[(None, "ekf")].edge == ((opts,) if opts else ())
    write_table(tmp_path, "tuning", table)
    rows = _csv(tmp_path / "tuning.csv")
    chosen = [r for r in rows if r["chosen"] == "1"]
    assert len(chosen) == 5                             # 4 training runs and the mean
    assert {(r["edge"], r["edge_options"]) for r in chosen} == {(edge, opts)}
    assert {r["edge"] for r in rows if r["chosen"] == "0"} == {""}
    page = tuning_html(tmp_path / "tuning.csv")
    assert ("on the grid's edge: " + opts in page) == (edge == "1")
