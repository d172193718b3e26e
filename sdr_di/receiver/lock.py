"""C/N0 estimation and lock detectors on prompt correlator outputs.

C/N0: moments method (M2M4)
---------------------------
For ``K`` prompts ``P_k = s_k + n_k`` with constant signal power ``|s|^2 = P_d`` (any phase,
any data sign) and complex Gaussian noise of power ``P_n``, ``M2 = mean |P|^2 = P_d + P_n``
and ``M4 = mean |P|^4 = P_d^2 + 4 P_d P_n + 2 P_n^2``, so ``P_d = sqrt(2 M2^2 - M4)``,
``P_n = M2 - P_d`` and ``C/N0 = P_d / (P_n T)`` for prompts of ``T`` seconds (Pauluzzi &
Beaulieu 2000). Insensitive to carrier phase and data/NH signs, so it works before the PLL
locks and before bit synchronization; the scalar receiver applies it to the 1 ms prompts of a
sliding window (default 100 ms). It is biased high at low SNR (below ~25 dB-Hz with 1 ms
prompts) and returns NaN when ``2 M2^2 <= M4`` (noise only, typically).

C/N0 with the noise power measured on the input (used by the scalar receiver)
-------------------------------------------------------------------------
The noise of a prompt summed over ``N`` samples has power ``N E|x|^2`` (signals are far below
the noise in each sample: 4e-4 of it per satellite at 40 dB-Hz and 25 MHz), so the receiver
measures ``E|x|^2`` on the samples it reads and the signal power is ``P_d = M2 - P_n``
(:func:`prompt_signal_power`, :func:`cn0_known_noise`). Lower variance than M2M4 (0.4 dB
rather than 1 dB for 100 prompts at 35 dB-Hz) and, on noise alone, NaN or below 25 dB-Hz
(three sigma of ``M2`` for 100 prompts) where M2M4 reads above 28 dB-Hz on a quarter of
100 ms windows: the C/N0 code-lock test (28 dB-Hz) is trustworthy.

Post-correlation noise (interference)
-----------------------------------
The input power counts every watt in the sampled band once, but what reaches a prompt is the
input spectrum weighted by the code's: white noise despreads to ``N E|x|^2``, an in-band
jammer to ``N J f_s kappa`` (``kappa = integral G_s G_j df``: 2.44 times its share of the
input power for a narrow jammer at the band centre of a 25 MHz file, nearly nothing near the
code spectrum's nulls). The input-power estimate then reads high under a centred jammer and
low, or NaN, under one near the nulls. Each receiver therefore also runs a **noise
correlator**: the channel's own code at a lag of at least :data:`NOISE_MIN_LAG_CHIPS` from
the prompt (:func:`noise_code_phase`: a different lag each epoch, so that the few hundred
chips it spans are a different stretch of the code each time: a fixed stretch has a fixed,
lumpy spectrum, which read a 2 MHz jammer 13 % low), over the first samples of each epoch
that span :data:`NOISE_SPAN_CHIPS` chips (:func:`noise_samples`: 1024 at 25 MHz, 103 at
2.5 MHz, at most :data:`NOISE_SAMPLES`), at the channel's carrier. Its
early, prompt and late sums hold no signal (Gold-code sidelobes ~1/sqrt(L) of the amplitude)
and the noise the prompt sees, so ``(|E|^2 + |P|^2 + |L|^2) / (3 n)`` estimates the
post-correlation noise power per sample (the three are 0.25 correlated in power: together
worth about 2.25 independent values). A value's distribution does not depend on the
number of samples ``n``: on noise alone each sum is ``CN(0, n sigma^2)``, so ``|S|^2 / n``
is ``sigma^2`` times an exponential variate whatever ``n`` (the Gold-code leakage
``|S_sig|^2 / n`` does not grow with ``n`` either); the span in chips, not in samples, sets
how lumpy each value's spectral weighting is. :class:`PostCorrelationNoise` keeps the last
1000 (1 s at one per epoch) and chooses the noise power the C/N0 uses: the input power while
the two agree within ``z`` (6) standard errors of the post-correlation mean (it is the
lower-variance estimate, and C/N0 outputs without interference stay what they were), the
post-correlation mean when they do not (interference, or a front end whose filter shapes the
noise).

Carrier lock (normalized I^2 - Q^2)
----------------------------------
``cos 2 phi`` estimated as ``mean(I^2 - Q^2) / P_d`` over the same window (the noise terms of
``I^2 - Q^2`` average out, and dividing by the M2M4 signal power rather than ``I^2 + Q^2``
keeps the metric near ``cos 2 phi`` whatever the SNR). Data-sign insensitive. Near 1 when the
Costas loop is locked (either half-cycle), near 0 (random sign) when not.

Code lock
---------
C/N0 above a threshold. :class:`LockCounter` adds the hysteresis (a state changes only after
``n`` consecutive contrary decisions).
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import CHIP_RATE_B3I, CODE_LENGTH_B3I
from .pairwise_sums import pairwise_sum, pairwise_sum_squares

__all__ = [
    "NOISE_MIN_LAG_CHIPS",
    "NOISE_SAMPLES",
    "NOISE_SPAN_CHIPS",
    "LockCounter",
    "PostCorrelationNoise",
    "carrier_lock_metric",
    "cn0_known_noise",
    "cn0_of_sums",
    "cn0_of_terms",
    "cn0_m2m4",
    "m2m4_powers",
    "noise_code_phase",
    "noise_code_phases",
    "noise_samples",
    "noise_values",
    "prompt_signal_power",
]


def _mean(a: np.ndarray) -> float:
    """``float(np.mean(a))`` of a float array, bit for bit (its reduction over all elements,
    divided by their count), without np.mean's Python layers: the lock detectors take
    several means of every channel's prompt window at each evaluation. NaN when empty."""
    n = a.size
    return float(np.add.reduce(a, axis=None)) / n if n else math.nan


