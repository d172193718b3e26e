"""Experiment registry, --param parsing, the noise-mismatch experiment, single runs, reports
and the CLI handlers (through a small argparse like ``sdr_di.cli``'s)."""

from __future__ import annotations

import argparse
import json
import math

import pytest

from sdr_di.errors import ExperimentError, SdrDiError
from sdr_di.experiments import (
    experiment_names,
    get_experiment,
    noise_mismatch,
    parse_params,
    plotting,
)
from sdr_di.studies import outputs, render_report, run_experiment
from sdr_di.studies.aggregate import aggregate
from sdr_di.studies.commands import add_parsers


def _cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="sdr-di")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


# ---------------------------------------------------------------- registry and parameters

def test_registry_knows_noise_mismatch_and_rejects_unknown_names():
    assert "noise-mismatch" in experiment_names()
    exp = get_experiment("noise-mismatch")
    assert exp.run is noise_mismatch.run and exp.tables is noise_mismatch.tables
    with pytest.raises(ExperimentError, match="unknown experiment 'nope'; known: .*noise"):
        get_experiment("nope")


def test_params_are_read_as_the_defaults_types():
    exp = get_experiment("noise-mismatch")
    p = parse_params(exp, ["case=r", "duration_s=12.5", "plots=no", "q_scale=4",
                          "filters=ekf,ukf", "r_window=1,2,3"])
    assert p["case"] == "r" and p["duration_s"] == 12.5 and p["plots"] is False
    assert p["q_scale"] == 4.0 and p["filters"] == "ekf,ukf" and p["r_window"] == "1,2,3"
    assert parse_params(exp, ["duration_s=none"])["duration_s"] is None


@pytest.mark.parametrize("pair, msg", [
    ("nokey", "expected key=value"),
    ("=3", "expected key=value"),
    ("speed=3", "unknown parameter of noise-mismatch; known: case, "),
    ("plots=maybe", "plots=maybe: expected true/false"),
    ("duration_s=-3", "duration_s=-3.0: expected a number > 0"),
    ("case=x", "case='x': expected 'q'"),
    ("filters=ekf,kalman", "unknown filter.*kalman"),
    ("r_window=5,1,2", "r_window='5,1,2': expected 'scenario', 'none' or 't0,t1,factor'"),
    ("scenario=/no/such.toml", "no such file"),
])
def test_bad_params_raise_one_line_errors(pair, msg):
    with pytest.raises(ExperimentError, match=msg) as info:
        parse_params(get_experiment("noise-mismatch"), [pair])
    assert "\n" not in str(info.value)


def test_compare_handover_wait_reaches_the_receivers_configuration():
    """``handover_wait_s`` (compare, and a study's ``[base]``) becomes the receiver's hand-over
    rule; a negative value is refused before any run."""
    from sdr_di.experiments import compare
    from sdr_di.experiments.variants import loop_config
    from sdr_di.integration.receiver import IntegrationConfig

    exp = get_experiment("compare")
    p = parse_params(exp, ["handover_wait_s=1.5"])
    assert p["handover_wait_s"] == 1.5
    assert IntegrationConfig(**loop_config(p)).handover_wait_s == 1.5
    assert "handover_wait_s" not in loop_config(parse_params(exp, []))   # receiver's default
    with pytest.raises(ExperimentError, match="handover_wait_s=-1.0: expected a number >= 0"):
        compare.check_params(parse_params(exp, ["handover_wait_s=-1"]))


@pytest.mark.parametrize("name", ["compare", "count-change", "outage", "weak-signal",
                                  "jamming"])
def test_nco_latency_parameter_of_every_deep_experiment(name):
    """``nco_latency`` (a study cell's parameter) becomes the deep loop's setting; absent, the
    receiver's default stays; anything but 0 or 1 is refused before any run."""
    from sdr_di.experiments.variants import loop_config
    from sdr_di.integration.receiver import IntegrationConfig

    exp = get_experiment(name)
    p = parse_params(exp, ["nco_latency=1"])
    exp.check_params(p)
    assert IntegrationConfig(**loop_config(p)).nco_latency == 1
    assert "nco_latency" not in loop_config(parse_params(exp, []))
    for bad in ("2", "true", "0.5"):
        with pytest.raises(ExperimentError, match=f"{name}: nco_latency=.*expected 0 or 1"):
            exp.check_params(parse_params(exp, [f"nco_latency={bad}"]))


def test_nco_latency_goes_to_deep_variants_only(monkeypatch):
    """One experiment with ``nco_latency=1`` and modes ``deep,loose``: the deep variant's
    configuration gets it, the loose one's does not (it would be refused: no NCOs)."""
    from sdr_di.experiments._deep import run_deep_variant
    from sdr_di.integration import settings

    made = []

    def recorder(**kw):
        made.append(kw)
        raise ValueError("recorded")

    # the one builder (build_integration_config) makes every configuration
    monkeypatch.setattr(settings, "IntegrationConfig", recorder)
    for mode in ("deep", "loose"):
        dr = run_deep_variant(None, "ekf", mode=mode, nco_latency=1, filter_rate_hz=50.0)
        assert dr.error == "OptionsError: recorded"
    assert made[0] == {"filter": "ekf", "filter_options": {}, "nco_latency": 1,
                       "filter_rate_hz": 50.0}
    assert made[1] == {"filter": "ekf", "filter_options": {}, "mode": "loose",
                       "filter_rate_hz": 50.0}


