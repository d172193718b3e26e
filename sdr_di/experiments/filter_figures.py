"""Per-filter figures shared by the experiments: names, quantities and the RMSE bar plot.

Experiments that compare filters name their figures ``"<filter>.<quantity>_<stat>"``
(e.g. ``"ff-aukf.pos_m_rmse"``) with the quantities and statistics below.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ..errors import ExperimentError
from ..filters import FILTER_NAMES

__all__ = ["QUANTITIES", "STATS", "filter_list", "filter_names_in", "parse_filter_spec",
           "rmse_bar_plot"]

#: (figure stem, axis label) of the error norms every filter comparison reports.
QUANTITIES = (("att_deg", "attitude [deg]"), ("vel_mps", "velocity [m/s]"),
              ("pos_m", "position [m]"))
#: Statistics of each quantity.
STATS = ("rmse", "max")


def filter_list(exp: str, text: str) -> list[str]:
    """Filter names of a ``filters`` parameter (``all`` or a comma list).

    An entry may carry filter options after colons (``ff-aukf:q_states=nominal``,
    :func:`parse_filter_spec`); the entries are returned as given (lower case).
    """
    if str(text).strip().lower() == "all":
        return list(FILTER_NAMES)
    names = [n.strip().lower() for n in str(text).split(",") if n.strip()]
    bad = [n for n in names if n.partition(":")[0] not in FILTER_NAMES]
    if bad or not names:
        raise ExperimentError(f"{exp}: filters={text!r}: unknown filter(s) "
                              f"{', '.join(bad) or '(none given)'}; valid: all or "
                              f"{', '.join(FILTER_NAMES)}")
    for n in names:
        parse_filter_spec(exp, n)
    return names


def _option_value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_filter_spec(exp: str, spec: str) -> tuple[str, dict]:
    """``"ff-aukf:q_states=nominal:window=25"`` -> ``("ff-aukf", {"q_states": "nominal",
    "window": 25})``: the filter name and its options (numbers read as int or float).

    Raises
    ------
    ExperimentError
        Unknown filter, an option without ``=``, or a ``.``/``@``/``,`` in the spec (these
        separate figure names, modes and list entries).
    """
    if any(c in str(spec) for c in ".@,"):
        raise ExperimentError(f"{exp}: filter {spec!r}: '.', '@' and ',' are not allowed in "
                              "a filter entry (they separate figure names, modes, entries)")
    name, *opts = str(spec).strip().lower().split(":")
    if name not in FILTER_NAMES:
        raise ExperimentError(f"{exp}: filter {spec!r}: unknown filter {name!r}; valid: "
                              f"{', '.join(FILTER_NAMES)}")
    options = {}
    for o in opts:
        key, eq, val = o.partition("=")
        if not eq or not key or not val:
            raise ExperimentError(f"{exp}: filter {spec!r}: option {o!r} is not key=value")
        options[key] = _option_value(val)
    return name, options


def filter_names_in(stats: dict) -> list[str]:
    """Variant labels that prefix figure keys (``"ff-aukf.pos_m_rmse"``,
    ``"ekf@tight.pos_m_rmse"``, ``"ff-aukf:q_states=nominal.pos_m_rmse"``), in order."""
    seen = []
    for key in stats:
        name, dot, _ = key.partition(".")
        base = name.partition("@")[0].partition(":")[0]
        if dot and base in FILTER_NAMES and name not in seen:
            seen.append(name)
    return seen


def rmse_bar_plot(results: list[dict], out_dir: Path, title: str) -> list[Path]:
    """``rmse_by_filter.png``: mean RMSE per filter over the runs, std as error bars."""
    from . import plotting

    if not results or plotting.matplotlib_missing():
        return []
    names = filter_names_in(results[0]["figures"])
    if not names:
        return []
    panels = []
    for q, label in QUANTITIES:
        vals = np.array([[r["figures"].get(f"{n}.{q}_rmse", math.nan) for n in names]
                         for r in results], float)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            panels.append((f"RMSE {label}", np.nanmean(vals, axis=0),
                           np.nanstd(vals, axis=0) if len(results) > 1 else None))
    return [plotting.bar_chart(Path(out_dir) / "rmse_by_filter.png", names, panels,
                               title=f"{title} ({len(results)} runs)")]