def m2m4_powers(prompts: np.ndarray) -> tuple[float, float]:
    """Signal and noise power ``(P_d, P_n)`` of complex prompts by the moments method.

    Returns ``(nan, M2)`` when the moments are inconsistent with a positive signal power.
    """
    p2 = (prompts.real * prompts.real + prompts.imag * prompts.imag)
    m2 = _mean(p2)
    m4 = _mean(p2 * p2)
    d = 2.0 * m2 * m2 - m4
    if not (d > 0.0 and m2 > 0.0):
        return math.nan, m2
    pd = math.sqrt(d)
    return pd, m2 - pd


def prompt_signal_power(prompts: np.ndarray, noise_power: float) -> float:
    """``M2 - P_n``: signal power of complex prompts whose noise power is known (may be
    negative for noise alone)."""
    p = np.asarray(prompts)
    return _mean(p.real * p.real + p.imag * p.imag) - float(noise_power)


def cn0_known_noise(prompts: np.ndarray, noise_power, t_coh_s) -> float:
    """C/N0 [dB-Hz] of complex prompts of ``t_coh_s`` seconds with known noise power per
    prompt (NaN when the signal power is not positive).

    ``noise_power`` and ``t_coh_s`` may also be per-prompt arrays, for prompts summed over
    different lengths (``N_b = n_b E|x|^2``, ``T_b = n_b / f_s``): the estimate is then
    ``sum(|P_b|^2 - N_b) / sum(N_b T_b)``, the least-squares signal amplitude of the sums
    (equal to the scalar form for equal lengths).
    """
    if np.ndim(noise_power) == 0 and np.ndim(t_coh_s) == 0:
        pd = prompt_signal_power(prompts, noise_power)
        if not (pd > 0.0 and noise_power > 0.0):
            return math.nan
        return 10.0 * math.log10(pd / (noise_power * t_coh_s))
    p = np.asarray(prompts)
    nb = np.asarray(noise_power, float)
    tb = np.asarray(t_coh_s, float)
    if nb.shape != p.shape:          # (per-prompt arrays, the usual case, need no view)
        nb = np.broadcast_to(nb, p.shape)
    if tb.shape != p.shape:
        tb = np.broadcast_to(tb, p.shape)
    return cn0_of_sums(p, nb, tb)


