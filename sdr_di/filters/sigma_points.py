"""Deterministic point sets for the sigma-point filters (UKF and CKF share everything else).

A point set is ``X_i = x + L xi_i`` with ``L`` the lower Cholesky factor of ``P``
(``P = L L^T``, the "symmetric sampling based on the Cholesky decomposition" of paper 004
eq 16 and paper 003 eq 17-18), unit points ``xi_i`` and weights ``Wm`` (mean) and ``Wc``
(covariance). Only the unit points and weights differ between the filters:

* :class:`MerweScaledSigmaPoints` -- scaled unscented transform, paper 004 eq 16-18
  (Julier 2002; Wan & van der Merwe 2000): ``2n + 1`` points ``0, +-gamma e_i``,
  ``lambda = alpha^2 (n + kappa) - n``, ``gamma = sqrt(n + lambda)``,
  ``Wm_0 = lambda / (n + lambda)``, ``Wc_0 = Wm_0 + 1 - alpha^2 + beta``,
  ``Wm_i = Wc_i = 1 / (2 (n + lambda))``. (Paper 004 eq 18 prints ``1 + alpha^2 - beta``;
  that is a typo -- with ``beta = 2`` it would make ``Wc_0`` more negative; the standard
  ``1 - alpha^2 + beta`` is used, as in paper 001 eq 10.)

  Defaults ``alpha = 0.5, beta = 2, kappa = 0`` (inside paper 004's range
  ``1e-4 <= alpha <= 1``, ``kappa >= 0``; ``beta = 2`` is optimal for Gaussian priors): for
  the 17-state model the points lie at ``+-alpha sqrt(n + kappa) = +-2.06`` standard
  deviations, ``Wm_0 = -3``, ``Wc_0 = -0.25``. The covariance stays positive semi-definite
  for any ``alpha`` because it equals ``sum_{i>0} W_i D_i D_i^T + (beta - alpha^2) d d^T``
  (``D_i`` deviations from the centre point, ``d`` the mean shift). The often quoted
  ``alpha = 1e-3`` is accepted but makes ``Wm_0 = 1 - 1/alpha^2 ~ -1e6``: rounding errors of
  ``f`` (``eps |f|``) reach the mean amplified by ``~1/alpha^2``, i.e. ~6 significant digits
  are lost (5-state linear test problem: 1.5e-9 vs 1e-14 deviation from the exact Kalman
  filter).
* :class:`CubaturePoints` -- third-degree spherical-radial cubature rule, paper 003 eq 19:
  ``2n`` points ``+-sqrt(n) e_i``, all weights ``1 / (2n)`` (Arasaratnam & Haykin 2009).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["CubaturePoints", "MerweScaledSigmaPoints", "SigmaPoints"]


class SigmaPoints:
    """Base class of a unit point set; subclasses implement :meth:`_build`.

    Attributes
    ----------
    has_center : bool
        True if the first unit point is the origin (the UKF centre point).
    """

    has_center = False
    name = "sigma points"

    def __init__(self) -> None:
        self._cache: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def num_points(self, n: int) -> int:
        """Number of points for state dimension ``n``."""
        return self.unit_points(n).shape[0]

    def unit_points(self, n: int) -> np.ndarray:
        """Unit points ``xi`` as rows, shape ``(p, n)``."""
        return self._get(n)[0]

    def weights(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Mean and covariance weights ``(Wm, Wc)``, each shape ``(p,)``."""
        _, wm, wc = self._get(n)
        return wm, wc

    def _get(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        got = self._cache.get(n)
        if got is None:
            got = self._build(n)
            for a in got:
                a.setflags(write=False)
            self._cache[n] = got
        return got

    def _build(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        raise NotImplementedError


class MerweScaledSigmaPoints(SigmaPoints):
    """Scaled unscented-transform sigma points (paper 004 eq 16-18).

    Parameters
    ----------
    alpha : float
        Spread of the points around the mean, ``0 < alpha <= 1`` (default 0.5).
    beta : float
        Prior-distribution parameter; 2 is optimal for Gaussian states (default 2).
    kappa : float
        Secondary scaling, ``n + kappa > 0`` (default 0).
    """

    has_center = True
    name = "scaled unscented"

    def __init__(self, alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0) -> None:
        super().__init__()
        if not (alpha > 0.0 and math.isfinite(alpha)):
            raise ValueError(f"UKF alpha must be > 0, got {alpha}")
        self.alpha, self.beta, self.kappa = float(alpha), float(beta), float(kappa)

    def lam(self, n: int) -> float:
        """``lambda = alpha^2 (n + kappa) - n``."""
        return self.alpha ** 2 * (n + self.kappa) - n

    def _build(self, n: int):
        if n + self.kappa <= 0:
            raise ValueError(f"UKF needs n + kappa > 0 (n = {n}, kappa = {self.kappa})")
        lam = self.lam(n)
        c = n + lam
        gamma = math.sqrt(c)
        xi = np.zeros((2 * n + 1, n))
        xi[1:n + 1] = gamma * np.eye(n)
        xi[n + 1:] = -gamma * np.eye(n)
        wm = np.full(2 * n + 1, 0.5 / c)
        wc = wm.copy()
        wm[0] = lam / c
        wc[0] = lam / c + (1.0 - self.alpha ** 2 + self.beta)
        return xi, wm, wc


class CubaturePoints(SigmaPoints):
    """Third-degree spherical-radial cubature points (paper 003 eq 19): ``+-sqrt(n) e_i``."""

    has_center = False
    name = "cubature"

    def _build(self, n: int):
        s = math.sqrt(n)
        xi = np.vstack([s * np.eye(n), -s * np.eye(n)])
        w = np.full(2 * n, 1.0 / (2 * n))
        return xi, w, w.copy()
