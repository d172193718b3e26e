"""``sdr-di study`` (issue 16): spec checking, the file cache's keys, the paired statistics,
resumption and failures on a cheap stand-in experiment (on a 2-worker Dask cluster), and
``studies/smoke.toml`` end to end (slow: real generation and receiver runs at 2.5 MHz).
"""

from __future__ import annotations

import csv
import math
import os
import sys
from pathlib import Path

import cloudpickle
import numpy as np
import pytest
from scipy import stats

from sdr_di.errors import StudyError
from sdr_di.experiments import Experiment, register_experiment
from sdr_di.studies.paired import claim_verdict, compare_pair, holm, t_interval
from sdr_di.studies.study import run_study
from sdr_di.studies.spec import load_study, parse_study

REPO = Path(__file__).resolve().parents[1]
cloudpickle.register_pickle_by_value(sys.modules[__name__])


# ---- statistics ----------------------------------------------------------------------------
def test_holm_matches_the_step_down_rule():
    p = [0.01, 0.04, 0.03, 0.005, math.nan]
    adj = holm(p)
    # sorted: 0.005 (x4), 0.01 (x3), 0.03 (x2), 0.04 (x1), running max
    assert adj[3] == pytest.approx(0.02) and adj[0] == pytest.approx(0.03)
    assert adj[2] == pytest.approx(0.06) and adj[1] == pytest.approx(0.06)
    assert math.isnan(adj[4])


def test_t_interval_is_scipys():
    x = np.array([0.3, -0.1, 0.25, 0.4, 0.05, 0.2, 0.15, 0.33])
    mean, lo, hi, p = t_interval(x, 0.95)
    ref = stats.ttest_1samp(x, 0.0)
    ci = ref.confidence_interval(0.95)
    assert (lo, hi) == pytest.approx((ci.low, ci.high)) and p == pytest.approx(ref.pvalue)
    assert mean == pytest.approx(x.mean())


def test_wins_sign_test_and_failed_runs_as_losses():
    x_b = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    x_f = np.array([0.8, 0.7, 0.9, 0.85, 0.75, 0.8, 0.9, math.nan])   # seed 7 failed
    c = compare_pair("c", "f", "b", "pos", x_f, x_b, 0.95)
    assert (c.n, c.n_pairs, c.wins, c.losses) == (8, 7, 7, 1)
    assert c.sign_p == pytest.approx(9 / 256)        # P(W >= 7 | 8, 1/2) = 0.035
    assert c.d_ci_high < 0 and c.ratio < 1
    assert claim_verdict([c], 7, 0.036, True, "log_ratio") == "holds"
    assert claim_verdict([c], 7, 0.035, True, "log_ratio") == "not shown"   # 0.0352 > 0.035
    assert claim_verdict([c], 8, 0.036, True, "log_ratio") == "not shown"
    # the baseline failing is a win for the other filter
    c2 = compare_pair("c", "f", "b", "pos", [0.5, 2.0], [math.nan, 1.0], 0.95)
    assert (c2.wins, c2.losses, c2.n_pairs) == (1, 1, 1)
    # the reverse direction
    r = compare_pair("c", "f", "b", "pos", x_b * 1.5, x_b * (1 + 0.01 * np.arange(8)), 0.95)
    assert claim_verdict([r], 7, 0.036, True, "difference") == "reversed"


# ---- spec ------------------------------------------------------------------------------------
BASE = {"study": {"name": "t", "experiment": "compare", "filters": ["ekf", "ff-aukf"],
                  "baseline": "ekf", "runs": 2}}