def cn0_of_sums(prompts: np.ndarray, noise_power: np.ndarray, t_coh_s: np.ndarray) -> float:
    """:func:`cn0_known_noise` of prompt sums with per-sum noise powers and lengths, given
    as arrays of the prompts' shape (no checks): ``10 log10(sum(|P_b|^2 - N_b) /
    sum(N_b T_b))`` [dB-Hz], NaN when either sum is not positive."""
    p = prompts
    return cn0_of_terms(p.real * p.real + p.imag * p.imag - noise_power, noise_power * t_coh_s)


def cn0_of_terms(signal_terms: np.ndarray, noise_terms: np.ndarray) -> float:
    """:func:`cn0_of_sums` from its per-sum terms ``|P_b|^2 - N_b`` and ``N_b T_b``
    (contiguous 1-d arrays): ``10 log10(sum(signal_terms) / sum(noise_terms))`` [dB-Hz], NaN
    when either sum is not positive."""
    add = np.add.reduce                         # (x.sum()'s reduction, one call less)
    pd = float(add(signal_terms, axis=None))
    den = float(add(noise_terms, axis=None))
    if not (pd > 0.0 and den > 0.0):
        return math.nan
    return 10.0 * math.log10(pd / den)


def cn0_m2m4(prompts: np.ndarray, t_coh_s: float) -> float:
    """C/N0 [dB-Hz] of complex prompts of ``t_coh_s`` seconds (M2M4, module notes).

    Parameters
    ----------
    prompts : numpy.ndarray
        Complex prompt correlator outputs (at least 2; 50-100 recommended).
    t_coh_s : float
        Integration time of each prompt [s].

    Returns
    -------
    float
        C/N0 [dB-Hz], NaN when the signal power estimate is not positive, 99 when the noise
        estimate is not (a very strong signal).
    """
    p = np.asarray(prompts)
    if p.size < 2:
        return math.nan
    pd, pn = m2m4_powers(p)
    if not (pd > 0.0) or not (pn > 0.0):
        return math.nan if not pd > 0.0 else 99.0
    return 10.0 * math.log10(pd / (pn * t_coh_s))


def carrier_lock_metric(prompts: np.ndarray, signal_power: float | None = None) -> float:
    """Estimate of ``cos 2 phi`` of complex prompts (module notes), clipped to [-1, 1].

    Parameters
    ----------
    prompts : numpy.ndarray
        Complex prompts (any data signs).
    signal_power : float, optional
        ``P_d`` from :func:`m2m4_powers` of the same prompts; computed when omitted. Without a
        positive signal power the classical ``sum(I^2 - Q^2) / sum(I^2 + Q^2)`` is returned.
    """
    p = np.asarray(prompts)
    if p.size == 0:
        return 0.0
    i2 = p.real * p.real
    q2 = p.imag * p.imag
    nbd = _mean(i2 - q2)
    if signal_power is None:
        signal_power, _ = m2m4_powers(p)
    if signal_power is not None and signal_power > 0.0:
        den = signal_power
    else:
        den = _mean(i2 + q2)
    if not den > 0.0:
        return 0.0
    return max(-1.0, min(1.0, nbd / den))


class LockCounter:
    """Lock decision with hysteresis.

    Parameters
    ----------
    n_lock : int
        Consecutive positive tests needed to declare lock.
    n_unlock : int
        Consecutive negative tests needed to declare loss of lock.
    """

    __slots__ = ("_count", "locked", "n_lock", "n_unlock")

    def __init__(self, n_lock: int, n_unlock: int):
        self.n_lock = max(1, int(n_lock))
        self.n_unlock = max(1, int(n_unlock))
        self.locked = False
        self._count = 0

    def reset(self, locked: bool = False) -> None:
        self.locked = bool(locked)
        self._count = 0

    @property
    def count(self) -> int:
        """Consecutive tests contrary to the current state."""
        return self._count

    def update(self, ok: bool) -> bool:
        """Feed one test outcome; returns the (possibly changed) lock state."""
        if ok == self.locked:
            self._count = 0
            return self.locked
        self._count += 1
        if self._count >= (self.n_lock if ok else self.n_unlock):
            self.locked = ok
            self._count = 0
        return self.locked


