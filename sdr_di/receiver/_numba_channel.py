"""Numba kernels of a scalar channel's per-block and per-epoch bookkeeping.

Plain arrays and scalars in and out; the model, the notation and the plain Python forms that
these transcribe (the tested references) are in :mod:`sdr_di.receiver.channel`:

:func:`plan_block`
    :meth:`Channel._plan_reference <sdr_di.receiver.channel.Channel._plan_reference>`'s
    loop: the correlator rows (each epoch followed by its noise-correlator row), the NCO
    state after each epoch and the history rows of the epochs of the next block, the same
    float64 operations in the same order (the same values bit for bit).
:func:`plain_epochs`
    :meth:`Channel._epoch <sdr_di.receiver.channel.Channel._epoch>` of a bit-synchronized
    channel without a tracking log, over consecutive epochs in which nothing but sums and
    counters changes (no completed bit, no lock evaluation, not the block's last epoch,
    which updates the loops): prompt ring, NH wipe-off, coherent and bit sums. It stops at
    the first epoch that needs the Python form.

:func:`prompt_moments`
    the means :meth:`Channel._evaluate <sdr_di.receiver.channel.Channel._evaluate>`'s lock
    detectors take of the prompt window with a known noise power
    (:func:`~sdr_di.receiver.lock.prompt_signal_power` and the numerator of
    :func:`~sdr_di.receiver.lock.carrier_lock_metric`), read from the ring, with numpy's
    sums (:mod:`~sdr_di.receiver.pairwise_sums`).

The first two replace Python run once per epoch per channel (about 60 % of the channels' CPU time in
a 2.5 MHz run, ``docs/notes/speed.md`` session 23).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .pairwise_sums import pairwise_sum


@njit(cache=True, boundscheck=False)
def plan_block(m, start, th, ph, dph, ep, rate, dchip, dphi, ddop, fd, f_est, f_rate, f_mid,
               code_len, noise_samples, noise_min_lag, noise_lag_step, hist, rows, ends):
    """The NCO of the next ``m`` epochs of one channel (one loop update).

    Parameters
    ----------
    m : int
        Epochs in the block.
    start : int
        First sample of the block.
    th, ph, dph : float
        Code phase [chips], carrier NCO phase [cycles, in [0, 1)] and accumulated Doppler
        phase [cycles] at ``start``.
    ep : int
        Code epoch number of the first epoch.
    rate, dchip : float
        Code NCO rate [chips/s] and step [chips/sample].
    dphi, ddop : float
        Carrier NCO step with and without the IF [cycles/sample].
    fd, f_est, f_rate, f_mid : float
        NCO Doppler [Hz], the loop's Doppler estimate [Hz], its rate [Hz/s] and the sample it
        refers to (history columns).
    code_len : int
        Chips per code period ``L``.
    noise_samples, noise_min_lag, noise_lag_step : int
        The noise row's most samples (:func:`~sdr_di.receiver.lock.noise_samples`),
        ``NOISE_MIN_LAG_CHIPS`` and the lag step of
        :func:`~sdr_di.receiver.lock.noise_code_phase`.
    hist : float64 (H, 9)
        History ring, written at row ``ep % H``: ``(start, theta, rate, dphase, fd, ep,
        f_est, f_rate, f_mid)``.
    rows : float64 (>= 2 m, 6)
        Written: correlator rows ``(start, n, theta, dchip, phi, dphi)``, epoch ``i`` at
        ``2 i`` and its noise row at ``2 i + 1``.
    ends : float64 (>= m, 4)
        Written: ``(next start, theta, phi, dphase)`` after epoch ``i``.
    """
    lf = float(code_len)
    n_hist = hist.shape[0]
    span = code_len - 2 * noise_min_lag
    for i in range(m):
        n = math.ceil((lf - th) / dchip)
        if n < 1:
            n = 1
        r = 2 * i
        rows[r, 0] = start
        rows[r, 1] = n
        rows[r, 2] = th
        rows[r, 3] = dchip
        rows[r, 4] = ph
        rows[r, 5] = dphi
        t = th + noise_min_lag + (ep * noise_lag_step) % span
        if t >= code_len:
            t = t - code_len
        rows[r + 1, 0] = start
        rows[r + 1, 1] = n if n < noise_samples else noise_samples
        rows[r + 1, 2] = t
        rows[r + 1, 3] = dchip
        rows[r + 1, 4] = ph
        rows[r + 1, 5] = dphi
        h = ep % n_hist
        hist[h, 0] = start
        hist[h, 1] = th
        hist[h, 2] = rate
        hist[h, 3] = dph
        hist[h, 4] = fd
        hist[h, 5] = ep
        hist[h, 6] = f_est
        hist[h, 7] = f_rate
        hist[h, 8] = f_mid
        th = th + n * dchip - lf
        if th < 0.0:
            th = 0.0
        ph += n * dphi
        ph -= math.floor(ph)
        dph += n * ddop
        start += n
        ep += 1
        ends[i, 0] = start
        ends[i, 1] = th
        ends[i, 2] = ph
        ends[i, 3] = dph


@njit(cache=True, boundscheck=False)
def plain_epochs(outs, i0, m, ep, bit_off, bit_ms, is_d1, nh, ring, coh_e, coh_p, coh_l,
                 bit_acc, bit_n, eval_count, lock_eval_ms, frozen):
    """Epochs ``i0, i0 + 1, ...`` of a block of ``m`` of a bit-synchronized channel, up to
    the first one that needs :meth:`Channel._epoch <sdr_di.receiver.channel.Channel._epoch>`
    (module notes).

    Parameters
    ----------
    outs : complex128 (>= m, 3)
        Early, prompt, late sums of the block's epochs.
    i0, m : int
        First epoch to process and epochs in the block.
    ep : int
        Code epoch number of epoch ``i0``.
    bit_off, bit_ms : int
        Epoch (mod ``bit_ms``) of the bit edges, and epochs per bit.
    is_d1 : bool
        D1 (NH code wiped off with ``nh``).
    nh : float64 (20,)
        NH20 signs.
    ring : complex128 (R,)
        Prompt ring, written at ``ep % R``.
    coh_e, coh_p, coh_l : complex
        Coherent E, P, L sums.
    bit_acc : float
        Prompt I sum of the bit in progress.
    bit_n, eval_count : int
        Epochs in the bit sum and since the last lock evaluation.
    lock_eval_ms : int
        Epochs between lock evaluations.
    frozen : bool
        The block's loop update and lock evaluations are skipped (the mode changed).

    Returns
    -------
    tuple
        ``(i, coh_e, coh_p, coh_l, bit_acc, bit_n, eval_count)``: the first epoch not
        processed (``m - 1`` at most; ``i - i0`` epochs were added to the coherent sums), the
        new sums and counters.
    """
    n_ring = ring.size
    i = i0
    while i < m - 1:
        k = (ep - bit_off) % bit_ms
        if k == bit_ms - 1:
            break
        if eval_count + 1 >= lock_eval_ms and not frozen:
            break
        e = outs[i, 0]
        p = outs[i, 1]
        l = outs[i, 2]
        ring[ep % n_ring] = p
        if is_d1 and nh[k] < 0.0:
            e, p, l = -e, -p, -l
        coh_e += e
        coh_p += p
        coh_l += l
        if k == 0:
            bit_acc = 0.0
            bit_n = 0
        bit_acc += p.real
        bit_n += 1
        eval_count += 1
        ep += 1
        i += 1
    return i, coh_e, coh_p, coh_l, bit_acc, bit_n, eval_count


@njit(cache=True, boundscheck=False)
def prompt_moments(ring, end, n):
    """``(mean(I^2 + Q^2), mean(I^2 - Q^2))`` of the ``n`` prompts of ``ring`` before slot
    ``end`` (oldest first, wrapping round the ring): ``lock._mean`` of ``p.real * p.real +
    p.imag * p.imag`` and of ``p.real * p.real - p.imag * p.imag`` (numpy's pairwise sums
    divided by ``n``), bit for bit."""
    size = ring.shape[0]
    power = np.empty(n)
    diff = np.empty(n)
    for k in range(n):
        p = ring[(end - n + k) % size]
        i2 = p.real * p.real
        q2 = p.imag * p.imag
        power[k] = i2 + q2
        diff[k] = i2 - q2
    return pairwise_sum(power, 0, n) / n, pairwise_sum(diff, 0, n) / n
