"""The forward range model: predicted pseudoranges and carrier phase-ranges from a receiver
position and clock, the broadcast orbits and the atmosphere models.

It is the model the PVT solves (:mod:`sdr_di.receiver.pvt`), run forwards::

    P  = | R_z(omega_e tau) r_sat(t_tx) - r | + b - c dt_sv(t_tx) + T + I     code [m]
    Pc = P - 2 I                                                           carrier [m]
    t_sv(k) = t_nom(k) - P / c          satellite-clock transmit time of the code at sample k

with ``t_nom(k)`` the receiver-clock (nominal) time of IF sample ``k``, ``b`` the receiver
clock bias [m] (``t_nom - BDT`` times c), ``tau`` the geometric travel time (iterated; Sagnac
by rotating the satellite into the ECEF frame of the reception instant), ``dt_sv`` the
broadcast clock with the relativistic term, ``T`` Saastamoinen and ``I`` the B3I-scaled
Klobuchar delay (elevations floored at 0.1 deg as in the generator and the PVT).

Users: the deep loop's NCO commands (:mod:`sdr_di.deep.nco`, from the INS position) and the
scalar receiver's re-acquisition after a blockage (:mod:`sdr_di.receiver.prediction`, from
the last fix).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from ..constants import C_LIGHT
from ..orbits.broadcast import (GEO_INCLINATION_ROT, sat_pos_vel_clock_stacked,
                                stack_ephemerides)
from ..orbits.ephemeris import Ephemeris, Klobuchar
from . import _numba_range_model as _k
from .pvt import (PvtConfig, atmosphere_delays_numpy, atmosphere_kernel_args,
                  sagnac_rotation)

__all__ = ["RangePrediction", "predict_ranges"]

_TAU0_S = 0.075
#: One numba kernel call for one receive instant (:mod:`._numba_range_model`, the numpy
#: form's values to a few ulp); False: the numpy form only (the tested reference).
jit = True
_GEO_CX, _GEO_SX = math.cos(GEO_INCLINATION_ROT), math.sin(GEO_INCLINATION_ROT)


@dataclasses.dataclass
class RangePrediction:
    """Predicted observables of ``n_sat`` satellites at ``n_t`` receive instants.

    Attributes
    ----------
    P, Pc : ndarray (n_sat, n_t)
        Code pseudorange and carrier phase-range [m].
    tau : ndarray (n_sat, n_t)
        Geometric travel time [s] (seed of the next call).
    r_sat, v_sat : ndarray (n_sat, n_t, 3)
        Satellite ECEF position [m] (rotated into the reception frame) and velocity [m/s].
    U : ndarray (n_sat, n_t, 3)
        Unit line-of-sight vectors receiver -> satellite (ECEF).
    """

    P: np.ndarray
    Pc: np.ndarray
    tau: np.ndarray
    r_sat: np.ndarray
    v_sat: np.ndarray
    U: np.ndarray


def predict_ranges(ephemerides: Sequence[Ephemeris], week: int, sow_nom, r_rx, clock_bias_m,
                   iono: Klobuchar | None, *, tau0: np.ndarray | None = None,
                   passes: int = 2, config: PvtConfig | None = None) -> RangePrediction:
    """INS-predicted pseudoranges of several satellites at several receive instants.

    Parameters
    ----------
    ephemerides : sequence of Ephemeris
        One broadcast record per satellite.
    week : int
        BDT week of ``sow_nom``.
    sow_nom : array_like (n_t,)
        Receiver-clock (nominal) receive times [s of week].
    r_rx : array_like (n_t, 3)
        Receiver ECEF positions at those instants [m].
    clock_bias_m : array_like (n_t,)
        Receiver clock bias ``b`` [m] at those instants.
    iono : Klobuchar or None
        Broadcast ionosphere coefficients (None: no ionosphere).
    tau0 : array_like (n_sat, n_t), optional
        Travel-time seeds [s] (e.g. the previous call's ``tau``); default 75 ms with 3 more
        passes.
    passes : int
        Travel-time iterations when seeded (2 converge to < 1e-12 s from a 1 ms seed error).
    config : PvtConfig, optional
        Atmosphere switches (``ionosphere``, ``troposphere``), as the PVT.
    """
    cfg = config or PvtConfig()
    sow = np.atleast_1d(np.asarray(sow_nom, float))
    r = np.asarray(r_rx, float).reshape(-1, 3)
    b = np.broadcast_to(np.asarray(clock_bias_m, float), sow.shape)
    n_s, n_t = len(ephemerides), sow.size
    if tau0 is None:
        tau = np.full((n_s, n_t), _TAU0_S)
        passes = passes + 3
    else:
        tau = np.array(tau0, float).reshape(n_s, n_t)
    t_r = sow - b / C_LIGHT                                  # BDT of reception
    stack = stack_ephemerides(ephemerides)      # every satellite in one numpy pass
    if jit and n_t == 1 and n_s > 0:
        return _predict_one_instant(stack, week, float(t_r[0]), r[0], float(b[0]),
                                    tau[:, 0].copy(), iono, cfg, passes)
    r_rep = np.repeat(r[None], n_s, 0).reshape(-1, 3)
    for _ in range(passes):
        r_sat, v_sat, dt_sv, _ = sat_pos_vel_clock_stacked(stack, t_r[None, :] - tau,
                                                           week=week)
        rot, rho, _ = sagnac_rotation(r_sat.reshape(-1, 3), r_rep)
        tau = rho.reshape(n_s, n_t) / C_LIGHT
    r_rot = rot.reshape(n_s, n_t, 3)
    rho = rho.reshape(n_s, n_t)
    trop = np.empty((n_s, n_t))
    ion = np.empty((n_s, n_t))
    for j in range(n_t):
        _, _, T, I = atmosphere_delays_numpy(r[j], r_rot[:, j], float(t_r[j]), iono, cfg)
        trop[:, j], ion[:, j] = T, I
    P = rho + b[None, :] - C_LIGHT * dt_sv + trop + ion
    U = (r_rot - r[None]) / rho[..., None]
    return RangePrediction(P=P, Pc=P - 2.0 * ion, tau=tau, r_sat=r_rot, v_sat=v_sat, U=U)


def _predict_one_instant(stack, week: int, t_r: float, r: np.ndarray, b: float,
                         tau: np.ndarray, iono: Klobuchar | None, cfg: PvtConfig,
                         passes: int) -> RangePrediction:
    """:func:`predict_ranges` at one receive instant in one call of
    :func:`._numba_range_model.predict_instant` (the numpy form's values to a few ulp;
    ``t_r`` BDT of reception [s of week], ``r`` (3,) [m], ``b`` [m], ``tau`` (n,)
    travel-time seeds [s], overwritten)."""
    n = stack.size
    r_rot = np.empty((n, 3))
    v_sat = np.empty((n, 3))
    P = np.empty((n, 1))
    Pc = np.empty((n, 1))
    U = np.empty((n, 1, 3))
    _k.predict_instant(stack.table, stack.geo, _GEO_CX, _GEO_SX, float(week), t_r,
                       np.ascontiguousarray(r, float), b, tau, passes,
                       *atmosphere_kernel_args(iono, cfg), r_rot, v_sat, P[:, 0], Pc[:, 0],
                       U[:, 0])
    return RangePrediction(P=P, Pc=Pc, tau=tau.reshape(n, 1), r_sat=r_rot.reshape(n, 1, 3),
                           v_sat=v_sat.reshape(n, 1, 3), U=U)
