"""Numba kernel of the vector loop's correlator rows: every channel's code epochs of one
filter interval in one call.

:func:`epoch_rows` is :func:`sdr_di.deep.vector_tracking._epoch_rows` (the plain numpy form,
which documents the NCO model) for all channels at once, with the same float64 operations
in the same order, so the same values bit for bit (tested); it replaces seven small numpy
pipelines and their concatenation per interval (about 0.2 ms of Python per 20 ms interval).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, boundscheck=False)
def epoch_rows(next_start, epoch, phase, c0, dc, dp0, dp1, is_d1, nh20, code_len, k0, k1):
    """Correlator rows of every channel over ``[k0, k1)`` (one row per code epoch that
    starts in ``[next_start_c, k1)``), channels in the order of the inputs.

    Parameters
    ----------
    next_start, epoch : int64 (n_ch,)
        First sample and number of each channel's next code epoch; updated in place.
    phase : float64 (n_ch,)
        Carrier NCO phase at ``next_start`` [cycles]; updated in place.
    c0, dc : float64 (n_ch,)
        Code NCO chip count at ``k0`` and its rate [chips/sample].
    dp0, dp1 : float64 (n_ch,)
        Carrier NCO frequency of the previous and this interval [cycles/sample].
    is_d1 : bool (n_ch,)
        D1 channel (NH code wiped off with ``nh20``).
    nh20 : float64 (20,)
        NH code signs.
    code_len : int
        Chips per code period.
    k0, k1 : int
        The interval's IF samples.

    Returns
    -------
    reps : int64 (n_ch,) rows of each channel; starts, n : int64; theta, phi, dphi, nh :
    float64; ep : int64 (sum(reps),) as ``_epoch_rows`` returns them.
    """
    n_ch = next_start.size
    L = code_len
    N = float(k1 - k0)
    reps = np.zeros(n_ch, np.int64)
    cap = 0
    for c in range(n_ch):
        if next_start[c] < k1:
            cap += int((k1 - next_start[c]) * dc[c] / L) + 3
    starts = np.empty(cap, np.int64)
    n_out = np.empty(cap, np.int64)
    theta = np.empty(cap)
    phi = np.empty(cap)
    dphi = np.empty(cap)
    nh = np.empty(cap)
    ep_out = np.empty(cap, np.int64)
    r = 0
    for c in range(n_ch):
        s0 = next_start[c]
        e0 = epoch[c]
        if s0 >= k1:
            continue
        m_max = int((k1 - s0) * dc[c] / L) + 3
        ph0 = phase[c]
        adv = 0.0
        start = s0
        m = 0
        end_last = s0
        for j in range(m_max):
            # raw end of epoch e0 + j (the next epoch's start, before the 1-sample floor)
            end_raw = np.int64(math.ceil(k0 + ((e0 + 1 + j) * L - c0[c]) / dc[c]))
            if start >= k1:
                break
            end = max(end_raw, start + 1)
            n = end - start
            ep = e0 + j
            th = c0[c] + (start - k0) * dc[c] - ep * L
            dp = dp0[c] + (dp1[c] - dp0[c]) * ((start + 0.5 * n - k0) / N + 0.5)
            p = ph0 + adv
            p -= math.floor(p)
            adv = adv + n * dp
            starts[r] = start
            n_out[r] = n
            theta[r] = th
            phi[r] = p
            dphi[r] = dp
            nh[r] = nh20[ep % 20] if is_d1[c] else 1.0
            ep_out[r] = ep
            r += 1
            m += 1
            end_last = end
            start = end_raw
        reps[c] = m
        end_phase = ph0 + adv
        next_start[c] = end_last
        epoch[c] = e0 + m
        phase[c] = end_phase - math.floor(end_phase)
    return (reps, starts[:r], n_out[:r], theta[:r], phi[:r], dphi[:r], nh[:r], ep_out[:r])
