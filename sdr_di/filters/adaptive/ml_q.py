"""Maximum-likelihood process-noise estimation inside a UKF, paper 000 (Hu et al. 2020):
``ml-q-ukf``.

ML estimator with a fixed-length window of ``N`` epochs (paper 000 eq 47)::

    Q_ML = (1/N) sum_{j=k-N+1..k} [ P_j + (x_j - x_j/j-1)(x_j - x_j/j-1)^T
                                    - sum_i w_i (xi_i,j/j-1 - x_j/j-1)(...)^T ]

where the last sum is the sigma-point spread of the time update, i.e. ``P_j/j-1 - Q_j-1``
(the prior covariance without the ``Q`` that was added). With a diagonal ``Q`` (paper 000
Remark 3, eq 49, the form used in its simulations) only the diagonal is estimated::

    q_ii = (1/N) sum_j [ (P_j)_ii + (x_j - x_j/j-1)_i^2 - (P_j/j-1 - Q_j-1)_ii ]

Default ``diagonal=True`` (eq 49); ``diagonal=False`` uses the full eq 47. Window ``N = 25``
(paper value). The estimate replaces ``Q`` only when

* the window is full, and
* the steady-state test of paper 000 section 3.3 accepts the current epoch: the innovation
  ``z_k - z_k^-`` "falls in the scope around zero mean within a range of 2 sigma",
  ``sigma^2 = diag(H P^- H^T + R)`` -- implemented per component, all ``|y_i| <= 2 sigma_i``
  (``steady_test='2sigma'``, default); ``steady_test='nis'`` accepts when the normalized
  innovation squared is below the 95.45 % chi-square quantile with ``m_k`` degrees of freedom
  (the same 2-sigma level, independent of the measurement count); ``None`` disables the test.

Positive definiteness: diagonal estimates are clipped to the ``Q`` floor; the full estimate is
raised to ``>= diag(Q floor)`` (eigenvalue clip in floor-scaled coordinates). ``mask`` limits
the estimation to some states (others keep their nominal ``Q0``), as paper 000 estimates only
the gyro and accelerometer noise terms.

Change of the measurement count N
    Not affected: the window holds state-space quantities (``n``-vectors or ``n x n``
    matrices) whatever ``m_k``; the steady-state test uses the current epoch's innovation of
    any length.
"""

from __future__ import annotations

import numpy as np

from ...errors import FilterError
from .._linalg import floor_pd
from .base import AdaptiveRule, flag

__all__ = ["MLProcessNoiseUKF"]


class MLProcessNoiseUKF(AdaptiveRule):
    """Windowed ML estimate of ``Q`` (paper 000 eq 47/49) with the steady-state gate.

    Parameters
    ----------
    window : int
        Window length ``N`` [epochs] (default 25).
    diagonal : bool
        Estimate only the diagonal (eq 49, default) or the full matrix (eq 47).
    steady_test : {'2sigma', 'nis', None}
        Steady-state gate (default '2sigma').
    mask : (n,) bool array_like, optional
        States whose ``Q`` is estimated (default all).
    q_floor : float or array_like, optional
        See :class:`~sdr_di.filters.adaptive.base.AdaptiveRule`.

    Attributes
    ----------
    steady : bool
        Outcome of the steady-state test at the last update.
    n_q_updates : int
        Number of epochs at which ``Q`` was replaced.
    """

    name = "ml-q-ukf"
    reference = "Hu et al., Information Fusion 2020 (paper 000), eq 47/49, section 3.3"

    def __init__(self, window: int = 25, diagonal: bool = True, steady_test: str | None = "2sigma",
                 mask=None, q_floor=None) -> None:
        super().__init__(q_floor)
        if int(window) < 1:
            raise FilterError(f"ml-q-ukf: window must be >= 1, got {window}")
        if steady_test not in ("2sigma", "nis", None):
            raise FilterError(f"ml-q-ukf: steady_test must be '2sigma', 'nis' or None, "
                              f"got {steady_test!r}")
        self.window = int(window)
        self.diagonal = flag("ml-q-ukf", "diagonal", diagonal)
        self.steady_test = steady_test
        self._mask_opt = mask
        self.steady = False
        self.n_q_updates = 0
        self._chi2: dict[int, float] = {}

    def on_bind(self, filt) -> None:
        n = filt.x.size
        shape = (self.window, n) if self.diagonal else (self.window, n, n)
        self._buf = np.zeros(shape)
        self._ptr = 0
        self._count = 0
        self.Q_nominal = filt.Q.copy()
        if self._mask_opt is None:
            self.mask = np.ones(n, dtype=bool)
        else:
            mask = np.asarray(self._mask_opt, dtype=bool)
            if mask.shape != (n,):
                raise FilterError(f"{filt.name}: mask must have {n} booleans")
            self.mask = mask

    def _is_steady(self, filt) -> bool:
        if self.steady_test is None:
            return True
        y = filt.y
        if self.steady_test == "2sigma":
            return bool(np.all(y * y <= 4.0 * np.diagonal(filt.S)))
        m = y.size
        lim = self._chi2.get(m)
        if lim is None:
            # imported here: scipy.stats costs every run ~0.5 s to import
            from scipy.stats import chi2

            lim = self._chi2[m] = float(chi2.ppf(0.9545, m))
        return filt.nis <= lim

    def after_update(self, filt, z, R_prior) -> None:
        dx = filt.x_post - filt.x_prior
        spread = filt.P_prior - filt.Q_used          # sum_i w_i (xi - x^-)(xi - x^-)^T
        if self.diagonal:
            term = np.diagonal(filt.P_post) + dx * dx - np.diagonal(spread)   # eq 49
        else:
            term = filt.P_post + np.outer(dx, dx) - spread                    # eq 47
        self._buf[self._ptr] = term
        self._ptr = (self._ptr + 1) % self.window
        self._count = min(self._count + 1, self.window)
        self.steady = self._is_steady(filt)
        if self._count < self.window or not self.steady:
            return
        est = self._buf.mean(axis=0)
        if self.diagonal:
            q = np.where(self.mask, np.maximum(est, self.q_floor), np.diagonal(self.Q_nominal))
            if np.all(self.mask):
                filt.Q = np.diag(q)
            else:
                Q = self.Q_nominal.copy()
                idx = np.flatnonzero(self.mask)
                Q[idx, :] = 0.0
                Q[:, idx] = 0.0
                Q[idx, idx] = q[idx]
                filt.Q = Q
        else:
            Qf = floor_pd(est, self.q_floor)
            if not np.all(self.mask):
                Q = self.Q_nominal.copy()
                idx = np.flatnonzero(self.mask)
                Q[idx, :] = 0.0
                Q[:, idx] = 0.0
                Q[np.ix_(idx, idx)] = Qf[np.ix_(idx, idx)]
                filt.Q = Q
            else:
                filt.Q = Qf
        self.n_q_updates += 1
        self.n_adaptations += 1
