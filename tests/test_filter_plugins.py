"""Filter entries ``NAME[:opt=value...]`` with typed options, plugin filters (register_filter,
entry points, import paths), ``sdr-di filters`` and the example filter (examples/)."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from sdr_di.cli import main
from sdr_di.errors import FilterError
from sdr_di.filters import (
    FILTER_NAMES,
    LinearProcessModel,
    make_filter,
    parse_filter_spec,
    register_filter,
    unregister_filter,
)

REPO = Path(__file__).resolve().parents[1]

PLUGIN_SRC = textwrap.dedent('''
    from sdr_di.filters import EKF

    class SameEKF(EKF):
        """An EKF subclass that changes nothing."""

    class TunedEKF(EKF):
        def __init__(self, process_model, measurement_model, x0, P0, Q0, R0=None, *,
                     scale: float = 1.0, flag: bool = False, **kwargs):
            super().__init__(process_model, measurement_model, x0, P0, Q0, R0, **kwargs)
            self.Q = self.Q * scale
            self.flag = flag

    class NoInterface:
        def __init__(self, *args, **kwargs):
            pass

    def broken_factory(*args, **kwargs):
        raise RuntimeError("plugin bug")
''')


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """A plugin module ``tmp_filters_plug`` in a temporary folder on sys.path."""
    (tmp_path / "tmp_filters_plug.py").write_text(PLUGIN_SRC)
    monkeypatch.syspath_prepend(str(tmp_path))
    return "tmp_filters_plug"


def _one_line_exit_2(capsys, argv, match):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("sdr-di: error: ") and err.count("\n") == 1, err
    assert match in err, err
    return err


# ---- typed options ---------------------------------------------------------------------------
@pytest.mark.parametrize("text, want", [
    ("ff-aukf:adapt_q=false", {"adapt_q": False}),
    ("ff-aukf:adapt_q=No:adapt_r=1", {"adapt_q": False, "adapt_r": True}),
    ("FF-AUKF:q_states=nominal:window=25:d=0.9", {"q_states": "nominal", "window": 25,
                                                  "d": 0.9}),
    ("sage-husa-ukf:forgetting=none:warmup=5", {"forgetting": None, "warmup": 5}),
    ("ukf:alpha=1e-3", {"alpha": 1e-3}),
    ("ekf", {}),
])
def test_options_take_their_parameters_types(text, want):
    spec = parse_filter_spec(text)
    assert spec.name == text.split(":")[0].lower()
    assert spec.options == want
    assert [type(v) for v in spec.options.values()] == [type(v) for v in want.values()]


@pytest.mark.parametrize("text, match", [
    ("ff-aukf:adapt_q=maybe", "expected true/false/1/0/yes/no"),
    ("ff-aukf:adapt_q=2", "expected true/false"),
    ("ff-aukf:window=2.5", "whole number"),
    ("ff-aukf:d=abc", "expected a number"),
    ("ff-aukf:q_states=some", "q_states must be 'all' or 'nominal'"),
    ("ff-aukf:window", "not key=value"),
    ("ff-aukf:window=1:window=2", "given twice"),
    ("ekf:dt=0.1", "set by the receiver"),
    ("ekf:window=3", "unknown option 'window'"),
    ("ff-aukf:s_bounds=1", "cannot be given as text"),
    ("kalman", "unknown filter"),
    ("pkg.mod", "package.module:Name"),
])
def test_bad_entries_are_filter_errors(text, match):
    with pytest.raises(FilterError, match=match):
        parse_filter_spec(text)


def test_a_false_option_reaches_the_rule_as_false():
    spec = parse_filter_spec("ff-aukf:adapt_q=false")
    kf = make_filter(spec.name, LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                     np.eye(2), **spec.options)
    assert kf.rule.adapt_q is False


# ---- run and lc take entries with options ------------------------------------------------------
@pytest.fixture(scope="module")
def short_file(if_files):
    """1 s at 2.5 MHz (``s.bin``): the session's file that test_run_diagnostics also uses."""
    return if_files(1.0, name="s").if_file


