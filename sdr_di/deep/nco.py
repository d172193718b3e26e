"""INS-predicted pseudoranges and the code/carrier NCO commands of the vector loop.

Paper 004 Fig. 1: every channel's NCOs are commanded from the corrected INS position and
velocity, the satellites' broadcast orbits at transmit time, the receiver clock states and
the atmosphere models: the forward range model of :mod:`sdr_di.receiver.range_model` (the
model the PVT solves, run forwards; the scalar receiver's re-acquisition after a blockage
uses it too) gives the code pseudorange ``P``, the carrier phase-range ``Pc`` and the
satellite-clock transmit time ``t_sv(k) = t_nom(k) - P / c`` of the code at sample ``k``.

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

import numpy as np

from ..constants import C_LIGHT, CHIP_RATE_B3I, F_B3I
from ..receiver.range_model import RangePrediction, predict_ranges

__all__ = ["NcoCommand", "RangePrediction", "nco_commands", "predict_ranges"]


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
