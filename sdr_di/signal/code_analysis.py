"""Correlation properties of the truncated B3I Gold codes and a derived cross-correlation bound.

Why the Gold bound does not apply
---------------------------------
With n = 13 the full-period (N = 2^13 - 1 = 8191) Gold family has three-valued periodic cross-
correlation {-1, -t, t - 2} with t = 2^((n+1)/2) + 1 = 129, i.e. |R| <= 129 (-36 dB). The B3I
code is 10230 chips long, G1 is reset every 8190 chips and G2 runs on (period 8191), so the
10230-chip cyclic correlation is no longer a periodic Gold correlation.

Derivation (done by :func:`truncated_xcorr_bound`)
-------------------------------------------------
Write a chip of PRN i as u(t) v_i(t) (+/-1 levels): u(t) = a(t) for t < 8190 and a(t - 8190)
after the reset (a: G1 m-sequence), v_i(t) = b(t + phi_i) (b: G2 m-sequence, phi_i the offset
of the PRN's initial phase in it). For a cyclic shift tau the sum over t in [0, 10230) splits at
t = 8190, at the point where (t + tau) mod 10230 crosses 8190 and at its wrap point into at most
four windows W_s. In each window both products u(t)u(t') and v_i(t)v_j(t') are products of two
phases of the same m-sequence, hence (shift-and-add property) one phase of that m-sequence, or
the constant 1 when the two phases coincide. So every window sum is a *partial-period* sum of

* a Gold-family member a(t) b(t + d) (general case),
* an m-sequence a or b (one part degenerate), or
* the constant 1 (both degenerate). The G1 part degenerates only for d_a = tau - 2039 w +
  k' - k = 0 mod 8191 (w: wrap, k, k': reset branches); combined with the G2 part this needs
  phi_j - phi_i in {-1, 0, +1} mod 8191, which :func:`check_phase_separation` excludes for the
  63 B3I PRNs, so constant windows never occur between different PRNs.

A partial sum over L consecutive chips of a sequence f of period N with DFT F is bounded
(Sarwate's method) by

    |S_L| <= |F(0)| L / N + (max_{m != 0} |F(m)|) / N * sum_{m=1}^{N-1} |sin(pi m L / N) / sin(pi m / N)|.

For an m-sequence |F(0)| = 1 and |F(m)| = sqrt(N + 1) exactly. For the Gold family |F(0)| <= 129
(the periodic correlation values) and the spectral peak over all 8191 members was computed by
:func:`gold_spectral_peak`: 264.60 (stored rounded up as :data:`GOLD_SPECTRAL_PEAK`). Summing
the window bounds (Gold bound for windows where G1 does not degenerate, m-sequence bound where it
does) and maximizing over tau gives

    **B = 4226 (|R| / 10230 <= 0.413, -7.7 dB)** for every pair of distinct PRNs.

Measured (all 1953 pairs, all 10230 shifts, zero Doppler): **max |R| = 522** (0.051,
-25.8 dB, PRN 26 vs 41); largest autocorrelation sidelobe 406. The rigorous bound is loose by
the usual log N factor of partial-period bounds; for comparison, a random-code model (R ~ N(0,
10230)) predicts an expected maximum over the ~2e7 (pair, shift) values of about
101 * sqrt(2 ln 2e7) = 590, consistent with the measurement.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np

from ..constants import CODE_LENGTH_B3I
from .codes import G1_RESET_PERIOD, G1_TAPS, G2_TAPS, b3i_code, g2_initial_phase, lfsr13

__all__ = [
    "GOLD_SPECTRAL_PEAK",
    "GOLD_T",
    "M_PERIOD",
    "check_phase_separation",
    "correlation_extremes",
    "correlation_windows",
    "g2_phase_offsets",
    "gold_spectral_peak",
    "partial_sum_bound",
    "truncated_xcorr_bound",
]

#: Period of the 13-stage m-sequences.
M_PERIOD = 8191
#: Full-period Gold bound t(n) = 2^((n+1)/2) + 1 for n = 13.
GOLD_T = 129
#: Max over the 8191 Gold members a(t) b(t+d) and m != 0 of |DFT| (computed: 264.6007).
GOLD_SPECTRAL_PEAK = 264.61


@functools.lru_cache(maxsize=1)
def _m_sequences() -> tuple[np.ndarray, np.ndarray]:
    a = lfsr13((1,) * 13, G1_TAPS, M_PERIOD)
    b = lfsr13((1,) * 13, G2_TAPS, M_PERIOD)
    return a, b


def g2_phase_offsets() -> np.ndarray:
    """Offset phi_i (0..8190) of each PRN's G2 initial phase in the G2 m-sequence started from
    all ones, index 0 = PRN 1: the PRN's G2 output equals b[(t + phi_i) mod 8191]."""
    _, b = _m_sequences()
    ext = np.concatenate([b, b[:13]])
    weights = 1 << np.arange(12, -1, -1)
    windows = np.lib.stride_tricks.sliding_window_view(ext, 13)[:M_PERIOD] @ weights
    index = {int(w): k for k, w in enumerate(windows)}
    out = np.empty(63, dtype=np.int64)
    for prn in range(1, 64):
        first13 = lfsr13(g2_initial_phase(prn), G2_TAPS, 13)
        out[prn - 1] = index[int(first13 @ weights)]
    return out


