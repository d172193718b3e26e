"""Numba kernel of the discriminator measurements (one channel, the blocks of one interval).

Plain arrays only; the model and notation are documented in
:mod:`sdr_di.deep.discriminators`, whose :func:`~sdr_di.deep.discriminators.
interval_discriminators_numpy` is the tested reference.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ._numba_prefilter import wrap_half_pi


@numba.njit(cache=True)
def interval_discriminators(early, prompt, late, t_block, spacing, r_tau, r_phi, var_f_none):
    """Code and frequency discriminator measurements of one channel's interval.

    Parameters
    ----------
    early, prompt, late : complex128 (m,)
        Correlator sums of the interval's coherent blocks (NH wiped off).
    t_block : float64 (m,)
        Block durations [s], in time order and contiguous.
    spacing : float
        Early/late offset d [chips].
    r_tau, r_phi : float64 (m,)
        Discriminator noise variances of each block [chips^2], [rad^2].
    var_f_none : float
        Frequency variance [Hz^2] stated when the interval has a single block (no
        frequency information).

    Returns
    -------
    dtau, df, var_tau, var_f, nis : float
        Code error [chips], frequency error [Hz], their variances, and the sum of squared
        normalized residuals of the blocks about the fit (``2 m - 3`` degrees of freedom).
    """
    m = prompt.shape[0]
    z = np.empty(m)
    sw = 0.0
    swz = 0.0
    for j in range(m):
        ea = abs(early[j])
        la = abs(late[j])
        s = ea + la
        z[j] = (1.0 - spacing) * (ea - la) / s if s > 0.0 else 0.0
        w = 1.0 / r_tau[j]
        sw += w
        swz += w * z[j]
    dtau = swz / sw
    var_tau = 1.0 / sw
    nis = 0.0
    for j in range(m):
        d = z[j] - dtau
        nis += d * d / r_tau[j]
    if m < 2:
        return dtau, 0.0, var_tau, var_f_none, nis
    # block phases (two-quadrant: data-bit signs do not matter) unwrapped along the
    # interval, at the block centres; weighted least-squares slope
    t = np.empty(m)
    psi = np.empty(m)
    start = 0.0
    prev = 0.0
    for j in range(m):
        t[j] = start + 0.5 * t_block[j]
        start += t_block[j]
        pr = prompt[j]
        ph = math.atan(pr.imag / pr.real) if pr.real != 0.0 else 0.5 * math.pi
        if j == 0:
            psi[j] = ph
        else:
            psi[j] = psi[j - 1] + wrap_half_pi(ph - prev)
        prev = ph
    sw = 0.0
    st = 0.0
    sp = 0.0
    for j in range(m):
        w = 1.0 / r_phi[j]
        sw += w
        st += w * t[j]
        sp += w * psi[j]
    tb = st / sw
    pb = sp / sw
    stt = 0.0
    stp = 0.0
    for j in range(m):
        w = 1.0 / r_phi[j]
        stt += w * (t[j] - tb) * (t[j] - tb)
        stp += w * (t[j] - tb) * (psi[j] - pb)
    slope = stp / stt
    for j in range(m):
        d = psi[j] - pb - slope * (t[j] - tb)
        nis += d * d / r_phi[j]
    two_pi = 2.0 * math.pi
    return dtau, slope / two_pi, var_tau, 1.0 / (stt * two_pi * two_pi), nis