@pytest.mark.parametrize("mode", ["deep", "loose", "tight"])
def test_run_builds_the_config_from_an_entry(short_file, tmp_path, monkeypatch, mode):
    """``run --filter ff-aukf:q_states=nominal:adapt_q=false`` and ``ekf:psd_fallback=clip``:
    the configuration handed to ``run_integrated`` carries the name and the typed options."""
    import sdr_di.integration.run_integrated as rd

    seen = []

    class Stop(Exception):
        pass

    def fake_run_integrated(source, out_dir, *, config, **kw):
        seen.append(config)
        raise Stop

    monkeypatch.setattr(rd, "run_integrated", fake_run_integrated)
    for entry, name, opts in (
            ("ff-aukf:q_states=nominal:adapt_q=false", "ff-aukf",
             {"q_states": "nominal", "adapt_q": False}),
            ("ekf:psd_fallback=clip", "ekf", {"psd_fallback": "clip"})):
        with pytest.raises(Stop):
            main(["run", str(short_file), "--mode", mode, "--no-progress", "--filter", entry,
                  "--out", str(tmp_path / "o")])
        assert seen[-1].filter == name and seen[-1].filter_options == opts
        assert seen[-1].mode == mode


def test_run_refuses_a_bad_option_in_one_line_before_any_work(short_file, tmp_path, capsys):
    out = tmp_path / "o"
    _one_line_exit_2(capsys, ["run", str(short_file), "--mode", "deep", "--no-progress",
                              "--filter", "ff-aukf:adapt_q=maybe", "--out", str(out)],
                     "adapt_q='maybe': expected true/false/1/0/yes/no")
    assert not out.exists()


def test_lc_takes_options(tmp_path, capsys):
    assert main(["lc", "--filter", "ff-aukf:adapt_q=false:q_states=nominal", "--duration",
                 "3", "--out", str(tmp_path)]) == 0
    summ = json.loads((tmp_path / "default_lc_ff-aukf_summary.json").read_text())
    used = summ["assumptions"]["filter"]
    assert used["options"] == {"adapt_q": False, "q_states": "nominal"}
    assert used["spec"] == "ff-aukf:adapt_q=false:q_states=nominal"
    head = (tmp_path / "default_lc_ff-aukf.csv").read_text().splitlines()[0]
    assert "ff-aukf:adapt_q=false:q_states=nominal" in head
    _one_line_exit_2(capsys, ["lc", "--filter", "ff-aukf:adapt_q=maybe", "--out",
                              str(tmp_path / "x")], "expected true/false")


# ---- plugins ----------------------------------------------------------------------------------
def test_an_ekf_subclass_that_changes_nothing_gives_the_ekfs_numbers(plugin, tmp_path):
    """lc, 20 s: the same error series, to the last digit, and the summary names the import
    path and the class."""
    assert main(["lc", "--filter", "ekf", "--duration", "20", "--out", str(tmp_path)]) == 0
    assert main(["lc", "--filter", f"{plugin}:SameEKF", "--duration", "20", "--out",
                 str(tmp_path)]) == 0
    ekf = (tmp_path / "default_lc_ekf.csv").read_text().splitlines()
    same = (tmp_path / f"default_lc_{plugin}_SameEKF.csv").read_text().splitlines()
    assert f"filter {plugin}:SameEKF;" in same[0]
    assert same[1:] == ekf[1:] and len(ekf) > 10
    summ = json.loads((tmp_path / f"default_lc_{plugin}_SameEKF_summary.json").read_text())
    assert summ["filter"] == f"{plugin}:SameEKF"
    assert summ["assumptions"]["filter"]["class"] == f"{plugin}:SameEKF"


def test_assumptions_record_what_the_built_filter_uses(plugin, tmp_path):
    """A plugin that scales its Q: the summary's Q0 is the scaled one, not the nominal."""
    assert main(["lc", "--filter", "ekf", "--duration", "3", "--out", str(tmp_path)]) == 0
    assert main(["lc", "--filter", f"{plugin}:TunedEKF:scale=4:flag=no", "--duration", "3",
                 "--out", str(tmp_path)]) == 0
    q_ekf = json.loads((tmp_path / "default_lc_ekf_summary.json").read_text())[
        "assumptions"]["filter"]["Q0_diag"]
    used = json.loads((tmp_path / f"default_lc_{plugin}_TunedEKF_summary.json").read_text())[
        "assumptions"]["filter"]
    assert used["options"] == {"scale": 4.0, "flag": False}
    np.testing.assert_allclose(used["Q0_diag"], 4.0 * np.asarray(q_ekf), rtol=1e-12)


def test_plugin_options_are_typed_from_its_signature(plugin):
    spec = parse_filter_spec(f"{plugin}:TunedEKF:scale=2:flag=yes:psd_fallback=clip")
    assert spec.name == f"{plugin}:TunedEKF"
    assert spec.options == {"scale": 2.0, "flag": True, "psd_fallback": "clip"}
    with pytest.raises(FilterError, match="expected true/false"):
        parse_filter_spec(f"{plugin}:TunedEKF:flag=maybe")
    with pytest.raises(FilterError, match="unknown option 'gain'"):
        parse_filter_spec(f"{plugin}:TunedEKF:gain=2")