def check_phase_separation() -> int:
    """Smallest circular distance between the G2 offsets of two PRNs (must be >= 2 for the
    bound of :func:`truncated_xcorr_bound` to hold)."""
    phi = np.sort(g2_phase_offsets())
    gaps = np.diff(np.concatenate([phi, [phi[0] + M_PERIOD]]))
    return int(gaps.min())


def gold_spectral_peak(chunk: int = 512) -> tuple[float, set[int]]:
    """Spectral peak of the Gold family of G1/G2 (slow: 8191 FFTs of length 8191, a few s).

    Returns
    -------
    peak : float
        max over members d and frequencies m != 0 of |sum_t a(t) b(t+d) exp(-2j pi m t / N)|.
    dc_values : set of int
        The distinct |F(0)| (periodic correlation magnitudes; {1, 127, 129} for a Gold family).
    """
    a, b = _m_sequences()
    la = 1.0 - 2.0 * a
    lb = 1.0 - 2.0 * b
    idx = np.arange(M_PERIOD)
    peak, dc = 0.0, set()
    for c0 in range(0, M_PERIOD, chunk):
        d = np.arange(c0, min(M_PERIOD, c0 + chunk))
        spec = np.abs(np.fft.fft(la[None, :] * lb[(idx[None, :] + d[:, None]) % M_PERIOD], axis=1))
        dc |= set(np.rint(spec[:, 0]).astype(int).tolist())
        peak = max(peak, float(spec[:, 1:].max()))
    return peak, dc


@functools.lru_cache(maxsize=1)
def _dirichlet_sums() -> np.ndarray:
    """S(L) = sum_{m=1}^{N-1} |sin(pi m L / N) / sin(pi m / N)| for L = 0..N."""
    n = M_PERIOD
    m = np.arange(1, n)
    inv = 1.0 / np.abs(np.sin(np.pi * m / n))
    s = np.empty(n + 1)
    for c0 in range(0, n + 1, 256):
        L = np.arange(c0, min(n + 1, c0 + 256))
        s[L] = (np.abs(np.sin(np.pi * np.outer(L, m) / n)) * inv).sum(axis=1)
    return s


def partial_sum_bound(length: int, kind: str, spectral_peak: float = GOLD_SPECTRAL_PEAK) -> float:
    """Bound on |sum| of ``length`` consecutive chips (0 <= length <= 8191) of a Gold-family
    member (``kind='gold'``) or of an m-sequence (``kind='m'``)."""
    n = M_PERIOD
    s = _dirichlet_sums()[int(length)]
    if kind == "m":
        return (length + np.sqrt(n + 1.0) * s) / n
    if kind == "gold":
        return (GOLD_T * length + spectral_peak * s) / n
    raise ValueError(f"kind must be 'gold' or 'm', got {kind!r}")


def correlation_windows(tau: int) -> list[tuple[int, int, bool]]:
    """Windows of the 10230-chip cyclic correlation at shift ``tau`` (module docstring).

    Returns
    -------
    list of (start, length, g1_degenerate)
        Chip ranges ``[start, start + length)`` of the first code over which both m-sequence
        products are single phases; ``g1_degenerate`` when the G1 product is the constant 1.
    """
    n_code, reset = CODE_LENGTH_B3I, G1_RESET_PERIOD
    cuts = {0, n_code, reset, n_code - tau}
    cuts.add(reset - tau if tau < reset else reset + n_code - tau)
    edges = sorted(c for c in cuts if 0 <= c <= n_code)
    out = []
    for s0, s1 in zip(edges[:-1], edges[1:]):
        if s1 <= s0:
            continue
        k = int(s0 >= reset)
        s = s0 + tau
        w = int(s >= n_code)
        k2 = int(s - w * n_code >= reset)
        d_a = (tau - (n_code - M_PERIOD) * w + k2 - k) % M_PERIOD
        out.append((s0, s1 - s0, bool(d_a == 0)))
    return out


def truncated_xcorr_bound(spectral_peak: float = GOLD_SPECTRAL_PEAK) -> tuple[float, int]:
    """Derived bound on the zero-Doppler cyclic cross-correlation of two distinct B3I codes.

    Returns
    -------
    bound : float
        max over tau of the sum of the window bounds (module docstring) [chips].
    tau : int
        Shift where the bound is largest.
    """
    best, arg = 0.0, 0
    for tau in range(1, CODE_LENGTH_B3I):
        total = sum(
            partial_sum_bound(L, "m" if deg else "gold", spectral_peak)
            for _, L, deg in correlation_windows(tau)
        )
        if total > best:
            best, arg = total, tau
    return best, arg


def correlation_extremes(prns=range(1, 64)) -> dict:
    """Measured zero-Doppler cyclic correlation extremes over all shifts, via FFT.

    Returns
    -------
    dict
        ``max_cross`` (max |R| over distinct pairs), ``max_cross_pair``, ``max_auto_sidelobe``.
    """
    prns = list(prns)
    spec = np.fft.rfft(np.array([b3i_code(p) for p in prns], dtype=np.float64), axis=1)
    n = CODE_LENGTH_B3I
    best, pair = 0.0, None
    for i, j in itertools.combinations(range(len(prns)), 2):
        r = np.abs(np.fft.irfft(spec[i] * np.conj(spec[j]), n=n)).max()
        if r > best:
            best, pair = float(r), (prns[i], prns[j])
    auto = np.fft.irfft(np.abs(spec) ** 2, n=n, axis=1)
    return {
        "max_cross": round(best),
        "max_cross_pair": pair,
        "max_auto_sidelobe": round(float(np.abs(auto[:, 1:]).max())),
    }
