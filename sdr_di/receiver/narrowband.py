"""Input cleaning before acquisition: DC removal and blanking of narrowband lines.

Why
---
Acquisition correlates the input with each PRN's replica over a Doppler grid. Power that is
not white noise but a *line* (a DC offset of the ADC, a continuous-wave interferer, a spur
of the front end's clock) is correlated energy: wiped off at Doppler ``fd`` it becomes a tone
that the code's own 1 kHz line spectrum (the code repeats every 1 ms) picks up at every
``fd`` that puts the tone on one of those lines, for every PRN. No detection statistic can
reject it, since it is real, coherent energy. A DC offset of a few LSB on complex baseband
noise is enough for 20 and more PRNs to pass the threshold at 22-39 dB-Hz. So the lines are
removed from the input before the search.

Method
------
1. **DC**: the mean of the block is subtracted (complex mean for I/Q, real mean otherwise)
   when it is significant, beyond 4 standard errors ``sqrt(P / N)`` (a 3 LSB offset on
   4-bit noise of 40 ms at 25 MHz is about 1300 of them; a mean consistent with zero is
   left alone rather than replaced by its own estimation noise).
2. **Lines**: the periodogram ``|X(f)|^2`` of the whole block (one FFT of ``N`` samples,
   resolution ``fs / N``: 25 Hz on 40 ms) is compared with a local noise reference, the
   median of the periodogram over segments of ``segment_bins`` bins divided by ``ln 2`` (the
   median of an exponential variable with mean ``m`` is ``m ln 2``; segments follow a
   front-end passband that is not flat). With noise only, each bin is exponential with that
   mean, so a bin exceeds ``T`` times it with probability ``exp(-T)``; ``T = ln(N / pfa)``
   keeps the probability of blanking any noise-only bin of the block near ``pfa``. Every bin
   above the threshold is set to zero (a strong line's leakage raises its neighbours above
   the threshold too, so the notch widens with the line's power), then the block is
   transformed back.

A B3I signal never triggers it: its power is spread over 20 MHz in 1 kHz lines that NH and
data modulation smear further; at 50 dB-Hz a line holds about 0.2 times the noise of a 25 Hz
bin, far below the threshold (about 20 times the mean at 1e6 bins).

Cost: one forward and one inverse FFT of the block (about 0.1 s for 40 ms at 25 MHz).
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import scipy.fft

__all__ = ["CleanedInput", "remove_dc_and_lines"]

#: A mean is removed when it exceeds this many standard errors of the mean.
_DC_SIGMAS = 4.0


@dataclasses.dataclass
class CleanedInput:
    """Result of :func:`remove_dc_and_lines`.

    Attributes
    ----------
    samples : numpy.ndarray
        Cleaned samples (``complex64`` for I/Q input, ``float32`` for real input).
    dc : complex
        Mean removed [input units] (0 when the mean was not significant).
    line_hz : numpy.ndarray
        Centre frequencies of the blanked groups of bins [Hz], relative to the sampled band
        (baseband: -fs/2..fs/2; real input: 0..fs/2).
    blanked_fraction : float
        Fraction of the band set to zero.
    input_power : float
        Mean ``|x|^2`` after DC removal [input units^2] (0 for a constant file).
    """

    samples: np.ndarray
    dc: complex
    line_hz: np.ndarray
    blanked_fraction: float
    input_power: float


def remove_dc_and_lines(x: np.ndarray, sampling_rate_hz: float, *, pfa: float = 1e-3,
                        segment_bins: int = 4096, workers: int | None = None) -> CleanedInput:
    """Subtract the mean and blank narrowband lines (module notes).

    Parameters
    ----------
    x : numpy.ndarray
        1-D complex (I/Q) or real samples.
    sampling_rate_hz : float
        fs [Hz].
    pfa : float, optional
        Probability of blanking any noise-only bin of the block. Default 1e-3.
    segment_bins : int, optional
        Bins per segment of the local noise reference. Default 4096.
    workers : int, optional
        Threads for ``scipy.fft``.

    Returns
    -------
    CleanedInput
    """
    is_complex = np.iscomplexobj(x)
    y = np.asarray(x, dtype=np.complex64 if is_complex else np.float32)
    n = y.size
    dc = complex(np.mean(y, dtype=np.complex128 if is_complex else np.float64)) if n else 0j
    power = float(np.mean(np.abs(y - dc) ** 2)) if n else 0.0
    # the mean is removed when it is significant: beyond _DC_SIGMAS standard errors
    # (sqrt(power / n)); a mean consistent with zero is left alone (subtracting it would only
    # add its own estimation noise)
    if abs(dc) > _DC_SIGMAS * math.sqrt(power / max(n, 1)) or not power > 0.0:
        y = y - (np.complex64(dc) if is_complex else np.float32(dc.real))
    else:
        dc = 0j
    empty = np.zeros(0)
    if n < 64 or not power > 0.0:
        return CleanedInput(y, dc, empty, 0.0, power)
    spec = scipy.fft.fft(y, workers=workers) if is_complex else \
        scipy.fft.rfft(y, workers=workers)
    p = spec.real.astype(np.float64) ** 2 + spec.imag.astype(np.float64) ** 2
    nb = p.size
    seg = max(64, min(int(segment_bins), nb))
    n_seg = max(1, nb // seg)
    edges = np.linspace(0, nb, n_seg + 1).astype(np.int64)
    ref = np.empty(nb)
    for a, b in itertools.pairwise(edges):
        ref[a:b] = np.median(p[a:b]) / math.log(2.0)
    thr = math.log(nb / pfa)
    mask = p > thr * np.maximum(ref, np.finfo(float).tiny)
    if not mask.any():
        return CleanedInput(y, dc, empty, 0.0, power)
    spec[mask] = 0.0
    y = (scipy.fft.ifft(spec, workers=workers) if is_complex
         else scipy.fft.irfft(spec, n, workers=workers)).astype(y.dtype)
    idx = np.flatnonzero(mask)
    freqs = (scipy.fft.fftfreq(n, 1.0 / sampling_rate_hz) if is_complex
             else scipy.fft.rfftfreq(n, 1.0 / sampling_rate_hz))
    lines = _group_centres(idx, freqs)
    frac = float(np.count_nonzero(mask)) / nb
    return CleanedInput(y, dc, lines, frac, power)


def _group_centres(idx: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    """Centre frequency of each run of adjacent blanked bins (its middle bin) [Hz]."""
    if idx.size == 0:
        return np.zeros(0)
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.concatenate(([0], breaks + 1))
    ends = np.concatenate((breaks, [idx.size - 1]))
    mid = idx[(starts + ends) // 2]
    return np.asarray(freqs[mid], dtype=np.float64)
