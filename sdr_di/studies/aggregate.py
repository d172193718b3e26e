"""Statistics of figures over the runs of a campaign.

Runs are taken in index order (never completion order) and sums use :func:`math.fsum`, so
the same seeds give bit-identical aggregates whatever the cluster and scheduling.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

__all__ = ["aggregate", "single_stats"]


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def aggregate(figure_dicts: Iterable[dict]) -> dict[str, dict]:
    """Mean, std, min, max of every numeric figure over runs.

    Parameters
    ----------
    figure_dicts : iterable of dict
        The figures of each successful run, in run-index order.

    Returns
    -------
    dict
        ``{figure: {"n", "n_nonfinite", "mean", "std", "min", "max"}}`` for numeric figures
        (``n`` finite values; ``std`` is the sample standard deviation, 0 for one value;
        NaN statistics when no value is finite) and ``{figure: {"value": s}}`` for a text
        figure equal in every run (text figures that differ are listed as ``"(varies)"``).
    """
    values: dict[str, list] = {}
    for figs in figure_dicts:
        for key, v in figs.items():
            values.setdefault(key, []).append(v)
    out: dict[str, dict] = {}
    for key, vs in values.items():
        if all(_is_number(v) for v in vs):
            fin = [float(v) for v in vs if math.isfinite(v)]
            n = len(fin)
            if n:
                mean = math.fsum(fin) / n
                std = math.sqrt(math.fsum((v - mean) ** 2 for v in fin) / (n - 1)) if n > 1 \
                    else 0.0
                lo, hi = min(fin), max(fin)
            else:
                mean = std = lo = hi = math.nan
            out[key] = {"n": n, "n_nonfinite": len(vs) - n, "mean": mean, "std": std,
                        "min": lo, "max": hi}
        else:
            texts = {str(v) for v in vs}
            out[key] = {"value": texts.pop() if len(texts) == 1 else "(varies)"}
    return out


def single_stats(figures: dict) -> dict[str, dict]:
    """Figures of one run in the shape of :func:`aggregate` (``n = 1``, ``std = 0``)."""
    return aggregate([figures])
