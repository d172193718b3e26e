"""INS-predicted pseudoranges and the code/carrier NCO commands of the vector loop.

Paper 004 Fig. 1: every channel's NCOs are commanded from the corrected INS position and
velocity, the satellites' broadcast orbits at transmit time, the receiver clock states and
the atmosphere models. The model is the one the PVT solves (:mod:`sdr_di.receiver.pvt`), run
forwards::

    P  = | R_z(omega_e tau) r_sat(t_tx) - r | + b - c dt_sv(t_tx) + T + I     code [m]
    Pc = P - 2 I                                                           carrier [m]
    t_sv(k) = t_nom(k) - P / c          satellite-clock transmit time of the code at sample k

with ``t_nom(k)`` the receiver-clock (nominal) time of IF sample ``k``, ``b`` the receiver
clock bias [m] (``t_nom - BDT`` times c), ``tau`` the geometric travel time (iterated; Sagnac
by rotating the satellite into the ECEF frame of the reception instant), ``dt_sv`` the
broadcast clock with the relativistic term, ``T`` Saastamoinen and ``I`` the B3I-scaled
Klobuchar delay (elevations floored at 0.1 deg as in the generator and the PVT).

NCO commands over an interval ``[k0, k1)`` (:func:`nco_commands`):

* code: the replica's chip count ``chips(k) = f_code (t_sv(k) - S0)`` (``S0`` a whole
  millisecond near the start of the run, so the count stays below ~1e9 chips and keeps
  1e-7 chip resolution in float64) is linear between ``k0`` and ``k1``: rate
  ``(chips(k1) - chips(k0)) fs / (k1 - k0)`` [chips/s] and phase ``chips(k0)``;
* carrier: Doppler ``-(f_carr / c) (Pc(k1) - Pc(k0)) / T`` [Hz], the interval average of the
  predicted phase-range rate (the carrier phase itself is kept continuous by the loop).

Code-epoch numbering: epoch ``e`` of a channel is the replica period whose chip count lies in
``[e L, (e + 1) L)``; its satellite-clock start time is ``S0 + e ms``, which gives the NH-code
chip ``(S0_ms + e) mod 20`` and the data-bit boundaries (D1 bits start at whole 20 ms of
BDT, D2 bits at whole 2 ms).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from ..constants import C_LIGHT, CHIP_RATE_B3I, F_B3I
from ..orbits.broadcast import sat_pos_vel_clock
from ..orbits.ephemeris import Ephemeris, Klobuchar
from ..receiver.pvt import PvtConfig, atmosphere_delays, sagnac_rotation

__all__ = ["NcoCommand", "RangePrediction", "nco_commands", "predict_ranges"]

_TAU0_S = 0.075


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
    r_sat = np.empty((n_s, n_t, 3))
    v_sat = np.empty((n_s, n_t, 3))
    dt_sv = np.empty((n_s, n_t))
    for _ in range(passes):
        for i, eph in enumerate(ephemerides):
            rs, vs, dts, _ = sat_pos_vel_clock(eph, t_r - tau[i], week=week)
            r_sat[i], v_sat[i], dt_sv[i] = rs, vs, dts
        rot, rho, _ = sagnac_rotation(r_sat.reshape(-1, 3), np.repeat(r[None], n_s, 0)
                                          .reshape(-1, 3))
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


@dataclasses.dataclass
class NcoCommand:
    """Code and carrier NCO commands of ``n_sat`` channels over one interval ``[k0, k1)``.

    Attributes
    ----------
    chips0 : ndarray (n_sat,)
        Replica chip count at sample ``k0`` relative to ``S0`` [chips] (module notes).
    code_rate_cps : ndarray (n_sat,)
        Code NCO rate [chips/s].
    doppler_hz : ndarray (n_sat,)
        Carrier Doppler [Hz] (NCO frequency = IF + Doppler).
    k0, k1 : int
        Interval [samples].
    """

    chips0: np.ndarray
    code_rate_cps: np.ndarray
    doppler_hz: np.ndarray
    k0: int
    k1: int

    def chips_at(self, k) -> np.ndarray:
        """Chip count of every channel at sample(s) ``k`` (broadcast (n_sat,) with ``k``)."""
        return self.chips0 + self.code_rate_cps * (np.asarray(k, float) - self.k0) \
            / self._fs

    _fs: float = 1.0


def nco_commands(P0, Pc0, P1, Pc1, k0: int, k1: int, fs: float, t_nom_rel0: float,
                 t_nom_rel1: float, carrier_hz: float = F_B3I) -> NcoCommand:
    """NCO commands over ``[k0, k1)`` from the predictions at its two ends (module notes).

    Parameters
    ----------
    P0, Pc0 : array_like (n_sat,)
        Predicted code pseudorange and carrier phase-range at sample ``k0`` [m].
    P1, Pc1 : array_like (n_sat,)
        The same at sample ``k1`` [m].
    k0, k1 : int
        Interval [samples], ``k1 > k0``.
    fs : float
        Sampling rate [Hz].
    t_nom_rel0, t_nom_rel1 : float
        Receiver-clock times of ``k0`` and ``k1`` minus ``S0`` [s] (small numbers, so the
        chip counts keep their precision).
    carrier_hz : float
        Carrier frequency [Hz].
    """
    if not k1 > k0:
        raise ValueError(f"empty NCO interval [{k0}, {k1})")
    c0 = CHIP_RATE_B3I * (t_nom_rel0 - np.asarray(P0, float) / C_LIGHT)
    c1 = CHIP_RATE_B3I * (t_nom_rel1 - np.asarray(P1, float) / C_LIGHT)
    n = float(k1 - k0)
    rate = (c1 - c0) * fs / n
    T = n / fs
    dop = -(carrier_hz / C_LIGHT) * (np.asarray(Pc1, float) - np.asarray(Pc0, float)) / T
    return NcoCommand(chips0=c0, code_rate_cps=rate, doppler_hz=dop, k0=int(k0), k1=int(k1),
                      _fs=float(fs))


def whole_ms_reference(sow: float) -> tuple[float, float]:
    """``(S0, frac)``: ``S0`` the whole millisecond at or below ``sow`` and ``sow - S0`` [s]."""
    s0 = math.floor(sow * 1000.0) / 1000.0
    return s0, sow - s0
