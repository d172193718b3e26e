"""Study tuning (issue 26 item 1): the ``[tuning]`` table's checks, the choice on training
seeds, and a tuned study end to end on a cheap stand-in experiment (in this process)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from sdr_di.errors import FilterError, StudyError
from sdr_di.experiments import Experiment, register_experiment
from sdr_di.studies.campaign import run_seed
from sdr_di.experiments.entries import check_filter_entry
from sdr_di.studies.study import run_study
from sdr_di.studies.spec import parse_study
from sdr_di.studies.tuning_spec import grid_entry
from sdr_di.filters import make_filter


def _toy_run(params: dict, seed: int, out_dir) -> dict:
    """Stand-in for ``compare``: a filter's position RMSE is ``base (1 + ln(q_scale/opt)^2)``
    (optimal at q_scale = opt, 2 unless the cell says) times 1.2 for ukf; ``r_scale`` = 8
    makes the run diverge."""
    rng = np.random.default_rng(seed)
    base = 1.0 + rng.random()
    fig = {}
    for entry in params["filters"].split(","):
        name, opts = check_filter_entry("toy", entry)
        k = (1.2 if name == "ukf" else 1.0) * (
            1 + math.log(opts.get("q_scale", 1) / params["opt"]) ** 2)
        fig[f"{entry}.completed"] = int(opts.get("r_scale", 1) != 8)
        fig[f"{entry}.handover_s"] = 12.0
        for q in ("pos_m", "vel_mps", "att_deg"):
            fig[f"{entry}.{q}_rmse"] = base * k
        if opts.get("r_scale", 1) == 8:
            fig[f"{entry}.pos_m_rmse"] = math.nan
    return fig


register_experiment(Experiment(name="test-tuning-toy", run=_toy_run,
                               default_params={"filters": "", "modes": "deep", "cell": "",
                                               "opt": 2.0}))


def _spec(**tuning) -> dict:
    return {"study": {"name": "toy", "experiment": "test-tuning-toy", "runs": 3,
                      "filters": ["ekf", "ukf"], "baseline": "ekf"},
            "cells": [{"name": "a", "cell": "a"}, {"name": "b", "cell": "b"}],
            "claims": [{"text": "ukf beats ekf", "filter": "ukf", "quantities": ["pos"],
                        "min_wins": 2}],
            "tuning": {"base_seed": 7, "runs": 4, "criterion": "mean_log_pos_rmse",
                       "grid": {"ekf": {"q_scale": [0.5, 2.0, 8], "r_scale": [1.0, 8]}},
                       **tuning}}


def _csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_q_and_r_scale_are_core_options_of_every_filter():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(3, 3))
    Q0, R0 = A @ A.T + np.eye(3), np.diag([1.0, 2.0])
    for name in ("ekf", "ukf", "ckf", "ff-aukf"):
        f = make_filter(name, None, None, np.zeros(3), np.eye(3), Q0, R0, q_scale=3.0,
                        r_scale=0.5)
        assert np.allclose(f.Q, 3.0 * Q0) and np.allclose(f.R, 0.5 * R0)
        assert np.allclose(f._resolve_R(np.array([4.0, 6.0]), 2, "t"), np.diag([2.0, 3.0]))
        assert np.allclose(f._resolve_R(None, 2, "t"), 0.5 * R0)      # scaled once
        plain = make_filter(name, None, None, np.zeros(3), np.eye(3), Q0, R0)
        assert np.array_equal(plain.Q, Q0) and np.array_equal(plain.R, R0)
    with pytest.raises(FilterError, match="q_scale must be a positive number"):
        make_filter("ekf", None, None, np.zeros(3), np.eye(3), Q0, q_scale=0.0)


def test_grid_entries_carry_no_dots():
    assert grid_entry("ekf", (("q_scale", 0.5),)) == "ekf:q_scale=5e-1"
    assert grid_entry("ff-aukf:window=20@tight", (("window", 40), ("d", 0.96))) == \
        "ff-aukf:window=40:d=96e-2@tight"
    assert check_filter_entry("t", "ff-aukf:d=96e-2")[1] == {"d": 0.96}


@pytest.mark.parametrize("patch, match", [
    ({"base_seed": 0}, "training seeds overlap the evaluation seeds"),
    ({"grid": {"ff-aukf": {"window": [10, 20]}}}, "not one of the study's filters"),
    ({"grid": {"ekf": {"q_sacle": [1.0]}}}, "ekf has no option 'q_sacle'"),
    ({"grid": {"ekf": {"q_scale": ["2"]}}}, r"q_scale='2' must be a finite number"),
    ({"grid": {"ekf": {"q_scale": [1.0, 1]}}}, "duplicate values"),
    ({"criterion": "min_pos"}, "criterion must be one of"),
    ({"cells": ["c"]}, "cells must be a non-empty list"),
    ({"nis_band": [0.5, 2.0]}, "nis_column and nis_band go together"),
])
def test_bad_tuning_tables_are_one_line_study_errors(patch, match):
    with pytest.raises(StudyError, match=match) as info:
        parse_study(_spec(**patch))
    assert "\n" not in str(info.value)


def test_a_boolean_grid_of_strings_is_refused():
    raw = _spec(grid={"ff-aukf": {"adapt_q": ["false", "true"]}})
    raw["study"]["filters"] = ["ekf", "ff-aukf"]
    raw["claims"] = []
    from sdr_di.filters.spec import filter_option_info

    infos, _ = filter_option_info("ff-aukf")
    flag = next((i.name for i in infos if isinstance(i.default, bool)), None)
    if flag is None:
        pytest.skip("ff-aukf has no boolean option")
    raw["tuning"]["grid"] = {"ff-aukf": {flag: ["false", "true"]}}
    with pytest.raises(StudyError, match="TOML boolean"):
        parse_study(raw)
    raw["tuning"]["grid"] = {"ff-aukf": {flag: [False, True]}}
    assert len(parse_study(raw).tuning.grids["ff-aukf"]) == 2


def test_tuning_picks_the_optimal_grid_point_then_evaluates_it(tmp_path):
    spec = parse_study(_spec())
    assert spec.tuning is not None and spec.hash != parse_study(
        {k: v for k, v in _spec().items() if k != "tuning"}).hash
    out = tmp_path / "toy"
    res = run_study(spec, out, workers=0)
    # 2 cells x 4 training seeds + 2 cells x 3 evaluation seeds
    assert res.n_run == 8 + 6 and res.n_skipped == 0
    assert res.tuning[(None, "ekf")].entry == "ekf:q_scale=2:r_scale=1"
    tab = _csv(out / "tuning.csv")
    train = {run_seed(7, i) for i in range(4)}
    per_run = [r for r in tab if r["seed"] != "mean"]
    assert {int(r["seed"]) for r in per_run} == train
    assert len(per_run) == 2 * 4 * 6 and sum(r["seed"] == "mean" for r in tab) == 6
    chosen = {r["options"] for r in tab if r["chosen"] == "1"}
    assert chosen == {"q_scale=2.0 r_scale=1.0"}
    means = {r["options"]: float(r["score"]) for r in tab if r["seed"] == "mean"}
    assert means["q_scale=2.0 r_scale=8"] == math.inf        # diverged runs lose
    assert min(means, key=means.get) == "q_scale=2.0 r_scale=1.0"
    # evaluation: the chosen entry on the evaluation seeds, the claim follows it
    runs = _csv(out / "runs.csv")
    assert {(r["filter"], r["entry"]) for r in runs} == {("ekf", "ekf:q_scale=2:r_scale=1"),
                                                         ("ukf", "ukf")}
    assert {int(r["seed"]) for r in runs} == {run_seed(0, i) for i in range(3)}
    cells = {(r["cell"], r["filter"]): r for r in _csv(out / "cells.csv")}
    assert float(cells[("a", "ukf")]["pos_ratio"]) == pytest.approx(
        1.2 * (1 + math.log(0.5) ** 2))
    assert cells[("a", "ukf")]["claim1"] in ("reversed", "not shown")
    assert {r["against"] for r in _csv(out / "comparisons.csv")} == {"ekf"}
    html = (out / "report.html").read_text()
    assert "Tuning" in html and "q_scale=2" in html
    # item 5: 3 paired seeds give no interval worth printing; seeds as in runs.csv
    assert "interval not informative at n = 3" in html
    assert f"<td>{run_seed(0, 2)}</td>" in html and f"<td>{run_seed(7, 1)}</td>" in html
    # resumable: nothing runs again
    again = run_study(parse_study(_spec()), out, workers=0)
    assert again.n_run == 0 and again.n_skipped == 14


def test_nis_band_restricts_the_choice(tmp_path):
    from sdr_di.studies.tuning import choose

    spec = parse_study(_spec(nis_column="nis_mean", nis_band=[0.5, 2.0]))
    rows = []
    for q, rmse, nis in ((0.5, 3.0, 1.0), (2.0, 1.0, 5.0), (8, 2.0, 1.5)):
        for r in (1.0, 8):
            rows.append({"cell": "a", "seed_index": 0, "seed": 11, "status": "ok",
                         "filter": grid_entry("ekf", (("q_scale", q), ("r_scale", r))),
                         "pos_rmse_m": rmse * (1 if r == 1.0 else 2), "nis_mean": nis})
    choices, tab = choose(spec.tuning, rows)
    assert choices[(None, "ekf")].options == {"q_scale": 8, "r_scale": 1.0}
    assert choices[(None, "ekf")].constraint_met is True
    assert {r["nis_ok"] for r in tab if r["options"].startswith("q_scale=2.0")} == {0}
    # two columns: a point is eligible only when both stay in the band
    two = parse_study(_spec(nis_column=["nis_mean", "nis_rate"], nis_band=[0.5, 2.0]))
    rows2 = [{**r, "nis_rate": 3.0 if r["filter"].startswith("ekf:q_scale=8") else 1.0}
             for r in rows]
    assert choose(two.tuning, rows2)[0][(None, "ekf")].options == {"q_scale": 0.5,
                                                                   "r_scale": 1.0}
    with pytest.raises(StudyError, match="nis_column 'nis_mean' is not a runs.csv column"):
        choose(spec.tuning, [{k: v for k, v in r.items() if k != "nis_mean"} for r in rows])


def test_overlapping_seeds_are_a_one_line_cli_error_before_any_work(tmp_path):
    import subprocess
    import sys

    spec = tmp_path / "overlap.toml"
    spec.write_text('[study]\nfilters = ["ekf", "ukf"]\nruns = 2\nbase_seed = 3\n'
                    '[tuning]\nbase_seed = 3\nruns = 4\ncriterion = "mean_log_pos_rmse"\n'
                    '[tuning.grid.ekf]\nq_scale = [1.0, 2.0]\n')
    out = tmp_path / "o"
    proc = subprocess.run([sys.executable, "-m", "sdr_di.cli", "study", str(spec), "--out",
                           str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.startswith("sdr-di: error: ") and proc.stderr.count("\n") == 1
    assert "training seeds overlap the evaluation seeds" in proc.stderr
    assert not out.exists()


def test_the_smoke_spec_tunes_one_option_on_four_training_seeds():
    from sdr_di.studies.spec import load_study

    spec = load_study(Path(__file__).resolve().parents[1] / "studies" / "smoke.toml")
    t = spec.tuning
    assert t.runs == 4 and t.cells == ("baseline",)
    assert t.grids == {"ekf": ((("q_scale", 1.0),), (("q_scale", 4.0),))}


def test_per_cell_tuning_picks_each_cells_optimum(tmp_path):
    raw = _spec(per_cell=True)
    raw["cells"][1]["opt"] = 8.0                 # cell b: q_scale = 8 is optimal
    spec = parse_study(raw)
    res = run_study(spec, tmp_path / "toy", workers=0)
    assert res.tuning[("a", "ekf")].entry == "ekf:q_scale=2:r_scale=1"
    assert res.tuning[("b", "ekf")].entry == "ekf:q_scale=8:r_scale=1"
    runs = _csv(tmp_path / "toy" / "runs.csv")
    assert {(r["cell"], r["entry"]) for r in runs if r["filter"] == "ekf"} == {
        ("a", "ekf:q_scale=2:r_scale=1"), ("b", "ekf:q_scale=8:r_scale=1")}
    means = [r for r in _csv(tmp_path / "toy" / "tuning.csv") if r["seed"] == "mean"]
    assert {(r["cell"], r["options"]) for r in means if r["chosen"] == "1"} == {
        ("a", "q_scale=2.0 r_scale=1.0"), ("b", "q_scale=8 r_scale=1.0")}
    with pytest.raises(StudyError, match="per_cell = true tunes every cell"):
        parse_study(_spec(per_cell=True, cells=["a"]))


def test_ratio_bounds_of_a_two_seed_interval_do_not_overflow():
    """A Holm-corrected interval over 2 training seeds has log bounds near +-1000: the
    ratio bounds in cells.csv are inf and 0, not an OverflowError (the paper004 training
    stage stopped on it)."""
    from sdr_di.studies.paired import ratio_of_log

    assert ratio_of_log(1000.0) == math.inf and ratio_of_log(-1000.0) == 0.0
    assert ratio_of_log(math.log(2.0)) == pytest.approx(2.0)
    assert math.isnan(ratio_of_log(math.nan))


def test_mean_ratio_of_the_report_and_the_comparison_is_one_function():
    """The geometric-mean ratio of ``Comparison.ratio`` and of the HTML report's claim
    table: NaN for a non-finite mean log ratio, inf (not an OverflowError) beyond the float
    range."""
    import dataclasses

    from sdr_di.studies.paired import Comparison, mean_ratio

    assert mean_ratio(math.log(0.5)) == pytest.approx(0.5)
    assert mean_ratio(800.0) == math.inf
    assert math.isnan(mean_ratio(math.inf)) and math.isnan(mean_ratio(-math.inf))
    assert math.isnan(mean_ratio(math.nan))
    names = [f.name for f in dataclasses.fields(Comparison) if f.default is dataclasses.MISSING]
    c = Comparison(**{n: ("x" if n in ("cell", "filter", "against", "quantity") else 1.0)
                      for n in names})
    c.log_mean = 800.0
    assert c.ratio == math.inf


def test_the_cli_says_when_a_tuned_point_lies_on_the_grid_edge(tmp_path, capsys):
    """``sdr-di study`` prints each tuned entry; one on an edge of its grid (cell b's optimum
    q_scale = 8 is the grid's highest value) says so, as tuning.csv's ``edge`` does. Its
    progress bar counts the training runs too."""
    from sdr_di.cli import main

    spec = tmp_path / "toy.toml"
    spec.write_text("""
[study]
name = "toy"
experiment = "test-tuning-toy"
runs = 3
filters = ["ekf", "ukf"]
baseline = "ekf"
[[cells]]
name = "a"
cell = "a"
[[cells]]
name = "b"
cell = "b"
opt = 8.0
[tuning]
base_seed = 7
runs = 4
criterion = "mean_log_pos_rmse"
per_cell = true
grid = { ekf = { q_scale = [0.5, 2.0, 8] } }
""")
    assert main(["study", str(spec), "--out", str(tmp_path / "out"), "--workers", "0"]) == 0
    cap = capsys.readouterr()
    # the bar counts the 2 x 4 training runs beside the 2 x 3 evaluation runs
    assert "14/14" in cap.err.replace("\r", "\n").splitlines()[-1], cap.err[-300:]
    lines = [ln for ln in cap.out.splitlines() if ln.startswith("tuned:")]
    a = next(ln for ln in lines if " in a " in ln)
    b = next(ln for ln in lines if " in b " in ln)
    assert "q_scale=2" in a and "edge" not in a, a
    assert "q_scale=8" in b and "on the grid's edge: q_scale (highest)" in b, b
