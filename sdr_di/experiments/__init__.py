"""Robustness experiments (issue 6): each a small module run with a seed on generated files.

* :mod:`.registry`: experiments by name; an experiment is a small module with ``NAME``,
  ``default_params`` and ``run(params, seed, out_dir) -> dict`` of scalar figures, plus
  optional ``check_params``, ``tables`` and ``plots`` hooks (``docs/experiments.md``).
* :mod:`.noise_mismatch`: wrong Q (paper 000) or wrong R (paper 003) for every filter.
* :mod:`.count_change`, :mod:`.outage`, :mod:`.weak_signal`, :mod:`.jamming`: the receiver
  modes under a changing satellite count, a blockage, a C/N0 sweep, a jammer ramp.
* :mod:`.compare`: every filter and mode on the same files (the run of a study cell).
* :mod:`.variants`, :mod:`._deep`, :mod:`.filter_figures`, :mod:`.plotting`: their shared
  pieces (one receiver variant on shared files, generated inputs, figure names, PNG plots).

Running experiments (one run, Monte Carlo campaigns on Dask, studies with paired
statistics) and their reports are the package :mod:`sdr_di.studies` (their 0.1 names here
were removed in 0.2.0: CHANGELOG.md).
"""

from .registry import (
    Experiment,
    experiment_names,
    get_experiment,
    parse_params,
    register_experiment,
)

__all__ = [
    "Experiment",
    "experiment_names",
    "get_experiment",
    "parse_params",
    "register_experiment",
]
