"""Per-filter figures shared by the experiments: names, quantities and the RMSE bar plot.

Experiments that compare filters name their figures ``"<filter>.<quantity>_<stat>"``
(e.g. ``"ff-aukf.pos_m_rmse"``) with the quantities and statistics below.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from ..errors import ExperimentError, SdrDiError
from ..filters import FILTER_NAMES
from ..filters import parse_filter_spec as _parse
from ..filters.plugins import is_import_path, plugin_names
from ..filters.spec import split_filter_spec

__all__ = ["QUANTITIES", "STATS", "canonical_entry", "filter_list", "filter_names_in",
           "parse_filter_spec", "split_figure_key",
           "rmse_bar_plot"]

#: (figure stem, axis label) of the error norms every filter comparison reports.
QUANTITIES = (("att_deg", "attitude [deg]"), ("vel_mps", "velocity [m/s]"),
              ("pos_m", "position [m]"))
#: Statistics of each quantity.
STATS = ("rmse", "max")


def canonical_entry(entry: str) -> str:
    """A filter entry (``ff-aukf:q_states=nominal``, ``ekf@tight``) in lower case, except an
    import path (``pkg.mod:MyEKF``) and its options, whose case is kept."""
    text = str(entry).strip()
    spec, at, mode = text.partition("@")
    try:
        name, pairs = split_filter_spec(spec)
    except SdrDiError:  # malformed: left to parse_filter_spec's message
        return text.lower()
    if not is_import_path(name):
        return text.lower()
    return ":".join([name] + [f"{k}={v}" for k, v in pairs]) + (
        f"@{mode.strip().lower()}" if at else "")


def filter_list(exp: str, text: str) -> list[str]:
    """Filter entries of a ``filters`` parameter (``all`` or a comma list).

    An entry may carry filter options after colons (``ff-aukf:q_states=nominal``) or be a
    plugin (``pkg.mod:MyEKF``), :func:`parse_filter_spec`; the entries are returned as
    given (:func:`canonical_entry`).
    """
    if str(text).strip().lower() == "all":
        return list(FILTER_NAMES)
    names = [canonical_entry(n) for n in str(text).split(",") if n.strip()]
    if not names:
        raise ExperimentError(f"{exp}: filters={text!r}: unknown filter(s) (none given); "
                              f"valid: all or {', '.join(FILTER_NAMES)}")
    for n in names:
        parse_filter_spec(exp, n)
    return names


def parse_filter_spec(exp: str, spec: str) -> tuple[str, dict]:
    """``"ff-aukf:q_states=nominal:window=25"`` -> ``("ff-aukf", {"q_states": "nominal",
    "window": 25})``: the filter name and its options, typed by
    :func:`sdr_di.filters.parse_filter_spec` (the one parser of filter entries).

    Raises
    ------
    ExperimentError
        Unknown filter, a plugin that fails to import, a bad option or value, or a ``@``/``,``
        in the spec (these separate modes and list entries).
    """
    if any(c in str(spec) for c in "@,"):
        raise ExperimentError(f"{exp}: filter {spec!r}: '@' and ',' are not allowed in "
                              "a filter entry (they separate modes and entries)")
    try:
        fs = _parse(canonical_entry(spec))
    except SdrDiError as exc:
        raise ExperimentError(f"{exp}: {exc}") from None
    return fs.name, dict(fs.options)


def split_figure_key(key: str) -> tuple[str, str]:
    """``"ff-aukf:d=0.9@tight.seg1.updating"`` -> ``("ff-aukf:d=0.9@tight", "seg1.updating")``.

    The label ends at the first ``.`` after its last ``:`` (an import path's dots come before
    it) that is not followed by a digit (a number's decimal point); figure names start with a
    letter."""
    key = str(key)
    i = key.rfind(":") + 1
    while True:
        j = key.find(".", i)
        if j < 0:
            return key, ""
        if j + 1 < len(key) and not key[j + 1].isdigit():
            return key[:j], key[j + 1:]
        i = j + 1


def filter_names_in(stats: dict) -> list[str]:
    """Variant labels that prefix figure keys (``"ff-aukf.pos_m_rmse"``,
    ``"ekf@tight.pos_m_rmse"``, ``"ff-aukf:q_states=nominal.pos_m_rmse"``,
    ``"pkg.mod:MyEKF.pos_m_rmse"``), in order (:func:`split_figure_key`)."""
    seen = []
    for key in stats:
        name, dot = split_figure_key(key)[0], "." in key
        base = name.partition("@")[0]
        known = base.partition(":")[0] in FILTER_NAMES or base in plugin_names() or (
            is_import_path(base) and "." in base.partition(":")[0])
        if dot and known and name not in seen:
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