#: Smallest code lag of the noise correlator from the prompt [chips] (either side).
NOISE_MIN_LAG_CHIPS = 64
#: Most samples of each epoch the noise correlator sums (:func:`noise_samples`).
NOISE_SAMPLES = 1024
#: Code chips the noise correlator spans in each epoch (about 4 % of a period: 1024 samples
#: at 25 MHz; :func:`noise_samples`).
NOISE_SPAN_CHIPS = 419.0
_NOISE_LAG_STEP = 3989  # chips per epoch (prime, near L (3 - sqrt 5) / 2: well spread lags)


def noise_samples(sampling_rate_hz: float) -> int:
    """Samples of each epoch the noise correlator sums at ``sampling_rate_hz`` [Hz]: those
    that span :data:`NOISE_SPAN_CHIPS` chips at the nominal chip rate, at most
    :data:`NOISE_SAMPLES` (1024 at 25 MHz and above, 103 at 2.5 MHz; module notes: the
    values' statistics do not depend on it, the correlator's cost does)."""
    n = math.ceil(NOISE_SPAN_CHIPS * float(sampling_rate_hz) / CHIP_RATE_B3I)
    return max(1, min(NOISE_SAMPLES, n))


def noise_code_phase(theta: float, epoch: int) -> float:
    """Code phase of the noise correlator [chips, in ``[0, L)``] for code epoch ``epoch``
    whose prompt starts at ``theta`` [chips, in ``[0, L)``]: a lag in ``[m, L - m]``
    (``m`` = :data:`NOISE_MIN_LAG_CHIPS`) that moves by :data:`_NOISE_LAG_STEP` chips per
    epoch."""
    span = CODE_LENGTH_B3I - 2 * NOISE_MIN_LAG_CHIPS
    t = theta + NOISE_MIN_LAG_CHIPS + (int(epoch) * _NOISE_LAG_STEP) % span
    return t - CODE_LENGTH_B3I if t >= CODE_LENGTH_B3I else t


def noise_code_phases(theta: np.ndarray, epoch: np.ndarray) -> np.ndarray:
    """:func:`noise_code_phase` of arrays of code phases [chips] and epochs (the same
    float64 operations in the same order: the same values)."""
    span = CODE_LENGTH_B3I - 2 * NOISE_MIN_LAG_CHIPS
    t = (np.asarray(theta, np.float64) + NOISE_MIN_LAG_CHIPS) + \
        (np.asarray(epoch, np.int64) * _NOISE_LAG_STEP) % span
    return np.where(t >= CODE_LENGTH_B3I, t - CODE_LENGTH_B3I, t)


def noise_values(early, prompt, late, n_samples) -> np.ndarray:
    """Noise power per sample of noise-correlator sums, ``(|E|^2 + |P|^2 + |L|^2) / (3 n)``
    (complex arrays, ``n`` > 0 samples each) [stored units^2]: the values
    :class:`PostCorrelationNoise` keeps (the same operations, in the same order, as its
    :meth:`~PostCorrelationNoise.add` on a channel's block)."""
    e, p, l = early, prompt, late
    return (e.real ** 2 + e.imag ** 2 + p.real ** 2 + p.imag ** 2 + l.real ** 2
            + l.imag ** 2) / (3.0 * np.asarray(n_samples, float))


def _is_scalar(x) -> bool:
    """``np.ndim(x) == 0`` without converting a list to an array."""
    return x.ndim == 0 if isinstance(x, np.ndarray) else not hasattr(x, "__len__")


