"""Ensemble consistency of a study cell: ANEES and ANIS over its runs with their band.

Per cell and filter (Bar-Shalom, Li and Kirubarajan 2001, section 5.4.2):

* **The runs averaged** (``n_ensemble``): the filter's runs of the cell with status ``ok``
  whose NEES of position, velocity and attitude and whose NIS of every block the filter
  reports are all finite. One set of runs for every statistic, so all of a row's averages
  are over the same ``N`` runs.
* **The averages** ``anees_<q>`` (``q`` in pos, vel, att) and ``anis_<block>``: the mean over
  those runs of each run's value in ``runs.csv`` (``nees_<q>``, ``nis_<block>``), which is the
  run's time mean, over the scored window, of its NEES or NIS per degree of freedom. NaN for
  a block the filter's mode does not have (and for every column when ``N = 0``).
* **The band** ``_lo``, ``_hi``:
  :func:`~sdr_di.integration.consistency.ensemble_band` ``(N, dim)``, the two-sided 95 %
  chi-square band of the ensemble average at one epoch, per degree of freedom
  (``chi2.ppf([0.025, 0.975], N dim) / (N dim)``); ``dim`` 3 for NEES and, for NIS, the
  median over the runs of their block size (``nis_dof``: the number of channels in deep and
  tight mode, 3 in loose). A run's time mean varies less than one epoch's value, so the
  band is wider than that of the averaged quantity: an average outside it is inconsistent,
  one inside it is consistent at the per-epoch level only. It is the criterion of
  ``scripts/check_consistency.py --ensemble``, which takes the time mean of the ensemble
  average at the epochs the runs share; here the runs' windows start at their own seed's
  latest hand-over, so the two means differ by the weighting of the epochs only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..integration.consistency import CONSISTENCY_KEYS, ensemble_band

__all__ = ["ENSEMBLE_COLUMNS", "ensemble_consistency"]

#: NEES keys first, then every mode's NIS blocks (:data:`CONSISTENCY_KEYS` order).
_KEYS = tuple(k for k in CONSISTENCY_KEYS if k.startswith("nees_")) + tuple(
    k for k in CONSISTENCY_KEYS if k.startswith("nis_"))

#: The columns :func:`ensemble_consistency` adds to a ``cells.csv`` row, in order.
ENSEMBLE_COLUMNS = ("n_ensemble",) + tuple(
    f"a{k}{s}" for k in _KEYS for s in ("", "_lo", "_hi"))


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def ensemble_consistency(rows: Sequence[dict], level: float = 0.95) -> dict:
    """ANEES and ANIS of one cell and filter with their bands (module docstring).

    Parameters
    ----------
    rows : sequence of dict
        The filter's ``runs.csv`` rows of the cell: ``status``, ``nees_pos``, ``nees_vel``,
        ``nees_att`` (per degree of freedom, dimensionless), ``nis_<block>`` (NaN for
        another mode's blocks) and ``nis_dof`` (NaN or absent in records written before it
        was recorded: the NIS averages then have no band).
    level : float
        Two-sided probability of the band.

    Returns
    -------
    dict
        ``{column: value}`` for every column of :data:`ENSEMBLE_COLUMNS`.
    """
    ok = [r for r in rows if r.get("status") == "ok"]
    present = [k for k in _KEYS if any(_finite(r.get(k)) for r in ok)]
    use = [r for r in ok if all(_finite(r.get(k)) for k in present)]
    n = len(use)
    dofs = [float(r["nis_dof"]) for r in use if _finite(r.get("nis_dof"))]
    nis_dim = max(1, int(round(float(np.median(dofs))))) if dofs else None
    out: dict = {"n_ensemble": n}
    for k in _KEYS:
        value = lo = hi = math.nan
        if n and k in present:
            value = math.fsum(float(r[k]) for r in use) / n
            dim = 3 if k.startswith("nees_") else nis_dim
            if dim is not None:
                lo, hi = ensemble_band(n, dim, level)
        out.update({f"a{k}": value, f"a{k}_lo": lo, f"a{k}_hi": hi})
    return out
