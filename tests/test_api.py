"""The public Python API (``sdr_di.generate``, ``sdr_di.run``, ``sdr_di.study``; issue 27
item 2): each function on a tiny case, and the same files as the CLI command it mirrors."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import sdr_di
from sdr_di.cli import main
from sdr_di.experiments import Experiment, register_experiment


def test_import_sdr_di_loads_no_numerics():
    """``import sdr_di`` gives the API, its options objects and its errors without numpy, the
    receiver or the study machinery."""
    code = ("import sys, sdr_di; print(sorted(m for m in sys.modules if m == 'numpy' or "
            "m.startswith('sdr_di.')), callable(sdr_di.run) and callable(sdr_di.study) "
            "and callable(sdr_di.generate))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split("\n")[0]
    assert out == "['sdr_di.api', 'sdr_di.errors', 'sdr_di.options'] True"


@pytest.fixture(scope="module")
def short_file(tmp_path_factory):
    """3 s of the default scenario at 2.5 MHz, from the API and from the CLI."""
    d = tmp_path_factory.mktemp("api_gen")
    files = sdr_di.generate(d / "api", duration_s=3.0, sampling_rate_hz=2.5e6, seed=7)
    assert main(["generate", "--no-progress", "--duration", "3", "--fs", "2.5e6", "--seed",
                 "7", "--out", str(d / "cli")]) == 0
    return files, d / "cli"


def test_generate_writes_the_cli_files(short_file):
    files, cli = short_file
    assert files.if_file == files.files["if"] and files.if_file.name == "default.bin"
    for label, path in files.files.items():
        assert path.is_file(), label
        # the sidecar names its own folder's files; the others are the same bytes
        if label != "metadata":
            assert path.read_bytes() == (cli / path.name).read_bytes(), label


def test_scalar_run_returns_metrics_and_paths_like_the_cli(short_file, tmp_path):
    files, _ = short_file
    res = sdr_di.run(files.if_file, out=tmp_path / "api")
    assert res.mode == "scalar" and res.out_dir == tmp_path / "api"
    assert set(res.files) >= {"pvt", "nmea", "channels"}
    assert all(p.is_file() and p.parent == res.out_dir for p in res.files.values())
    assert res.metrics["n_epochs"] > 0 and res.processed_s == pytest.approx(3.0)
    # 3 s hold no fix: the CLI says so with exit status 1 and keeps its outputs
    assert main(["run", str(files.if_file), "--no-progress", "--out",
                 str(tmp_path / "cli")]) == 1
    assert res.files["pvt"].read_bytes() == (tmp_path / "cli" / res.files["pvt"].name
                                             ).read_bytes()


@pytest.mark.parametrize("kw, match", [
    ({"mode": "vector"}, "mode must be one of"),
    ({"filter": "ekf"}, "filter: only with mode deep, loose or tight"),
    ({"mode": "deep", "gnss_rate_hz": 5.0}, "gnss_rate_hz: only with mode loose or tight"),
    ({"approx_pos": (40.0, 116.0, 100.0)}, "approx_pos: only in scalar mode, with ephemeris"),
    ({"rate_hz": 0.0}, "rate_hz must be a finite number > 0"),
    ({"mode": "loose", "iono_wait_s": -1.0}, "iono_wait_s must be a finite number >= 0"),
    ({"pll_bw_hz": 40.0}, "unstable loop"),
    ({"mode": "tight", "gnss_rate_hz": 3.0}, "10 Hz divided by a whole number"),
    ({"mode": "loose", "nco_latency": 1}, "nco_latency: only with mode deep"),
    ({"mode": "deep", "nco_latency": 2}, "nco_latency must be 0 or 1"),
])
def test_run_refuses_options_that_do_not_fit_before_any_work(short_file, tmp_path, kw, match):
    files, _ = short_file
    with pytest.raises(ValueError, match=match):
        sdr_di.run(files.if_file, out=tmp_path / "o", **kw)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_loose_run_writes_the_cli_solution(if_files, tmp_path):
    """A loose run through the API writes the CLI's CSV byte for byte, with the accuracy
    after the hand-over (default scenario at 2.5 MHz, 13.5 s of the session's 16 s file:
    hand-over at about 12.2 s)."""
    files = if_files(16.0)
    res = sdr_di.run(files.if_file, mode="loose", filter="ekf", duration_s=13.5,
                     out=tmp_path / "api")
    assert res.mode == "loose" and set(res.files) == {"solution", "summary", "channels", "nis"}
    assert 10.0 < res.metrics["handover_s"] < 13.0
    assert res.metrics["n"] >= 3 and np.isfinite(res.metrics["pos_m_rmse"])
    assert res.metrics["pos_m_rmse"] < 5.0
    assert main(["run", str(files.if_file), "--mode", "loose", "--filter", "ekf",
                 "--duration", "13.5", "--no-progress", "--out", str(tmp_path / "cli")]) == 0
    assert res.files["solution"].read_bytes() == \
        (tmp_path / "cli" / res.files["solution"].name).read_bytes()


# ---- study on a stand-in experiment (the machinery, not a receiver run) ----------------------
def _stand_in(params: dict, seed: int, out_dir) -> dict:
    rng = np.random.default_rng(seed)
    base = 1.0 + rng.random()
    fig = {}
    for f, k in (("ekf", 1.0), ("ff-aukf", 0.8)):
        fig[f"{f}.completed"] = 1
        fig[f"{f}.handover_s"] = 12.0
        for q in ("pos_m", "vel_mps", "att_deg"):
            fig[f"{f}.{q}_rmse"] = base * k * (1 + 0.01 * rng.random())
    return fig


register_experiment(Experiment(name="test-api-stand-in", run=_stand_in,
                               default_params={"filters": "", "modes": "deep"}))

SPEC = {"study": {"name": "api", "experiment": "test-api-stand-in", "runs": 3,
                  "filters": ["ekf", "ff-aukf"], "baseline": "ekf"},
        "cells": [{"name": "only"}],
        "claims": [{"text": "ff-aukf beats ekf", "filter": "ff-aukf", "quantities": ["pos"],
                    "min_wins": 3, "max_sign_p": 0.2, "interval_excludes_zero": False}]}


def test_study_from_a_mapping_a_file_and_a_spec(tmp_path):
    from sdr_di.studies.spec import parse_study

    res = sdr_di.study(SPEC, tmp_path / "a", workers=0)
    assert res.out_dir == tmp_path / "a" and not res.failed
    assert (tmp_path / "a" / "report.html").is_file()
    assert (tmp_path / "a" / "cells.csv").is_file()
    row = next(r for r in res.cells if r["filter"] == "ff-aukf")
    assert row["claim1"] == "holds"
    # the same spec as a parsed StudySpec resumes the folder: nothing to run
    again = sdr_di.study(parse_study(SPEC), tmp_path / "a", workers=0, report=False)
    assert again.n_run == 0 and again.n_skipped == 3
    toml = tmp_path / "spec.toml"
    toml.write_text(
        '[study]\nname = "api"\nexperiment = "test-api-stand-in"\nruns = 3\n'
        'filters = ["ekf", "ff-aukf"]\nbaseline = "ekf"\n[[cells]]\nname = "only"\n'
        '[[claims]]\ntext = "ff-aukf beats ekf"\nfilter = "ff-aukf"\nquantities = ["pos"]\n'
        'min_wins = 3\nmax_sign_p = 0.2\ninterval_excludes_zero = false\n')
    from_file = sdr_di.study(toml, tmp_path / "b", workers=0, report=False)
    assert (tmp_path / "b" / "cells.csv").read_bytes() == \
        (tmp_path / "a" / "cells.csv").read_bytes()
    assert Path(from_file.out_dir) == tmp_path / "b"
