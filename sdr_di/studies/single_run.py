"""One run of an experiment (``sdr-di robustness``): in-process, or on a Dask scheduler."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path

from ..errors import CampaignError
from ..io.atomic import ensure_output_dir
from .execute import execute_run, write_files
from .outputs import write_single_outputs
from ..experiments.registry import Experiment, get_experiment, parse_params

__all__ = ["RunResult", "run_experiment"]


@dataclasses.dataclass
class RunResult:
    """Outcome of :func:`run_experiment`: the record (``status``, ``figures`` or ``error``,
    ``files``...), the parameters used and the output folder."""

    experiment: str
    params: dict
    record: dict
    out_dir: Path

    @property
    def ok(self) -> bool:
        """Whether the run completed."""
        return self.record["status"] == "ok"


def run_experiment(experiment: str | Experiment, params: Mapping | None = None, seed: int = 0,
                   *, out_dir: str | Path, scheduler: str | None = None) -> RunResult:
    """Run ``experiment`` once with ``seed`` and write its outputs into ``out_dir``.

    Parameters
    ----------
    experiment : str or Experiment
    params : mapping, optional
        Typed values overriding the defaults.
    seed : int
    out_dir : path
        Output folder (``result.json``, ``figures.csv/.md``, the experiment's tables, plots
        and files).
    scheduler : str, optional
        Run it as one task on this Dask scheduler instead of in this process.

    Raises
    ------
    ExperimentError
        Unknown experiment or bad parameter.
    CampaignError
        Negative seed, scheduler unreachable, or the worker died.
    """
    exp = get_experiment(experiment)
    params = parse_params(exp, overrides=dict(params or {}))
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise CampaignError(f"seed must be an integer >= 0, got {seed!r}")
    out = ensure_output_dir(out_dir)
    if scheduler is None:
        from ..paths import outside_scope

        with outside_scope():   # the run's intermediate files are its own, as on a worker
            rec = execute_run(exp, params, seed, 0)
    else:
        from distributed import KilledWorker

        from .campaign import _client

        with _client(scheduler, None, 0) as client:
            try:
                rec = client.submit(execute_run, exp, params, seed, 0, pure=False).result()
            except KilledWorker as exc:
                raise CampaignError(f"{exp.name}: the worker died during the run ({exc})") \
                    from None
    files = rec.pop("files", {})
    rec["files"] = write_files(out, files) if files else []
    write_single_outputs(exp, rec, params, out)
    return RunResult(experiment=exp.name, params=params, record=rec, out_dir=out)
