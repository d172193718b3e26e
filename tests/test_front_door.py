"""One front door (issue 48 items 1-3): ``sdr-di run`` and ``sdr_di.run`` build the same
:class:`~sdr_di.options.RunOptions`, so they write the same files and raise the same errors;
the errors are exported from ``sdr_di``; one filter-entry parser, one JSON rule, one
``IntegrationConfig`` builder.

The two-door table runs each option set through the CLI (``sdr_di.cli``, in-process: the
handler the console script calls) and through the API, on one 16 s, 2.5 MHz file of the
default scenario (the integrated modes hand over at about 12.2 s), and compares every output
file byte for byte, except the run's date in the RINEX headers and the timings in the
summary.
"""

from __future__ import annotations

import inspect
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import sdr_di
from sdr_di import cli
from sdr_di.options import RunOptions


@pytest.fixture(scope="module")
def if_file(if_files) -> Path:
    """16 s of the default scenario at 2.5 MHz, from the session's factory."""
    return if_files(16.0).if_file


def _cli(argv: list[str]):
    """The CLI's handler of ``argv`` (what ``sdr-di`` runs after parsing, before printing
    the error): its return value, or the exception it raised."""
    args = cli.build_parser().parse_args(cli.attach_negative_values(argv))
    try:
        return args.func(args)
    except sdr_di.SdrDiError as exc:
        return exc


def _as_api_names(message: str) -> str:
    """A CLI message with each flag replaced by the API argument it sets."""
    flags = {flag: arg for arg, flag in cli.RUN_FLAGS.items()}
    return re.sub(r"--[a-z][a-z-]*", lambda m: flags.get(m.group(0), m.group(0)), message)


def _outputs(folder: Path) -> dict[str, bytes]:
    """The files of a run folder, without what depends on when and how fast it ran."""
    out = {}
    for p in sorted(folder.iterdir()):
        data = p.read_bytes()
        if p.suffix == ".rnx":         # "PGM / RUN BY / DATE" holds the run's time
            data = b"".join(ln for ln in data.splitlines(keepends=True)
                            if b"PGM / RUN BY / DATE" not in ln)
        if p.name.endswith("_summary.json"):
            summ = json.loads(data)
            for key in ("profile", "wall_s"):   # (a scalar run's summary has neither)
                summ.pop(key, None)
            data = json.dumps(summ, sort_keys=True).encode()
        out[p.name] = data
    return out


#: (id, CLI arguments after the file, API keywords): one row per option set.
SAME_FILES = [
    # scalar: the sidecar's navigation file (the API passed none: 0 fixes) and --duration
    # (the API refused it in scalar mode)
    ("scalar", ["--duration", "8"], {"duration_s": 8.0}),
    # deep with filter options (the API lowercased the entry and skipped the option parser)
    ("deep-ekf-q_scale", ["--mode", "deep", "--filter", "ekf:q_scale=4", "--duration", "13.5"],
     {"mode": "deep", "filter": "ekf:q_scale=4", "duration_s": 13.5}),
]


@pytest.mark.parametrize("argv, kw", [r[1:] for r in SAME_FILES], ids=[r[0] for r in SAME_FILES])
def test_both_doors_write_the_same_files(if_file, tmp_path, argv, kw):
    rc = _cli(["run", str(if_file), *argv, "--no-progress", "--out", str(tmp_path / "cli")])
    assert rc == 0, rc
    res = sdr_di.run(if_file, out=tmp_path / "api", **kw)
    cli_files, api_files = _outputs(tmp_path / "cli"), _outputs(tmp_path / "api")
    assert sorted(api_files) == sorted(cli_files) == sorted(p.name for p in res.files.values())
    for name, data in cli_files.items():
        assert api_files[name] == data, name
    if res.mode == "scalar":            # the fixes the sidecar's navigation data allows
        assert res.metrics["n_fixes"] > 0 and res.metrics["first_fix_s"] < 8.0
        assert ".rnx" in res.inputs["ephemeris"].name      # the sidecar's RINEX file
        assert res.processed_s == pytest.approx(8.0, abs=0.1)
    else:                               # the options reached the filter
        used = json.loads(res.files["summary"].read_text())["assumptions"]["filter"]
        assert used["spec"] == "ekf:q_scale=4.0"
        assert res.metrics["n"] > 0 and res.metrics["pos_m_rmse"] < 5.0


