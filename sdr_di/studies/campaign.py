"""Monte Carlo campaigns: an experiment repeated with independent seeds, in parallel on Dask.

One code path for both kinds of cluster: without a scheduler address a
:class:`distributed.LocalCluster` of worker *processes* (one thread each) is started on the
local cores for the campaign and closed after it; with ``scheduler="tcp://host:port"`` the
campaign connects a :class:`distributed.Client` to that scheduler. Either way runs are
submitted as tasks of :func:`~.execute.execute_run` through :func:`~.tasks.run_tasks`, the
task engine a study uses too (a campaign is a study's one-cell case, without pairing:
``docs/studies.md``).

Decisions
---------
* Seed of run ``i`` = first word of ``numpy.random.SeedSequence(base_seed, spawn_key=(i,))``
  (the ``i``-th child of the base seed: independent streams, stable when ``runs`` changes),
  unless explicit ``seeds`` are given.
* At most as many runs are in flight as the cluster has worker threads; the next run is
  submitted when one completes. A task that is only *queued* on a worker therefore never
  shares the fate of a worker that dies under another run.
* The local cluster's scheduler is started with ``allowed_failures = 0``: a run whose worker
  dies fails at once with :class:`distributed.KilledWorker` (reported as that run's failure)
  instead of being retried on the next worker (and possibly killing it too). An external
  scheduler keeps its own setting (``distributed.scheduler.allowed-failures``, default 3: a
  run that kills its worker is tried 4 times); the campaign records the value it found.
* Each record is written to ``runs/<i>.json`` (and the run's files to ``runs/<i>/``) as soon
  as it arrives, so a crashed or interrupted campaign keeps what it had. Aggregates use the
  successful runs in index order, so identical seeds give identical aggregates.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import shutil
import signal
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..errors import CampaignError
from ..io.atomic import ensure_output_dir
from .aggregate import aggregate
from .execute import execute_run, write_json, write_run_record
from .outputs import write_campaign_outputs
from .seeds import run_seed
from ..experiments.registry import Experiment, get_experiment, parse_params
from .tasks import Task, run_tasks

__all__ = ["CampaignResult", "run_campaign", "run_seed"]

log = logging.getLogger(__name__)


def quiet_loggers(families: Sequence[str]) -> None:
    """Silence every logger of the given families, children included: a child with a level
    of its own ignores its parent's (Dask's configuration sets ``tornado.application`` to
    ERROR, so silencing ``tornado`` alone left its tracebacks)."""
    names = [n for n in list(logging.root.manager.loggerDict)
             if n.split(".", 1)[0] in families]
    for name in (*families, *names):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


@contextlib.contextmanager
def _quiet_on_sigint():
    """While runs are collected, Ctrl-C first silences Dask's and tornado's loggers, then
    raises KeyboardInterrupt: the interrupted client's callbacks on the event-loop thread
    (``sync``'s cancel) otherwise log a traceback, racing the CLI's own one-line message.
    Only in the main thread (elsewhere signals cannot be handled)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum, frame):
        quiet_loggers(("distributed", "tornado", "asyncio"))
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@dataclasses.dataclass
class CampaignResult:
    """Outcome of :func:`run_campaign`.

    Attributes
    ----------
    experiment : str
    params : dict
    records : list of dict
        One per run in index order (``status``, ``seed``, ``figures`` or ``error``...).
    stats : dict
        :func:`~.aggregate.aggregate` of the successful runs.
    out_dir : Path
    scheduler : str
        Address of the scheduler used.
    elapsed_s : float
    """

    experiment: str
    params: dict
    records: list
    stats: dict
    out_dir: Path
    scheduler: str
    elapsed_s: float

    @property
    def failed(self) -> list[dict]:
        """Records of the runs that failed."""
        return [r for r in self.records if r["status"] != "ok"]

    @property
    def n_ok(self) -> int:
        """Number of successful runs."""
        return sum(r["status"] == "ok" for r in self.records)


def _positive_int(value, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise CampaignError(f"{what} must be an integer >= 1, got {value!r}")
    return int(value)


class WorkersCappedWarning(UserWarning):
    """More local workers asked for than the machine has cores: capped."""


def local_workers(workers: int | None) -> int:
    """Worker processes of a local cluster: ``workers``, at most the cores this process may
    run on (more only queue for the same cores and start slowly: 64 workers on 2 cores took
    93 s instead of 1.2 s, issue 49 item 6), with a warning when capped; default the cores."""
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    if workers is None or workers == 0:
        return cores
    if workers > cores:
        import warnings

        warnings.warn(f"--workers {workers}: this machine has {cores} cores; starting "
                      f"{cores} workers", WorkersCappedWarning, stacklevel=2)
        return cores
    return workers


@contextlib.contextmanager
def _client(scheduler: str | None, workers: int | None, allowed_failures: int):
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="10s", set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise CampaignError(f"cannot connect to Dask scheduler {scheduler}: {exc}") from None
        with client:
            yield client
        return
    n = local_workers(workers)
    muted: dict[str, int] = {}
    try:
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                          dashboard_address=":0", silence_logs=logging.ERROR,
                          scheduler_kwargs={"allowed_failures": allowed_failures}) as cluster, \
                Client(cluster, set_as_default=False) as client:
            try:
                yield client
            finally:  # the teardown's CommClosedError tracebacks are not the user's business
                muted = mute_loggers(("distributed", "tornado", "asyncio"))
    finally:
        for name, level in muted.items():
            logging.getLogger(name).setLevel(level)


