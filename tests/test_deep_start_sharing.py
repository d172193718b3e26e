"""Deep start-ups shared between the tasks of a process (``experiments._deep.shared_start``).

The receiver is replaced by a stand-in that records which start-up each run was given, so
these tests check the bookkeeping of :func:`~sdr_di.experiments._deep.run_deep_variant`
alone; that a run continued from a kept start-up equals its own start-up is tested on real
signals in ``tests/test_deep.py``, and the smoke study counts the shared start-ups of a real
study (``tests/test_study.py``).
"""

from __future__ import annotations

import types

import pytest

from sdr_di.experiments import _deep
from sdr_di.integration import receiver as R


class _Start:
    def __init__(self, key, nav):
        self.key, self.nav = key, nav


class _Receiver:
    """Stand-in for IntegratedReceiver: the start-up's key is the IF path and ``span``."""

    calls: list = []
    span = "whole file"

    def __init__(self, cfg, scalar=None):
        self.scalar = scalar
        self.deep_start = None
        self.scalar_record = None

    def run(self, source, imu, *, prns, nav, truth, start=None, keep_start=False):
        key = (str(source.path), self.span)
        _Receiver.calls.append((start, keep_start))
        if start is not None and (start.key != key or start.nav is not nav):
            raise R.StartMismatchError("start-up state made on other data")
        if keep_start:
            self.deep_start = _Start(key, nav)
        return types.SimpleNamespace(handover_s=12.0)


@pytest.fixture
def files(tmp_path, monkeypatch):
    """An IF file and an ephemeris file in a study's file cache, and a fresh share list."""
    monkeypatch.setattr(R, "IntegratedReceiver", _Receiver)
    monkeypatch.setattr(_deep, "_shared", [])
    _Receiver.calls = []
    _Receiver.span = "whole file"
    token = _deep.FILE_CACHE.set(tmp_path)
    (tmp_path / "run.bin").write_bytes(b"\0" * 64)
    (tmp_path / "nav.rnx").write_text("nav")
    yield tmp_path
    _deep.FILE_CACHE.reset(token)


def _inputs(folder, if_name="run.bin"):
    """A task's inputs on the files of ``folder`` (its own source and navigation objects, as
    each task opens its own)."""
    path = folder / if_name
    return _deep.Inputs(source=types.SimpleNamespace(path=path, sampling_rate_hz=2.5e6),
                        imu=None, truth=None, nav=object(), prns=[1],
                        paths={"if": path}, nav_path=folder / "nav.rnx")


def test_the_next_task_on_the_same_files_continues_from_the_first_tasks_start_up(files):
    first, second = _inputs(files), _inputs(files)
    for f in ("ekf", "ukf"):
        assert _deep.run_deep_variant(first, f).error is None
    made = first.starts[(R.IntegrationConfig().handover_wait_s,
                              R.IntegrationConfig().iono_wait_s)]
    assert _Receiver.calls == [(None, True), (made, False)]
    nav_before = second.nav
    for f in ("ekf", "ukf"):
        assert _deep.run_deep_variant(second, f).error is None
    assert _Receiver.calls[2:] == [(made, False), (made, False)]
    assert second.nav is made.nav is not nav_before   # the start-up's own navigation data


def test_a_start_up_of_another_span_is_not_taken_and_the_run_makes_its_own(files):
    assert _deep.run_deep_variant(_inputs(files), "ekf").error is None
    _Receiver.span = "first 20 s"
    second = _inputs(files)
    assert _deep.run_deep_variant(second, "ekf").error is None
    shared = _Receiver.calls[0]
    assert [c[1] for c in _Receiver.calls] == [True, False, True]   # refused, then its own
    own = next(iter(second.starts.values()))
    assert own.key[1] == "first 20 s" and own is not shared
    assert _deep.run_deep_variant(second, "ukf").error is None       # the task's own
    assert _Receiver.calls[-1] == (own, False)


def test_no_sharing_outside_a_file_cache_or_between_files(files):
    token = _deep.FILE_CACHE.set(None)
    try:
        _deep.run_deep_variant(_inputs(files), "ekf")
        _deep.run_deep_variant(_inputs(files), "ekf")
    finally:
        _deep.FILE_CACHE.reset(token)
    assert [c[0] for c in _Receiver.calls] == [None, None]
    (files / "other.bin").write_bytes(b"\0" * 64)
    _deep.run_deep_variant(_inputs(files), "ekf")
    _deep.run_deep_variant(_inputs(files, "other.bin"), "ekf")
    assert [c[0] for c in _Receiver.calls[2:]] == [None, None]
    # a file rewritten since (another size): its old start-up is not taken
    (files / "run.bin").write_bytes(b"\0" * 128)
    _deep.run_deep_variant(_inputs(files), "ekf")
    assert _Receiver.calls[-1] == (None, True)


def test_at_most_shared_starts_are_kept(files, monkeypatch):
    monkeypatch.setattr(_deep, "SHARED_STARTS", 2)
    for k in range(4):
        (files / f"f{k}.bin").write_bytes(b"\0" * 64)
        _deep.run_deep_variant(_inputs(files, f"f{k}.bin"), "ekf")
    assert [e[0][0][0][0].endswith(f"f{k}.bin") for e, k in zip(_deep._shared, (2, 3))] == \
        [True, True]
    monkeypatch.setattr(_deep, "SHARED_STARTS", 1)
    _deep.run_deep_variant(_inputs(files, "f0.bin"), "ekf")
    assert len(_deep._shared) == 1
    monkeypatch.setattr(_deep, "SHARED_STARTS", 0)
    _deep.run_deep_variant(_inputs(files, "f1.bin"), "ekf")
    assert len(_deep._shared) == 1