@pytest.mark.parametrize("patch, match", [
    ({"study": {**BASE["study"], "filters": ["ekf", "kalman"]}}, "unknown filter"),
    ({"study": {**BASE["study"], "baseline": "ukf"}}, "baseline 'ukf' is not in filters"),
    ({"study": {**BASE["study"], "colour": 1}}, "unknown key"),
    ({"cells": [{"name": "a", "filter_rate_hz": -5.0}]}, "cell 'a'.*filter_rate_hz"),
    ({"cells": [{"name": "a"}, {"name": "a"}]}, "not unique"),
    ({"cells": [{"name": "a", "modes": "deep,tight"}]}, "one coupling mode"),
    ({"claims": [{"filter": "ff-aukf", "min_wins": 7, "quantities": ["heading"]}]},
     "quantities"),
    ({"claims": [{"filter": "ukf", "min_wins": 7}]}, "two of the study's filters"),
    ({"cells": [{"name": "a", "assume": {"imu.flux": 1.0}}]}, "unknown key .flux."),
])
def test_bad_specs_are_one_line_study_errors(patch, match):
    with pytest.raises(StudyError, match=match) as info:
        parse_study({**BASE, **patch})
    assert "\n" not in str(info.value)


def test_factorial_crosses_cells_and_the_hash_ignores_runs():
    spec = parse_study({**BASE, "cells": [{"name": "a"}, {"name": "b", "cn0_dbhz": 35.0}],
                        "factorial": {"filter_rate_hz": [50.0, 10.0],
                                      "truth.imu.accel_bias_mg": [4.0, 8.0]}})
    assert len(spec.cells) == 8
    c = next(c for c in spec.cells if c.name == "b filter_rate_hz=10.0 "
             "truth.imu.accel_bias_mg=8.0")
    assert c.params["cn0_dbhz"] == 35.0 and c.params["filter_rate_hz"] == 10.0
    assert c.params["truth"] == {"imu.accel_bias_mg": 8.0}
    more = parse_study({**BASE, "study": {**BASE["study"], "runs": 9},
                        "cells": [{"name": "a"}, {"name": "b", "cn0_dbhz": 35.0}],
                        "factorial": {"filter_rate_hz": [50.0, 10.0],
                                      "truth.imu.accel_bias_mg": [4.0, 8.0]}})
    assert more.hash == spec.hash
    assert parse_study(BASE).hash != spec.hash


def test_shipped_specs_parse():
    paths = sorted((REPO / "studies").glob("*.toml"))
    assert {p.stem for p in paths} >= {"smoke", "paper004", "paper000", "paper003", "coupling"}
    for path in paths:
        spec = load_study(path)
        assert spec.cells and spec.filters and spec.claims, path


# ---- file cache keys -------------------------------------------------------------------------
def test_file_keys_depend_only_on_what_the_files_depend_on():
    from sdr_di.experiments._deep import base_scenario, file_keys

    p = {"sampling_rate_hz": 2.5e6}
    k0 = file_keys(base_scenario(p, 1, 10.0))
    imu = file_keys(base_scenario({**p, "truth": {"imu.accel_random_walk_mps_sqrth": 0.5}},
                                  1, 10.0))
    fs = file_keys(base_scenario({**p, "sampling_rate_hz": 5e6}, 1, 10.0))
    seed = file_keys(base_scenario(p, 2, 10.0))
    assert imu[0] == k0[0] and imu[1] != k0[1]          # same IF, other IMU file
    assert fs[0] != k0[0] and fs[1] == k0[1]            # other IF, same IMU file
    assert seed[0] != k0[0] and seed[1] != k0[1]


def test_cached_imu_file_is_the_generators(tmp_path):
    """The IMU file the cache makes alone (for a cell that shares another cell's IF file)
    is byte-identical to the one generate_files writes."""
    from sdr_di.experiments._deep import _cached_files, base_scenario
    from sdr_di.sim.generate import generate_files

    sc = base_scenario({"sampling_rate_hz": 2.5e6}, 3, 1.0)
    ref = generate_files(sc, tmp_path / "ref", name="run", progress=False)
    other = base_scenario({"sampling_rate_hz": 2.5e6,
                           "truth": {"imu.accel_bias_mg": 8.0}}, 3, 1.0)
    _cached_files(other, tmp_path / "cache")             # generates the IF (+ its IMU)
    paths = _cached_files(sc, tmp_path / "cache")        # same IF key: IMU made alone
    assert paths["if"].read_bytes() == ref["if"].read_bytes()
    assert paths["imu"].read_bytes() == ref["imu"].read_bytes()
    assert len([p for p in (tmp_path / "cache").glob("s3-if-*") if p.is_dir()]) == 1