def mute_loggers(families: Sequence[str]) -> dict[str, int]:
    """:func:`quiet_loggers` for a while: returns the levels to restore (issue 49 item 21:
    one of two API studies printed a Dask ``CommClosedError`` traceback at teardown)."""
    names = [*families, *(n for n in list(logging.root.manager.loggerDict)
                          if n.split(".", 1)[0] in families)]
    levels = {n: logging.getLogger(n).level for n in names}
    quiet_loggers(families)
    return levels


def _collect(client, exp: Experiment, params: dict, seeds: list[int], runs_dir: Path,
             records: dict[int, dict], on_record) -> None:
    """Run the campaign's tasks (:func:`~.tasks.run_tasks`), write each record as it arrives
    and store it in ``records`` (index -> record without file bytes)."""
    tasks = [Task(f"{exp.name}-run-{i}", i, s, execute_run, (exp, params, s, i))
             for i, s in enumerate(seeds)]

    def done(task: Task, rec: dict) -> None:
        rec.pop("lost", None)
        write_run_record(runs_dir, rec)
        rec.pop("files", None)
        records[task.index] = rec
        if on_record is not None:
            on_record(rec)

    run_tasks(client, tasks, done)


def run_campaign(experiment: str | Experiment, params: Mapping | None = None, runs: int = 4,
                 *, base_seed: int = 0, seeds: Sequence[int] | None = None,
                 scheduler: str | None = None, workers: int | None = None,
                 out_dir: str | Path, allowed_failures: int = 0, overwrite: bool = False,
                 on_record: Callable[[dict], None] | None = None) -> CampaignResult:
    """Run ``experiment`` ``runs`` times with independent seeds on Dask and aggregate.

    Parameters
    ----------
    experiment : str or Experiment
        Registered name (``"noise-mismatch"``) or an :class:`~sdr_di.experiments.registry.Experiment`.
    params : mapping, optional
        Typed parameter values overriding the experiment's defaults.
    runs : int
        Number of runs (>= 1).
    base_seed : int
        Seed of the campaign; run ``i`` uses :func:`run_seed` ``(base_seed, i)``.
    seeds : sequence of int, optional
        Explicit seeds instead (length ``runs``).
    scheduler : str, optional
        Dask scheduler address (``tcp://host:8786``); default: a local cluster.
    workers : int, optional
        Worker processes of the local cluster (default: the number of cores).
    out_dir : path
        Output folder (module docstring of :mod:`sdr_di.experiments` for its layout).
    allowed_failures : int
        Worker deaths a run may survive on the local cluster (default 0).
    overwrite : bool
        Replace the run records of an earlier campaign in ``out_dir``.
    on_record : callable, optional
        Called with each record as it arrives (progress display).

    Returns
    -------
    CampaignResult

    Raises
    ------
    ExperimentError
        Unknown experiment or bad parameter.
    CampaignError
        ``runs``/``workers``/``seeds`` invalid, output folder holds another campaign,
        scheduler unreachable.
    """
    t_start = time.perf_counter()
    exp = get_experiment(experiment)
    runs = _positive_int(runs, "runs")
    if workers is not None:
        workers = _positive_int(workers, "workers")
    if scheduler is not None and workers is not None:
        raise CampaignError("--workers applies to the local cluster only; with --scheduler "
                            "the cluster's workers are used")
    if seeds is None:
        seeds = [run_seed(base_seed, i) for i in range(runs)]
    else:
        seeds = [int(s) for s in seeds]
        if len(seeds) != runs:
            raise CampaignError(f"{len(seeds)} seeds given for {runs} runs")
    params = parse_params(exp, overrides=dict(params or {}))
    out = Path(out_dir)
    runs_dir = out / "runs"
    if runs_dir.exists() and not overwrite:
        raise CampaignError(f"output folder {out} already holds campaign runs; choose "
                            "another --out or pass --force to replace them")
    config = {"experiment": exp.name, "description": exp.description, "params": params,
              "runs": runs, "base_seed": int(base_seed), "seeds": seeds}
    records: dict[int, dict] = {}
    # connect (or start the local cluster) before touching the output folder
    with _client(scheduler, workers, allowed_failures) as client:
        address = client.scheduler.address
        try:
            found_failures = client.run_on_scheduler(
                lambda dask_scheduler: dask_scheduler.allowed_failures)
        except Exception:  # noqa: BLE001 - informational only
            found_failures = None
        ensure_output_dir(out)
        if runs_dir.exists():
            shutil.rmtree(runs_dir)
        ensure_output_dir(runs_dir)
        write_json(out / "campaign.json", {**config, "status": "running",
                                           "scheduler": address})
        try:
            with _quiet_on_sigint():
                _collect(client, exp, params, seeds, runs_dir, records, on_record)
        except BaseException as exc:
            # keep what arrived: the run records are on disk; say the campaign did not finish
            status = "interrupted" if isinstance(exc, KeyboardInterrupt) else "crashed"
            write_json(out / "campaign.json", {**config, "status": status,
                                               "scheduler": address,
                                               "error": f"{type(exc).__name__}: {exc}",
                                               "n_records": len(records)})
            raise

    ordered = [records[i] for i in range(runs)]
    stats = aggregate(r["figures"] for r in ordered if r["status"] == "ok")
    result = CampaignResult(experiment=exp.name, params=params, records=ordered, stats=stats,
                            out_dir=out, scheduler=address,
                            elapsed_s=time.perf_counter() - t_start)
    write_campaign_outputs(exp, result, config={**config, "scheduler": address,
                                                "scheduler_allowed_failures": found_failures})
    return result
