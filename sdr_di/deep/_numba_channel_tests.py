"""Numba kernel of the vector loop's per-channel tests, for the channels of one pass.

Plain arrays only. It transcribes, channel after channel, the plain forms that stay the
tested references (``tests/test_deep_channel_tests.py``, bit for bit):
:meth:`PostCorrelationNoise.add_values <sdr_di.receiver.lock.PostCorrelationNoise.add_values>`
and :meth:`~sdr_di.receiver.lock.PostCorrelationNoise.noise_power`,
:meth:`BitPower.add <sdr_di.deep.bit_power.BitPower.add>` and
:meth:`~sdr_di.deep.bit_power.BitPower.cn0_dbhz`, and the fast and loss tests of
:mod:`sdr_di.deep.channel_tests`. Sums are numpy's (:mod:`sdr_di.receiver.pairwise_sums`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..receiver.pairwise_sums import (pairwise_sum, pairwise_sum_complex,
                                      pairwise_sum_squares, segment_sum_complex)


@njit(cache=True, boundscheck=False)
def _noise_add(v, i, ok, vals, s, cnt, ring_i, ring_count):
    """Channel ``i``'s noise ring: the values ``vals[s:s + cnt]`` where ``ok``
    (PostCorrelationNoise.add_values: the same slots)."""
    size = v.shape[1]
    m = 0
    for e in range(s, s + cnt):
        if ok[e]:
            m += 1
    if m == 0:
        return
    if m >= size:
        # the last `size` values, in order from slot 0
        skip = m - size
        k = 0
        for e in range(s, s + cnt):
            if ok[e]:
                if skip > 0:
                    skip -= 1
                else:
                    v[i, k] = vals[e]
                    k += 1
        ring_i[i] = 0
        ring_count[i] = size
        return
    j = ring_i[i]
    for e in range(s, s + cnt):
        if ok[e]:
            v[i, j] = vals[e]
            j += 1
            if j == size:
                j = 0
    ring_i[i] = j
    ring_count[i] = min(size, ring_count[i] + m)


@njit(cache=True, boundscheck=False)
def _noise_power(v, i, count, input_power, z, min_values):
    """PostCorrelationNoise.noise_power of channel ``i``'s ring (``input_power`` > 0)."""
    if count < min_values:
        return input_power
    row = v[i]
    s = pairwise_sum(row, 0, count)
    s2 = pairwise_sum_squares(row, 0, count)
    m = s / count
    if not m > 0.0:
        return input_power
    if not input_power > 0.0:
        return m
    se = math.sqrt(max(s2 / count - m * m, 0.0) / count)
    return m if abs(m - input_power) > z * se else input_power


@njit(cache=True, boundscheck=False)
def _push(bp_p, bp_n, i, size, count, new, p, n):
    """BitPower._push_one of one sum on channel ``i``'s ring (``size`` long, newest last)."""
    row_p = bp_p[i]
    row_n = bp_n[i]
    for k in range(size - 1):
        row_p[k] = row_p[k + 1]
        row_n[k] = row_n[k + 1]
    row_p[size - 1] = p
    row_n[size - 1] = n
    count[i] = min(count[i] + 1, size)
    new[i] += 1


@njit(cache=True, boundscheck=False)
def _bit_sums_add(bp_p, bp_n, i, size, count, new, acc_p, acc_n, prompts, nsamp, bit_start,
                  s, cnt, seg_p, seg_n):
    """BitPower.add of the epochs ``[s, s + cnt)`` (cnt >= 1) to channel ``i``."""
    new[i] = 0
    # the epochs before the first bit start complete the bit carried (all of them when no
    # bit starts here: BitPower.add's sum of p is its sum of p[:head] with head = cnt)
    head = 0
    while head < cnt and not bit_start[s + head]:
        head += 1
    acc_p[i] = acc_p[i] + pairwise_sum_complex(prompts, s, head)
    ns = 0
    for e in range(s, s + head):
        ns += nsamp[e]
    acc_n[i] = acc_n[i] + float(ns)
    if head == cnt:
        return
    if acc_n[i] > 0.0:
        _push(bp_p, bp_n, i, size, count, new, acc_p[i], acc_n[i])
    # the bits that start here (np.add.reduceat's segments)
    k = 0
    e0 = s + head
    while e0 < s + cnt:
        e1 = e0 + 1
        while e1 < s + cnt and not bit_start[e1]:
            e1 += 1
        seg_p[k] = segment_sum_complex(prompts, e0, e1 - e0)
        tot = 0
        for e in range(e0, e1):
            tot += nsamp[e]
        seg_n[k] = float(tot)
        k += 1
        e0 = e1
    # every bit but the last is complete (BitPower._push: the newest min(k - 1, size))
    done = k - 1
    if done > 0:
        mm = min(done, size)
        row_p = bp_p[i]
        row_n = bp_n[i]
        if mm < size:
            for q in range(size - mm):
                row_p[q] = row_p[q + mm]
                row_n[q] = row_n[q + mm]
        for q in range(mm):
            row_p[size - mm + q] = seg_p[done - mm + q]
            row_n[size - mm + q] = seg_n[done - mm + q]
        count[i] = min(count[i] + mm, size)
        new[i] += mm
    acc_p[i] = seg_p[k - 1]
    acc_n[i] = seg_n[k - 1]