class PostCorrelationNoise:
    """Post-correlation noise power per sample from noise-correlator sums (module notes).

    Parameters
    ----------
    n_values : int, optional
        Values kept (one per noise row; default 1000: 1 s at one per 1 ms epoch).
    z : float, optional
        Standard errors by which the post-correlation mean must differ from the input power
        to replace it (default 6: without interference the input power is kept, and the
        outputs with it, on every one of the ~1e5 tests of a long run; a jammer that moves
        the noise by more than about 0.6 dB is taken up within a second).
    min_values : int, optional
        Values needed before the test is made (default 200).

    Attributes
    ----------
    count : int
        Values held.
    """

    def __init__(self, n_values: int = 1000, z: float = 6.0, min_values: int = 200) -> None:
        if n_values < 2 or min_values < 2:
            raise ValueError("n_values and min_values must be >= 2")
        self._v = np.zeros(int(n_values))
        self._i = 0
        self.count = 0
        self._s = self._s2 = 0.0     # sums of the values held and of their squares
        self._dirty = False          # values added since the sums were made (_sums)
        self.z = float(z)
        self.min_values = int(min_values)

    def add(self, early, prompt, late, n_samples) -> None:
        """Add noise-correlator sums (complex, scalars or sequences of the same length) of
        ``n_samples`` samples each (a scalar or a sequence) [stored units]."""
        if _is_scalar(prompt):
            early, prompt, late, n_samples = (early,), (prompt,), (late,), (n_samples,)
        elif _is_scalar(n_samples):
            n_samples = [n_samples] * len(prompt)
        # (the receivers' channels pass noise_values of several channels at once to
        # add_values; this form is for sums given one channel's block at a time)
        n = np.asarray(n_samples, float)
        ok = n > 0
        self.add_values(noise_values(*(np.asarray(a, np.complex128)[ok]
                                       for a in (early, prompt, late)), n[ok]))

    def add_values(self, vals) -> None:
        """Add noise powers per sample (:func:`noise_values` of sums of at least one
        sample) [stored units^2]."""
        m = len(vals)
        if m == 0:
            return
        v, size = self._v, self._v.size
        if m >= size:
            v[:] = vals[m - size:]
            self._i, self.count = 0, size
        else:
            i, j = self._i, self._i + m
            if j <= size:
                v[i:j] = vals
            else:
                v[i:] = vals[:size - i]
                v[:j - size] = vals[size - i:]
            self._i, self.count = j % size, min(size, self.count + m)
        self._dirty = True

    def _sums(self) -> tuple[float, float]:
        """Sums of the values held and of their squares, made when asked for after values
        were added (a channel adds every block and asks every lock evaluation)."""
        if self._dirty:
            # numpy's pairwise sums of the values held and of their squares (not BLAS's
            # dot, whose order follows the CPU), by the kernels that repeat them bit for bit
            # (pairwise_sums: about a third of the numpy calls' time on a full ring); the
            # vector loop's kernel, deep._numba_channel_tests, sums them the same way
            self._s = float(pairwise_sum(self._v, 0, self.count))
            self._s2 = float(pairwise_sum_squares(self._v, 0, self.count))
            self._dirty = False
        return self._s, self._s2

    @property
    def n_values(self) -> int:
        """Values the ring holds at most."""
        return int(self._v.size)

    def ring(self) -> tuple[np.ndarray, int]:
        """The ring's values in their slots (the first :attr:`count` held) and the next slot
        written: what the vector loop continues (:class:`~sdr_di.deep.channel_tests.
        ChannelTests`)."""
        return self._v, self._i

    def clear(self) -> None:
        """Forget every value."""
        self._i = 0
        self.count = 0
        self._s = self._s2 = 0.0
        self._dirty = False

    def per_sample(self) -> float:
        """Mean post-correlation noise power per sample [stored units^2] (NaN when empty)."""
        if self.count == 0:
            return math.nan
        return self._sums()[0] / self.count

    def noise_power(self, input_power: float | None) -> float | None:
        """Noise power per sample for the C/N0 (module notes): ``input_power`` (may be None)
        unless the post-correlation mean differs from it by more than ``z`` standard errors
        (or there is no input power and enough values), then that mean."""
        k = self.count
        if k < self.min_values:
            return input_power
        s, s2 = self._sums()
        m = s / k
        if not m > 0.0:
            return input_power
        if input_power is None or not input_power > 0.0:
            return m
        se = math.sqrt(max(s2 / k - m * m, 0.0) / k)
        return m if abs(m - input_power) > self.z * se else input_power
