"""Extended Kalman filter on the same process/measurement models as the UKF and CKF.

Time update ``x^- = f(x, dt)``, ``P^- = F P F^T + Q`` with ``F = df/dx`` at the previous
estimate; measurement prediction ``z^- = h(x^-)``, ``P_zz = H P^- H^T``, ``P_xz = P^- H^T``
with ``H = dh/dx`` at ``x^-``; the correction is the common one of
:class:`~sdr_di.filters.base.KalmanFilterBase`. The Jacobians are the models' ``F``/``H``
methods (analytic where the model provides them, central differences otherwise), so the EKF
is the first-order linearization of exactly the model the sigma-point filters propagate.
"""

from __future__ import annotations

import numpy as np

from .base import KalmanFilterBase, MeasurementPrediction
from .models import MeasurementModel

__all__ = ["EKF"]


class EKF(KalmanFilterBase):
    """Extended Kalman filter. Parameters as :class:`~sdr_di.filters.base.KalmanFilterBase`.

    Attributes (besides the common ones)
    ------------------------------------
    F : (n, n) ndarray
        Transition Jacobian of the last predict.
    H : (m, n) ndarray
        Measurement Jacobian of the last measurement prediction.
    """

    kind = "EKF"

    def __init__(self, process_model, measurement_model, x0, P0, Q0, R0=None, **kwargs) -> None:
        super().__init__(process_model, measurement_model, x0, P0, Q0, R0, **kwargs)
        self.F = np.eye(self.x.size)
        self.H = np.zeros((0, self.x.size))

    def _propagate(self, x, P, dt):
        x_new, F = self.process_model.f_and_F(x, dt)
        x_new, F = np.asarray(x_new, dtype=float), np.asarray(F, dtype=float)
        self.F = F
        return x_new, F @ P @ F.T

    def predict_measurement(self, model: MeasurementModel | None = None) -> MeasurementPrediction:
        model = self._measurement_model(model)
        H = np.atleast_2d(np.asarray(model.H(self.x), dtype=float))
        z_pred = np.atleast_1d(np.asarray(model.h(self.x), dtype=float))
        Pxz = self.P @ H.T
        self.H = H
        return MeasurementPrediction(z_pred, H @ Pxz, Pxz, model)
