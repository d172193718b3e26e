"""Running a list of seeded runs: on a Dask client, or in this process; one code path for
``campaign`` (one cell) and ``study`` (cells x seeds).

A :class:`Task` is one call returning a run record (:func:`~.execute.execute_run` never
raises for an error inside the run). :func:`run_tasks` keeps at most one task per worker
thread in flight (a task only queued on a worker never shares the fate of a worker that dies
under another task), submits the next as one completes, and hands every record to
``on_result`` the moment it arrives, in completion order; a task whose worker died, or that
was lost otherwise, becomes a ``"failed"`` record naming why.
"""

from __future__ import annotations

import dataclasses
import uuid
from collections.abc import Callable, Sequence
from typing import Any

from .execute import failed_record

__all__ = ["Task", "run_tasks", "run_tasks_here"]


@dataclasses.dataclass(frozen=True)
class Task:
    """One run: ``fn(*args)`` returns its record; ``index`` and ``seed`` name it in a
    failure record; ``name`` is the Dask key stem."""

    name: str
    index: int
    seed: int
    fn: Callable[..., dict]
    args: tuple


def _threads(client) -> int:
    try:
        return max(1, sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001 - scheduler briefly unreachable: keep one run in flight
        return 1


def run_tasks(client, tasks: Sequence[Task], on_result: Callable[[Task, dict], Any]) -> None:
    """Run ``tasks`` on the Dask ``client`` (module notes)."""
    from distributed import KilledWorker, as_completed

    token = uuid.uuid4().hex[:8]
    pending = list(tasks)
    where: dict[str, Task] = {}
    ac = as_completed(loop=client.loop)

    def submit_next() -> None:
        t = pending.pop(0)
        fut = client.submit(t.fn, *t.args, pure=False, key=f"{t.name}-{token}")
        where[fut.key] = t
        ac.add(fut)

    for _ in range(min(_threads(client), len(pending))):
        submit_next()
    for fut in ac:
        t = where.pop(fut.key)
        try:
            rec = fut.result()
        except KilledWorker as exc:
            rec = failed_record(t.index, t.seed, f"worker died while running this run ({exc})")
            rec["lost"] = True
        except Exception as exc:  # noqa: BLE001 - lost task: that run's failure
            rec = failed_record(t.index, t.seed, f"{type(exc).__name__}: {exc}")
            rec["lost"] = True
        finally:
            fut.release()
        on_result(t, rec)
        while pending and len(where) < _threads(client):
            submit_next()
        if pending and not where:
            submit_next()


def run_tasks_here(tasks: Sequence[Task], on_result: Callable[[Task, dict], Any]) -> None:
    """Run ``tasks`` one after the other in this process (no cluster), each outside the
    command's input guard (:func:`~sdr_di.paths.outside_scope`: a task's intermediate
    files are its own), as on a worker."""
    from ..paths import outside_scope

    for t in tasks:
        with outside_scope():
            rec = t.fn(*t.args)
        on_result(t, rec)
