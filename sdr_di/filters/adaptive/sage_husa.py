"""Sage-Husa (MAP) noise-statistics estimator inside a UKF, paper 001 (Cheng et al. 2014):
``sage-husa-ukf``.

Noise with unknown means and covariances, ``E[w] = q``, ``cov w = Q``, ``E[v] = r``,
``cov v = R`` (paper 001 eq 2); the UKF predicts ``x^- = sum Wm f(xi) + q`` and
``z^- = sum Wm h(xi) + r`` (eq 35, 37) and the estimator of eq 30-33 updates::

    q_k = (1/k) sum_j [ x_j/j - sum_i Wm_i f(xi_i,j-1) ]                           (30)
    Q_k = (1/k) sum_j (x_j/j - x_j/j-1)(x_j/j - x_j/j-1)^T                          (31)
    r_k = (1/k) sum_j [ z_j - sum_i Wm_i h(xi_i,j/j-1) ]                            (32)
    R_k = (1/k) sum_j (z_j - z_j/j-1)(z_j - z_j/j-1)^T                              (33)

computed recursively (``E_k = E_k-1 + (e_k - E_k-1)/k``, started from the nominal ``Q0`` and
the epoch's ``R^-``, which the gain ``1/1`` discards at the first epoch). ``forgetting=b``
replaces ``1/k`` by the fading-memory weight ``d_k = (1 - b)/(1 - b^(k+1))`` of the classic
Sage-Husa filter (default ``None``: the paper's unlimited memory). The estimates are applied
(``q`` added to the prediction, ``r`` subtracted from ``z``, ``Q`` and ``R`` used) once
``warmup`` epochs have been accumulated (default 10); before, the nominal ``Q0`` and the
epoch's ``R^-`` are used.
``estimate`` selects which of ``'q', 'Q', 'r', 'R'`` are estimated (default all four, as in
the paper).

Known bias of eq 31/33 (kept by default because it is the paper's estimator):
``E[(z - z^-)(z - z^-)^T] = H P^- H^T + R`` and ``E[dx dx^T] = P^- - P^+`` (not ``Q`` unless
the transition is the identity in steady state), so the literal ``R`` estimate is too large by
``H P^- H^T`` -- small when the measurement noise dominates the prediction uncertainty. (The
bias-corrected forms below can go indefinite during the initial transient, where the floor
takes over; with the unlimited memory those early terms decay only as ``1/k``.)
``bias_correction=True`` uses the classic unbiased Sage-Husa forms instead::

    R term: v v^T - P_zz          Q term: dx dx^T + P^+ - (P^- - Q_used)

Positive definiteness: ``Q`` and ``R`` estimates are raised to ``>= diag(floor)`` in the
Loewner order (``Q`` floor, and ``r_floor_rel * diag(R^-)``).

Change of the measurement count N
    ``r`` and ``R`` are averages of ``m_k``-vectors and ``m_k x m_k`` matrices, which cannot be
    continued with another length: on a change of ``m_k`` the measurement statistics restart
    (``k`` for r/R back to 0, ``n_restarts`` counts it) and the epoch's ``R^-`` is used until
    ``warmup`` new epochs have been accumulated. ``q`` and ``Q`` (state-sized) continue.
"""

from __future__ import annotations

import numpy as np

from ...errors import FilterError
from .._linalg import floor_pd
from .base import AdaptiveRule, flag

__all__ = ["SageHusaUKF"]

_ALL = ("q", "Q", "r", "R")


