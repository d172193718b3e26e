"""Filter consistency of a run: NIS per measurement block, NEES per quantity, formal sigmas.

A filter is consistent when its covariances match its errors. Two normalized statistics
test that, each with expected value 1 per degree of freedom:

NIS per block ``b`` of an update (innovation ``y``, innovation covariance ``S``)::

    NIS_b = y_b^T (S_bb)^-1 y_b / dim_b

with ``y_b`` the block's rows of ``y`` and ``S_bb`` the block's diagonal block of ``S``
(the marginal covariance of ``y_b``). Blocks: deep ``code`` and ``rate`` (z = [code ranges,
rates], paper 004 eq 7-9), tight ``range`` and ``rate``, loose and ``lc`` ``vel`` and
``pos`` (z = [velocity, position], paper 000 eq 13).

NEES per quantity ``q`` (position, velocity, attitude) of a solution row, against the
truth, with the filter's covariance after the feedback (the error state is then zero, so
the corrected solution's error is the filter's error)::

    NEES_q = e_q^T (P_qq)^-1 e_q / 3

``e_pos`` in ENU metres (:func:`~sdr_di.integration.metrics.nav_errors`) and ``P_pos``
mapped from the (lat, lon, h) error states to ENU metres (:func:`enu_blocks`); velocity in
ENU m/s; attitude the rotation vector ``phi`` in the navigation frame (ENU), the error
model's convention (:mod:`sdr_di.ins.error_model`, state 0-2) and that of ``nav_errors``.

Band (:data:`BAND_RULE`): the mean of ``N`` samples of a statistic with ``d`` degrees of
freedom per sample is, for a consistent filter and independent samples, chi-square with
``N d`` degrees of freedom divided by ``N d``. Successive samples of a closed loop are
correlated, so ``N`` is replaced by the effective count ``N_eff = N / (1 + 2 sum_k rho_k)``,
``rho_k`` the sample autocorrelation of the statistic at lag ``k``, summed over the
initial positive run of lags (up to ``N / 4``); ``N_eff`` is at most ``N``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import chdtri

from ..frames import radii_of_curvature
from . import _numba_consistency as _nb
from .metrics import time_window

__all__ = ["BAND_RULE", "CONSISTENCY_KEYS", "NIS_BLOCKS", "SD_COLUMNS", "block_nis",
           "chi2_band", "consistency_summary", "effective_count", "ensemble_band",
           "enu_blocks", "flat", "formal_sd", "nees_per_dof", "verdict"]

#: NIS block names of each mode, in the order of ``z`` (two equal halves).
NIS_BLOCKS = {"deep": ("code", "rate"), "tight": ("range", "rate"), "loose": ("vel", "pos"),
              "lc": ("vel", "pos")}

#: Every NIS block and NEES key of any mode (study ``runs.csv`` / ``cells.csv`` columns).
CONSISTENCY_KEYS = ("nis_code", "nis_range", "nis_rate", "nis_vel", "nis_pos", "nees_pos",
                    "nees_vel", "nees_att")

#: Formal 1-sigma columns of every integrated mode's solution CSV (:func:`formal_sd`).
SD_COLUMNS = ("pos_sd_e_m", "pos_sd_n_m", "pos_sd_u_m", "vel_sd_e", "vel_sd_n", "vel_sd_u",
              "att_sd_e_deg", "att_sd_n_deg", "att_sd_u_deg")

#: How the ``band`` of a consistency entry treats time-correlated samples.
BAND_RULE = ("95 % chi-square band of the mean of N_eff * dof samples, divided by "
             "N_eff * dof (dof: 3 for NEES, the block's median size for NIS); "
             "N_eff = N / (1 + 2 sum_k rho_k), rho_k the statistic's lag-k sample "
             "autocorrelation summed over the initial positive lags (k <= N/4); N_eff <= N")


#: Whether :func:`block_nis` runs its numba kernel (:mod:`._numba_consistency`, one call per
#: update); False: the numpy form (the tested reference; the two agree to an ulp).
jit = True


def block_nis(y: np.ndarray, S: np.ndarray, n_blocks: int = 2) -> np.ndarray:
    """NIS per degree of freedom of each of ``n_blocks`` equal contiguous blocks of ``y``.

    Parameters
    ----------
    y : (m,) array
        Innovation ``z - z^-``.
    S : (m, m) array
        Its covariance ``P_zz + R``.
    n_blocks : int
        Equal blocks of ``y`` (``m`` a multiple of it; otherwise one block, the rest NaN).

    Returns
    -------
    (n_blocks,) array
        ``y_b^T S_bb^-1 y_b / dim_b`` of each block.
    """
    y = np.asarray(y, float)
    S = np.asarray(S, float)
    out = np.full(n_blocks, math.nan)
    m = y.size
    if jit:
        _nb.block_nis(y, S, n_blocks, out)
        return out
    if m == 0:
        return out
    if m % n_blocks:
        out[0] = float(y @ np.linalg.solve(S, y)) / m
        return out
    k = m // n_blocks
    for b in range(n_blocks):
        s = slice(b * k, (b + 1) * k)
        yb = y[s]
        out[b] = float(yb @ np.linalg.solve(S[s, s], yb)) / k
    return out


def enu_blocks(P: np.ndarray, llh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Attitude [rad^2], velocity [(m/s)^2] and position [m^2] 3x3 blocks of the 17-state
    ``P`` (paper 004 Table 1 layout), all in ENU; position mapped from (lat, lon, h)."""
    P = np.asarray(P, float)
    lat, h = float(llh[0]), float(llh[2])
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    J = np.array([[0.0, (R_N + h) * math.cos(lat), 0.0],     # E from d lon
                  [R_M + h, 0.0, 0.0],                        # N from d lat
                  [0.0, 0.0, 1.0]])                           # U from d h
    return P[0:3, 0:3].copy(), P[3:6, 3:6].copy(), J @ P[6:9, 6:9] @ J.T