@pytest.mark.parametrize("entry, match", [
    ("no_such_plugin_module:Foo", "cannot import 'no_such_plugin_module'"),
    ("{plugin}:Missing", "has no 'Missing'"),
    ("{plugin}:NoInterface", "lacks the filter interface (predict, update, x, P, Q"),
    ("{plugin}:broken_factory", "the factory failed (RuntimeError: plugin bug)"),
])
def test_a_failing_plugin_is_one_line_and_exit_2_before_any_work(plugin, short_file, tmp_path,
                                                                  capsys, entry, match):
    out = tmp_path / "o"
    for argv in (["run", str(short_file), "--mode", "deep", "--no-progress", "--out",
                  str(out)], ["lc", "--duration", "3", "--out", str(out)]):
        _one_line_exit_2(capsys, [*argv, "--filter", entry.format(plugin=plugin)], match)
        assert not out.exists()


def test_register_filter_adds_a_name(plugin):
    import importlib

    mod = importlib.import_module(plugin)
    register_filter("same-ekf", mod.SameEKF)
    try:
        assert parse_filter_spec("Same-EKF:psd_fallback=clip").name == "same-ekf"
        kf = make_filter("same-ekf", LinearProcessModel(np.eye(2)), None, np.zeros(2),
                         np.eye(2), np.eye(2), dt=0.1)
        assert isinstance(kf, mod.SameEKF) and kf.name == "same-ekf"
        with pytest.raises(FilterError, match="built-in"):
            register_filter("ekf", mod.SameEKF)
        with pytest.raises(FilterError, match="without"):
            register_filter("a:b", mod.SameEKF)
    finally:
        unregister_filter("same-ekf")
    with pytest.raises(FilterError, match="unknown filter"):
        parse_filter_spec("same-ekf")


def test_entry_points_add_names(plugin, monkeypatch, capsys):
    import importlib.metadata

    ep = importlib.metadata.EntryPoint(name="tuned-ekf", value=f"{plugin}:TunedEKF",
                                       group="sdr_di.filters")
    real = importlib.metadata.entry_points

    def fake(**kw):
        if kw.get("group") == "sdr_di.filters":
            return importlib.metadata.EntryPoints([ep])
        return real(**kw)

    monkeypatch.setattr(importlib.metadata, "entry_points", fake)
    spec = parse_filter_spec("tuned-ekf:scale=3")
    assert spec.name == "tuned-ekf" and spec.options == {"scale": 3.0}
    kf = make_filter("tuned-ekf", LinearProcessModel(np.eye(2)), None, np.zeros(2),
                     np.eye(2), np.eye(2), dt=0.1, **spec.options)
    assert kf.name == "tuned-ekf" and np.allclose(kf.Q, 3 * np.eye(2))
    assert main(["filters"]) == 0
    assert "tuned-ekf" in capsys.readouterr().out


# ---- sdr-di filters --------------------------------------------------------------------------
def test_filters_command_lists_every_name_with_its_options(capsys):
    assert main(["filters"]) == 0
    out = capsys.readouterr().out
    names = [line.split()[0] for line in out.splitlines() if line and not line[0].isspace()]
    assert names[:len(FILTER_NAMES)] == list(FILTER_NAMES)
    block = out.split("\nff-aukf")[1].split("\nrae-aukf")[0]
    assert "paper 004 eq 26-39" in block
    for opt in ("window", "d ", "adapt_q", "q_states", "alpha"):
        assert f"    {opt}" in block
    assert "default 'all'" in block and "default True" in block


# ---- examples/ --------------------------------------------------------------------------------
def test_example_filter_inflates_q_on_large_innovations(monkeypatch):
    monkeypatch.syspath_prepend(str(REPO))
    from sdr_di.filters import LinearMeasurementModel

    spec = parse_filter_spec("examples.innovation_q_ekf:InnovationQEKF:gain=2:window=3")
    assert spec.options == {"gain": 2.0, "window": 3}
    kf = make_filter(spec.name, LinearProcessModel(np.eye(1)), LinearMeasurementModel(
        np.eye(1)), np.zeros(1), np.eye(1), 0.01 * np.eye(1), np.eye(1), **spec.options)
    kf.predict()
    kf.update(np.array([0.1]))          # small innovation: Q stays
    assert kf.Q[0, 0] == pytest.approx(0.01)
    kf.predict()
    kf.update(np.array([30.0]))         # NIS/m far above 1: Q inflated, capped at 10x
    assert kf.Q[0, 0] == pytest.approx(0.1)


