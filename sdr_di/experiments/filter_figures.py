"""Per-filter figure names shared by the experiments: quantities, statistics, labels.

Experiments that compare filters name their figures ``"<filter>.<quantity>_<stat>"``
(e.g. ``"ff-aukf.pos_m_rmse"``) with the quantities and statistics below. The entries
themselves are parsed by :mod:`sdr_di.experiments.entries`; the RMSE bar plot is
:func:`sdr_di.experiments.plotting.rmse_bar_plot`. Nothing here draws.
"""

from __future__ import annotations

from ..filters.plugins import is_import_path, plugin_names
from ..filters.registry import FILTER_NAMES

__all__ = ["QUANTITIES", "STATS", "filter_names_in", "split_figure_key"]

#: (figure stem, axis label) of the error norms every filter comparison reports.
QUANTITIES = (("att_deg", "attitude [deg]"), ("vel_mps", "velocity [m/s]"),
              ("pos_m", "position [m]"))
#: Statistics of each quantity.
STATS = ("rmse", "max")


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
