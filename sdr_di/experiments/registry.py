"""Experiment registry: names -> experiment modules, and ``--param key=value`` parsing.

An *experiment* is a small module (see ``docs/experiments.md``) with

``NAME`` : str
    The command-line name (``"noise-mismatch"``).
``DESCRIPTION`` : str
    One line for ``--help`` and reports.
``default_params`` : dict
    Every parameter the experiment accepts with its default; the default's type decides how a
    ``--param key=value`` string is read (bool, int, float, str; a dict reads a JSON object;
    ``None`` reads a number, or ``none``, or else keeps the string).
``run(params, seed, out_dir) -> dict``
    One seeded run: a flat dict of scalar figures (float, int, str); may write time series
    (CSV) and plots (PNG) into ``out_dir``. Must depend only on ``params`` and ``seed``.

and optionally

``check_params(params) -> None``
    Raise :class:`~sdr_di.errors.ExperimentError` for a bad value (called before any run).
``tables(stats) -> dict[str, list[dict]]``
    Named tables built from figure statistics ``stats[figure] = {"n", "mean", "std", "min",
    "max"}`` (one run: ``n = 1``, ``std = 0``).
``plots(results, out_dir) -> list[Path]``
    Campaign-level plots from the list of successful run results (``{"index", "seed",
    "figures"}``).

Built-in experiments are listed in :data:`BUILTIN` as ``name -> module path`` and imported
lazily; others (tests, plug-ins) are added with :func:`register_experiment`.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import math
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from types import ModuleType
from typing import Any

from ..errors import ExperimentError

__all__ = ["BUILTIN", "Experiment", "experiment_names", "get_experiment", "parse_params",
           "register_experiment"]

#: Built-in experiments: command name -> module (imported on first use). The deep-mode
#: experiments (``count-change``, ``outage``, ``weak-signal``) are added here, one line each.
BUILTIN: dict[str, str] = {
    "noise-mismatch": "sdr_di.experiments.noise_mismatch",
    "count-change": "sdr_di.experiments.count_change",
    "outage": "sdr_di.experiments.outage",
    "weak-signal": "sdr_di.experiments.weak_signal",
    "compare": "sdr_di.experiments.compare",
    "jamming": "sdr_di.experiments.jamming",
}

_REGISTERED: dict[str, Experiment] = {}


@dataclasses.dataclass(frozen=True)
class Experiment:
    """An experiment: its name, defaults and hooks (see the module docstring).

    Instances are pickled to Dask workers, so ``run`` and the hooks must be importable
    module-level functions.
    """

    name: str
    run: Callable[[dict, int, Path], dict]
    default_params: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    description: str = ""
    check_params: Callable[[dict], None] | None = None
    tables: Callable[[dict], dict] | None = None
    plots: Callable[[list, Path], list] | None = None

    @classmethod
    def from_module(cls, module: ModuleType) -> Experiment:
        """Build an :class:`Experiment` from a module following the interface above."""
        for attr in ("NAME", "run", "default_params"):
            if not hasattr(module, attr):
                raise ExperimentError(f"experiment module {module.__name__} has no {attr!r}")
        return cls(name=module.NAME, run=module.run, default_params=dict(module.default_params),
                   description=getattr(module, "DESCRIPTION", ""),
                   check_params=getattr(module, "check_params", None),
                   tables=getattr(module, "tables", None), plots=getattr(module, "plots", None))


def register_experiment(experiment: Experiment | ModuleType) -> Experiment:
    """Register an experiment (an :class:`Experiment` or a module) under its name."""
    if isinstance(experiment, ModuleType):
        experiment = Experiment.from_module(experiment)
    _REGISTERED[experiment.name] = experiment
    return experiment


def experiment_names() -> list[str]:
    """Names of all known experiments (built-in and registered), sorted."""
    return sorted(set(BUILTIN) | set(_REGISTERED))


def get_experiment(name: str | Experiment) -> Experiment:
    """The experiment called ``name``.

    Raises
    ------
    ExperimentError
        No such experiment.
    """
    if isinstance(name, Experiment):
        return name
    if name in _REGISTERED:
        return _REGISTERED[name]
    if name in BUILTIN:
        return register_experiment(importlib.import_module(BUILTIN[name]))
    raise ExperimentError(f"unknown experiment {name!r}; known: {', '.join(experiment_names())}")


_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


def _coerce(key: str, text: str, default: Any) -> Any:
    t = text.strip()
    try:
        if isinstance(default, bool):
            if t.lower() in _TRUE:
                return True
            if t.lower() in _FALSE:
                return False
            raise ValueError("expected true/false")
        if isinstance(default, dict):
            v = json.loads(t)
            if not isinstance(v, dict):
                raise ValueError("expected a JSON object")  # noqa: TRY004 - reported below
            return v
        if isinstance(default, int):
            return int(t)
        if isinstance(default, float):
            v = float(t)
            if not math.isfinite(v):
                raise ValueError("not finite")
            return v
        if default is None:
            if t.lower() in ("", "none"):
                return None
            try:
                v = float(t)
            except ValueError:
                return t
            if not math.isfinite(v):
                raise ValueError("not finite")
            return v
    except ValueError as exc:
        kind = ("true/false" if isinstance(default, bool) else
                "a JSON object" if isinstance(default, dict) else type(default).__name__)
        raise ExperimentError(f"--param {key}={text}: expected {kind} ({exc})") from None
    return t


def parse_params(experiment: Experiment, pairs: Iterable[str] = (),
                 overrides: Mapping[str, Any] | None = None) -> dict:
    """Defaults of ``experiment`` updated by ``key=value`` strings and ``overrides``.

    Parameters
    ----------
    experiment : Experiment
    pairs : iterable of str
        ``"key=value"`` strings (``--param``); values are read as the default's type.
    overrides : mapping, optional
        Already-typed values (``--duration``...); keys must be known parameters.

    Raises
    ------
    ExperimentError
        Malformed pair, unknown key, value of the wrong kind, or rejected by the experiment's
        ``check_params``.
    """
    params = dict(experiment.default_params)
    known = ", ".join(sorted(params)) or "(none)"
    for pair in pairs:
        key, sep, value = pair.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ExperimentError(f"--param {pair!r}: expected key=value")
        if key not in params:
            raise ExperimentError(f"--param {key}: unknown parameter of {experiment.name}; "
                                  f"known: {known}")
        params[key] = _coerce(key, value, experiment.default_params[key])
    for key, value in (overrides or {}).items():
        if key not in params:
            raise ExperimentError(f"{experiment.name} has no parameter {key!r}; known: {known}")
        params[key] = value
    if experiment.check_params is not None:
        experiment.check_params(params)
    return params