# ---- the machinery on a stand-in experiment --------------------------------------------------
def _fake_run(params: dict, seed: int, out_dir) -> dict:
    """Stand-in for ``compare``: ff-aukf's RMSE is 0.8 x ekf's on every seed; cell 'bad'
    raises on ``bad_seed``; ukf diverges on ``div_seed``."""
    if params["cell"] == "bad" and seed == params["bad_seed"]:
        raise FloatingPointError("stand-in failure")
    if params["kill_once"] and seed == params["bad_seed"] and \
            not Path(params["kill_once"]).exists():
        Path(params["kill_once"]).touch()
        os._exit(3)                     # the worker dies under this task, once
    rng = np.random.default_rng(seed)
    base = 1.0 + rng.random()
    fig = {}
    for f, k in (("ekf", 1.0), ("ff-aukf", 0.8), ("ukf", 1.1)):
        fig[f"{f}.completed"] = 1
        fig[f"{f}.handover_s"] = 12.0
        for q in ("pos_m", "vel_mps", "att_deg"):
            fig[f"{f}.{q}_rmse"] = base * k * (1 + 0.01 * rng.random())
    if seed == params["div_seed"]:
        fig["ukf.completed"] = 0
        fig["ukf.pos_m_rmse"] = math.nan
    (Path(out_dir) / "note.txt").write_text(f"{seed}\n")
    return fig


FAKE = register_experiment(Experiment(
    name="test-study-fake", run=_fake_run,
    default_params={"cell": "", "bad_seed": -1, "div_seed": -1, "kill_once": "",
                    "filters": "", "modes": "deep"}))


def _fake_spec(runs: int, bad_seed: int = -1, div_seed: int = -1, **extra) -> dict:
    return {"study": {"name": "fake", "experiment": "test-study-fake", "runs": runs,
                      "filters": ["ekf", "ff-aukf", "ukf"], "baseline": "ekf", **extra},
            "base": {"bad_seed": bad_seed, "div_seed": div_seed},
            "cells": [{"name": "good", "cell": "good"}, {"name": "bad", "cell": "bad"}],
            "claims": [{"text": "ff-aukf beats ekf", "filter": "ff-aukf",
                        "quantities": ["pos", "vel"], "min_wins": 5, "max_sign_p": 0.05,
                        "interval_excludes_zero": True}]}