def test_example_study_spec_parses_with_the_plugin(monkeypatch):
    from sdr_di.studies.spec import load_study

    monkeypatch.chdir(REPO)             # the module is found under the current folder
    spec = load_study(REPO / "examples" / "custom_filter_study.toml")
    assert spec.filters == ("ekf", "examples.innovation_q_ekf:InnovationQEKF:gain=2")


# ---- deep mode and studies --------------------------------------------------------------------
@pytest.mark.slow
def test_run_deep_with_a_plugin_by_import_path(plugin, if_files, tmp_path, capsys):
    """``run --mode deep --filter MODULE:TunedEKF:scale=2`` on 13.5 s of the session's 16 s
    file at 2.5 MHz (hand-over at about 12.2 s): the summary and the CSV header name the
    import path and the options, and the summary's Q0 is the plugin's (2x the nominal)."""
    out = tmp_path / "run"
    rc = main(["run", str(if_files(16.0).if_file), "--duration", "13.5", "--mode", "deep",
               "--no-progress", "--filter", f"{plugin}:TunedEKF:scale=2", "--out", str(out)])
    assert rc == 0, capsys.readouterr()
    summ = json.loads((out / f"default_deep_{plugin}_TunedEKF_summary.json").read_text())
    assert summ["filter"] == f"{plugin}:TunedEKF" and summ["metrics"]["n"] > 0
    used = summ["assumptions"]["filter"]
    assert used["spec"] == f"{plugin}:TunedEKF:scale=2.0"
    assert used["class"] == f"{plugin}:TunedEKF"
    from sdr_di.integration.receiver import IntegrationConfig
    from sdr_di.ins.error_model import process_noise

    imu = IntegrationConfig().imu
    q0 = np.diag(process_noise(0.02, gyro_random_walk_si=imu.gyro_random_walk_si,
                               accel_random_walk_si=imu.accel_random_walk_si,
                               gyro_bias_si=imu.gyro_bias_si, accel_bias_si=imu.accel_bias_si,
                               bias_time_s=3600.0)[:15, :15])
    np.testing.assert_allclose(used["Q0_diag"][:15], 2.0 * q0, rtol=1e-9)
    head = (out / f"default_deep_{plugin}_TunedEKF.csv").read_text().splitlines()[0]
    assert f"filter {plugin}:TunedEKF:scale=2.0," in head


def test_a_study_spec_runs_a_plugin_by_import_path(plugin, tmp_path, monkeypatch):
    """A study spec naming ``MODULE:TunedEKF:scale=3`` beside ``ekf``: the receiver gets the
    import path and the typed options, and runs.csv/cells.csv carry the entry as its label.
    The receiver runs are stand-ins (the real deep run is the test above)."""
    from sdr_di.experiments import _deep, variants
    from sdr_di.studies.study import run_study
    from sdr_di.studies.spec import load_study

    spec_path = tmp_path / "plug.toml"
    entry = f"{plugin}:TunedEKF:scale=3"
    spec_path.write_text(textwrap.dedent(f'''
        [study]
        name = "plug"
        experiment = "compare"
        filters = ["ekf", "{entry}"]
        baseline = "ekf"
        runs = 1
        [base]
        sampling_rate_hz = 2.5e6
        duration_s = 2.0
        settle_s = 0.5
    '''))
    calls = []

    def stand_in(inputs, filter_name, **kw):
        calls.append((filter_name, kw.get("filter_options")))
        return _deep.DeepRun(filter_name, None, "RuntimeError: stand-in", -1)

    monkeypatch.setattr(variants, "run_deep_variant", stand_in)
    spec = load_study(spec_path)
    assert spec.filters == ("ekf", entry)
    run_study(spec, tmp_path / "out", runs=1, workers=0)
    assert (f"{plugin}:TunedEKF", {"scale": 3.0}) in calls and ("ekf", {}) in calls
    import csv

    with open(tmp_path / "out" / "runs.csv", newline="") as fh:
        labels = {r["filter"] for r in csv.DictReader(fh)}
    assert labels == {"ekf", entry}
    bad = spec_path.read_text().replace("scale=3", "scale=big")
    spec_path.write_text(bad)
    from sdr_di.errors import StudyError

    with pytest.raises(StudyError, match="scale='big': expected a number"):
        load_study(spec_path)


