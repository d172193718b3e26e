"""A study's runs work in a temporary folder of the study's own output set, never in the
system's temporary folder, so a worker killed in the middle of a run (the cluster shut
down, Ctrl-C) leaves no empty ``sdr-di-run-*`` folder behind (issue 28 item 3)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from sdr_di.studies.execute import execute_run
from sdr_di.studies.study import execute_cell_run


class _Recorder:
    """An experiment stand-in: records the folder it was given, writes a file there."""

    name = "recorder"

    def __init__(self) -> None:
        self.seen: list[Path] = []

    def run(self, params: dict, seed: int, out: Path) -> dict:
        self.seen.append(Path(out))
        (Path(out) / "x.txt").write_text("x")
        return {"value": 1.0}


def test_a_study_task_runs_under_the_study_cache_not_the_system_tmp(tmp_path, monkeypatch):
    system = tmp_path / "system-tmp"
    system.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system))
    cache = tmp_path / "study" / "cache"
    exp = _Recorder()
    rec = execute_cell_run(exp, {}, 5, 0, str(cache))
    assert rec["status"] == "ok" and rec["files"] == {"x.txt": b"x"}
    assert exp.seen[0].parent == cache / "tmp"            # worked in the study's folder
    assert not exp.seen[0].exists()                       # and removed it after the run
    assert list(system.iterdir()) == []                   # nothing in the system's tmp


def test_a_run_outside_a_study_uses_the_system_tmp_and_removes_it(tmp_path, monkeypatch):
    system = tmp_path / "system-tmp"
    system.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system))
    exp = _Recorder()
    rec = execute_run(exp, {}, 5, 0)
    assert rec["status"] == "ok"
    assert exp.seen[0].parent == system and exp.seen[0].name.startswith("sdr-di-run-")
    assert list(system.iterdir()) == []
