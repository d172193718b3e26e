"""Discriminator measurements of the centralized vector loop (``deep_measurements =
"discriminator"``; docs/deep.md, *Measurement architectures*).

The integration filter takes each channel's discriminator outputs of the interval
themselves, as in a centralized vector delay/frequency lock loop (Lashley and Bevly's VDFLL;
Petovello and Lachapelle 2006 compared it with the cascaded one): no per-channel state is
carried from one interval to the next, so consecutive measurements have independent errors.

Per coherent block ``j`` of the interval (duration ``T_j``, centre ``t_j``; the vector loop
cuts at most half an interval, never across a data bit, :func:`~sdr_di.deep.architectures.
block_ms`) the same discriminators and noise variances as the pre-filters'
(:mod:`sdr_di.deep.prefilter`)::

    z_tau,j = (1 - d) (|E| - |L|) / (|E| + |L|)          r_tau,j = d / (2 s_j) (1 + 1 / s_j)
    phi_j   = atan(Q_P / I_P)                            r_phi,j = 1 / (2 s_j) (1 + 1 / (2 s_j))

with ``s_j = C/N0 T_j``. The interval's measurements:

* code error ``dtau`` [chips]: the inverse-variance weighted mean of ``z_tau,j``, variance
  ``1 / sum(1 / r_tau,j)``;
* frequency error ``df`` [Hz]: the weighted least-squares slope of the block phases, unwrapped
  from block to block modulo pi (the two-quadrant arctangent ignores data-bit signs; unique
  while ``|df| < 1 / (4 dt)``, 25 Hz for 10 ms blocks), divided by ``2 pi``; variance
  ``1 / (4 pi^2 sum w_j (t_j - t_bar)^2)`` with ``w_j = 1 / r_phi,j``. Two blocks make the
  cross-product (arctangent) frequency discriminator; more are its least-squares
  generalization. An interval of one block states no frequency information
  (``sigma_f_none``, 100 Hz).

Both refer to the interval (the code to its weighted block centre, at most half an interval
before its end: ``beta |df| T / 2``, about 1e-4 chip for 1 Hz, below 1 % of the code noise
at 45 dB-Hz). The NIS of an interval is the sum of the blocks' squared normalized residuals
about these fits, ``2 m - 3`` degrees of freedom for ``m`` blocks: a false lock or a cycle
slip shows as a small tail probability, as with the pre-filters.

:class:`DiscriminatorBank` has the pre-filters' interface (:class:`~sdr_di.deep.prefilter.
PreFilterBank`): ``process``, ``outputs``, ``shift`` (the NCOs moved after the correlations,
with NCOs one interval ahead), ``reset`` and ``decorrelate`` (nothing to forget).
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import F_B3I
from ._numba_discriminators import interval_discriminators
from .prefilter import coherent_blocks, discriminator_variances, nis_test

__all__ = ["DiscriminatorBank", "interval_discriminators_numpy"]


def interval_discriminators_numpy(early, prompt, late, t_block, spacing: float, r_tau, r_phi,
                                  var_f_none: float) -> tuple[float, float, float, float,
                                                              float]:
    """The plain numpy form of the kernel :func:`~sdr_di.deep._numba_discriminators.
    interval_discriminators` (module notes): ``(dtau [chips], df [Hz], var_tau [chips^2],
    var_f [Hz^2], nis)``."""
    ea, la = np.abs(early), np.abs(late)
    s = ea + la
    z = np.where(s > 0.0, (1.0 - spacing) * (ea - la) / np.where(s > 0.0, s, 1.0), 0.0)
    w = 1.0 / np.asarray(r_tau, float)
    dtau = float(np.sum(w * z) / np.sum(w))
    var_tau = float(1.0 / np.sum(w))
    nis = float(np.sum(w * (z - dtau) ** 2))
    m = len(prompt)
    if m < 2:
        return dtau, 0.0, var_tau, float(var_f_none), nis
    t_block = np.asarray(t_block, float)
    t = np.cumsum(t_block) - 0.5 * t_block
    pr = np.asarray(prompt)
    ph = np.where(pr.real != 0.0, np.arctan(pr.imag / np.where(pr.real != 0.0, pr.real, 1.0)),
                  0.5 * np.pi)
    d = np.diff(ph)
    psi = ph[0] + np.concatenate([[0.0], np.cumsum(d - np.pi * np.floor(d / np.pi + 0.5))])
    wp = 1.0 / np.asarray(r_phi, float)
    tb = np.sum(wp * t) / np.sum(wp)
    pb = np.sum(wp * psi) / np.sum(wp)
    stt = np.sum(wp * (t - tb) ** 2)
    slope = np.sum(wp * (t - tb) * (psi - pb)) / stt
    nis += float(np.sum(wp * (psi - pb - slope * (t - tb)) ** 2))
    return dtau, float(slope / (2 * np.pi)), var_tau, float(1.0 / (stt * 4 * np.pi ** 2)), nis


class DiscriminatorBank:
    """Discriminator measurements of ``n`` channels (module notes), with the interface of
    :class:`~sdr_di.deep.prefilter.PreFilterBank`.

    Parameters
    ----------
    n : int
        Channels.
    spacing : float
        Early/late offset d [chips].
    carrier_hz : float
        Carrier frequency [Hz] (kept for the common interface).
    sigma_f_none : float
        Frequency sigma [Hz] stated for an interval of a single block (no frequency
        information). Default 100.

    Attributes
    ----------
    out : ndarray (n, 4)
        Last outputs ``[dtau (chips), df (Hz), var_tau (chips^2), var_f (Hz^2)]``.
    nis : ndarray (n,)
        NIS per degree of freedom of the last interval (``2 m - 3`` for ``m`` blocks).
    nis_p : ndarray (n,)
        Its chi-square tail probability (1 where there is no degree of freedom).
    """

    def __init__(self, n: int, spacing: float = 0.5, carrier_hz: float = F_B3I, *,
                 sigma_f_none: float = 100.0):
        self.n = int(n)
        self.spacing = float(spacing)
        self.carrier_hz = float(carrier_hz)
        self.var_f_none = float(sigma_f_none) ** 2
        self.out = np.zeros((self.n, 4))
        self.out[:, 3] = self.var_f_none
        self.out[:, 2] = math.inf
        self.nis = np.full(self.n, math.nan)
        self.nis_p = np.full(self.n, math.nan)

    def reset(self, i: int, dtau: float = 0.0, dphi: float = 0.0, df: float = 0.0,
              sigma_tau: float | None = None, sigma_phi: float = 1.0,
              sigma_f: float | None = None) -> None:
        """Nothing is carried between intervals: no prior to set."""

    #: :meth:`decorrelate` takes no prior (nothing is carried).
    takes_prior = False

    def decorrelate(self, i: int, frequency: bool | None = None,
                    prior: tuple[float, float] | None = None) -> None:
        """Nothing is carried between intervals: nothing to forget."""

    def set_frequency(self, i: int, df_hz: float) -> None:
        """Not used: the frequency is measured afresh every interval."""

    def shift(self, i: int, d_tau_chips: float, d_f_hz: float) -> None:
        """The channel's NCOs moved by ``d_tau`` chips and ``d_f`` Hz after its
        correlations (NCOs one interval ahead): the last outputs become the errors relative
        to the moved NCOs."""
        self.out[i, 0] -= d_tau_chips
        self.out[i, 1] -= d_f_hz

    def process(self, i: int, early, prompt, late, t_epoch, cn0_hz: float,
                block_start=None) -> None:
        """Channel ``i``'s epochs of the interval (NH wiped off) summed into coherent blocks
        (``block_start`` as :meth:`~sdr_di.deep.prefilter.PreFilterBank.process`), then the
        discriminator measurements (module notes)."""
        t = np.ascontiguousarray(t_epoch, dtype=np.float64)
        if t.size == 0:
            return
        self.process_blocks(i, *coherent_blocks(early, prompt, late, t, block_start), cn0_hz)

    def process_blocks(self, i: int, early, prompt, late, t, cn0_hz: float) -> None:
        """:meth:`process` of channel ``i``'s coherent blocks (at least one; their sums and
        durations ``t`` [s], :func:`~sdr_di.deep.prefilter.coherent_blocks`)."""
        t = np.ascontiguousarray(t, dtype=np.float64)
        r_tau, r_phi = discriminator_variances(cn0_hz, t, self.spacing)
        dtau, df, v_tau, v_f, nis = interval_discriminators(
            np.ascontiguousarray(early, np.complex128),
            np.ascontiguousarray(prompt, np.complex128),
            np.ascontiguousarray(late, np.complex128), np.ascontiguousarray(t), self.spacing,
            np.ascontiguousarray(r_tau), np.ascontiguousarray(r_phi), self.var_f_none)
        o = self.out[i]
        o[0], o[1], o[2], o[3] = dtau, df, v_tau, v_f
        self.nis[i], self.nis_p[i] = nis_test(nis, 2 * t.size - 3)

    def process_channels(self, ch0: int, counts, bounds, early, prompt, late, t,
                         cn0_hz) -> None:
        """:meth:`process_blocks` of channels ``ch0, ch0 + 1, ...`` (arguments as
        :meth:`~sdr_di.deep.prefilter.PreFilterBank.process_channels`), one after the
        other."""
        for k, cnt in enumerate(counts):
            if cnt:
                b = slice(bounds[k], bounds[k + 1])
                self.process_blocks(ch0 + k, early[b], prompt[b], late[b], t[b], cn0_hz[k])

    def outputs(self, i: int) -> tuple[float, float, float, float]:
        """``(dtau [chips], df [Hz], var_tau [chips^2], var_f [Hz^2])`` of channel ``i``'s
        last interval."""
        o = self.out[i]
        return float(o[0]), float(o[1]), float(o[2]), float(o[3])