def test_aggregate_statistics_and_nonfinite_values():
    st = aggregate([{"a": 1.0, "b": "x", "c": math.nan}, {"a": 3.0, "b": "x", "c": 2.0},
                    {"a": 2, "b": "y", "c": 4.0}])
    assert st["a"] == {"n": 3, "n_nonfinite": 0, "mean": 2.0, "std": 1.0, "min": 1.0,
                       "max": 3.0}
    assert st["b"] == {"value": "(varies)"}
    assert st["c"]["n"] == 2 and st["c"]["n_nonfinite"] == 1 and st["c"]["mean"] == 3.0


# ---------------------------------------------------------------- noise-mismatch behaviour

def test_noise_window_raises_the_errors_of_a_filter_that_keeps_nominal_r(tmp_path):
    base = {"case": "r", "duration_s": 14.0, "filters": "ekf", "plots": False}
    figs = {}
    for w in ("none", "4,12,400"):
        out = tmp_path / w.replace(",", "_")
        out.mkdir()
        figs[w] = noise_mismatch.run({**noise_mismatch.default_params, **base, "r_window": w},
                                     5, out)
        assert (out / "errors_ekf.csv").is_file()
    assert "ekf.win_pos_m_rmse" in figs["4,12,400"] and "ekf.win_pos_m_rmse" not in figs["none"]
    assert figs["4,12,400"]["ekf.pos_m_rmse"] > 1.5 * figs["none"]["ekf.pos_m_rmse"]
    assert figs["4,12,400"]["r_scale"] == 1.0 and figs["none"]["n_epochs"] == 14


def test_wrong_q_case_uses_the_paper000_q_scale_and_seed_changes_the_result(tmp_path):
    p = {**noise_mismatch.default_params, "duration_s": 5.0, "filters": "ukf", "plots": False}
    a = noise_mismatch.run(p, 1, tmp_path)
    b = noise_mismatch.run(p, 2, tmp_path)
    assert a["q_scale"] == 16.0 and a["case"] == "q"
    assert a["ukf.pos_m_rmse"] != b["ukf.pos_m_rmse"]
    assert a == noise_mismatch.run(p, 1, tmp_path)


# ---------------------------------------------------------------- single run and report

def test_robustness_command_writes_tables_plots_and_a_self_contained_report(tmp_path, capsys):
    out = tmp_path / "r"
    rc = _cli(["robustness", "noise-mismatch", "--duration", "5", "--seed", "4", "--out",
               str(out), "--param", "filters=ekf,ml-q-ukf"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "ml-q-ukf.pos_m_rmse" in text and "report.html" in text
    for name in ("result.json", "figures.csv", "figures.md", "filters.csv", "filters.md",
                 "errors_ekf.csv", "error_norms.png", "rmse_by_filter.png", "report.html"):
        assert (out / name).is_file(), name
    page = (out / "report.html").read_text()
    assert page.count("<table>") == 2 and page.count("data:image/png;base64,") == 2
    assert "<td>ml-q-ukf</td>" in page and "src=\"http" not in page
    assert not list(out.glob("*.part"))


def test_plots_are_skipped_with_a_note_without_matplotlib(tmp_path, monkeypatch):
    monkeypatch.setattr(plotting, "matplotlib_missing", lambda: plotting.PLOTS_SKIPPED)
    assert outputs.plotting is plotting
    res = run_experiment("noise-mismatch", {"duration_s": 3.0, "filters": "ekf"}, 1,
                         out_dir=tmp_path)
    assert res.ok and res.record["figures"]["plots_note"] == plotting.PLOTS_SKIPPED
    assert not list(tmp_path.glob("*.png"))
    meta = json.loads((tmp_path / "result.json").read_text())
    assert plotting.PLOTS_SKIPPED in meta["notes"]
    page = render_report(tmp_path).read_text()
    assert "matplotlib is not installed" in page and "no plots in this folder" in page


def test_report_of_a_folder_without_results_is_an_error(tmp_path):
    with pytest.raises(ExperimentError, match="not an experiment output folder"):
        render_report(tmp_path)
    with pytest.raises(ExperimentError):
        _cli(["report", str(tmp_path)])


# ---------------------------------------------------------------- CLI errors

@pytest.mark.parametrize("argv, msg", [
    (["campaign", "nope", "--runs", "2"], "unknown experiment 'nope'"),
    (["campaign", "noise-mismatch", "--runs", "0"], "runs must be an integer >= 1"),
    (["campaign", "noise-mismatch", "--runs", "2", "--param", "x=1"], "unknown parameter"),
    (["campaign", "noise-mismatch", "--runs", "2", "--duration", "0"], "--duration must be"),
    (["campaign", "noise-mismatch", "--runs", "2", "--seed", "-1"], "--seed must be >= 0"),
    (["robustness", "noise-mismatch", "--param", "case"], "expected key=value"),
    (["robustness", "noise-mismatch", "--seed", "-2"], "seed must be an integer >= 0"),
])
def test_cli_bad_input_raises_sdr_di_errors(tmp_path, argv, msg):
    with pytest.raises(SdrDiError, match=msg):
        _cli(argv + ["--out", str(tmp_path / "o")])
    assert not (tmp_path / "o").exists()


def test_cli_parser_rejects_missing_runs():
    with pytest.raises(SystemExit):
        _cli(["campaign", "noise-mismatch"])