# ---- tuning grids name plugins (issue 48 item 2) ----------------------------------------------
def _plugin_toy_run(params: dict, seed: int, out_dir) -> dict:
    """Stand-in for ``compare``: position RMSE ``base (1 + ln(scale / 2)^2)`` for an entry
    with a ``scale`` option (optimal at 2), ``1.5 base`` for ``ekf``; each entry parsed by
    the experiments' parser, so a grid entry must reach it with its typed options."""
    import math

    from sdr_di.experiments.entries import check_filter_entry

    rng = np.random.default_rng(seed)
    base = 1.0 + rng.random()
    fig = {}
    for entry in params["filters"].split(","):
        name, opts = check_filter_entry("toy", entry)
        k = 1.5 + 0.1 * rng.random() if name == "ekf" else \
            1 + math.log(opts.get("scale", 1.0) / 2.0) ** 2
        fig[f"{entry}.completed"] = 1
        fig[f"{entry}.handover_s"] = 12.0
        for q in ("pos_m", "vel_mps", "att_deg"):
            fig[f"{entry}.{q}_rmse"] = base * k
    return fig


def _plugin_tuning_spec(study_entry: str, grid_key: str) -> dict:
    return {"study": {"name": "plug-tune", "experiment": "test-plugin-tuning-toy", "runs": 2,
                      "filters": ["ekf", study_entry], "baseline": "ekf"},
            "tuning": {"base_seed": 7, "runs": 4, "criterion": "mean_log_pos_rmse",
                       "grid": {grid_key: {"scale": [0.5, 2.0, 8.0]}}}}


@pytest.fixture
def toy_experiment():
    from sdr_di.experiments import Experiment, register_experiment

    register_experiment(Experiment(name="test-plugin-tuning-toy", run=_plugin_toy_run,
                                   default_params={"filters": "", "modes": "deep"}))


def _fake_entry_point(monkeypatch, name: str, value: str) -> None:
    import importlib.metadata

    ep = importlib.metadata.EntryPoint(name=name, value=value, group="sdr_di.filters")
    real = importlib.metadata.entry_points
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda **kw: (
        importlib.metadata.EntryPoints([ep]) if kw.get("group") == "sdr_di.filters"
        else real(**kw)))


@pytest.mark.parametrize("how", ["import path", "entry point"])
def test_a_tuning_grid_names_a_plugin(plugin, toy_experiment, monkeypatch, tmp_path, how):
    """``[tuning.grid."MODULE:TunedEKF"]`` (and an entry-point name, written in another
    case) tunes the plugin's own ``scale`` option: the grid is checked against its
    signature, and the study picks the optimum (2) and evaluates it."""
    from sdr_di.studies.spec import parse_study
    from sdr_di.studies.study import run_study

    if how == "import path":
        entry = key = f"{plugin}:TunedEKF"
    else:
        _fake_entry_point(monkeypatch, "tuned-ekf", f"{plugin}:TunedEKF")
        entry, key = "tuned-ekf", "Tuned-EKF"
    spec = parse_study(_plugin_tuning_spec(entry, key))
    assert list(spec.tuning.grids) == [entry]          # keyed by the study's entry
    assert spec.tuning.grids[entry] == ((("scale", 0.5),), (("scale", 2.0),),
                                        (("scale", 8.0),))
    res = run_study(spec, tmp_path / "out", workers=0, render=False)
    assert res.tuning[(None, entry)].entry == f"{entry}:scale=2"
    import csv

    with open(tmp_path / "out" / "runs.csv", newline="") as fh:
        used = {r["entry"] for r in csv.DictReader(fh)}
    assert used == {"ekf", f"{entry}:scale=2"}


@pytest.mark.parametrize("grid, match", [
    ({"scale": ["big"]}, "must be a finite number"),           # typed from the signature
    ({"gain": [1.0]}, "has no option 'gain'"),
])
def test_a_plugin_grid_is_checked_against_its_signature(plugin, grid, match):
    from sdr_di.errors import StudyError
    from sdr_di.studies.spec import parse_study

    # SameEKF: EKF's signature, no **kwargs: an unknown option is refused
    entry = f"{plugin}:SameEKF" if "gain" in grid else f"{plugin}:TunedEKF"
    raw = _plugin_tuning_spec(entry, entry)
    raw["tuning"]["grid"] = {entry: grid}
    with pytest.raises(StudyError, match=match):
        parse_study(raw)


def test_a_grid_key_that_names_no_study_filter_is_refused(plugin):
    from sdr_di.errors import StudyError
    from sdr_di.studies.spec import parse_study

    raw = _plugin_tuning_spec(f"{plugin}:TunedEKF", f"{plugin}:SameEKF")
    with pytest.raises(StudyError, match="not one of the study's filters"):
        parse_study(raw)
