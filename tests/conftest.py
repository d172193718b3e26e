"""Suite-wide guards, and the IF-file factory the tests share (``if_files``)."""

import signal
from pathlib import Path

import pytest


@pytest.fixture(autouse=True)
def _sigint_disposition_kept():
    """A test must leave the process's SIGINT disposition as it found it.

    The Ctrl-C tests start children that inherit it: a test that leaves SIGINT ignored makes
    them fail far from the cause (a child with SIG_IGN never sees the interrupt). This guard
    names the test that changed it.
    """
    before = signal.getsignal(signal.SIGINT)
    yield
    after = signal.getsignal(signal.SIGINT)
    if after is not before:
        signal.signal(signal.SIGINT, before)
        pytest.fail(f"SIGINT disposition changed by this test: {before!r} -> {after!r}")


def _listing(folder: Path) -> dict[str, tuple[int, int]]:
    """Each entry of ``folder`` by name: (size [bytes], modification time [ns])."""
    return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in folder.iterdir()}


@pytest.fixture(scope="session")
def if_files(tmp_path_factory):
    """The IF-file factory of the whole test run: ``if_files(duration_s, sampling_rate_hz=2.5e6,
    seed=None, name=None, **overrides)`` -> :class:`sdr_di.api.GeneratedFiles` of the default
    scenario (``sdr_di.generate``: ``overrides`` are its other arguments, ``cn0_dbhz``,
    ``sample_format``, ``prns``, ``scenario``...), generated once per set of arguments and
    shared by every test that asks for the same file.

    The files are shared: a test that changes one copies it first (``shutil.copytree`` of
    ``.if_file.parent``, which holds that one set and nothing else), and a run writes under
    ``tmp_path``, never beside the file. The factory checks that a set's folder is as it made
    it each time the set is asked for again, and fails the asking test if not (the test that
    changed it ran before). A session fixture lives once per process: under
    ``pytest -n 2 --dist loadscope`` each worker makes the files of the modules it gets.

    Ask for a file the suite already makes before a new one (2.5 MHz, the scenario's seed
    unless given): ``(0.02, name="s")``, ``(0.1)``, ``(1.0, name="s")``, ``(16.0)`` (runs
    read 8-13.5 s of it with ``--duration``), ``(26.0)``, ``(37.0)``. A test of generation
    itself, or of a scenario these arguments cannot express, generates its own file.
    """
    import sdr_di

    made: dict = {}

    def make(duration_s: float, sampling_rate_hz: float = 2.5e6, seed: int | None = None,
             name: str | None = None, **overrides):
        key = (float(duration_s), float(sampling_rate_hz), seed, name,
               tuple(sorted((k, repr(v)) for k, v in overrides.items())))
        if key not in made:
            files = sdr_di.generate(tmp_path_factory.mktemp("if_files"), duration_s=duration_s,
                                    sampling_rate_hz=sampling_rate_hz, seed=seed, name=name,
                                    **overrides)
            made[key] = files, _listing(files.if_file.parent)
        files, listing = made[key]
        now = _listing(files.if_file.parent)
        if now != listing:
            changed = sorted(n for n in listing.keys() | now.keys()
                             if listing.get(n) != now.get(n))
            pytest.fail(f"if_files: the shared set in {files.if_file.parent} changed since it "
                        f"was made ({', '.join(changed)}): an earlier test wrote into it "
                        "instead of a copy")
        return files

    return make
