"""Maximum-likelihood measurement-noise estimation by SQP inside a CKF, paper 003
(Gao et al. 2021): ``ml-r-ckf``.

With the innovations ``y_j = z_j - z_j^-`` and their predicted covariance without noise
``P_zz,j`` (``H P_j^- H^T``, from the cubature points), a diagonal ``R = diag(r_1..r_m)``
(eq 36) is estimated by minimizing the negative log-likelihood (eq 35, 38)::

    J(r) = sum_j [ ln |P_zz,j + R| + y_j^T (P_zz,j + R)^-1 y_j ],   r_i > 0  (eq 37)

with :func:`scipy.optimize.minimize` ``method='SLSQP'`` (the paper's SQP, eq 39-44), the
analytic gradient ``dJ/dr_i = sum_j [ (S_j^-1)_ii - (S_j^-1 y_j)_i^2 ]``, variables scaled by
the epoch's prior ``diag(R^-)`` (so all are O(1)), bounds ``r_i >= r_floor_rel * R^-_ii``
(the constraint ``R > 0``; default ``r_floor_rel = 1e-6``) and a warm start from the previous
estimate. The estimate is used in the current update (paper 003 section 3.4, step 2 and
eq 45): the window includes the current innovation.

Window: paper 003 sums over all epochs ``1..k``; to follow a noise change (its 16x-enlarged
interval) a sliding window of ``window`` epochs is used here (default 50). Estimation starts
once ``min_samples`` epochs are stored (default 10); before that the prior ``R^-`` is used.
``every`` solves only every k-th epoch (default 1) and reuses the last estimate in between.

Change of the measurement count N
    The parameters are one variance per measurement and the window holds ``m_k``-vectors and
    ``m_k x m_k`` matrices, so a change of ``m_k`` restarts the window (``n_restarts``); the
    prior ``R^-`` is used until ``min_samples`` epochs of the new size are stored.
"""

from __future__ import annotations

import numpy as np

from ...errors import FilterError
from .base import AdaptiveRule

__all__ = ["MLMeasurementNoiseCKF", "ml_r_objective"]


def ml_r_objective(u: np.ndarray, scale: np.ndarray, Y: np.ndarray, Pzz: np.ndarray
                   ) -> tuple[float, np.ndarray]:
    """Negative log-likelihood (eq 35) per epoch and its gradient in scaled variables.

    Parameters
    ----------
    u : (m,) ndarray
        Scaled variances, ``r = u * scale``.
    scale : (m,) ndarray
        Variable scaling (the prior diagonal).
    Y : (w, m) ndarray
        Innovations of the window.
    Pzz : (w, m, m) ndarray
        Their predicted covariances without noise.

    Returns
    -------
    (J / w, dJ/du / w)
    """
    r = u * scale
    S = Pzz.copy()
    idx = np.arange(r.size)
    S[:, idx, idx] += r
    Sinv = np.linalg.inv(S)
    a = np.einsum("wij,wj->wi", Sinv, Y)
    _, logdet = np.linalg.slogdet(S)
    w = Y.shape[0]
    J = float(np.sum(logdet) + np.einsum("wi,wi->", Y, a)) / w
    grad_r = (np.diagonal(Sinv, axis1=1, axis2=2) - a * a).sum(axis=0) / w
    return J, grad_r * scale


class MLMeasurementNoiseCKF(AdaptiveRule):
    """ML estimate of a diagonal ``R`` over a sliding window, solved by SLSQP (paper 003).

    Parameters
    ----------
    window : int
        Sliding window [epochs] (default 50).
    min_samples : int
        Stored epochs before the first estimate (default 10).
    every : int
        Solve every ``every`` epochs (default 1).
    maxiter : int
        SLSQP iteration limit per solve (default 50).
    ftol : float
        SLSQP tolerance on the per-epoch objective (default 1e-9).
    r_floor_rel : float
        Lower bound of each variance relative to the prior diagonal (default 1e-6).

    Attributes
    ----------
    r_hat : ndarray or None
        Current estimate of ``diag(R)`` (``None`` before the first solve).
    last_result : scipy.optimize.OptimizeResult or None
    n_restarts : int
    n_solves : int
    """

    name = "ml-r-ckf"
    reference = "Gao et al., Math. Problems in Engineering 2021 (paper 003), eq 29-45"

    def __init__(self, window: int = 50, min_samples: int = 10, every: int = 1,
                 maxiter: int = 50, ftol: float = 1e-9, r_floor_rel: float = 1e-6) -> None:
        super().__init__(None)
        if int(window) < 1 or int(min_samples) < 1 or int(every) < 1:
            raise FilterError("ml-r-ckf: window, min_samples and every must be >= 1")
        self.window = int(window)
        self.min_samples = min(int(min_samples), self.window)
        self.every = int(every)
        self.maxiter = int(maxiter)
        self.ftol = float(ftol)
        self.r_floor_rel = float(r_floor_rel)
        self.r_hat: np.ndarray | None = None
        self.last_result = None
        self.n_restarts = 0
        self.n_solves = 0
        self._m = -1
        self._count = 0
        self._ptr = 0
        self._k = 0

    def before_update(self, filt, mp, z, R_prior):
        m = z.size
        if m != self._m:
            if self._m >= 0:
                self.n_restarts += 1
            self._m = m
            self._Y = np.zeros((self.window, m))
            self._P = np.zeros((self.window, m, m))
            self._count = self._ptr = 0
            self.r_hat = None
        p = self._ptr
        self._Y[p] = z - mp.z_pred                          # eq 31
        self._P[p] = mp.Pzz                                 # H P^- H^T, eq 32
        self._ptr = (p + 1) % self.window
        self._count = min(self._count + 1, self.window)
        self._k += 1
        if self._count < self.min_samples:
            return z, R_prior
        if self.r_hat is None or self._k % self.every == 0:
            scale = np.diagonal(R_prior).copy()
            u0 = np.ones(m) if self.r_hat is None else self.r_hat / scale
            c = self._count
            Y = self._Y[:c]
            P = self._P[:c]
            lb = self.r_floor_rel
            u0 = np.maximum(u0, lb)
            # imported here: scipy.optimize costs ~0.15 s of CPU at import, in every process
            # that imports the filters (every sdr-di run but scalar's), used only here
            from scipy.optimize import minimize

            res = minimize(ml_r_objective, u0, args=(scale, Y, P), jac=True, method="SLSQP",
                           bounds=[(lb, None)] * m,
                           options={"maxiter": self.maxiter, "ftol": self.ftol})
            self.last_result = res
            if np.all(np.isfinite(res.x)):
                self.r_hat = np.maximum(res.x, lb) * scale
            self.n_solves += 1
            self.n_adaptations += 1
        if self.r_hat is None:
            return z, R_prior
        return z, np.diag(self.r_hat)
