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
from ..frames import ecef_to_llh_point
from ..orbits.atmosphere import (B1I_TO_B3I, KLOBUCHAR_H_M, KLOBUCHAR_R_M,
                                 saastamoinen_zenith)
from ..orbits.broadcast import geo_to_ecef, sat_pos_vel_clock_stacked, stack_ephemerides
from ..orbits.ephemeris import Ephemeris, Klobuchar
from . import _numba_range_model as _k
from .pvt import _EL_FLOOR, PvtConfig, atmosphere_delays, sagnac_rotation

__all__ = ["RangePrediction", "predict_ranges"]

_TAU0_S = 0.075
#: Numba kernels for one receive instant (:mod:`._numba_range_model`); False: the numpy
#: form only (the tested reference).
jit = True
_ZENITH = np.array([np.pi / 2.0])
_RATIO_K = KLOBUCHAR_R_M / (KLOBUCHAR_R_M + KLOBUCHAR_H_M)
_IONO_M_PER_S = C_LIGHT * B1I_TO_B3I


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
        _, _, T, I = atmosphere_delays(r[j], r_rot[:, j], float(t_r[j]), iono, cfg)
        trop[:, j], ion[:, j] = T, I
    P = rho + b[None, :] - C_LIGHT * dt_sv + trop + ion
    U = (r_rot - r[None]) / rho[..., None]
    return RangePrediction(P=P, Pc=P - 2.0 * ion, tau=tau, r_sat=r_rot, v_sat=v_sat, U=U)


def _predict_one_instant(stack, week: int, t_r: float, r: np.ndarray, b: float,
                         tau: np.ndarray, iono: Klobuchar | None, cfg: PvtConfig,
                         passes: int) -> RangePrediction:
    """:func:`predict_ranges` at one receive instant with the kernels of
    :mod:`._numba_range_model` (the same values; ``t_r`` BDT of reception [s of week],
    ``r`` (3,) [m], ``b`` [m], ``tau`` (n,) travel-time seeds [s])."""
    n = stack.size
    tab = stack.table
    wk = float(week)
    w = np.empty((6, n))
    vk = np.empty(n)
    r_sat = np.empty((n, 3))
    v_sat = np.empty((n, 3))
    dt_sv = np.empty(n)
    r_rot = np.empty((n, 3))
    rho = np.empty(n)
    geo = stack.geo.any()
    for _ in range(passes):
        _k.orbit_anomaly(tab, wk, t_r, tau, w)
        np.arctan2(w[4], w[5], out=vk)
        _k.orbit_state(tab, w, vk, r_sat, v_sat, dt_sv)
        if geo:         # (n, 1, 3): the stacked form's shapes, so its matmul's sums
            geo_to_ecef(r_sat.reshape(n, 1, 3), v_sat.reshape(n, 1, 3),
                        w[0].reshape(n, 1), stack.geo)
        _k.sagnac(r_sat, r, r_rot, rho)
        tau = rho / C_LIGHT
    # the atmosphere (pvt.atmosphere_delays) at the receiver's geodetic position
    lat, lon, h = ecef_to_llh_point(r)
    sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
    h01 = np.empty((2, n))
    y = np.empty(2 * n)
    x = np.empty(2 * n)
    _k.line_of_sight_enu(r_rot, r, sl, cl, so, co, h01, y, x)
    np.hypot(h01[0], h01[1], out=x[:n])
    el_az = np.arctan2(y, x)
    wa = np.empty((5, n))
    _k.klobuchar_1(el_az, _EL_FLOOR, _RATIO_K, wa)
    ion_on = bool(cfg.ionosphere and iono is not None)
    phi_m = asin_lam = vk        # (unused without the ionosphere)
    alpha = beta = _ZENITH
    t_day = 0.0
    if ion_on:
        asin_ratio = np.arcsin(wa[3])
        arg = np.empty(n)
        _k.klobuchar_2(wa, asin_ratio, sl, cl, arg)
        phi_m = np.arcsin(arg)
        _k.klobuchar_3(wa, phi_m, arg)
        asin_lam = np.arcsin(arg)
        alpha, beta = np.asarray(iono.alpha, float), np.asarray(iono.beta, float)
        t_day = float(np.mod(np.float64(t_r), 86400.0))
    zenith_m = float(saastamoinen_zenith(np.float64(lat), np.float64(h))) \
        if cfg.troposphere else 0.0
    P = np.empty((n, 1))
    Pc = np.empty((n, 1))
    U = np.empty((n, 1, 3))
    _k.ranges(wa, phi_m, asin_lam, lon, t_day, alpha, beta, _IONO_M_PER_S, ion_on, zenith_m,
              bool(cfg.troposphere), rho, b, dt_sv, r_rot, r, P[:, 0], Pc[:, 0], U[:, 0])
    return RangePrediction(P=P, Pc=Pc, tau=tau.reshape(n, 1), r_sat=r_rot.reshape(n, 1, 3),
                           v_sat=v_sat.reshape(n, 1, 3), U=U)
