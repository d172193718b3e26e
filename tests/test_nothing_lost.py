"""Issue 49, "Nothing lost, nothing misleading": one test (or a few) per numbered item.

Every case runs the CLI in-process on a 0.02 s, 2.5 MHz set (``small_set``) or on inputs
made here; none tracks a signal, so the module takes seconds.
"""

from __future__ import annotations

import dataclasses
import gzip
import json
import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

import sdr_di
from sdr_di.cli import main
from sdr_di.errors import SdrDiError
from sdr_di.scenario import DEFAULT_SCENARIO, REPO_ROOT

GD = ["generate", "--no-progress", "--fs", "2.5e6", "--duration", "0.02"]
RINEX = REPO_ROOT / "ephemeris" / "ESBC00DNK_R_20201770000_01D_MN.rnx.gz"

BOOM_PLUGIN = '''
from sdr_di.filters import EKF


class Boom(EKF):
    """An EKF whose update raises on its third call."""

    calls = 0

    def update(self, *args, **kwargs):
        self.calls += 1
        if self.calls >= 3:
            raise ZeroDivisionError("boom")
        return super().update(*args, **kwargs)
'''

MARK_PLUGIN = '''
import os
from pathlib import Path

Path(os.environ["SDR_DI_TEST_MARK"]).write_text("imported")
from sdr_di.filters import EKF


class Mark(EKF):
    """Leaves a file behind when imported."""
'''


@pytest.fixture(scope="module")
def small_set(if_files) -> Path:
    """The folder of a generated 0.02 s set at 2.5 MHz: ``s.bin``, ``s.json``, ``s_imu.csv``,
    ``s_truth.csv`` (the session's factory; a test that changes it works on ``work``)."""
    return if_files(0.02, name="s").if_file.parent


@pytest.fixture
def work(small_set, tmp_path) -> Path:
    """A private copy of the small set in ``tmp_path/set``."""
    shutil.copytree(small_set, tmp_path / "set")
    return tmp_path / "set"


def scenario_file(path: Path) -> Path:
    """The default scenario, its ephemeris made absolute, written to ``path``."""
    path.write_text(DEFAULT_SCENARIO.read_text().replace(
        '"../ephemeris/', f'"{REPO_ROOT}/ephemeris/'))
    return path


def one_line(capsys, argv: list[str], status: int = 2) -> str:
    """Run the CLI; assert the exit status and a single ``sdr-di: error:`` line; return it."""
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == status, err
    assert len(lines) == 1 and lines[0].startswith("sdr-di: error: "), err
    return lines[0]


def tree(d: Path) -> set[str]:
    return {p.relative_to(d).as_posix() for p in d.rglob("*")}


# -- item 1: an output never replaces an input ---------------------------------------------

def test_run_refuses_to_write_its_navigation_file_over_the_ephemeris(work, capsys):
    nav = work / "s_nav.rnx"
    nav.write_bytes(gzip.decompress(RINEX.read_bytes()))
    before, files = nav.read_bytes(), tree(work)
    err = one_line(capsys, ["run", work / "s.bin", "--ephemeris", nav, "--out", work,
                            "--no-progress"])
    assert "is the ephemeris" in err and "s_nav.rnx" in err
    assert nav.read_bytes() == before and tree(work) == files


def test_generate_refuses_to_write_its_sidecar_over_the_scenario(tmp_path, capsys):
    sc = scenario_file(tmp_path / "x.json")
    before = sc.read_bytes()
    err = one_line(capsys, [*GD, "--scenario", sc, "--name", "x", "--out", tmp_path])
    assert "is the scenario" in err
    assert sc.read_bytes() == before and tree(tmp_path) == {"x.json"}
    with pytest.raises(SdrDiError, match="is the scenario"):      # the API's door too
        sdr_di.generate(tmp_path, scenario=sc, name="x", duration_s=0.02,
                        sampling_rate_hz=2.5e6)
    assert sc.read_bytes() == before