@njit(cache=True, boundscheck=False)
def _cn0(bp_p, bp_n, i, size, count, last, noise_power, fs, sig, nse):
    """BitPower.cn0_dbhz of channel ``i`` from its last ``last`` sums (-1: all) [dB-Hz]."""
    k = count if last < 0 else min(last, count)
    if k <= 0 or not noise_power > 0.0:
        return math.nan
    lo = size - k
    for q in range(k):
        p = bp_p[i, lo + q]
        nb = noise_power * bp_n[i, lo + q]
        sig[q] = p.real * p.real + p.imag * p.imag - nb
        nse[q] = nb * (bp_n[i, lo + q] / fs)
    pd = pairwise_sum(sig, 0, k)
    den = pairwise_sum(nse, 0, k)
    if not (pd > 0.0 and den > 0.0):
        return math.nan
    return 10.0 * math.log10(pd / den)


@njit(cache=True, boundscheck=False)
def channel_tests(ch0, counts, prompts, nsamp, bit_start, noise, noise_ok, input_power, fs,
                  bp_p, bp_n, bp_size, bp_count, bp_acc_p, bp_acc_n,
                  nz_v, nz_i, nz_count, nz_z, nz_min,
                  fast_k, loss_k, cn0_min_k, fast_threshold, loss_threshold,
                  cn0, rejoining, fast_fail, new, count_tested):
    """The tests of channels ``ch0, ch0 + 1, ...`` on their epochs of one pass, in place.

    Parameters
    ----------
    ch0 : int
        First channel of the pass.
    counts : int64 (m,)
        Epochs of each of the pass's ``m`` channels, consecutive in the epoch arrays.
    prompts : complex128 (e,)
        Prompts, NH wiped off.
    nsamp : int64 (e,)
        Samples of each epoch.
    bit_start : bool (e,)
        Epochs that begin a data bit.
    noise : float64 (e,)
        Each epoch's noise-correlator value [stored units^2] where ``noise_ok``.
    input_power : float
        Input power per sample [stored units^2].
    fs : float
        Sample rate [Hz].
    bp_p, bp_n, bp_size, bp_count, bp_acc_p, bp_acc_n
        Bit-sum rings (channel ``i``'s newest in ``[i, bp_size[i] - 1]``), sums held, the bit
        being summed (prompt sum, samples).
    nz_v, nz_i, nz_count, nz_z, nz_min
        Noise-value rings, next slot, values held, z and values needed
        (PostCorrelationNoise).
    fast_k, loss_k, cn0_min_k : int64 (n,)
        Bit sums of the fast test, the loss test and of the first C/N0 taken up.
    fast_threshold, loss_threshold : float
        C/N0 the fast and the loss test need [dB-Hz].
    cn0, rejoining, fast_fail : (n,)
        Each channel's C/N0 [dB-Hz], rejoining flag and last test result (0 pass, 1 fast
        test failed, 2 loss test too): updated where the channel completed a bit sum.
    new : int64 (n,)
        Bit sums completed by the pass (0 for a channel without epochs).
    count_tested : int64 (n,)
        Sums held when the tests ran (before a loss empties the ring).
    """
    nmax = bp_p.shape[1]
    sig = np.empty(nmax)
    nse = np.empty(nmax)
    seg_p = np.empty(prompts.shape[0] + 1, np.complex128)
    seg_n = np.empty(prompts.shape[0] + 1)
    s = 0
    for m in range(counts.shape[0]):
        i = ch0 + m
        cnt = counts[m]
        new[i] = 0
        if cnt == 0:
            continue
        _noise_add(nz_v, i, noise_ok, noise, s, cnt, nz_i, nz_count)
        npow = _noise_power(nz_v, i, nz_count[i], input_power, nz_z[i], nz_min[i])
        size = bp_size[i]
        _bit_sums_add(bp_p, bp_n, i, size, bp_count, new, bp_acc_p, bp_acc_n, prompts,
                      nsamp, bit_start, s, cnt, seg_p, seg_n)
        s += cnt
        if new[i] == 0:
            continue
        fast = _cn0(bp_p, bp_n, i, size, bp_count[i], fast_k[i], npow, fs, sig, nse)
        ff = 0 if fast >= fast_threshold else 1
        if ff and not _cn0(bp_p, bp_n, i, size, bp_count[i], loss_k[i], npow, fs, sig,
                           nse) >= loss_threshold:
            ff = 2
        fast_fail[i] = ff
        count_tested[i] = bp_count[i]
        if ff >= 2:
            bp_count[i] = 0
            bp_acc_p[i] = 0j
            bp_acc_n[i] = 0.0
            cn0[i] = math.nan
            rejoining[i] = True
        elif ff == 0 and bp_count[i] >= (size if rejoining[i] else cn0_min_k[i]):
            rejoining[i] = False
            cn0[i] = _cn0(bp_p, bp_n, i, size, bp_count[i], -1, npow, fs, sig, nse)
