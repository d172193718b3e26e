"""The correlator outputs of a pass's channels, made ready for their tests, decoders and
pre-filters (:class:`PassEpochs`), in one kernel call.

The vector loop's kernel returns every epoch's early, prompt and late sums and its noise
correlator's (:meth:`~sdr_di.deep.vector_tracking.VectorTracking.correlate`). For the
channels of a pass (consecutive epochs, ``counts[k]`` of channel ``k``) :func:`pass_epochs`
makes, for all of them at once:

* E, P, L with the NH code wiped off (``nh``: the NH20 chip of a D1 epoch, else 1);
* each epoch's noise value (:func:`~sdr_di.receiver.lock.noise_values`; an epoch whose
  noise row had no sample has none: ``ok`` false);
* the epochs' durations [s] and the data-bit starts (``epoch % bit_ms == 0``);
* the coherent blocks of each channel (:func:`~sdr_di.deep.prefilter.
  coherent_blocks_of_channels`: blocks of ``min(bit_ms, block_ms)`` that end at bit
  edges);
* the prompts' sums over each channel's data bits for its navigation decoder
  (:meth:`~sdr_di.deep.navdecode.ChannelNavDecoder.add_sums`; bit numbers
  ``(ms0 + epoch) // bit_ms``).

:func:`pass_epochs_numpy` is the numpy form (the tested reference, bit for bit:
``tests/test_deep_channel_tests.py``); :data:`jit` false runs it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..receiver.lock import noise_values
from ._numba_pass_epochs import pass_epochs_kernel
from .prefilter import coherent_blocks_of_channels

__all__ = ["PassEpochs", "pass_epochs", "pass_epochs_kernel_form", "pass_epochs_numpy"]

#: Whether :func:`pass_epochs` runs the kernel (else the numpy form).
jit = True


@dataclasses.dataclass
class PassEpochs:
    """What :func:`pass_epochs` makes of a pass's epochs (``m`` epochs, ``b`` blocks,
    ``s`` bit sums, ``n`` channels)."""

    E: np.ndarray             # complex (m,): early, NH wiped off
    P: np.ndarray             # complex (m,): prompt, NH wiped off
    L: np.ndarray             # complex (m,): late, NH wiped off
    noise: np.ndarray         # (m,): noise value where ok [stored units^2]
    ok: np.ndarray            # bool (m,): the epoch's noise row had samples
    bit_start: np.ndarray     # bool (m,): the epoch begins a data bit
    blocks: tuple             # (E, P, L, t [s], bounds): coherent blocks, channel k's
    #                           [bounds[k], bounds[k + 1]) (coherent_blocks_of_channels)
    nav_bits: np.ndarray      # int64 (s,): bit numbers of the prompts' bit sums
    nav_sums: np.ndarray      # complex (s,): the sums
    nav_bounds: np.ndarray    # int64 (n + 1,): channel k's sums [nav_bounds[k], ...[k + 1])


def pass_epochs(epl: np.ndarray, a0: int, a1: int, nh: np.ndarray, n_noise: np.ndarray,
                nsamp: np.ndarray, epoch: np.ndarray, fs: float, counts, bit_ms,
                block_ms: int, ms0) -> PassEpochs:
    """The epochs ``[a0, a1)`` of an interval's rows (module notes).

    Parameters
    ----------
    epl : complex (2 N, 3)
        E, P, L of epoch ``e`` in row ``2 e``, of its noise correlator in row ``2 e + 1``
        (a view of the kernel's float output ``(2 N, 3, 2)``).
    a0, a1 : int
        The pass's epochs.
    nh, n_noise, nsamp, epoch : (N,)
        Every epoch's NH sign, noise-row samples, samples and number (ms since ``S0`` on
        the satellite clock).
    fs : float
        Sample rate [Hz].
    counts, bit_ms, ms0 : sequences of int (n,)
        Each channel's epochs in the pass, data bit [ms] and its decoder's ``ms0``.
    block_ms : int
        Longest coherent block [ms].
    """
    form = pass_epochs_kernel_form if jit else pass_epochs_numpy
    return form(epl, a0, a1, nh, n_noise, nsamp, epoch, fs, counts, bit_ms, block_ms, ms0)


def pass_epochs_kernel_form(epl, a0, a1, nh, n_noise, nsamp, epoch, fs, counts, bit_ms,
                            block_ms, ms0) -> PassEpochs:
    """:func:`pass_epochs` in numba (:func:`~sdr_di.deep._numba_pass_epochs.
    pass_epochs_kernel`)."""
    out = epl.base
    if not (isinstance(out, np.ndarray) and out.dtype == np.float64
            and out.shape == epl.shape + (2,) and out.flags.c_contiguous):
        out = np.stack((epl.real, epl.imag), axis=-1)
    r = pass_epochs_kernel(out, int(a0), int(a1), nh, n_noise, nsamp, epoch, float(fs),
                           np.asarray(counts, np.int64), np.asarray(bit_ms, np.int64),
                           int(block_ms), np.asarray(ms0, np.int64))
    E, P, L, noise, ok, bit_start, Eb, Pb, Lb, Tb, bounds, bits, sums, nb = r
    return PassEpochs(E, P, L, noise, ok, bit_start, (Eb, Pb, Lb, Tb, bounds.tolist()), bits,
                      sums, nb)


def pass_epochs_numpy(epl, a0, a1, nh, n_noise, nsamp, epoch, fs, counts, bit_ms, block_ms,
                      ms0) -> PassEpochs:
    """:func:`pass_epochs` in numpy (the reference of the kernel)."""
    ep, nz = epl[2 * a0:2 * a1:2], epl[2 * a0 + 1:2 * a1:2]
    sign = nh[a0:a1]
    E, P, L = ep[:, 0] * sign, ep[:, 1] * sign, ep[:, 2] * sign
    n_nz = n_noise[a0:a1]
    ok = n_nz > 0
    noise = noise_values(nz[:, 0], nz[:, 1], nz[:, 2], n_nz if ok.all() else
                         np.where(ok, n_nz, 1))
    t = nsamp[a0:a1] / fs
    epochs = epoch[a0:a1]
    bits = np.repeat(np.asarray(bit_ms, np.int64), counts)
    bit_start = epochs % bits == 0
    block = np.minimum(np.asarray(bit_ms, np.int64), int(block_ms))
    blocks = coherent_blocks_of_channels(
        E, P, L, t, bit_start if np.array_equal(block, bit_ms) else
        epochs % np.repeat(block, counts) == 0, counts)
    # the prompts' bit sums, each channel's as ChannelNavDecoder.add makes them
    bitno = (np.repeat(np.asarray(ms0, np.int64), counts) + epochs) // bits
    offs = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=offs[1:])
    first = np.ones(bitno.size, bool)
    if bitno.size:
        np.not_equal(bitno[1:], bitno[:-1], out=first[1:])
        first[offs[:-1][offs[:-1] < offs[1:]]] = True
    edges = first.nonzero()[0]
    sums = np.add.reduceat(P, edges) if edges.size else np.zeros(0, np.complex128)
    return PassEpochs(E, P, L, noise, ok, bit_start, blocks, bitno[edges], sums,
                      np.searchsorted(edges, offs))
