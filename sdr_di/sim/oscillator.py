"""Truth receiver oscillator: a sample path of the receiver clock bias (scenario
``[oscillator]``; model and presets in :mod:`sdr_di.oscillator`).

The receiver clock reads ``tau = t + b(t)`` at true time ``t`` (BDT since the scenario start).
The bias is::

    b(t) = bias_s + drift_s_s t          deterministic part, scenario [receiver_clock]
         + x(t)                          power-law noise, x(0) = 0, mean frequency 0
         + integral_0^t Gamma . f_b dt   g-sensitivity: Gamma [1/g] (body axes) times the
                                         trajectory's specific force f_b [g]

Noise generation on the truth grid (interval ``tau0``, the IMU rate), phase ``x`` at the grid
times and fractional frequency as interval averages:

* white FM (h0) and random-walk FM (h_-2): the exact discretization of the two-state clock
  ``x' = y + w_x``, ``y' = w_y`` with ``S_x = h0 / 2``, ``S_y = 2 pi^2 h_-2`` (the same
  covariance as the filter's :meth:`~sdr_di.ins.error_model.ClockModel.Q`);
* flicker FM (h_-1): Kasdin and Walter (1992, *Discrete simulation of power law noise*): white
  noise of variance ``Q_d`` through the fractional-difference filter ``h_0 = 1``,
  ``h_k = h_{k-1} (k - 1 + alpha/2) / k`` with ``alpha = 1``, by FFT convolution over the
  whole path (not a truncated filter); the one-sided PSD of the interval-average frequency
  is then ``Q_d / (pi f)`` at ``f << 1 / tau0``, so ``Q_d = pi h_-1``; phase increments
  ``tau0 y_k``.

The path is drawn from a ``numpy.random.Generator`` seeded from the scenario seed (stream
``0xC10C``) and is the same for every chunking of the IF. Between grid points the bias is
interpolated linearly (frequency constant over each 5 ms interval at 200 Hz).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..oscillator import G0, OscillatorSpec

__all__ = ["ClockTruth", "kasdin_walter", "power_law_phase", "scenario_clock", "simulate_clock"]

#: Random stream of the oscillator (spawned from the scenario seed).
CLOCK_STREAM = 0xC10C


def kasdin_walter(n: int, alpha: float, variance: float, rng: np.random.Generator) -> np.ndarray:
    """``n`` samples of discrete power-law noise with PSD ``variance / |2 sin(pi f tau0)|^alpha``
    (Kasdin and Walter 1992): white noise of ``variance`` filtered by the fractional
    difference ``(1 - z^-1)^(-alpha/2)``, by FFT convolution, starting from rest.

    Parameters
    ----------
    n : int
        Number of samples.
    alpha : float
        Spectral exponent (1: flicker, 2: random walk, 0: white).
    variance : float
        Variance ``Q_d`` of the driving white noise.
    rng : numpy.random.Generator
    """
    if n <= 0:
        return np.zeros(0)
    k = np.arange(1, n)
    h = np.empty(n)
    h[0] = 1.0
    h[1:] = np.cumprod((k - 1 + alpha / 2.0) / k)
    w = rng.standard_normal(n) * math.sqrt(variance)
    size = 1 << (2 * n - 1).bit_length()
    return np.fft.irfft(np.fft.rfft(h, size) * np.fft.rfft(w, size), size)[:n]


def power_law_phase(spec: OscillatorSpec, n: int, tau0: float,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Time deviation ``x`` [s] at ``n + 1`` grid points ``0, tau0, ..., n tau0`` (``x[0] = 0``)
    and the interval-average fractional frequency ``y`` (n,) of the power-law noise of
    ``spec`` (module notes). The three terms use independent draws in a fixed order, so a
    term set to zero leaves the others' paths unchanged."""
    w = rng.standard_normal((3, n))  # white FM; random-walk FM phase and frequency
    dx = np.zeros(n)
    if spec.h0 > 0.0:
        dx += math.sqrt(spec.h0 / 2.0 * tau0) * w[0]
    if spec.h_2 > 0.0:
        # exact discretization of x' = y, y' = w_y (S_y = 2 pi^2 h_-2) over one interval:
        # the phase gained and the frequency step, correlated as in ClockModel.Q
        S = 2.0 * math.pi**2 * spec.h_2
        L = np.linalg.cholesky(np.array([[S * tau0**3 / 3.0, S * tau0**2 / 2.0],
                                         [S * tau0**2 / 2.0, S * tau0]]))
        a, dy = L @ w[1:]
        y_start = np.concatenate([[0.0], np.cumsum(dy)[:-1]])  # frequency at interval starts
        dx += y_start * tau0 + a
    if spec.h_1 > 0.0:
        dx += tau0 * kasdin_walter(n, 1.0, math.pi * spec.h_1, rng)
    x = np.concatenate([[0.0], np.cumsum(dx)])
    return x, dx / tau0


