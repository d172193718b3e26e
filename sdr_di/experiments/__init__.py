"""Robustness experiments, Monte Carlo campaigns on Dask, and their reports (issue 6).

* :mod:`.registry`: experiments by name; an experiment is a small module with ``NAME``,
  ``default_params`` and ``run(params, seed, out_dir) -> dict`` of scalar figures, plus
  optional ``check_params``, ``tables`` and ``plots`` hooks (``docs/experiments.md``).
* :mod:`.noise_mismatch`: wrong Q (paper 000) or wrong R (paper 003) for every filter.
* :func:`run_experiment`: one run (``sdr-di robustness``).
* :func:`run_campaign`: ``runs`` seeded runs in parallel on a Dask cluster (local processes
  by default, or a scheduler address), aggregated (``sdr-di campaign``).
* :func:`render_report`: one self-contained HTML page of a result folder (``sdr-di report``).
"""

from .campaign import CampaignResult, run_campaign, run_seed
from .registry import (
                       Experiment,
                       experiment_names,
                       get_experiment,
                       parse_params,
                       register_experiment,
)
from .report import render_report
from .single_run import RunResult, run_experiment

__all__ = [
    "CampaignResult",
    "Experiment",
    "RunResult",
    "experiment_names",
    "get_experiment",
    "parse_params",
    "register_experiment",
    "render_report",
    "run_campaign",
    "run_experiment",
    "run_seed",
]
