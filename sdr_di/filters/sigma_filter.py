"""Sigma-point Kalman filters: one machinery, two point sets (UKF and CKF).

:class:`SigmaPointFilter` implements the time update and the measurement prediction with any
:class:`~sdr_di.filters.sigma_points.SigmaPoints` set; :class:`UKF` plugs in the scaled
unscented points (paper 004 eq 13-25) and :class:`CKF` the cubature points (paper 003
eq 17-28). Both use the common correction of :class:`~sdr_di.filters.base.KalmanFilterBase`.

Time update (paper 004 eq 16, 19-20; paper 003 eq 17-22)::

    L = chol(P),  X_i = x + L xi_i,  Y_i = f(X_i, dt)
    x^- = sum Wm_i Y_i,  P^- = sum Wc_i (Y_i - x^-)(Y_i - x^-)^T + Q

Measurement prediction: the points are *redrawn* from ``(x^-, P^-)`` (so the additive ``Q``
is seen by the measurement, which makes the filter exact for linear models)::

    X_i = x^- + chol(P^-) xi_i,  Z_i = h(X_i)
    z^- = sum Wm_i Z_i,  P_zz = sum Wc_i (Z_i - z^-)(Z_i - z^-)^T,
    P_xz = sum Wc_i (X_i - x^-)(Z_i - z^-)^T

With a linear ``h = H x`` this is ``H x^-``, ``H P^- H^T``, ``P^- H^T`` -- paper 004 eq 21-23
and paper 003 eq 23-26 -- to rounding. Means and covariances are accumulated as deviations
from the first point (``D_i = Y_i - Y_0``), which avoids cancellation against a large mean
and keeps the covariance positive semi-definite with a negative centre weight. Models may
provide ``f_batch``/``h_batch`` to evaluate all points in one vectorized call (otherwise one
call per point).
"""

from __future__ import annotations

import numpy as np

from ..errors import FilterError
from . import _numba_sigma as _nb
from .base import KalmanFilterBase, MeasurementPrediction
from .models import MeasurementModel
from .sigma_points import CubaturePoints, MerweScaledSigmaPoints, SigmaPoints

__all__ = ["CKF", "UKF", "SigmaPointFilter", "weighted_moments"]

#: Whether the points, the weighted moments and the cross covariance run their numba
#: kernels (:mod:`._numba_sigma`, one call each); False: the numpy forms (the tested
#: references; the two agree to rounding).
jit = True