class SageHusaUKF(AdaptiveRule):
    """Sage-Husa noise-statistics estimator (paper 001 eq 30-33) around a UKF.

    Parameters
    ----------
    estimate : iterable of {'q', 'Q', 'r', 'R'}
        Statistics to estimate (default all four).
    warmup : int
        Epochs accumulated before an estimate is applied (default 10).
    forgetting : float or None
        Fading-memory constant ``b`` in (0, 1), or ``None`` for the paper's ``1/k``.
    bias_correction : bool
        Use the unbiased forms of the ``Q``/``R`` terms (default False: paper eq 31/33).
    r_floor_rel : float
        ``R`` floor relative to the prior diagonal (default 1e-6).
    q_floor : float or array_like, optional
        See :class:`~sdr_di.filters.adaptive.base.AdaptiveRule`.

    Attributes
    ----------
    q_hat, Q_hat, r_hat, R_hat : ndarray
        Current estimates (``r_hat``/``R_hat`` have the current measurement size).
    n_restarts : int
        Restarts of the measurement statistics caused by a change of ``m_k``.
    """

    name = "sage-husa-ukf"
    reference = "Cheng et al., J. Applied Mathematics 2014 (paper 001), eq 30-33"

    def __init__(self, estimate=_ALL, warmup: int = 10, forgetting: float | None = None,
                 bias_correction: bool = False, r_floor_rel: float = 1e-6,
                 q_floor=None) -> None:
        super().__init__(q_floor)
        est = tuple(estimate)
        bad = [e for e in est if e not in _ALL]
        if bad or not est:
            raise FilterError(f"sage-husa-ukf: estimate must be a non-empty subset of {_ALL}, "
                              f"got {est!r}")
        if forgetting is not None and not 0.0 < forgetting < 1.0:
            raise FilterError(f"sage-husa-ukf: forgetting must be in (0, 1) or None, "
                              f"got {forgetting}")
        self.estimate = frozenset(est)
        self.warmup = max(int(warmup), 1)
        self.forgetting = forgetting
        self.bias_correction = flag("sage-husa-ukf", "bias_correction", bias_correction)
        self.r_floor_rel = float(r_floor_rel)
        self.n_restarts = 0
        self._m = -1
        self._k_s = 0
        self._k_m = 0

    def on_bind(self, filt) -> None:
        n = filt.x.size
        self.q_hat = np.zeros(n)
        self.Q_hat = filt.Q.copy()
        self.r_hat = np.zeros(0)
        self.R_hat = np.zeros((0, 0))
        self._x_f = filt.x.copy()
        self._r_applied = np.zeros(0)

    def _gain(self, k: int) -> float:
        b = self.forgetting
        if b is None:
            return 1.0 / k
        return (1.0 - b) / (1.0 - b ** (k + 1))

    def after_predict(self, filt) -> None:
        self._x_f = filt.x                        # sum_i Wm_i f(xi_i), eq 28
        if "q" in self.estimate and self._k_s >= self.warmup:
            filt.x = filt.x + self.q_hat          # eq 35
            filt.x_prior = filt.x.copy()

    def before_update(self, filt, mp, z, R_prior):
        m = z.size
        if m != self._m:                          # m-sized statistics cannot continue
            if self._m >= 0:
                self.n_restarts += 1
            self._m = m
            self._k_m = 0
            self.r_hat = np.zeros(m)
            self.R_hat = R_prior.copy()           # discarded by the 1/k gain at k = 1
        self._z_raw = z
        self._z_sigma = mp.z_pred                 # sum_i Wm_i h(xi_i), eq 29
        ready = self._k_m >= self.warmup
        z_eff, R_used = z, R_prior
        self._r_applied = np.zeros(m)
        if ready and "r" in self.estimate:
            self._r_applied = self.r_hat
            z_eff = z - self.r_hat                # z - (z^- + r) = (z - r) - z^-, eq 37
        if ready and "R" in self.estimate:
            R_used = floor_pd(self.R_hat, self.r_floor_rel * np.diagonal(R_prior))
        return z_eff, R_used

    def after_update(self, filt, z, R_prior) -> None:
        self._k_s += 1
        g = self._gain(self._k_s)
        if "q" in self.estimate:
            self.q_hat = self.q_hat + g * ((filt.x_post - self._x_f) - self.q_hat)      # eq 30
        if "Q" in self.estimate:
            dx = filt.x_post - filt.x_prior
            term = np.outer(dx, dx)                                                     # eq 31
            if self.bias_correction:
                term = term + filt.P_post - (filt.P_prior - filt.Q_used)
            self.Q_hat = self.Q_hat + g * (term - self.Q_hat)
        self._k_m += 1
        gm = self._gain(self._k_m)
        if "r" in self.estimate:
            e = self._z_raw - self._z_sigma                                             # eq 32
            self.r_hat = self.r_hat + gm * (e - self.r_hat)
        if "R" in self.estimate:
            v = filt.y                                       # z - (sum Wm h + r), eq 33
            term = np.outer(v, v)
            if self.bias_correction:
                term = term - (filt.S - filt.R_used)         # minus P_zz
            self.R_hat = self.R_hat + gm * (term - self.R_hat)
        if "Q" in self.estimate and self._k_s >= self.warmup:
            filt.Q = floor_pd(self.Q_hat, self.q_floor)
            self.n_adaptations += 1