def test_acquire_refuses_an_output_that_links_to_its_input(work, tmp_path, capsys):
    out = tmp_path / "acq"
    out.mkdir()
    (out / "s_acquisition.csv").symlink_to(work / "s.bin")   # the real path is the input
    before = (work / "s.bin").read_bytes()
    err = one_line(capsys, ["acquire", work / "s.bin", "--out", out])
    assert "is the IF file" in err and (work / "s.bin").read_bytes() == before


def test_lc_refuses_to_write_over_its_scenario(tmp_path, capsys):
    sc = scenario_file(tmp_path / "default_lc_ekf.csv")     # scenario name "default"
    before = sc.read_bytes()
    err = one_line(capsys, ["lc", "--scenario", sc, "--duration", "2", "--out", tmp_path])
    assert "is the scenario" in err and sc.read_bytes() == before


# -- items 2 and 12: a plugin that raises mid-run fails alone, in one line, leaving nothing ---

@pytest.fixture
def plugins(tmp_path, monkeypatch):
    d = tmp_path / "plugins"
    d.mkdir()
    (d / "i49_boom.py").write_text(BOOM_PLUGIN)
    (d / "i49_mark.py").write_text(MARK_PLUGIN)
    monkeypatch.syspath_prepend(str(d))
    monkeypatch.setenv("SDR_DI_TEST_MARK", str(tmp_path / "IMPORTED"))
    return tmp_path / "IMPORTED"


def test_a_plugin_raising_mid_run_is_one_line_exit_1_and_leaves_no_folder(plugins, tmp_path,
                                                                          capsys):
    out = tmp_path / "lc_out"
    err = one_line(capsys, ["lc", "--filter", "i49_boom:Boom", "--duration", "5", "--out", out],
                   status=1)
    assert "filter plugin 'i49_boom:Boom': update() raised ZeroDivisionError: boom (call 3)" \
        in err
    assert not out.exists()


def test_a_plugins_failure_is_an_sdr_di_error_that_a_study_records_per_filter(plugins):
    """A study records a filter's run as failed on an SdrDiError (experiments._deep
    run_filter): the guard turns the plugin's exception into one."""
    from sdr_di.errors import PluginError
    from sdr_di.filters import make_filter
    from sdr_di.ins.error_model import InsErrorModel
    from sdr_di.coupling.measurements import RangeRateMeasurementModel

    f = make_filter("i49_boom:Boom", InsErrorModel(), RangeRateMeasurementModel(),
                    np.zeros(17), np.eye(17), np.eye(17), None, dt=0.02)
    f.calls = 2
    with pytest.raises(PluginError, match=r"update\(\) raised ZeroDivisionError") as exc:
        f.update(np.zeros(2), np.eye(2))
    assert isinstance(exc.value, SdrDiError) and exc.value.exit_status == 1


# -- item 3: OSError on a path ------------------------------------------------------------

@pytest.mark.parametrize("argv", [
    [*GD, "--out", "{d}/" + "x" * 300],
    [*GD, "--name", "n" * 250, "--out", "{d}/o"],
    ["run", "{set}/s.bin", "--out", "{d}/" + "x" * 300, "--no-progress"],
    ["run", "{d}/" + "/".join(["y" * 200] * 25) + "/s.bin"],
    ["acquire", "{set}/s.bin", "--out", "{d}/" + "/".join(["y" * 200] * 25)],
    ["lc", "--duration", "2", "--out", "{d}/" + "x" * 300],
    ["report", "{d}/" + "x" * 300],
    ["study", "{d}/" + "x" * 300 + ".toml", "--out", "{d}/st"],
], ids=["generate-out", "generate-name", "run-out", "run-4kb-path", "acquire-4kb-out",
        "lc-out", "report-dir", "study-spec"])
def test_a_path_too_long_is_one_line_exit_2(work, tmp_path, capsys, argv):
    files = tree(tmp_path)
    err = one_line(capsys, [a.format(d=tmp_path, set=work) for a in argv])
    assert len(err) < 600 and tree(tmp_path) == files


