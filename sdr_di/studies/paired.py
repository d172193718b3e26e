"""Paired statistics of a study: filter vs filter on the same seeds, with a family-wise error
rate held across cells x filters x quantities.

For one cell, a filter ``f``, the filter it is compared with ``b`` (the study's baseline, or
a claim's ``against``) and a quantity (position, velocity or attitude RMSE), the seeds give
pairs ``(x_f[i], x_b[i])`` from the same files. A run that failed or diverged (the task
failed, the variant raised, or its RMSE is not finite) has no value.

* **Win count and exact sign test.** ``f`` wins seed ``i`` when both values exist and
  ``x_f < x_b``, or when only ``f``'s exists (a failed run is a loss for its filter). Ties
  and seeds where both failed are non-wins: the count is conservative for either side.
  The one-sided sign test is the exact binomial tail ``P(W >= wins | n, 1/2)`` over all
  ``n`` seeds (:func:`scipy.stats.binomtest`).
* **Paired t interval** on the seeds where both have a value: on the differences
  ``d = x_f - x_b`` (in the quantity's unit) and on the log ratios ``ln(x_f / x_b)``
  (reported as the ratio ``exp``, its geometric mean). With 8 seeds a percentile bootstrap
  undercovers (about 89 % for a nominal 95 %); the t interval is exact for normal
  differences and close to nominal for mildly skewed ones, which log ratios of RMSE are.
* **Multiplicity.** The t test's and the sign test's p-values are Holm-adjusted over the
  family (every cell x compared filter x quantity, :func:`holm`); intervals are at level
  ``1 - alpha / m`` (Bonferroni, the interval counterpart of Holm's first step: Holm's
  step-down has no interval form of its own), so a *corrected interval* covers all ``m``
  differences at once with probability at least ``1 - alpha``.

A claim (:class:`~.spec.Claim`) holds in a cell when, for every quantity it names,
the filter wins at least ``min_wins`` seeds, the uncorrected one-sided sign-test p is at most
``max_sign_p`` and (when asked) the corrected interval of the spec's kind lies below 0; it is
*reversed* when the other filter meets the same criterion; otherwise it is *not shown*.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from scipy import stats

__all__ = ["Comparison", "claim_verdict", "compare_pair", "holm", "t_interval"]


def holm(p_values: Sequence[float]) -> np.ndarray:
    """Holm step-down adjusted p-values (NaN stays NaN and is not counted in ``m``)."""
    p = np.asarray(p_values, float)
    out = np.full(p.shape, math.nan)
    ok = np.flatnonzero(np.isfinite(p))
    m = ok.size
    if m == 0:
        return out
    order = ok[np.argsort(p[ok], kind="stable")]
    running = 0.0
    for rank, idx in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[idx]))
        out[idx] = running
    return out


def t_interval(x: np.ndarray, level: float) -> tuple[float, float, float, float]:
    """Mean, two-sided t interval at ``level`` and the t test's two-sided p (mean 0).

    Fewer than 2 values: the mean (or NaN) and NaN bounds; zero spread: the mean as both
    bounds and p = 0 (or 1 when the mean is 0).
    """
    x = np.asarray(x, float)
    n = x.size
    if n == 0:
        return math.nan, math.nan, math.nan, math.nan
    mean = float(np.mean(x))
    if n < 2:
        return mean, math.nan, math.nan, math.nan
    sd = float(np.std(x, ddof=1))
    if sd == 0.0:
        return mean, mean, mean, (1.0 if mean == 0.0 else 0.0)
    half = float(stats.t.ppf(0.5 + level / 2.0, n - 1)) * sd / math.sqrt(n)
    p = float(stats.ttest_1samp(x, 0.0).pvalue)
    return mean, mean - half, mean + half, p


def ratio_of_log(log_ratio: float) -> float:
    """``exp(log_ratio)``: inf beyond the float range (a Holm-corrected interval over 2 seeds
    reaches log bounds of +-1000), NaN for NaN."""
    if math.isnan(log_ratio):
        return math.nan
    return math.inf if log_ratio > 709.0 else math.exp(log_ratio)


def mean_ratio(log_mean: float) -> float:
    """Geometric-mean ratio ``exp(log_mean)`` of a paired comparison: NaN when the mean log
    ratio is not finite (an RMSE of 0 or inf in a pair), inf beyond the float range."""
    return ratio_of_log(log_mean) if math.isfinite(log_mean) else math.nan


@dataclasses.dataclass
class Comparison:
    """Filter ``filter`` against ``against`` on one cell and quantity (module notes).

    ``d_*`` are in the quantity's unit; ``ratio*`` are ``exp`` of the log-ratio mean and
    interval bounds; ``*_holm`` are filled by the study once the family is known.
    """

    cell: str
    filter: str
    against: str
    quantity: str
    n: int
    n_pairs: int
    wins: int
    losses: int
    d_mean: float
    d_ci_low: float
    d_ci_high: float
    d_p: float
    log_mean: float
    log_ci_low: float
    log_ci_high: float
    log_p: float
    sign_p: float
    sign_p_reverse: float
    level: float
    t_p_holm: float = math.nan
    sign_p_holm: float = math.nan

    @property
    def ratio(self) -> float:
        """Geometric-mean RMSE ratio ``filter / against``."""
        return mean_ratio(self.log_mean)

    def interval(self, kind: str) -> tuple[float, float]:
        """Corrected interval of the differences (``"difference"``) or log ratios."""
        return ((self.d_ci_low, self.d_ci_high) if kind == "difference"
                else (self.log_ci_low, self.log_ci_high))


def compare_pair(cell: str, filt: str, against: str, quantity: str, x_f: Sequence[float],
                 x_b: Sequence[float], level: float) -> Comparison:
    """Win count, sign tests and paired t intervals of ``x_f`` vs ``x_b`` (one value per
    seed, NaN where the run failed or diverged) at interval ``level`` (module notes)."""
    xf = np.asarray(x_f, float)     # RMSE of the filter and of the baseline, per seed
    xb = np.asarray(x_b, float)
    ok_f = np.isfinite(xf) & (xf >= 0)
    ok_b = np.isfinite(xb) & (xb >= 0)
    both = ok_f & ok_b
    wins = int(np.sum(both & (xf < xb)) + np.sum(ok_f & ~ok_b))
    losses = int(np.sum(both & (xb < xf)) + np.sum(ok_b & ~ok_f))
    n = int(xf.size)
    sign_p = float(stats.binomtest(wins, n, 0.5, alternative="greater").pvalue) if n else \
        math.nan
    sign_r = float(stats.binomtest(losses, n, 0.5, alternative="greater").pvalue) if n else \
        math.nan
    d = xf[both] - xb[both]
    d_mean, d_lo, d_hi, d_p = t_interval(d, level)
    pos = both & (xf > 0) & (xb > 0)
    lr = np.log(xf[pos] / xb[pos])
    l_mean, l_lo, l_hi, l_p = t_interval(lr, level) if pos.sum() == both.sum() else \
        (math.nan,) * 4
    return Comparison(cell, filt, against, quantity, n, int(both.sum()), wins, losses,
                      d_mean, d_lo, d_hi, d_p, l_mean, l_lo, l_hi, l_p, sign_p, sign_r, level)


def claim_verdict(comps: Sequence[Comparison], min_wins: int, max_sign_p: float,
                  excludes_zero: bool, kind: str) -> str:
    """``"holds"``, ``"reversed"`` or ``"not shown"`` of a claim on one cell, from its
    comparisons (one per quantity it names; module notes)."""
    def meets(c: Comparison, reverse: bool) -> bool:
        wins, p = (c.losses, c.sign_p_reverse) if reverse else (c.wins, c.sign_p)
        if not (wins >= min_wins and math.isfinite(p) and p <= max_sign_p):
            return False
        if not excludes_zero:
            return True
        lo, hi = c.interval(kind)
        return (math.isfinite(lo) and lo > 0) if reverse else (math.isfinite(hi) and hi < 0)

    if comps and all(meets(c, False) for c in comps):
        return "holds"
    if comps and all(meets(c, True) for c in comps):
        return "reversed"
    return "not shown"
