"""Accuracy of a receiver's solution file against the generator's truth file.

Errors are solution minus truth at the solution epochs (BDT of the fix), truth interpolated
with :meth:`~sdr_di.ins.truth.Truth.ecef_at`; position error is the ECEF 3-D error [m],
velocity error the ENU 3-D error [m/s]. RMSE = sqrt(mean ||e||^2) (DESIGN section 6).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..frames import C_e_n
from ..io.imu_files import read_truth
from ..io.solution_files import read_solution_csv

__all__ = ["rmse_max", "solution_errors", "solution_vs_truth"]


def rmse_max(e: np.ndarray) -> tuple[float, float]:
    """``(sqrt(mean ||e_k||^2), max ||e_k||)`` of rows ``e`` (n, 3); NaN for no rows
    (DESIGN section 6: RMSE = sqrt(mean ||e||^2); every mode's metrics use it)."""
    e = np.atleast_2d(np.asarray(e, float))
    if e.shape[0] == 0:
        return math.nan, math.nan
    n2 = np.sum(e * e, axis=1)
    return float(math.sqrt(np.mean(n2))), float(math.sqrt(np.max(n2)))


def solution_errors(solution_csv: str | Path, truth_csv: str | Path,
                    t_min_s: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Errors of the valid fixes of a solution file against the truth file.

    Returns
    -------
    t : (n,) fix times [s since the truth start]
    dr_e : (n, 3) ECEF position error [m]
    dv_n : (n, 3) ENU velocity error [m/s]
    """
    sol = read_solution_csv(solution_csv)
    truth, week, sow = read_truth(truth_csv)
    ok = np.asarray(sol["status"]) == "fix"
    t = (np.asarray(sol["week"], float) - week) * 604800.0 + np.asarray(sol["sow"], float) - sow
    ok &= np.isfinite(t) & (t >= max(t_min_s, truth.t[0])) & (t <= truth.t[-1])
    t = t[ok]
    r = np.column_stack([sol["x_m"], sol["y_m"], sol["z_m"]]).astype(float)[ok]
    v_n = np.column_stack([sol["ve_mps"], sol["vn_mps"], sol["vu_mps"]]).astype(float)[ok]
    if t.size == 0:
        return t, np.zeros((0, 3)), np.zeros((0, 3))
    r_t, v_t = truth.ecef_at(t)
    lat = np.interp(t, truth.t, truth.llh[:, 0])
    lon = np.interp(t, truth.t, truth.llh[:, 1])
    v_nt = np.einsum("kij,kj->ki", C_e_n(lat, lon), v_t)
    return t, r - r_t, v_n - v_nt


def solution_vs_truth(solution_csv: str | Path, truth_csv: str | Path,
                      t_min_s: float = 0.0) -> dict:
    """Position and velocity RMSE/max of the valid fixes of a solution file.

    Parameters
    ----------
    solution_csv, truth_csv : path
        ``*_pvt.csv`` of ``sdr-di run`` and ``*_truth.csv`` of ``sdr-di generate``.
    t_min_s : float
        Ignore fixes earlier than this many seconds after the truth start.

    Returns
    -------
    dict
        ``n_fixes``, ``first_fix_s``, ``pos_rmse_m``, ``pos_max_m``, ``vel_rmse_mps``,
        ``vel_max_mps`` (NaN when there is no fix).
    """
    t, dr, dv = solution_errors(solution_csv, truth_csv, t_min_s)
    out = {"n_fixes": int(t.size), "first_fix_s": float(t[0]) if t.size else float("nan")}
    if t.size == 0:
        return {**out, "pos_rmse_m": np.nan, "pos_max_m": np.nan, "vel_rmse_mps": np.nan,
                "vel_max_mps": np.nan}
    out["pos_rmse_m"], out["pos_max_m"] = rmse_max(dr)
    out["vel_rmse_mps"], out["vel_max_mps"] = rmse_max(dv)
    return out