# -- item 4: parsers' depth ---------------------------------------------------------------

def test_a_toml_nested_3000_deep_is_one_line(tmp_path, capsys):
    deep = tmp_path / "deep.toml"
    deep.write_text("x = " + "[" * 3000 + "]" * 3000 + "\n")
    one_line(capsys, [*GD, "--scenario", deep, "--out", tmp_path / "o"])
    one_line(capsys, ["study", deep, "--out", tmp_path / "st"])
    one_line(capsys, ["lc", "--assume", deep])
    assert tree(tmp_path) == {"deep.toml"}


# -- item 5: huge requests refused up front -----------------------------------------------

def test_generate_beyond_the_free_space_is_refused_with_the_estimate(tmp_path, capsys):
    err = one_line(capsys, [*GD[:-2], "--duration", "1e9", "--out", tmp_path / "o"])
    assert "needs about 5.14 PB" in err and not (tmp_path / "o").exists()


def test_lc_duration_has_an_upper_bound(capsys):
    assert "must be <= 3600 s" in one_line(capsys, ["lc", "--duration", "1e9"])


def test_a_study_of_a_million_cells_is_refused_before_its_expansion(tmp_path, capsys):
    spec = tmp_path / "big.toml"
    levels = ", ".join(str(float(v)) for v in range(1, 101))
    spec.write_text('[study]\nname = "big"\nfilters = ["ekf"]\nruns = 1\n[factorial]\n'
                    f'"truth.imu.gyro_bias_deg_h" = [{levels}]\n'
                    f'"truth.imu.accel_bias_mg" = [{levels}]\n'
                    f'"truth.imu.gyro_scale_factor_ppm" = [{levels}]\n')
    err = one_line(capsys, ["study", spec, "--out", tmp_path / "st"])
    assert "1,000,000 cells x 1 runs" in err and "--force" in err and "GB" in err


# -- item 6: --workers above the cores ----------------------------------------------------

def test_workers_above_the_cores_are_capped_with_a_warning():
    from sdr_di.studies.campaign import WorkersCappedWarning, local_workers

    cores = len(os.sched_getaffinity(0))
    with pytest.warns(WorkersCappedWarning, match=f"starting {cores} workers"):
        assert local_workers(cores + 62) == cores
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert local_workers(1) == 1 and local_workers(None) == cores


# -- item 7: the IMU and the reference on one grid ------------------------------------------

def test_a_50_hz_imu_takes_the_200_hz_reference_at_its_times(small_set):
    from sdr_di.errors import ImuDataError
    from sdr_di.integration.run_integrated import metrics_note, reference_on_imu_grid
    from sdr_di.io.imu_files import read_imu, read_truth

    imu, truth = read_imu(small_set / "s_imu.csv"), read_truth(small_set / "s_truth.csv")[0]
    imu50 = dataclasses.replace(imu, t=imu.t[::4], w_ib_b=imu.w_ib_b[::4], f_b=imu.f_b[::4],
                                rate_hz=50.0)
    with pytest.warns(UserWarning, match="IMU at 50 Hz, reference .* at 200 Hz"):
        on = reference_on_imu_grid(truth, imu50, "t.csv")
    np.testing.assert_array_equal(on.t, imu50.t)
    np.testing.assert_array_equal(on.llh, truth.llh[::4])
    odd = dataclasses.replace(imu50, t=imu50.t + 0.001)
    with pytest.raises(ImuDataError, match="does not hold the IMU's sample times"):
        reference_on_imu_grid(truth, odd, "t.csv")
    assert "no reference file" in metrics_note({"n": 0, "pos_m_rmse": float("nan")}, None)
    assert metrics_note({"n": 5, "pos_m_rmse": 1.0}, "t.csv") is None


# -- item 8: IF plausibility before acquisition ------------------------------------------

@pytest.mark.parametrize("kind,match", [("text", "are text"), ("zeros", "every byte is 0x00"),
                                        ("pattern", "repeat exactly every 1000 bytes")])
