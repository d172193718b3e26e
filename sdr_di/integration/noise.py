"""Simulated GNSS position/velocity noise for loosely coupled runs, with variance schedules.

The true measurement noise at time ``t`` is zero-mean Gaussian with the diagonal covariance
``diag(s_vel^2 I3, s_h^2, s_h^2, s_v^2) * factor(t)`` in the loose measurement order
(velocity E, N, U [m/s]; position N, E, U [m]); ``factor(t)`` is the product of the factors of
every :class:`NoiseWindow` with ``t0 <= t <= t1`` (paper 003 section 4.1: ``16 R`` during
500-700 s). The filter is given its own ``R`` (nominal times ``r_scale``), not this one.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..frames import radii_of_curvature

__all__ = ["GnssNoise", "NoiseWindow"]


@dataclasses.dataclass(frozen=True)
class NoiseWindow:
    """Variance factor ``factor`` applied for ``t0 <= t <= t1`` [s]."""

    t0: float
    t1: float
    factor: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.t0) and math.isfinite(self.t1) and self.t1 > self.t0):
            raise ValueError(f"noise window needs t0 < t1, got ({self.t0}, {self.t1})")
        if not (math.isfinite(self.factor) and self.factor > 0):
            raise ValueError(f"noise window factor must be > 0, got {self.factor}")


@dataclasses.dataclass(frozen=True)
class GnssNoise:
    """GNSS solution noise (1-sigma) and its schedule.

    Attributes
    ----------
    sigma_h_m, sigma_v_m : float
        Horizontal (per axis) and vertical position noise [m].
    sigma_vel_mps : float
        Velocity noise per axis [m/s].
    windows : tuple of NoiseWindow
    """

    sigma_h_m: float = 2.0
    sigma_v_m: float = 3.0
    sigma_vel_mps: float = 0.05
    windows: tuple[NoiseWindow, ...] = ()

    def __post_init__(self) -> None:
        for name in ("sigma_h_m", "sigma_v_m", "sigma_vel_mps"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"GnssNoise.{name} must be > 0, got {v}")

    def nominal_diag(self) -> np.ndarray:
        """Nominal variances (6,) in the loose measurement order."""
        sv, sh, su = self.sigma_vel_mps, self.sigma_h_m, self.sigma_v_m
        return np.array([sv * sv] * 3 + [sh * sh, sh * sh, su * su])

    def factor(self, t: float) -> float:
        """Variance factor at ``t`` [s]."""
        f = 1.0
        for w in self.windows:
            if w.t0 <= t <= w.t1:
                f *= w.factor
        return f

    def true_diag(self, t: float) -> np.ndarray:
        """True variances (6,) at ``t``."""
        return self.nominal_diag() * self.factor(t)

    def sample(self, t: float, llh_true, v_true, rng: np.random.Generator):
        """GNSS solution ``(llh, v_n)`` at ``t``: truth plus noise drawn from ``rng``."""
        e = rng.standard_normal(6) * np.sqrt(self.true_diag(t))
        lat, h = float(llh_true[0]), float(llh_true[2])
        R_M, R_N = (float(r) for r in radii_of_curvature(lat))
        llh = np.array([lat + e[3] / (R_M + h), llh_true[1] + e[4] / ((R_N + h) * math.cos(lat)),
                        h + e[5]])
        return llh, np.asarray(v_true, float) + e[0:3]