def formal_sd(P: np.ndarray, llh) -> np.ndarray:
    """Formal 1-sigma (9,): position E, N, U [m], velocity E, N, U [m/s], attitude E, N, U
    [deg] from ``P`` at ``llh`` (:func:`enu_blocks`)."""
    att, vel, pos = enu_blocks(P, llh)
    return np.r_[np.sqrt(np.diagonal(pos)), np.sqrt(np.diagonal(vel)),
                 np.degrees(np.sqrt(np.diagonal(att)))]


def nees_per_dof(e: np.ndarray, P: np.ndarray) -> float:
    """``e^T P^-1 e / dim e``; NaN for a non-finite error."""
    e = np.asarray(e, float)
    if not np.isfinite(e).all():
        return math.nan
    return float(e @ np.linalg.solve(np.asarray(P, float), e)) / e.size


def effective_count(x: np.ndarray) -> float:
    """``N / (1 + 2 sum_k rho_k)`` of a series (:data:`BAND_RULE`); ``N`` for N < 4."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    n = x.size
    if n < 4:
        return float(n)
    d = x - x.mean()
    c0 = float(d @ d)
    if c0 <= 0.0:
        return float(n)
    s = 0.0
    for k in range(1, n // 4 + 1):
        rho = float(d[:-k] @ d[k:]) / c0
        if rho <= 0.0:
            break
        s += rho
    return float(n / (1.0 + 2.0 * s))


def chi2_band(n_eff: float, dof: int, level: float = 0.95) -> list[float]:
    """``[low, high]`` of the mean of ``n_eff`` samples with ``dof`` degrees of freedom
    each (chi-square with ``n_eff * dof`` degrees of freedom over ``n_eff * dof``)."""
    k = n_eff * dof
    if not k > 0:
        return [math.nan, math.nan]
    a = (1.0 - level) / 2.0
    # chdtri(k, p): the chi-square quantile of upper tail p (scipy.special, so that the run
    # modules do not import scipy.stats at start-up: test_coupling)
    return [float(chdtri(k, 1.0 - a) / k), float(chdtri(k, a) / k)]


def ensemble_band(n_runs: int, dim: int, level: float = 0.95, *,
                  per_dof: bool = True) -> list[float]:
    """Two-sided chi-square band of an ensemble average over ``n_runs`` Monte Carlo runs
    (ANEES, ANIS; Bar-Shalom, Li and Kirubarajan 2001, section 5.4.2).

    For a consistent filter each run's NEES of dimension ``n`` is chi-square with ``n``
    degrees of freedom, so ``N * ANEES`` is chi-square with ``N n``: the band of ANEES is
    ``chi2.ppf([a, 1 - a], N n) / N`` with ``a = (1 - level) / 2``. This project's NEES and
    NIS are per degree of freedom (:func:`nees_per_dof`, :func:`block_nis`; expected 1), so
    by default the band is also divided by ``n``: :func:`chi2_band` with ``N`` samples.
    Each run's value is taken as one sample (a run's time average varies less than one
    sample, so the band is conservative for it).

    Parameters
    ----------
    n_runs : int
        Number of runs ``N`` (>= 1).
    dim : int
        Dimension ``n`` of the statistic (3 for NEES of position, velocity or attitude; the
        block size for NIS).
    level : float
        Two-sided probability of the band (default 0.95).
    per_dof : bool
        True (default): the band of the average per degree of freedom (around 1); False: of
        the average NEES itself (around ``n``), as in the book.

    Returns
    -------
    list of float
        ``[low, high]``.

    Raises
    ------
    ValueError
        ``n_runs`` or ``dim`` not a positive integer, or ``level`` not in (0, 1).
    """
    for name, v in (("n_runs", n_runs), ("dim", dim)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"ensemble_band: {name} must be a positive integer, got {v!r}")
    if not 0.0 < level < 1.0:
        raise ValueError(f"ensemble_band: level must be in (0, 1), got {level!r}")
    lo, hi = chi2_band(int(n_runs), int(dim), level)
    return [lo, hi] if per_dof else [lo * dim, hi * dim]


def verdict(value: float | None, band) -> str:
    """``consistent``, ``pessimistic`` (below the band: the covariance is larger than the
    errors) or ``overconfident`` (above it: smaller) of a mean NIS/NEES per degree of
    freedom against its ``[low, high]`` band; ``no samples`` for a missing value."""
    if value is None or not math.isfinite(float(value)):
        return "no samples"
    lo, hi = (math.nan if b is None else float(b) for b in band)
    if value < lo:
        return "pessimistic"
    if value > hi:
        return "overconfident"
    return "consistent"


def _entry(x: np.ndarray, dof: int) -> dict:
    x = np.asarray(x, float)
    fin = x[np.isfinite(x)]
    n_eff = effective_count(fin)
    return {"value": float(fin.mean()) if fin.size else None, "expected": 1.0,
            "n": int(fin.size), "n_eff": n_eff, "dof": int(dof),
            "band": [None if not math.isfinite(v) else v for v in chi2_band(n_eff, dof)]
            if fin.size else [None, None]}


def consistency_summary(mode: str, t_nis, nis_blocks, nis_dof, t_rows, nees,
                        t0: float | None = None, t1: float | None = None) -> dict:
    """The summary's ``consistency`` entry over ``t0 <= t <= t1`` (the RMSE window).

    Parameters
    ----------
    mode : str
        ``deep``, ``tight``, ``loose`` or ``lc`` (block names :data:`NIS_BLOCKS`).
    t_nis : (k,) array
        Time of each update [s].
    nis_blocks : (k, 2) array
        :func:`block_nis` of each update.
    nis_dof : (k,) array
        Degrees of freedom of each block at each update (block size).
    t_rows : (n,) array
        Time of each solution row [s].
    nees : (n, 3) array
        NEES per degree of freedom of position, velocity, attitude of each row (NaN
        without truth).

    Returns
    -------
    dict
        ``{"band_rule": BAND_RULE, "nis_<block>": entry, "nees_pos" / "nees_vel" /
        "nees_att": entry}``; an entry is ``{"value" (mean), "expected": 1, "n", "n_eff",
        "dof" (degrees of freedom of one sample), "band": [low, high]}``, ``value`` None
        without samples.
    """
    out: dict = {"band_rule": BAND_RULE}
    nb = np.asarray(nis_blocks, float).reshape(-1, 2)
    dof = np.asarray(nis_dof, float).reshape(-1)
    sel = time_window(t_nis, t0, t1)
    d = int(round(float(np.median(dof[sel])))) if sel.any() else 1
    for j, name in enumerate(NIS_BLOCKS[mode]):
        out[f"nis_{name}"] = _entry(nb[sel, j], max(d, 1))
    ne = np.asarray(nees, float).reshape(-1, 3)
    sel = time_window(t_rows, t0, t1)
    for j, q in enumerate(("pos", "vel", "att")):
        out[f"nees_{q}"] = _entry(ne[sel, j], 3)
    return out


def flat(consistency: dict) -> dict:
    """``{"nis_code": mean, ...}`` of a :func:`consistency_summary` (NaN for no value)."""
    return {k: (math.nan if v["value"] is None else v["value"])
            for k, v in consistency.items() if isinstance(v, dict)}