#: (id, CLI arguments after the file, API keywords): refused before any work by both doors.
SAME_ERRORS = [
    ("bad-mode", None, {"mode": "vector"}),        # argparse's choices in the CLI
    ("filter-in-scalar", ["--filter", "ekf"], {"filter": "ekf"}),
    ("imu-and-align-in-scalar", ["--imu", "x.csv", "--align", "gnss"],
     {"imu": "x.csv", "align": "gnss"}),
    ("gnss-rate-in-deep", ["--mode", "deep", "--gnss-rate", "5"],
     {"mode": "deep", "gnss_rate_hz": 5.0}),
    ("nco-latency-in-loose", ["--mode", "loose", "--nco-latency", "1"],
     {"mode": "loose", "nco_latency": 1}),
    ("deep-measurements-in-tight", ["--mode", "tight", "--deep-measurements", "reset"],
     {"mode": "tight", "deep_measurements": "reset"}),
    ("fusion-rate-without-reset", ["--mode", "deep", "--fusion-rate", "5"],
     {"mode": "deep", "fusion_rate_hz": 5.0}),
    ("approx-pos-without-ephemeris", ["--approx-pos", "40,116,100"],
     {"approx_pos": (40.0, 116.0, 100.0)}),
    ("rate-0", ["--rate", "0"], {"rate_hz": 0.0}),
    ("iono-wait-negative", ["--mode", "loose", "--iono-wait", "-1"],
     {"mode": "loose", "iono_wait_s": -1.0}),
    ("pll-bw-unstable", ["--pll-bw", "40"], {"pll_bw_hz": 40.0}),
    ("gnss-rate-not-10-over-n", ["--mode", "tight", "--gnss-rate", "3"],
     {"mode": "tight", "gnss_rate_hz": 3.0}),
    ("filter-option-value", ["--mode", "deep", "--filter", "ekf:q_scale=big"],
     {"mode": "deep", "filter": "ekf:q_scale=big"}),
    ("filter-unknown", ["--mode", "deep", "--filter", "nosuch"],
     {"mode": "deep", "filter": "nosuch"}),
    ("filter-rate-vs-imu-rate", ["--mode", "deep", "--filter-rate", "30"],
     {"mode": "deep", "filter_rate_hz": 30.0}),
    ("fs-nan", ["--fs", "nan", "--format", "iq_int8"],
     {"sampling_rate_hz": float("nan"), "sample_format": "iq_int8"}),
    ("start-week", ["--start-week", "10000"], {"start_week": 10000}),
    ("assume-missing", ["--mode", "deep", "--assume", "nope.toml"],
     {"mode": "deep", "assume": "nope.toml"}),
]


@pytest.mark.parametrize("argv, kw", [r[1:] for r in SAME_ERRORS],
                         ids=[r[0] for r in SAME_ERRORS])
def test_both_doors_refuse_the_same_way_before_any_work(if_file, tmp_path, argv, kw):
    with pytest.raises(sdr_di.SdrDiError) as info:
        sdr_di.run(if_file, out=tmp_path / "api", **kw)
    api = info.value
    assert not (tmp_path / "api").exists()
    if argv is None:                    # the CLI's parser refuses it first
        assert isinstance(api, sdr_di.OptionsError) and isinstance(api, ValueError)
        return
    got = _cli(["run", str(if_file), *argv, "--no-progress", "--out", str(tmp_path / "cli")])
    assert isinstance(got, sdr_di.SdrDiError), got
    assert type(got) is type(api)
    assert _as_api_names(str(got)) == str(api)
    assert not (tmp_path / "cli").exists()


