"""Covariance-matching process-noise scaling, paper 002 (Ding, Wang & Rizos 2007):
``q-scaling-ekf`` / ``q-scaling-ukf``.

The innovation covariance predicted by the filter, ``H P^- H^T + R`` (eq 16), is matched to
the one observed over a window of ``m`` innovations ``d_j`` (eq 17), assuming ``R`` right, through
one trace ratio (eq 19)::

    alpha_k = [ tr( (1/m) sum_{j=0..m-1} d_k-j d_k-j^T ) - tr(R_k) ] / tr(H P_k^- H^T)

and the process noise is rescaled as a whole (eq 22)::

    Q_k = Q_k-1 sqrt(alpha_k)        (i.e. Q_k = scale_k Q0,  scale_k = scale_k-1 sqrt(alpha_k))

``alpha`` settles at 1 when the predicted and observed innovation covariances agree. Window
``m = 64`` (paper value); ``alpha`` is computed and applied once the window holds
``min_samples`` epochs (default: a full window). For the UKF ``tr(H P^- H^T)`` is the trace of
the sigma-point ``P_zz`` (``tr S - tr R``). Works on any core filter (EKF and UKF in the
registry). Bounds (not in the paper; numerical safety): ``alpha`` is clipped to
``alpha_bounds`` (default (0.01, 100)) -- the window trace can fall below ``tr R`` and make
the ratio negative -- and the cumulative ``scale`` to ``scale_bounds`` (default (1e-6, 1e6)),
which is also the ``Q`` floor relative to ``Q0``.

Regime of use: ``alpha`` is a small difference of two traces divided by ``tr(H P^- H^T)``;
when the innovations are dominated by the measurement noise (``tr R >> tr H P^- H^T``, e.g.
many precise channels at a high rate) its window noise is large and, integrated by eq 22, makes
``scale`` wander. It is well behaved when the prediction uncertainty is a sizeable part of the
innovation covariance (paper 002's loosely coupled GPS/INS at 1 Hz).

Change of the measurement count N
    The traces are scalars, so the window keeps going: each epoch stores its innovation power
    *per measurement* ``d_j^T d_j / m_j`` and the window trace is rebuilt as
    ``m_k * mean_j(d_j^T d_j / m_j)`` -- exactly eq 17's trace when ``m`` is constant, and the
    per-channel normalization of paper 004 eq 39 when it changes. (Pseudorange and rate
    innovations are summed in one trace, as eq 19 sums all measurements.)
"""

from __future__ import annotations

import math

import numpy as np

from ...errors import FilterError
from .base import AdaptiveRule

__all__ = ["ProcessNoiseScaling"]


class ProcessNoiseScaling(AdaptiveRule):
    """Scale ``Q`` by ``sqrt(alpha)`` with the innovation trace ratio of paper 002.

    Parameters
    ----------
    window : int
        Innovation window ``m`` [epochs] (default 64).
    min_samples : int, optional
        Epochs in the window before adapting (default ``window``).
    alpha_bounds, scale_bounds : (float, float)
        Bounds of the per-epoch ratio and of the cumulative scale.

    Attributes
    ----------
    alpha : float
        Last trace ratio (eq 19), ``nan`` before the first adaptation.
    scale : float
        Cumulative factor, ``Q = scale * Q0``.
    """

    name = "q-scaling"
    reference = "Ding, Wang & Rizos 2007 (paper 002), eq 16-22"

    def __init__(self, window: int = 64, min_samples: int | None = None,
                 alpha_bounds: tuple[float, float] = (0.01, 100.0),
                 scale_bounds: tuple[float, float] = (1e-6, 1e6)) -> None:
        super().__init__(None)
        if int(window) < 1:
            raise FilterError(f"q-scaling: window must be >= 1, got {window}")
        self.window = int(window)
        self.min_samples = self.window if min_samples is None else max(1, int(min_samples))
        self.alpha_bounds = (float(alpha_bounds[0]), float(alpha_bounds[1]))
        self.scale_bounds = (float(scale_bounds[0]), float(scale_bounds[1]))
        self.alpha = math.nan
        self.scale = 1.0
        self._pw = np.zeros(self.window)
        self._ptr = 0
        self._count = 0

    def on_bind(self, filt) -> None:
        self.Q_nominal = filt.Q.copy()

    def after_update(self, filt, z, R_prior) -> None:
        d = filt.y
        m = d.size
        self._pw[self._ptr] = float(d @ d) / m
        self._ptr = (self._ptr + 1) % self.window
        self._count = min(self._count + 1, self.window)
        if self._count < self.min_samples:
            return
        tr_cov = m * float(self._pw[:self._count].mean())            # eq 17 (trace)
        tr_R = float(np.trace(filt.R_used))
        tr_hph = float(np.trace(filt.S)) - tr_R                       # tr(H P^- H^T)
        alpha = (tr_cov - tr_R) / tr_hph if tr_hph > 0.0 else self.alpha_bounds[1]
        lo, hi = self.alpha_bounds
        self.alpha = min(max(alpha, lo), hi)                          # eq 19
        self.scale = min(max(self.scale * math.sqrt(self.alpha), self.scale_bounds[0]),
                         self.scale_bounds[1])                        # eq 22
        filt.Q = self.scale * self.Q_nominal
        self.n_adaptations += 1
