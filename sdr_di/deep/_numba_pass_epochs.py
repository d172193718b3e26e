"""Numba kernel of :func:`~sdr_di.deep.pass_epochs.pass_epochs`: a pass's correlator outputs
made ready for the channels' tests, decoders and pre-filters. Plain arrays only; the
numpy form :func:`~sdr_di.deep.pass_epochs.pass_epochs_numpy` is the tested reference (the
same operations in the same order; sums in numpy's order,
:mod:`sdr_di.receiver.pairwise_sums`)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ..receiver.pairwise_sums import segment_sum, segment_sum_complex


@njit(cache=True, boundscheck=False)
def _segments(first, counts):
    """Segments of consecutive channels' epochs (``counts[k]`` each) that start where
    ``first`` is true (every channel's first epoch must be): ``(starts, bounds)``, segment
    ``j`` is ``[starts[j], starts[j + 1])``, channel ``k``'s segments are ``[bounds[k],
    bounds[k + 1])``."""
    n_ch = counts.shape[0]
    n = 0
    for e in range(first.shape[0]):
        if first[e]:
            n += 1
    starts = np.empty(n + 1, np.int64)
    bounds = np.empty(n_ch + 1, np.int64)
    j = 0
    e = 0
    for k in range(n_ch):
        bounds[k] = j
        for q in range(counts[k]):
            if first[e]:
                starts[j] = e
                j += 1
            e += 1
    starts[n] = e
    bounds[n_ch] = j
    return starts, bounds


@njit(cache=True, boundscheck=False)
def pass_epochs_kernel(out, a0, a1, nh, n_noise, nsamp, epoch, fs, counts, bit_ms, block_ms,
                       ms0):
    """The epochs ``[a0, a1)``: returns ``(E, P, L, noise, ok, bit_start, Eb, Pb, Lb, Tb,
    bounds, nav_bits, nav_sums, nav_bounds)`` (:class:`~sdr_di.deep.pass_epochs.
    PassEpochs`). ``out``: float64 ``(2 N, 3, 2)``, (re, im) of E, P, L of epoch ``e`` in
    row ``2 e``, of its noise correlator in row ``2 e + 1``."""
    m = a1 - a0
    E = np.empty(m, np.complex128)
    P = np.empty(m, np.complex128)
    L = np.empty(m, np.complex128)
    noise = np.empty(m)
    ok = np.empty(m, np.bool_)
    t = np.empty(m)
    bit_start = np.empty(m, np.bool_)
    block_start = np.empty(m, np.bool_)
    bitno = np.empty(m, np.int64)
    n_ch = counts.shape[0]
    e = 0
    for k in range(n_ch):
        bk = bit_ms[k]
        blk = min(bk, block_ms)
        for q in range(counts[k]):
            r = 2 * (a0 + e)
            s = complex(nh[a0 + e], 0.0)
            E[e] = complex(out[r, 0, 0], out[r, 0, 1]) * s
            P[e] = complex(out[r, 1, 0], out[r, 1, 1]) * s
            L[e] = complex(out[r, 2, 0], out[r, 2, 1]) * s
            nn = n_noise[a0 + e]
            ok[e] = nn > 0
            v = out[r + 1]
            noise[e] = (v[0, 0] ** 2 + v[0, 1] ** 2 + v[1, 0] ** 2 + v[1, 1] ** 2
                        + v[2, 0] ** 2 + v[2, 1] ** 2) / (3.0 * float(nn if nn > 0 else 1))
            t[e] = nsamp[a0 + e] / fs
            ep = epoch[a0 + e]
            bit_start[e] = ep % bk == 0
            # every channel's first epoch starts a block (coherent_blocks_of_channels)
            block_start[e] = q == 0 or ep % blk == 0
            bitno[e] = (ms0[k] + ep) // bk
            e += 1
    # coherent blocks: reduceat over the block starts (the inputs when every epoch is one)
    starts, bounds = _segments(block_start, counts)
    nb = starts.shape[0] - 1
    if nb == m:
        Eb, Pb, Lb, Tb = E, P, L, t
    else:
        Eb = np.empty(nb, np.complex128)
        Pb = np.empty(nb, np.complex128)
        Lb = np.empty(nb, np.complex128)
        Tb = np.empty(nb)
        for j in range(nb):
            e, f = starts[j], starts[j + 1]
            Eb[j] = segment_sum_complex(E, e, f - e)
            Pb[j] = segment_sum_complex(P, e, f - e)
            Lb[j] = segment_sum_complex(L, e, f - e)
            Tb[j] = segment_sum(t, e, f - e)
    # the prompts' sums over each channel's bits (ChannelNavDecoder.add)
    first = np.empty(m, np.bool_)
    e = 0
    for k in range(n_ch):
        for q in range(counts[k]):
            first[e] = q == 0 or bitno[e] != bitno[e - 1]
            e += 1
    bit0, nav_bounds = _segments(first, counts)
    ns = bit0.shape[0] - 1
    nav_bits = np.empty(ns, np.int64)
    nav_sums = np.empty(ns, np.complex128)
    for j in range(ns):
        nav_bits[j] = bitno[bit0[j]]
        nav_sums[j] = segment_sum_complex(P, bit0[j], bit0[j + 1] - bit0[j])
    return E, P, L, noise, ok, bit_start, Eb, Pb, Lb, Tb, bounds, nav_bits, nav_sums, \
        nav_bounds
