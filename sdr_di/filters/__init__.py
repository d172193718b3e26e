"""Integration filters: EKF, UKF, CKF and pluggable adaptive rules (DESIGN sections 1, 4).

Generic Kalman-filter layer of the receiver's 17-state integration filter and of the loosely
coupled runs. Everything runs at filter rate in plain numpy/scipy (no numba).

Build a filter by name::

    from sdr_di.filters import make_filter
    kf = make_filter("ff-aukf", process_model, measurement_model, x0, P0, Q0, R0=None, dt=0.1)
    kf.predict()                       # x^-, P^- (f(x, dt) of the process model)
    kf.update(z, R=R_k)                # z = [drho_1..N, drho_dot_1..N], R_k from pre-filters
    kf.x, kf.P, kf.y, kf.S, kf.K, kf.residual, kf.log_likelihood, kf.rule.adaptation_time_s

Names (:data:`FILTER_NAMES`): ``ekf``, ``ukf``, ``ckf``, ``ff-aukf``, ``rae-aukf``,
``ml-q-ukf``, ``sage-husa-ukf``, ``q-scaling-ekf``, ``q-scaling-ukf``, ``ml-r-ckf``; and
plugins: ``register_filter(name, factory)``, installed packages' entry points, import paths
``package.module:Name`` (docs/filters.md).

Modules
-------
``models``        :class:`ProcessModel` (``f``, ``F``, ``f_batch``), :class:`MeasurementModel`
                  (``h``, ``H``, ``h_batch``), linear and function wrappers
``base``          :class:`KalmanFilterBase`: common interface, validation, correction
``ekf``           :class:`EKF`
``sigma_points``  scaled unscented and cubature point sets
``sigma_filter``  :class:`SigmaPointFilter` and its :class:`UKF` / :class:`CKF`
``adaptive``      one module per paper rule (see :mod:`sdr_di.filters.adaptive`)
``registry``      :func:`make_filter`, :func:`filter_table`
``spec``          :func:`parse_filter_spec`: ``NAME[:opt=value...]`` with typed options
``plugins``       :func:`register_filter`, entry points ``sdr_di.filters``, import paths
``state``         state layouts (the 17 states; ``error_states=`` :func:`state_layout`) and
                  measurement blocks
``errors``        :class:`FilterError`, :class:`CovarianceError`
"""

from ..errors import CovarianceError, FilterError
from .adaptive import (
                       AdaptiveRule,
                       ForgettingFactorAUKF,
                       MLMeasurementNoiseCKF,
                       MLProcessNoiseUKF,
                       ProcessNoiseScaling,
                       SageHusaUKF,
                       SageWindowAUKF,
)
from .base import KalmanFilterBase, MeasurementPrediction
from .ekf import EKF
from .models import (
                       FunctionMeasurementModel,
                       FunctionProcessModel,
                       LinearMeasurementModel,
                       LinearProcessModel,
                       MeasurementModel,
                       ProcessModel,
                       numerical_jacobian,
)
from .plugins import register_filter, unregister_filter
from .registry import FILTER_NAMES, filter_options, filter_record, filter_table, make_filter
from .spec import FilterSpec, parse_filter_spec
from .state import StateLayout, state_layout
from .sigma_filter import CKF, UKF, SigmaPointFilter
from .sigma_points import CubaturePoints, MerweScaledSigmaPoints, SigmaPoints

__all__ = [
                       "CKF",
                       "EKF",
                       "FILTER_NAMES",
                       "FilterSpec",
                       "UKF",
                       "AdaptiveRule",
                       "CovarianceError",
                       "CubaturePoints",
                       "FilterError",
                       "ForgettingFactorAUKF",
                       "FunctionMeasurementModel",
                       "FunctionProcessModel",
                       "KalmanFilterBase",
                       "LinearMeasurementModel",
                       "LinearProcessModel",
                       "MLMeasurementNoiseCKF",
                       "MLProcessNoiseUKF",
                       "MeasurementModel",
                       "MeasurementPrediction",
                       "MerweScaledSigmaPoints",
                       "ProcessModel",
                       "ProcessNoiseScaling",
                       "SageHusaUKF",
                       "SageWindowAUKF",
                       "SigmaPointFilter",
                       "SigmaPoints",
                       "StateLayout",
                       "filter_options",
                       "filter_record",
                       "filter_table",
                       "make_filter",
                       "numerical_jacobian",
                       "parse_filter_spec",
                       "register_filter",
                       "state_layout",
                       "unregister_filter",
]
