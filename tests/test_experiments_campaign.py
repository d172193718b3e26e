"""Campaigns on Dask: local default vs an explicit scheduler, killed workers, partial records.

Each test starts at most one small cluster (2 worker processes) and runs short (6 s)
noise-mismatch runs on three filters, to stay light on a shared 2-core machine.
"""

from __future__ import annotations

import json
import logging
import os
import sys

import cloudpickle
import pytest

from sdr_di.errors import CampaignError
from sdr_di.experiments import Experiment
from sdr_di.studies import render_report, run_campaign, run_seed

# the test-only experiments below travel to the workers by value (no import of this file)
cloudpickle.register_pickle_by_value(sys.modules[__name__])

SHORT = {"duration_s": 6.0, "filters": "ekf,ukf,sage-husa-ukf", "plots": False}


def _kill_run(params: dict, seed: int, out_dir) -> dict:
    """Test experiment: dies with its worker process for ``kill_seed``."""
    if seed == params["kill_seed"]:
        os._exit(3)
    (out_dir / "note.txt").write_text(f"seed {seed}\n")
    return {"x": float(seed), "twice": 2 * seed, "label": "same"}


def _raise_run(params: dict, seed: int, out_dir) -> dict:
    if seed == params["bad_seed"]:
        raise ValueError(f"bad seed {seed}")
    return {"x": float(seed)}


KILL = Experiment(name="test-kill", run=_kill_run, default_params={"kill_seed": -1})
RAISE = Experiment(name="test-raise", run=_raise_run, default_params={"bad_seed": -1})


@pytest.fixture(scope="module")
def local_campaign(tmp_path_factory):
    """The same 4-run campaign on the default local cluster (2 worker processes)."""
    out = tmp_path_factory.mktemp("campaign_local")
    return run_campaign("noise-mismatch", SHORT, runs=4, base_seed=7, workers=2, out_dir=out)


def test_local_default_and_scheduler_address_give_identical_aggregates(local_campaign,
                                                                        tmp_path):
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=logging.ERROR) as cluster:
        remote = run_campaign("noise-mismatch", SHORT, runs=4, base_seed=7,
                              scheduler=cluster.scheduler_address, out_dir=tmp_path)
    assert remote.scheduler == cluster.scheduler_address
    assert local_campaign.n_ok == remote.n_ok == 4
    assert [r["seed"] for r in remote.records] == [run_seed(7, i) for i in range(4)]
    assert remote.stats == local_campaign.stats
    # the runs really differ (independent seeds), so equality is not trivial
    st = remote.stats["ekf.pos_m_rmse"]
    assert st["n"] == 4 and st["std"] > 0 and st["min"] < st["max"]
    on_disk = json.loads((tmp_path / "campaign.json").read_text())
    assert on_disk["status"] == "done" and on_disk["n_failed"] == 0
    assert on_disk["stats"]["ekf.pos_m_rmse"]["mean"] == st["mean"]


def test_campaign_outputs_and_report(local_campaign):
    out = local_campaign.out_dir
    for name in ("aggregate.csv", "aggregate.md", "runs.csv", "runs.md", "filters.csv",
                 "filters.md", "campaign.json"):
        assert (out / name).is_file(), name
    for i in range(4):
        rec = json.loads((out / "runs" / f"{i}.json").read_text())
        assert rec["status"] == "ok" and rec["index"] == i
        assert (out / "runs" / str(i) / "errors_ekf.csv").is_file()
    md = (out / "filters.md").read_text()
    assert "| filter |" in md and "| sage-husa-ukf |" in md and "pos_m_rmse_std" in md
    assert "rmse_by_filter.png" in json.loads((out / "campaign.json").read_text())["plots"]
    page = render_report(out).read_text()
    assert page.count("<table>") >= 3
    assert "data:image/png;base64," in page and "sage-husa-ukf" in page


def test_killed_worker_loses_only_that_run(tmp_path):
    seeds = [11, 12, 13, 14]
    res = run_campaign(KILL, {"kill_seed": 12}, runs=4, seeds=seeds, workers=2,
                       out_dir=tmp_path)
    status = {r["seed"]: r["status"] for r in res.records}
    assert status == {11: "ok", 12: "failed", 13: "ok", 14: "ok"}
    failed = res.failed[0]
    assert failed["index"] == 1 and "worker died" in failed["error"]
    assert "KilledWorker" in failed["error"] or "killed" in failed["error"].lower()
    assert res.stats["x"]["n"] == 3 and res.stats["x"]["mean"] == pytest.approx(38 / 3)
    assert res.stats["label"] == {"value": "same"}
    rec = json.loads((tmp_path / "runs" / "1.json").read_text())
    assert rec["status"] == "failed" and "worker died" in rec["error"]
    assert (tmp_path / "runs" / "2" / "note.txt").read_text() == "seed 13\n"
    summary = json.loads((tmp_path / "campaign.json").read_text())
    assert summary["n_failed"] == 1 and summary["failed"][0]["seed"] == 12
    assert summary["scheduler_allowed_failures"] == 0
    assert "worker died" in render_report(tmp_path).read_text()


def test_exception_in_run_is_recorded_and_other_runs_complete(tmp_path):
    res = run_campaign(RAISE, {"bad_seed": 2}, runs=3, seeds=[1, 2, 3], workers=1,
                       out_dir=tmp_path)
    assert [r["status"] for r in res.records] == ["ok", "failed", "ok"]
    assert res.failed[0]["error"] == "ValueError: bad seed 2"
    assert "Traceback" in res.failed[0]["traceback"]
    assert res.stats["x"]["mean"] == 2.0


def test_run_seeds_are_deterministic_and_distinct():
    a = [run_seed(5, i) for i in range(50)]
    assert a == [run_seed(5, i) for i in range(50)]
    assert len(set(a)) == 50
    assert run_seed(6, 0) != run_seed(5, 0)


@pytest.mark.parametrize("kw, msg", [
    ({"runs": 0}, "runs must be an integer >= 1"),
    ({"runs": 2.5}, "runs must be an integer >= 1"),
    ({"runs": 2, "workers": 0}, "workers must be an integer >= 1"),
    ({"runs": 2, "seeds": [1]}, "1 seeds given for 2 runs"),
    ({"runs": 2, "workers": 2, "scheduler": "tcp://127.0.0.1:1"}, "--workers applies"),
])
def test_bad_campaign_configuration(tmp_path, kw, msg):
    with pytest.raises(CampaignError, match=msg):
        run_campaign(KILL, out_dir=tmp_path / "out", **kw)
    assert not (tmp_path / "out").exists()


def test_refuses_to_mix_with_an_earlier_campaign(tmp_path):
    (tmp_path / "runs").mkdir()
    with pytest.raises(CampaignError, match="already holds campaign runs"):
        run_campaign(KILL, runs=1, out_dir=tmp_path)


def test_interrupted_campaign_keeps_its_records_and_reports_them(tmp_path):
    def stop(rec: dict) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_campaign(KILL, runs=3, seeds=[1, 2, 3], workers=1, out_dir=tmp_path,
                     on_record=stop)
    summary = json.loads((tmp_path / "campaign.json").read_text())
    assert summary["status"] == "interrupted" and summary["n_records"] == 1
    assert json.loads((tmp_path / "runs" / "0.json").read_text())["figures"]["x"] == 1.0
    assert not (tmp_path / "runs" / "2.json").exists()
    page = render_report(tmp_path).read_text()
    assert "interrupted" in page and "Aggregate of the runs so far" in page
    assert "<td>twice</td><td>1</td><td>2</td>" in page