def test_main_prints_a_refusal_in_one_line_with_the_flag(if_file, tmp_path, capsys):
    assert cli.main(["run", str(if_file), "--pll-bw", "40", "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err == (
        "sdr-di: error: --pll-bw 40 Hz x 10 ms coherent time = 0.4 > 0.25 (unstable loop): "
        "at most 25 Hz\n")


def test_the_api_takes_filter_entries_with_options():
    """``ff-aukf:q_states=nominal`` and ``ekf:q_scale=4``: the options parsed and typed by
    the one parser, into the one configuration builder."""
    f = Path(__file__)                  # any existing file: no IF is read here
    cfg = RunOptions(f, mode="tight", filter="FF-AUKF:q_states=nominal").integration_config()
    assert (cfg.filter, cfg.filter_options, cfg.mode) == ("ff-aukf", {"q_states": "nominal"},
                                                          "tight")
    cfg = RunOptions(f, mode="deep", filter="ekf:q_scale=4").integration_config()
    assert cfg.filter == "ekf" and cfg.filter_options == {"q_scale": 4.0}


def test_scalar_mode_takes_ephemeris_and_duration(if_file, tmp_path):
    """The API refused them in scalar mode; the given file wins over the sidecar's."""
    nav = tmp_path / "given.rnx"
    opts = RunOptions(if_file, ephemeris=nav, duration_s=8.0)
    given, truth = opts.scalar_companions(opts.open_source())
    assert given == nav and truth is not None and truth.name.endswith("_truth.csv")
    sidecar_nav, _ = RunOptions(if_file).scalar_companions(opts.open_source())
    assert sidecar_nav is not None and sidecar_nav != nav
    assert RunOptions(if_file, assist=False).scalar_companions(opts.open_source())[0] is None


# ---- errors (item 3) --------------------------------------------------------------------------
def test_every_error_class_is_exported_from_sdr_di():
    import sdr_di.errors as errors

    classes = {n for n, c in vars(errors).items()
               if inspect.isclass(c) and issubclass(c, errors.SdrDiError)}
    assert classes <= set(sdr_di.__all__)
    assert all(getattr(sdr_di, n) is getattr(errors, n) for n in classes)
    for moved in ("HandoverError", "NoSatelliteError", "FormatCheckError"):
        assert moved in classes
    assert issubclass(sdr_di.OptionsError, ValueError)
    assert issubclass(sdr_di.FilterError, ValueError)


def test_help_names_only_files_of_the_repository():
    repo = Path(__file__).resolve().parents[1]
    text = sdr_di.__doc__ + sdr_di.api.__doc__
    assert "DESIGN" not in text
    for ref in re.findall(r"``((?:docs|studies|signals)/[\w./-]+)``", text):
        assert (repo / ref).exists(), ref


# ---- one of each (item 2) ---------------------------------------------------------------------
def test_non_finite_floats_are_null_in_every_json_file():
    import math

    import numpy as np

    from sdr_di.io.json_values import finite_or_nan, json_safe
    from sdr_di.studies.execute import restore_floats

    obj = {"a": math.nan, "b": [1.0, math.inf, {"c": -math.inf}], "d": np.array([np.nan, 2.0]),
           "e": np.float64(np.nan), 3: (1, "x")}
    text = json.dumps(json_safe(obj), allow_nan=False)     # strict JSON
    assert json.loads(text) == {"a": None, "b": [1.0, None, {"c": None}], "d": [None, 2.0],
                                "e": None, "3": [1, "x"]}
    back = restore_floats({"x": None, "y": "nan", "z": 1.5, "w": "inf"})
    assert math.isnan(back["x"]) and math.isnan(back["y"]) and back["z"] == 1.5
    assert back["w"] == math.inf and finite_or_nan("ekf") == "ekf"


def test_a_study_spec_parses_without_a_plotting_module():
    code = (
        "import sys\n"
        "from sdr_di.experiments import Experiment, register_experiment\n"
        "register_experiment(Experiment(name='stand-in', run=lambda p, s, o: {},\n"
        "                               default_params={'filters': '', 'modes': 'deep'}))\n"
        "from sdr_di.studies.spec import parse_study\n"
        "parse_study({'study': {'experiment': 'stand-in', 'runs': 1,\n"
        "                       'filters': ['ekf', 'ff-aukf:q_states=nominal@tight']},\n"
        "             'tuning': {'base_seed': 9, 'criterion': 'mean_pos_rmse',\n"
        "                        'grid': {'EKF': {'q_scale': [1.0, 2.0]}}}})\n"
        "print(sorted(m for m in sys.modules if 'plotting' in m or m == 'matplotlib'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_one_parser_and_one_builder():
    """The experiments' entry check and the grid keys use filters.spec; the CLI, the API and
    the experiments build IntegrationConfig with build_integration_config."""
    repo = Path(__file__).resolve().parents[1] / "sdr_di"
    assert "def parse_filter_spec" not in (repo / "experiments" / "filter_figures.py"
                                           ).read_text()
    for f in ("cli.py", "api.py", "experiments/_deep.py", "options.py"):
        assert "IntegrationConfig(" not in (repo / f).read_text(), f
    assert "imu_samples_per_interval" in (repo / "integration" / "receiver.py").read_text()
