"""Error metrics of a navigation run (DESIGN section 6: RMSE = sqrt(mean ||e||^2)).

Attitude error is the rotation vector ``phi`` with ``C_b^n(computed) = exp(-[phi x])
C_b^n(true)`` (the filter's convention), reported in degrees; velocity error in m/s (ENU);
position error in metres (E, N, U). ``max`` is the largest ``||e||``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..frames import radii_of_curvature
from ..ins.error_model import dcm_to_rotvec
from ..receiver.accuracy import rmse_max  # the one RMSE rule, beside the scalar fixes' errors

__all__ = ["nav_errors", "rmse_max", "summarize", "time_window"]


def nav_errors(llh, v_n, C_b_n, llh_true, v_true, C_true):
    """Errors (computed - true) at one epoch: attitude [deg] (3,), velocity (3,), pos ENU [m]."""
    att = np.degrees(dcm_to_rotvec(np.asarray(C_true) @ np.asarray(C_b_n).T))
    lat = float(llh_true[0])
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    d = np.asarray(llh, float) - np.asarray(llh_true, float)
    h = float(llh_true[2])
    pos = np.array([d[1] * (R_N + h) * math.cos(lat), d[0] * (R_M + h), d[2]])
    return att, np.asarray(v_n, float) - np.asarray(v_true, float), pos


def time_window(t, t0: float | None = None, t1: float | None = None) -> np.ndarray:
    """Boolean mask of ``t0 <= t <= t1`` (an open end where a bound is None); ``t`` [s]."""
    t = np.asarray(t, float)
    sel = np.ones(t.size, bool)
    if t0 is not None:
        sel &= t >= t0
    if t1 is not None:
        sel &= t <= t1
    return sel


def summarize(t, att, vel, pos, t0: float | None = None, t1: float | None = None) -> dict:
    """RMSE and max of attitude [deg], velocity [m/s], position [m] over ``t0 <= t <= t1``.

    Keys ``<q>_rmse``, ``<q>_max`` (norms) and ``<q>_rmse_axes`` (per-axis RMSE, E, N, U; the
    form of paper 000 Table 1) for ``q`` in ``att_deg``, ``vel_mps``, ``pos_m``; ``n`` epochs.
    """
    sel = time_window(t, t0, t1)
    out: dict[str, Any] = {"n": int(sel.sum())}
    for name, e in (("att_deg", att), ("vel_mps", vel), ("pos_m", pos)):
        r, m = rmse_max(np.asarray(e)[sel])
        out[f"{name}_rmse"] = r
        out[f"{name}_max"] = m
        sub = np.atleast_2d(np.asarray(e, float))[sel]
        out[f"{name}_rmse_axes"] = (np.sqrt(np.mean(sub * sub, axis=0)) if len(sub)
                                    else np.full(3, math.nan))
    return out