def _csv(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_study_machinery_failures_resumption_and_refusal(tmp_path):
    from sdr_di.studies.campaign import run_seed

    seeds = [run_seed(0, i) for i in range(6)]
    spec = parse_study(_fake_spec(6, bad_seed=seeds[2], div_seed=seeds[3]))
    out = tmp_path / "study"
    res = run_study(spec, out, runs=5, workers=2)        # a local Dask cluster
    assert res.n_run == 10 and res.n_skipped == 0
    cells = {(r["cell"], r["filter"]): r for r in _csv(out / "cells.csv")}
    runs = _csv(out / "runs.csv")
    # the failed task: every filter of (bad, seed 2) reported, the other runs kept
    failed = [r for r in runs if r["status"] == "failed"]
    assert {(r["cell"], r["seed_index"]) for r in failed} == {("bad", "2")}
    assert all("stand-in failure" in r["error"] for r in failed)
    assert cells[("bad", "ekf")]["n_ok"] == "4" and cells[("good", "ekf")]["n_ok"] == "5"
    # paired statistics: ff-aukf wins every seed it ran; the failed seed is a non-win
    assert cells[("good", "ff-aukf")]["pos_wins"] == "5"
    assert cells[("bad", "ff-aukf")]["pos_wins"] == "4"
    assert float(cells[("good", "ff-aukf")]["pos_ratio"]) == pytest.approx(0.8, rel=0.02)
    assert float(cells[("good", "ff-aukf")]["d_pos_ci_high"]) < 0
    assert cells[("good", "ff-aukf")]["claim1"] == "holds"
    assert cells[("bad", "ff-aukf")]["claim1"] == "not shown"     # 4 wins < 5
    assert cells[("good", "ekf")]["pos_best"] == "0" and cells[("good", "ff-aukf")][
        "pos_best"] == "1"
    # a diverged run is a loss and is reported
    div = [(r["cell"], r["seed_index"], r["filter"]) for r in runs if r["status"] == "diverged"]
    assert div == [("good", "3", "ukf"), ("bad", "3", "ukf")]
    assert cells[("good", "ukf")]["n_failed"] == "1"
    html = (out / "report.html").read_text()
    assert html.index("Verdict") < html.index("Summary per cell") < html.index("Plots") \
        < html.index("Raw tables")
    assert "stand-in failure" in html and "data:image/png;base64" in html
    # resumption: nothing reruns; one more seed runs only that seed
    again = run_study(spec, out, runs=5, workers=0)
    assert again.n_run == 0 and again.n_skipped == 10
    assert _csv(out / "cells.csv") == list(cells.values())
    more = run_study(spec, out, runs=6, workers=0)
    assert more.n_run == 2 and more.n_skipped == 10
    # another spec in the same folder is refused, unless forced
    other = parse_study(_fake_spec(6, bad_seed=seeds[2], div_seed=seeds[3], alpha=0.01))
    with pytest.raises(StudyError, match="different spec"):
        run_study(other, out, runs=2, workers=0)
    # forced: runs whose cell run key is unchanged are kept (alpha decides no run), a new
    # cell placed first runs alone, a cell whose parameters changed runs again
    forced = run_study(other, out, runs=2, workers=0, force=True)
    assert forced.n_run == 0 and forced.n_skipped == 4
    assert _csv(out / "runs.csv") == [r for r in runs if int(r["seed_index"]) < 2]
    edited = _fake_spec(6, bad_seed=seeds[2], div_seed=seeds[3])
    edited["cells"] = [{"name": "new", "cell": "new"}, {"name": "good", "cell": "good"},
                       {"name": "bad", "cell": "bad", "div_seed": seeds[0]}]
    third = run_study(parse_study(edited), out, runs=2, workers=0, force=True)
    assert third.n_run == 4 and third.n_skipped == 2
    kept = {(r["cell"], r["seed_index"], r["filter"]): r for r in _csv(out / "runs.csv")}
    for r in runs:
        if r["cell"] == "good" and int(r["seed_index"]) < 2:
            assert kept[("good", r["seed_index"], r["filter"])] == r
    assert kept[("bad", "0", "ukf")]["status"] == "diverged"      # its new parameter took
    # good's six seeds (kept for a later --runs 6) moved to its new index; old bad's removed
    assert sorted(p.name for p in (out / "runs").glob("*.json")) == sorted(
        [f"0_{i}.json" for i in range(2)] + [f"1_{i}.json" for i in range(6)]
        + [f"2_{i}.json" for i in range(2)])


def test_a_killed_worker_loses_only_its_task_which_runs_again_on_resume(tmp_path):
    from sdr_di.studies.campaign import run_seed

    seeds = [run_seed(0, i) for i in range(3)]
    raw = _fake_spec(3, bad_seed=seeds[1])
    raw["cells"] = [{"name": "good", "cell": "good",
                     "kill_once": str(tmp_path / "killed")}]
    spec = parse_study(raw)
    out = tmp_path / "study"
    res = run_study(spec, out, workers=2)
    lost = [r for r in res.runs if r["status"] == "failed"]
    assert {r["seed_index"] for r in lost} == {1} and "worker died" in lost[0]["error"]
    assert sum(r["status"] == "ok" for r in res.runs) == 6          # seeds 0 and 2 kept
    again = run_study(spec, out, workers=0)
    assert again.n_run == 1 and again.n_skipped == 2
    assert all(r["status"] == "ok" for r in again.runs)


# ---- studies/smoke.toml end to end -----------------------------------------------------------
@pytest.mark.slow
def test_smoke_study_end_to_end(tmp_path, monkeypatch):
    """The shipped smoke study (2 cells x 2 filters x 2 seeds, 2.5 MHz) in this process, with
    ff-aukf made to fail on one run: paired statistics in cells.csv, the failure reported and
    counted while the other runs are kept, the IF file shared by the two cells, and a second
    run of the same spec skipping every finished run."""
    from sdr_di.experiments import _deep, variants
    from sdr_di.studies.campaign import run_seed

    spec = load_study(REPO / "studies" / "smoke.toml")
    out = tmp_path / "smoke"
    cell = spec.cells[1]
    fail_seed = run_seed(spec.base_seed, 1)
    fail_imu = _deep.file_keys(_deep.base_scenario(cell.params, fail_seed,
                                                   cell.params["duration_s"]))[1]
    real = variants.run_deep_variant
    shared = []

    def flaky(inputs, filter_name, **kw):
        shared.append(Path(inputs.paths["if"]).parent.name)
        if filter_name == "ff-aukf" and inputs.paths["imu"].name == \
                f"s{fail_seed}-imu-{fail_imu}.csv":
            return _deep.DeepRun(filter_name, None, "FloatingPointError: injected", -1)
        return real(inputs, filter_name, **kw)

    monkeypatch.setattr(variants, "run_deep_variant", flaky)
    real_shared = _deep.shared_start
    hits = []

    def counted(inputs, rule):
        hits.append(real_shared(inputs, rule))
        return hits[-1]

    monkeypatch.setattr(_deep, "shared_start", counted)
    res = run_study(spec, out, runs=2, workers=0)
    assert res.n_run == 4 + 4           # the tuning tasks (baseline, 4 training seeds), then 4
    tuning = _csv(out / "tuning.csv")
    assert {r["options"] for r in tuning} == {"q_scale=1.0", "q_scale=4.0"}
    assert {r["seed"] for r in tuning} == {"mean", *(str(run_seed(1000, i)) for i in range(4))}
    assert sum(r["chosen"] == "1" for r in tuning) == 5     # the chosen point's runs + mean
    # a two-value grid: the chosen point is on its edge whichever it is
    assert {r["edge"] for r in tuning if r["chosen"] == "1"} == {"1"}
    ekf = res.tuning[(None, "ekf")].entry
    assert {(r["filter"], r["entry"]) for r in _csv(out / "runs.csv")} == {
        ("ekf", ekf), ("ff-aukf", "ff-aukf")}
    cells = {(r["cell"], r["filter"]): r for r in _csv(out / "cells.csv")}
    for cell in ("baseline", "imu-noise-10x"):
        row = cells[(cell, "ff-aukf")]
        for q, unit in (("pos", "m"), ("vel", "mps"), ("att", "deg")):
            assert math.isfinite(float(row[f"{q}_rmse_{unit}"]))
            assert row[f"d_{q}_{unit}"] != "" and row[f"{q}_wins"] != ""
        assert row["claim1"] in ("holds", "reversed", "not shown")
    runs = _csv(out / "runs.csv")
    bad = [r for r in runs if r["status"] != "ok"]
    assert [(r["cell"], r["seed_index"], r["filter"]) for r in bad] == [
        ("imu-noise-10x", "1", "ff-aukf")]
    assert "injected" in bad[0]["error"]
    assert sum(r["status"] == "ok" for r in runs) == 7
    # the spec's hand-over rule (1 s after the first fix, not the receiver's 6 s)
    assert all(6.0 < float(r["handover_s"]) < 9.0 for r in runs if r["status"] == "ok")
    assert cells[("imu-noise-10x", "ff-aukf")]["n_failed"] == "1"
    # consistency beside accuracy (issue 25): deep NIS blocks and NEES in both tables, NaN
    # for the failed run and for the other modes' blocks
    ok = [r for r in runs if r["status"] == "ok"]
    for k in ("nis_code", "nis_rate", "nees_pos", "nees_vel", "nees_att"):
        assert all(float(r[k]) > 0 for r in ok), k
        assert math.isnan(float(bad[0][k]))
        assert float(cells[("baseline", "ekf")][k]) > 0, k
    assert all(math.isnan(float(r["nis_pos"])) for r in runs)
    # the ensemble (issue 46 item 5): the ok runs, the deep blocks' bands from their size
    assert all(float(r["nis_dof"]) >= 4 for r in ok)
    for (cell, f), n in ((("baseline", "ekf"), 2), (("imu-noise-10x", "ff-aukf"), 1)):
        row = cells[(cell, f)]
        assert row["n_ensemble"] == str(n)
        for k in ("anees_pos", "anees_vel", "anees_att", "anis_code", "anis_rate"):
            assert float(row[f"{k}_lo"]) < 1 < float(row[f"{k}_hi"]), k
            assert float(row[k]) == pytest.approx(np.mean(
                [float(r[k[1:]]) for r in ok if (r["cell"], r["filter"]) == (cell, f)]))
        assert math.isnan(float(row["anis_range"])) and math.isnan(float(row["anis_pos_hi"]))
    assert math.isfinite(float(cells[("baseline", "ff-aukf")]["d_pos_ci_low"]))
    # both cells of a seed ran on one IF file (2 evaluation seeds, 4 training seeds), and the
    # second cell's task continued from the first's deep start-up (the tuning tasks and the
    # first cell of each seed ran their own)
    assert len(set(shared)) == 6
    assert [h is not None for h in hits] == [False] * 4 + [False, True, False, True]
    assert not (out / "cache").exists()
    assert "injected" in (out / "report.html").read_text()
    again = run_study(spec, out, runs=2, workers=0)
    assert again.n_run == 0 and again.n_skipped == 8


# ---- command line ----------------------------------------------------------------------------
def _run_cli(argv: list[str]) -> int:
    from sdr_di.cli import build_parser

    args = build_parser().parse_args(argv)
    return args.func(args)


@pytest.mark.parametrize("argv, msg", [
    (["study", "nope.toml"], "nope.toml: cannot read"),
    (["study", str(REPO / "studies" / "smoke.toml"), "--runs", "0"],
     "--runs must be an integer >= 1"),
    (["study", str(REPO / "studies" / "smoke.toml"), "--workers", "-1"], "--workers"),
])
def test_cli_bad_input_is_a_one_line_error_before_any_work(tmp_path, argv, msg):
    from sdr_di.errors import SdrDiError

    with pytest.raises(SdrDiError, match=msg):
        _run_cli(argv + ["--out", str(tmp_path / "o")])
    assert not (tmp_path / "o").exists()


def test_cli_refuses_a_folder_with_another_study(tmp_path, capsys):
    from sdr_di.studies.execute import write_json

    out = tmp_path / "o"
    out.mkdir()
    write_json(out / "study.json", {"hash": "0123456789abcdef"})
    with pytest.raises(StudyError, match="different spec"):
        _run_cli(["study", str(REPO / "studies" / "smoke.toml"), "--out", str(out)])
    assert sorted(p.name for p in out.iterdir()) == ["study.json"]