@dataclasses.dataclass
class ClockTruth:
    """Receiver clock along the truth grid.

    Attributes
    ----------
    t : (n,) array
        True time since the scenario start [s] (the truth and IMU grid).
    bias_s : (n,) array
        Receiver clock bias ``b(t)`` = receiver time - true time [s].
    drift_s_s : (n,) array
        Clock drift = fractional frequency [s/s], average over ``(t[k-1], t[k]]`` (the
        first: the deterministic drift plus the g-term at ``t[0]``).
    noise_s : (n,) array
        The oscillator's part of the bias (``bias_s`` minus the ``[receiver_clock]`` line)
        [s].
    spec : OscillatorSpec or None
        The truth oscillator (None: the deterministic ``[receiver_clock]`` only).
    """

    t: np.ndarray
    bias_s: np.ndarray
    drift_s_s: np.ndarray
    noise_s: np.ndarray
    spec: OscillatorSpec | None = None

    def noise_at(self, t: np.ndarray) -> np.ndarray:
        """Oscillator part of the bias [s] at true times ``t`` [s] (linear interpolation;
        constant beyond the ends)."""
        return np.interp(t, self.t, self.noise_s)

    @classmethod
    def deterministic(cls, t: np.ndarray, bias_s: float, drift_s_s: float) -> ClockTruth:
        """The ``[receiver_clock]`` line alone."""
        t = np.asarray(t, float)
        return cls(t, bias_s + drift_s_s * (t - t[0]), np.full(t.shape, float(drift_s_s)),
                   np.zeros(t.shape))


def simulate_clock(spec: OscillatorSpec, t: np.ndarray, rng: np.random.Generator, *,
                   bias_s: float = 0.0, drift_s_s: float = 0.0,
                   f_b: np.ndarray | None = None) -> ClockTruth:
    """A sample path of the receiver clock on the regular grid ``t`` [s] (module notes).

    Parameters
    ----------
    spec : OscillatorSpec
        Power-law coefficients and g-sensitivity.
    t : (n,) array
        Regular true-time grid [s], ``t[0]`` the start.
    rng : numpy.random.Generator
    bias_s, drift_s_s : float
        Deterministic bias at ``t[0]`` [s] and drift [s/s] (``[receiver_clock]``).
    f_b : (n, 3) array, optional
        Specific force along the body axes [m/s^2], interval averages over ``(t[k-1], t[k]]``
        (the truth's ``f_b``); required for a non-zero g-sensitivity.
    """
    t = np.asarray(t, float)
    n = t.size - 1
    tau0 = float(t[1] - t[0]) if n >= 1 else 1.0
    x, y = power_law_phase(spec, max(n, 0), tau0, rng)
    gam = np.asarray(spec.g_sensitivity_per_g, float)
    y0 = 0.0
    if np.any(gam != 0.0):
        if f_b is None or np.shape(f_b) != (t.size, 3):
            raise ValueError("simulate_clock: a g-sensitivity needs the specific force f_b "
                             f"(n, 3) on the grid, got {None if f_b is None else np.shape(f_b)}")
        y_g = np.asarray(f_b, float) @ gam / G0          # (n+1,), interval averages
        x = x + np.concatenate([[0.0], np.cumsum(y_g[1:] * tau0)])
        y = y + y_g[1:]
        y0 = float(y_g[0])
    line = bias_s + drift_s_s * (t - t[0])
    return ClockTruth(t, line + x, np.concatenate([[y0], y]) + drift_s_s, x, spec)


def scenario_clock(sc, truth) -> ClockTruth:
    """The receiver clock of a scenario on its truth grid: the ``[receiver_clock]`` line, plus
    the ``[oscillator]`` path when the scenario has a non-ideal one (``spec`` None otherwise).

    Parameters
    ----------
    sc : Scenario
    truth : Truth
        The scenario's trajectory (grid ``t``, specific force ``f_b``).
    """
    ck = sc.clock
    spec = sc.oscillator
    if spec is None or spec.is_ideal:
        return ClockTruth.deterministic(truth.t, ck.bias_s, ck.drift_s_s)
    rng = np.random.default_rng(np.random.SeedSequence([sc.seed, CLOCK_STREAM]))
    return simulate_clock(spec, truth.t, rng, bias_s=ck.bias_s, drift_s_s=ck.drift_s_s,
                          f_b=truth.f_b)