def weighted_moments(Y: np.ndarray, wm: np.ndarray, wc: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Weighted mean and covariance of the rows of ``Y``, computed about ``Y[0]`` (by
    :func:`._numba_sigma.moments` unless ``jit`` is off).

    Returns
    -------
    mean : (d,) ndarray
    cov : (d, d) ndarray
        ``sum wc_i (Y_i - mean)(Y_i - mean)^T``.
    D : (p, d) ndarray
        Deviations ``Y - Y[0]`` (for cross covariances).
    delta : (d,) ndarray
        ``mean - Y[0]``.
    """
    if jit:
        Y = np.ascontiguousarray(Y, dtype=float)
        p, d = Y.shape
        mean, cov, D, delta = np.empty(d), np.empty((d, d)), np.empty((p, d)), np.empty(d)
        _nb.moments(Y, np.asarray(wm, float), np.asarray(wc, float), mean, cov, D, delta)
        return mean, cov, D, delta
    ref = Y[0]
    D = Y - ref
    delta = wm @ D
    c = wc @ D
    # outer products by broadcasting (np.outer's own products, without its call overhead)
    dcol = delta[:, None]
    cov = (D.T * wc) @ D - dcol * c - c[:, None] * delta \
        + float(np.sum(wc)) * (dcol * delta)
    return ref + delta, 0.5 * (cov + cov.T), D, delta


class SigmaPointFilter(KalmanFilterBase):
    """Sigma-point Kalman filter with a pluggable point set.

    Parameters
    ----------
    process_model, measurement_model, x0, P0, Q0, R0
        As :class:`~sdr_di.filters.base.KalmanFilterBase`.
    points : SigmaPoints
        The point set (unit points and weights).
    **kwargs
        ``dt``, ``psd_fallback``, ``name``, ``rule``.

    Attributes (besides the common ones)
    ------------------------------------
    sigmas_f : (p, n) ndarray
        Points after the process model in the last predict (``Y_i``).
    sigmas_h : (p, m) ndarray
        Points after the measurement model in the last update (``Z_i``).
    """

    kind = "SPKF"

    def __init__(self, process_model, measurement_model, x0, P0, Q0, R0=None, *,
                 points: SigmaPoints, **kwargs) -> None:
        super().__init__(process_model, measurement_model, x0, P0, Q0, R0, **kwargs)
        self.points = points
        n = self.x.size
        self._xi = points.unit_points(n)
        self._wm, self._wc = points.weights(n)
        self.sigmas_f = np.zeros((self._xi.shape[0], n))
        self.sigmas_h = np.zeros((self._xi.shape[0], 0))

    def _draw(self, x: np.ndarray, P: np.ndarray, step: str) -> tuple[np.ndarray, np.ndarray]:
        """Points ``x + L xi_i`` (rows) and their deviations ``L xi_i`` from ``x`` (by
        :func:`._numba_sigma.draw` unless ``jit`` is off; the numpy form applies the failure
        policy when ``P`` is not positive definite)."""
        if jit:
            X, dX = np.empty(self._xi.shape), np.empty(self._xi.shape)
            if _nb.draw(np.asarray(x, float), np.asarray(P, float), self._xi, X, dX):
                return X, dX
        L, P_used = self._cholesky(P, step, "P")
        if P_used is not P:
            self.P = P_used
        dX = self._xi @ L.T
        return x + dX, dX

    def _propagate(self, x, P, dt):
        X, _ = self._draw(x, P, "predict")
        Y = np.asarray(self.process_model.f_batch(X, dt), dtype=float)
        self.sigmas_f = Y
        mean, cov, _, _ = weighted_moments(Y, self._wm, self._wc)
        return mean, cov

    def predict_measurement(self, model: MeasurementModel | None = None) -> MeasurementPrediction:
        model = self._measurement_model(model)
        X, dX = self._draw(self.x, self.P, "update")
        Z = np.asarray(model.h_batch(X), dtype=float)
        if Z.ndim == 1:
            Z = Z.reshape(len(X), -1)
        self.sigmas_h = Z
        wm, wc = self._wm, self._wc
        z_pred, Pzz, DZ, dz = weighted_moments(Z, wm, wc)
        # cross covariance: X deviations are exact (dX, zero weighted mean by symmetry)
        if jit:
            Pxz = np.empty((dX.shape[1], DZ.shape[1]))
            _nb.cross_covariance(np.ascontiguousarray(dX), DZ, wc, dz, Pxz)
        else:
            Pxz = (dX.T * wc) @ DZ - (wc @ dX)[:, None] * dz
        return MeasurementPrediction(z_pred, Pzz, Pxz, model)


class UKF(SigmaPointFilter):
    """Unscented Kalman filter (paper 004 eq 13-25) with scaled sigma points.

    Parameters
    ----------
    alpha, beta, kappa : float
        Scaled-UT parameters (defaults 0.5, 2, 0; see
        :class:`~sdr_di.filters.sigma_points.MerweScaledSigmaPoints`).
    **kwargs
        The other parameters, as :class:`SigmaPointFilter`.
    """

    kind = "UKF"

    def __init__(self, process_model, measurement_model, x0, P0, Q0, R0=None, *,
                 alpha: float = 0.5, beta: float = 2.0, kappa: float = 0.0, **kwargs) -> None:
        try:
            points = MerweScaledSigmaPoints(alpha, beta, kappa)
            if x0 is not None:
                points.unit_points(np.asarray(x0).size)
        except ValueError as exc:
            raise FilterError(f"{kwargs.get('name') or 'UKF'}: {exc}") from None
        super().__init__(process_model, measurement_model, x0, P0, Q0, R0,
                         points=points, **kwargs)


class CKF(SigmaPointFilter):
    """Cubature Kalman filter (paper 003 eq 17-28): ``2n`` points ``+-sqrt(n) e_i``."""

    kind = "CKF"

    def __init__(self, process_model, measurement_model, x0, P0, Q0, R0=None, **kwargs) -> None:
        super().__init__(process_model, measurement_model, x0, P0, Q0, R0,
                         points=CubaturePoints(), **kwargs)