def test_content_that_is_no_recording_is_refused(tmp_path, capsys, kind, match):
    p = tmp_path / "x.bin"
    if kind == "text":
        p.write_text((Path(sdr_di.__file__).parent / "cli.py").read_text()[:40000])
    elif kind == "zeros":
        p.write_bytes(bytes(200_000))
    else:
        rng = np.random.default_rng(1)
        p.write_bytes(np.tile(rng.integers(-3, 4, 1000).astype(np.int8), 200).tobytes())
    err = one_line(capsys, ["acquire", p, "--fs", "2.5e6", "--format", "iq_int8", "--out",
                            tmp_path / "o"])
    assert match in err and not (tmp_path / "o").exists()


# -- item 9: PRN lists deduplicated with a warning ----------------------------------------

def test_acquire_searches_a_repeated_prn_once_with_one_warning(work, tmp_path, capsys):
    rc = main(["acquire", str(work / "s.bin"), "--prn", "C10,C10,c10,10,C11",
               "--out", str(tmp_path / "a")])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    assert cap.err.strip() == "sdr-di: warning: --prn: C10 x4: each PRN is used once"
    rows = (tmp_path / "a" / "s_acquisition.csv").read_text().splitlines()[1:]
    assert [r.split(",")[0] for r in rows] == ["10", "11"] and "2 PRNs" in cap.out


def test_generate_uses_a_repeated_prn_once_with_one_warning_naming_the_flag(tmp_path, capsys):
    assert main([*GD, "--prn", "C10,c10", "--out", str(tmp_path)]) == 0
    assert capsys.readouterr().err.strip() == \
        "sdr-di: warning: --prn: C10 x2: each PRN is used once"
    meta = json.loads((tmp_path / "default.json").read_text())
    assert [s["prn"] for s in meta["satellites"]] == [10]


# -- item 10: sidecars ----------------------------------------------------------------------

@pytest.mark.parametrize("edit,match", [
    ("dup", "key 'sampling_rate_hz' given twice"),
    ("rate_1e308", "sampling_rate_hz 1e+308 Hz is outside"),
    ("rate_vs_n", "duration_s 0.02 s, but n_samples / sampling_rate_hz"),
    ("if_out_of_band", "if_hz 5e+06 Hz is outside the band"),
])
def test_a_sidecar_that_contradicts_itself_is_one_line_exit_2(work, capsys, edit, match):
    side = work / "s.json"
    meta = json.loads(side.read_text())
    if edit == "dup":
        side.write_text(side.read_text().replace(
            '"sampling_rate_hz":', '"sampling_rate_hz": 5000000.0, "sampling_rate_hz":', 1))
    else:
        key, value = {"rate_1e308": ("sampling_rate_hz", 1e308),
                      "rate_vs_n": ("sampling_rate_hz", 5e6),
                      "if_out_of_band": ("if_hz", 5e6)}[edit]
        side.write_text(json.dumps({**meta, key: value}))
    files = tree(work)
    err = one_line(capsys, ["run", side, "--no-progress"])
    assert match in err and len(err) < 300 and tree(work) == files


# -- item 11: a spec's plugins are imported only once the rest is valid -------------------

