"""Running experiments and deciding claims: one run, Monte Carlo campaigns, studies.

Specification
    :mod:`.spec`: study specifications (TOML): cells x filters x seeds, claims
    (``docs/studies.md``).
Execution
    :mod:`.execute` one seeded run in a private folder (on a Dask worker or here);
    :mod:`.tasks` a list of runs on a Dask client or in this process;
    :mod:`.single_run` one run (``sdr-di robustness``); :mod:`.campaign` seeded runs of one
    experiment (``sdr-di campaign``); :mod:`.study` a study (``sdr-di study``).
Statistics
    :mod:`.paired` paired comparisons over seeds with Holm's correction;
    :mod:`.aggregate` figures over runs.
Reports
    :mod:`.tables` CSV and Markdown tables; :mod:`.outputs` a campaign's tables, plots and
    summary; :mod:`.campaign_report` and :mod:`.study_report` the HTML pages
    (``sdr-di report``).
CLI
    :mod:`.commands` the sub-commands above.

The experiments themselves (what one run does) are :mod:`sdr_di.experiments`.
"""

import importlib

#: Public names and the module each lives in: imported on first use (PEP 562), so the CLI's
#: parser (``studies.commands``) does not pull in scipy.stats and the experiments for
#: ``sdr-di generate`` or ``sdr-di run``.
_EXPORTS = {
    "CampaignResult": "campaign",
    "run_campaign": "campaign",
    "run_seed": "campaign",
    "render_report": "campaign_report",
    "RunResult": "single_run",
    "run_experiment": "single_run",
    "StudySpec": "spec",
    "load_study": "spec",
    "parse_study": "spec",
    "run_study": "study",
}


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "CampaignResult",
    "RunResult",
    "StudySpec",
    "load_study",
    "parse_study",
    "render_report",
    "run_campaign",
    "run_experiment",
    "run_seed",
    "run_study",
]
