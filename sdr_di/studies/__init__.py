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

from .campaign import CampaignResult, run_campaign, run_seed
from .campaign_report import render_report
from .single_run import RunResult, run_experiment
from .spec import StudySpec, load_study, parse_study
from .study import run_study

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