def test_a_refused_study_spec_has_run_no_plugin_code(plugins, tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('[study]\nname = "t"\nfilters = ["ekf", "i49_mark:Mark"]\nruns = 0\n')
    one_line(capsys, ["study", spec, "--out", tmp_path / "st"])
    assert not plugins.exists()
    from sdr_di.studies.spec import load_study

    spec.write_text(spec.read_text().replace("runs = 0", "runs = 1"))
    assert load_study(spec).filters == ("ekf", "i49_mark:Mark") and plugins.exists()


def test_the_guide_says_that_naming_a_plugin_runs_its_code():
    text = (REPO_ROOT / "docs" / "guides" / "write_a_filter.md").read_text()
    assert "Naming a plugin runs its code" in text


# -- item 12: no empty folder after a failure -----------------------------------------------

def test_generate_failing_mid_write_leaves_no_folder(tmp_path, capsys, monkeypatch):
    from sdr_di.errors import OutputError
    from sdr_di.sim import generate as gen

    def full(*args, **kwargs):
        raise OutputError("disk full (test)")

    monkeypatch.setattr(gen, "write_truth", full)
    one_line(capsys, [*GD, "--out", tmp_path / "a" / "b"])
    assert tree(tmp_path) == set()


# -- item 13: two filters never share a file name --------------------------------------------

def test_integrated_runs_of_two_filters_have_their_own_files(tmp_path):
    from sdr_di.coupling.config import IntegrationConfig
    from sdr_di.integration.run_integrated import solution_names

    names = [solution_names(tmp_path, "s", IntegrationConfig(filter=f, mode=m))
             for f in ("ekf", "ukf", "pkg.mod:My") for m in ("deep", "tight")]
    flat = [p for n in names for p in n.values()]
    assert len(set(flat)) == len(flat)
    assert names[0]["solution"].name == "s_deep.csv"           # the default keeps its name
    assert names[2]["solution"].name == "s_deep_ukf.csv"
    assert names[4]["summary"].name == "s_deep_pkg.mod_My_summary.json"


# -- item 14: a notice while the kernels compile on first use ------------------------------

def test_the_first_run_on_a_machine_says_the_kernels_compile(work, tmp_path, capsys,
                                                            monkeypatch):
    import sdr_di.kernel_cache as kc

    monkeypatch.setattr(kc, "kernels_cached", lambda: False)
    main(["run", str(work / "s.bin"), "--out", str(tmp_path / "r")])   # with its bar
    assert kc.NOTE in capsys.readouterr().err
    monkeypatch.undo()
    assert kc.first_use_note() in ("", kc.NOTE)


# -- item 15: acquire writes where the docs say ----------------------------------------------

def test_acquire_writes_where_the_readme_and_the_guide_say(work, capsys):
    assert main(["acquire", str(work / "s.bin")]) == 0
    out = capsys.readouterr().out
    assert f"table     {work / 's_acq' / 's_acquisition.csv'}" in out
    assert "`STEM_acq/STEM_acquisition.csv` beside the file" in \
        (REPO_ROOT / "README.md").read_text()
    assert "`rec_acq/rec_acquisition.csv` beside the recording" in \
        (REPO_ROOT / "docs" / "guides" / "own_recording.md").read_text()


# -- item 16: generate --sigmf lists every file it wrote ------------------------------------

def test_generate_sigmf_lists_its_sigmf_pair(tmp_path, capsys):
    assert main([*GD, "--sigmf", "--out", str(tmp_path)]) == 0
    listed = {ln.split()[0]: Path(ln.split()[1])
              for ln in capsys.readouterr().out.splitlines()}
    assert set(listed.values()) == set(tmp_path.iterdir())
    assert listed["sigmf-data"].name == "default.sigmf-data"
    assert listed["sigmf-meta"].name == "default.sigmf-meta"


# -- item 17: sdr-di filters shows a plugin's docstring and flags one that cannot run -------

def test_filters_shows_a_plugins_docstring_and_flags_one_without_update(capsys):
    from sdr_di.filters import EKF, register_filter, unregister_filter

    class Documented(EKF):
        """An EKF that says what it is.

        More text."""

    class PredictOnly:
        """Predicts, never updates."""

        def __init__(self, *args, **kwargs):
            pass

        def predict(self, dt):
            pass

    register_filter("i49-documented", Documented)
    register_filter("i49-predict-only", PredictOnly)
    try:
        assert main(["filters"]) == 0
        out = capsys.readouterr().out.splitlines()
    finally:
        unregister_filter("i49-documented")
        unregister_filter("i49-predict-only")
    doc = next(ln for ln in out if ln.startswith("i49-documented"))
    bad = next(ln for ln in out if ln.startswith("i49-predict-only"))
    assert doc.endswith("An EKF that says what it is.")
    assert "NOT USABLE: lacks update; Predicts, never updates." in bad


# -- item 20: the no-fix causes follow the evidence ----------------------------------------

def test_no_fix_causes_follow_the_channels_evidence():
    from sdr_di.receiver.diagnosis import likely_causes

    kw = dict(format_name="iq_int8", given="read", if_hz=0.0, sampling_rate_hz=2.5e6)
    tracking = [{"cn0_dbhz": 36.0, "subframes": 2, "ephemeris_decoded": False}] * 7
    evidence, causes = likely_causes(tracking, 12.0, **kw)
    assert evidence == "7 channels track at 36 dB-Hz, 7 decoding subframes"
    assert causes[0].startswith("a file too short") and causes[1].startswith("the start")
    assert causes[-3].startswith("the sample format")        # the description last
    _, causes = likely_causes([], 12.0, **kw)
    assert causes[0].startswith("the sample format")
    assert causes[-1].startswith("a file too short")


# -- item 21: a bar over a study's runs, every file named, a quiet Dask teardown -----------

def test_study_progress_is_one_bar_with_failures_above_it(tmp_path):
    import io

    from sdr_di.studies.commands import StudyProgress

    buf = io.StringIO()
    with StudyProgress(3, file=buf) as show:
        show({"status": "ok", "cell": "a", "seed_index": 0})
        show({"status": "failed", "cell": "a", "seed_index": 1, "error": "boom"})
        assert show.bar.n == 2 and show.failed == 1
    assert "2/3" in buf.getvalue()


def test_study_outputs_name_every_file(tmp_path):
    from sdr_di.studies.study import study_outputs

    for name in ("runs.csv", "cells.csv", "comparisons.csv", "tuning.csv", "study.json",
                 "report.html"):
        (tmp_path / name).write_text("x")
    assert sorted(p.name for p in study_outputs(tmp_path).values()) == sorted(
        p.name for p in tmp_path.iterdir())


def test_dask_teardown_errors_are_not_printed(monkeypatch, capsys):
    import contextlib
    import logging

    import distributed

    from sdr_di.studies import campaign

    class Fake(contextlib.AbstractContextManager):
        def __init__(self, *args, **kwargs):
            pass

        def __exit__(self, *exc):   # what a closing cluster logs on a closed comm
            logging.getLogger("distributed.comm.tcp").error("CommClosedError: in teardown")

    monkeypatch.setattr(distributed, "LocalCluster", Fake)
    monkeypatch.setattr(distributed, "Client", Fake)
    handler = logging.StreamHandler()          # stderr, as Dask's own handler
    logging.getLogger("distributed").addHandler(handler)
    level = logging.getLogger("distributed.comm.tcp").level
    try:
        with campaign._client(None, 1, 0):
            pass
    finally:
        logging.getLogger("distributed").removeHandler(handler)
    assert "CommClosedError" not in capsys.readouterr().err
    assert logging.getLogger("distributed.comm.tcp").level == level      # restored


def test_a_failed_api_run_leaves_no_folder(work, tmp_path):
    out = tmp_path / "api_run"
    with pytest.raises(SdrDiError):
        sdr_di.run(work / "s.bin", prns=["C40"], out=out)      # no such satellite in the file
    assert not out.exists()


@pytest.mark.slow
def test_a_plugin_raising_in_a_tight_run_is_one_line_exit_1_and_leaves_no_folder(
        plugins, tmp_path, capsys):
    """The integrated loop end to end (13 s at 2.5 MHz: the hand-over at about 12.2 s, then
    the plugin's third update raises)."""
    assert main([*GD[:-1], "13", "--out", str(tmp_path)]) == 0
    capsys.readouterr()
    out = tmp_path / "run"
    err = one_line(capsys, ["run", tmp_path / "default.bin", "--mode", "tight", "--filter",
                            "i49_boom:Boom", "--no-progress", "--out", out], status=1)
    assert "filter plugin 'i49_boom:Boom': update() raised ZeroDivisionError: boom" in err
    assert not out.exists()
