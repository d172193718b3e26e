"""Common interface and measurement correction of every integration filter.

Interface (names after filterpy where it has the concept)
---------------------------------------------------------
Attributes (``n`` states, ``m_k`` measurements at the last update):

``x``, ``P``
    current state estimate (n,) and covariance (n, n)
``Q``
    process-noise covariance added by the next :meth:`predict` (n, n; its size never changes
    -- only the measurement side depends on the channel count); adaptive rules overwrite it
``R``
    default measurement-noise covariance, used when ``update`` gets no ``R`` (``None`` when
    ``R`` is passed every epoch, as with a varying channel count)
``dt``
    default time step [s] of :meth:`predict`
``x_prior``, ``P_prior`` / ``x_post``, ``P_post``
    state and covariance after the last predict (``x^-``, ``P^-``) / update (``x^+``, ``P^+``)
``Q_used``, ``R_used``
    the ``Q`` added in the last predict and the ``R`` used in the last update (after
    adaptation)
``y``
    innovation ``z - z^-`` (m_k,) of the last update (paper 004 eq 26)
``S``, ``S_inv``, ``K``
    innovation covariance ``P_zz + R``, its inverse (m_k, m_k) and the gain (n, m_k)
``residual``
    post-fit residual ``z - h(x^+)`` (m_k,) (paper 004 eq 32)
``nis``, ``log_likelihood``
    normalized innovation squared ``y^T S^-1 y`` and ``log N(y; 0, S)``
``epoch``
    number of updates with at least one measurement
``numerics_events``
    list of recorded covariance repairs (``psd_fallback='clip'``)
``rule``
    the attached adaptive rule, or ``None``
``adaptation_time_s``
    cumulative wall time [s] spent in the rule's hooks, ``rule.adaptation_time_s``
    (paper 004 section IV.B figure); ``0.0`` for a filter without a rule

Methods: :meth:`predict` ``(dt=None, Q=None)``, :meth:`update`
``(z, R=None, measurement_model=None)``, :meth:`predict_measurement`.

Correction (all filters, paper 004 eq 22-25, paper 003 eq 24-28): with the predicted
measurement ``z^-``, its covariance ``P_zz`` (without noise) and the cross covariance
``P_xz`` from the filter's own method (Jacobians for the EKF, sigma/cubature points for the
UKF/CKF)::

    S = P_zz + R,  K = P_xz S^-1,  x^+ = x^- + K (z - z^-),  P^+ = P^- - K S K^T

``S`` is factored by Cholesky (LAPACK ``dpotrf``); ``P`` is symmetrized after every step.

Numerics
--------
A covariance that is not positive definite where a Cholesky factor is needed (``P`` for the
sigma points, ``S`` in the update) raises :class:`~sdr_di.errors.CovarianceError`
naming the filter, the step and the smallest eigenvalue (``psd_fallback='raise'``, the
default), or, with ``psd_fallback='clip'``, is replaced by the nearest matrix with eigenvalues
clipped to ``1e-12 * max|eigenvalue|`` and the repair is appended to ``numerics_events``.
A non-positive-definite initial ``P0`` is rejected at construction.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..errors import CovarianceError, FilterError
from ._linalg import (
    cholesky_lower,
    clip_eigenvalues,
    min_eigenvalue,
    spd_inverse_from_cholesky,
    symmetrize,
)
from . import _numba_correct as _nb
from .models import MeasurementModel, ProcessModel

__all__ = ["KalmanFilterBase", "MeasurementPrediction"]

_LOG_2PI = math.log(2.0 * math.pi)
#: Whether :meth:`KalmanFilterBase._correct` runs its numba kernel (:mod:`._numba_correct`,
#: one call); False: the numpy form (the tested reference; the two agree to rounding). The
#: numpy form also takes over when the kernel finds ``S`` not positive definite (it owns
#: the failure policy).
jit = True


@dataclasses.dataclass
class MeasurementPrediction:
    """Predicted measurement statistics at the prior, before the noise ``R`` is added.

    Attributes
    ----------
    z_pred : (m,) ndarray
        Predicted measurement ``z^-``.
    Pzz : (m, m) ndarray
        Its covariance without measurement noise (``H P^- H^T`` for a linear model).
    Pxz : (n, m) ndarray
        State/measurement cross covariance (``P^- H^T``).
    model : MeasurementModel
        The model used (its ``h`` also gives the post-fit residual).
    """

    z_pred: np.ndarray
    Pzz: np.ndarray
    Pxz: np.ndarray
    model: MeasurementModel


def _as_square(name: str, a, n: int | None, who: str) -> np.ndarray:
    """Scalar -> a I, 1-D -> diag, 2-D -> checked square matrix (size n if given)."""
    arr = np.asarray(a, dtype=float)
    if arr.ndim == 0:
        if n is None:
            raise FilterError(f"{who}: {name} given as a scalar but its size is unknown")
        arr = float(arr) * np.eye(n)
    elif arr.ndim == 1:
        arr = np.diag(arr)
    elif arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise FilterError(f"{who}: {name} must be a square matrix, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise FilterError(f"{who}: {name} is {arr.shape[0]}x{arr.shape[1]} but {n}x{n} "
                          "is needed")
    if not np.all(np.isfinite(arr)):
        raise FilterError(f"{who}: {name} contains NaN or infinite values")
    scale = float(np.max(np.abs(arr))) if arr.size else 0.0
    if arr.size and float(np.max(np.abs(arr - arr.T))) > 1e-9 * max(scale, 1e-300):
        raise FilterError(f"{who}: {name} is not symmetric")
    return symmetrize(arr)


class KalmanFilterBase:
    """Shared state, validation, bookkeeping and correction step of EKF/UKF/CKF.

    Parameters
    ----------
    process_model : ProcessModel
        Gives ``f(x, dt)`` (and ``F``, ``f_batch``).
    measurement_model : MeasurementModel or None
        Default model for :meth:`update` (``h``, ``H``, ``h_batch``); may be ``None`` if
        every ``update`` passes one.
    x0 : (n,) array_like
        Initial state.
    P0 : (n, n) array_like
        Initial covariance; must be symmetric positive definite. A 1-D array is a diagonal.
    Q0 : (n, n) array_like
        Process-noise covariance per predict step (discrete-time, units of the state
        squared); symmetric positive semi-definite. Scalar or 1-D accepted (diagonal).
    R0 : array_like or None
        Default measurement-noise covariance (symmetric positive definite); ``None`` when the
        measurement count varies and ``R`` is passed to every :meth:`update`.
    dt : float
        Default predict interval [s] (default 1.0).
    psd_fallback : {'raise', 'clip'}
        What to do when ``P`` or ``S`` is not positive definite (see module docstring).
    q_scale, r_scale : float
        Positive factors on ``Q0`` (at construction) and on every ``R`` (``R0`` and the ``R``
        given to :meth:`update`), default 1: the free parameters a study tunes for a filter
        without an adaptive rule (an adaptive rule starts from the scaled values).
    name : str, optional
        Name used in messages and reports (registry name, e.g. ``'ff-aukf'``).
    rule : AdaptiveRule, optional
        Adaptive rule attached around the core filter (see :mod:`sdr_di.filters.adaptive`).
    """

    kind = "KF"

    def __init__(self, process_model: ProcessModel, measurement_model: MeasurementModel | None,
                 x0, P0, Q0, R0=None, *, dt: float = 1.0, psd_fallback: str = "raise",
                 q_scale: float = 1.0, r_scale: float = 1.0,
                 name: str | None = None, rule=None) -> None:
        self.name = name or self.kind
        who = self.name
        if psd_fallback not in ("raise", "clip"):
            raise FilterError(f"{who}: psd_fallback must be 'raise' or 'clip', "
                              f"got {psd_fallback!r}")
        self.psd_fallback = psd_fallback
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise FilterError(f"{who}: dt must be a positive number of seconds, got {dt!r}")
        self.dt = float(dt)
        for key, val in (("q_scale", q_scale), ("r_scale", r_scale)):
            if isinstance(val, bool) or not (isinstance(val, (int, float))
                                             and math.isfinite(val) and val > 0):
                raise FilterError(f"{who}: {key} must be a positive number, got {val!r}")
        self.q_scale, self.r_scale = float(q_scale), float(r_scale)
        self.process_model = process_model
        self.measurement_model = measurement_model

        x = np.asarray(x0, dtype=float)
        if x.ndim != 1 or x.size == 0:
            raise FilterError(f"{who}: x0 must be a non-empty 1-D vector, got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            raise FilterError(f"{who}: x0 contains NaN or infinite values")
        n = x.size
        dim = getattr(process_model, "dim_x", None)
        if dim is not None and dim != n:
            raise FilterError(f"{who}: x0 has {n} states but the process model has {dim}")
        P = _as_square("P0", P0, n, who)
        if cholesky_lower(P) is None:
            raise FilterError(f"{who}: initial covariance P0 is not positive definite "
                              f"(smallest eigenvalue {min_eigenvalue(P):.3e})")
        Q = _as_square("Q0", Q0, n, who) * self.q_scale
        qmin = min_eigenvalue(Q)
        if qmin < -1e-12 * max(float(np.max(np.abs(Q))), 1e-300):
            raise FilterError(f"{who}: process noise Q0 is not positive semi-definite "
                              f"(smallest eigenvalue {qmin:.3e})")
        if R0 is not None:
            R = _as_square("R0", R0, None, who) * self.r_scale
            if cholesky_lower(R) is None:
                raise FilterError(f"{who}: measurement noise R0 is not positive definite "
                                  f"(smallest eigenvalue {min_eigenvalue(R):.3e})")
        else:
            R = None

        self.x, self.P, self.Q, self.R = x, P, Q, R
        self.P0 = P.copy()
        self.Q0 = Q.copy()
        self.x_prior, self.P_prior = x.copy(), P.copy()
        self.x_post, self.P_post = x.copy(), P.copy()
        self.Q_used = Q
        self.R_used: np.ndarray | None = None
        self.z: np.ndarray | None = None
        self.y = np.zeros(0)
        self.S = np.zeros((0, 0))
        self.S_inv = np.zeros((0, 0))
        self.K = np.zeros((n, 0))
        self.residual = np.zeros(0)
        self.nis = 0.0
        self.log_likelihood = 0.0
        self.epoch = 0
        self.n_predict = 0
        self.last_prediction: MeasurementPrediction | None = None
        self.numerics_events: list[dict] = []
        self.rule = None
        if rule is not None:
            self.attach_rule(rule)

    # ------------------------------------------------------------------ public interface
    @property
    def dim_x(self) -> int:
        """State dimension ``n``."""
        return self.x.size

    @property
    def adaptation_time_s(self) -> float:
        """Cumulative time [s] in the adaptive rule's hooks (``rule.adaptation_time_s``;
        0.0 without a rule). Reset with ``rule.reset_timer()``."""
        rule = self.rule
        return 0.0 if rule is None else float(rule.adaptation_time_s)

    def attach_rule(self, rule) -> None:
        """Attach an adaptive rule (replaces any previous one) and let it bind to the filter.

        Parameters
        ----------
        rule : AdaptiveRule
            The rule (:class:`~sdr_di.filters.adaptive.base.AdaptiveRule`): its ``bind``
            captures the filter's nominal ``Q0``, floors and dimensions.
        """
        rule.bind(self)
        self.rule = rule

    def predict(self, dt: float | None = None, Q=None) -> None:
        """Time update: ``x^- = E[f(x, dt)]``, ``P^- = cov[f(x, dt)] + Q``.

        Parameters
        ----------
        dt : float, optional
            Interval [s]; default :attr:`dt`.
        Q : array_like, optional
            Process noise for this step only (overrides :attr:`Q`, including an adaptive
            rule's estimate).
        """
        dt = self.dt if dt is None else float(dt)
        Qk = self.Q if Q is None else _as_square("Q", Q, self.x.size, f"{self.name} predict")
        x, P_spread = self._propagate(self.x, self.P, dt)
        P = symmetrize(P_spread + Qk)
        if not (np.isfinite(x).all() and np.isfinite(P).all()):
            raise FilterError(f"{self.name} predict at epoch {self.epoch}: the process model "
                              "produced NaN or infinite values")
        self.x, self.P, self.Q_used = x, P, Qk
        self.x_prior, self.P_prior = x.copy(), P.copy()
        self.n_predict += 1
        rule = self.rule
        if rule is not None and rule._has_after_predict:
            rule._timed_after_predict(self)

    def _measurement_model(self, model: MeasurementModel | None) -> MeasurementModel:
        """``model``, else the filter's own; FilterError when neither is given."""
        model = model if model is not None else self.measurement_model
        if model is None:
            raise FilterError(f"{self.name}: no measurement model (give one to update or "
                              "to the constructor)")
        return model

    def update(self, z, R=None, measurement_model: MeasurementModel | None = None) -> None:
        """Measurement update with ``z`` (``m_k`` values; ``m_k`` may change every epoch).

        Parameters
        ----------
        z : (m_k,) array_like
            Measurement vector. An empty vector (no channel tracked) leaves ``x``/``P``
            unchanged.
        R : array_like, optional
            Measurement-noise covariance of this epoch, (m_k, m_k), or its diagonal (m_k,),
            or a scalar variance; default :attr:`R` (which must then be m_k x m_k). For the
            adaptive filters this is the *prior* ``R^-`` the rule adapts.
        measurement_model : MeasurementModel, optional
            Model of this epoch (default: the filter's).

        Raises
        ------
        FilterError
            Wrong-size or non-finite ``z``/``R``.
        CovarianceError
            ``S`` not positive definite (with ``psd_fallback='raise'``).
        """
        model = measurement_model if measurement_model is not None else self.measurement_model
        who = f"{self.name} update"
        if model is None:
            raise FilterError(f"{who}: no measurement model (pass measurement_model=)")
        z = np.asarray(z, dtype=float)
        if z.ndim == 0:
            z = z.reshape(1)
        if z.ndim != 1:
            raise FilterError(f"{who}: z must be a 1-D vector, got shape {z.shape}")
        if not np.isfinite(z).all():
            raise FilterError(f"{who}: z contains NaN or infinite values")
        m = z.size
        if m == 0:
            self._no_measurement()
            return
        mp = self.predict_measurement(model)
        if mp.z_pred.size != m:
            raise FilterError(f"{who}: z has {m} elements but the measurement model predicts "
                              f"{mp.z_pred.size}")
        R_prior = self._resolve_R(R, m, who)
        rule = self.rule
        z_eff, R_used = z, R_prior
        if rule is not None and rule._has_before_update:
            z_eff, R_used = rule._timed_before_update(self, mp, z, R_prior)
        self._correct(z_eff, R_used, mp)
        self.z = z
        if rule is not None and rule._has_after_update:
            rule._timed_after_update(self, z_eff, R_prior)

    def predict_measurement(self, model: MeasurementModel | None = None) -> MeasurementPrediction:
        """Predicted measurement, its covariance without noise and the cross covariance.

        Parameters
        ----------
        model : MeasurementModel, optional
            The measurement model of this update; default the filter's own.

        Returns
        -------
        MeasurementPrediction
            ``z_pred`` (m,), ``Pzz`` (m, m) without ``R``, ``Pxz`` (n, m) and the model.
        """
        raise NotImplementedError

    # ------------------------------------------------------------------ internals
    def _propagate(self, x: np.ndarray, P: np.ndarray, dt: float
                   ) -> tuple[np.ndarray, np.ndarray]:
        """Return (predicted mean, predicted covariance without Q)."""
        raise NotImplementedError

    def _resolve_R(self, R, m: int, who: str) -> np.ndarray:
        if R is None:
            if self.R is None:
                raise FilterError(f"{who}: no R given and the filter has no default R")
            R = self.R
            if R.shape[0] != m:
                raise FilterError(f"{who}: z has {m} elements but the default R is "
                                  f"{R.shape[0]}x{R.shape[0]}; pass R for this epoch")
            return R
        R = np.asarray(R, dtype=float)
        if R.ndim == 0:
            R = float(R) * np.eye(m)
        elif R.ndim == 1:
            if R.size != m:
                raise FilterError(f"{who}: z has {m} elements but the R diagonal has {R.size}")
            R = np.diag(R)
        elif R.shape != (m, m):
            raise FilterError(f"{who}: z has {m} elements but R has shape {R.shape}")
        if not np.isfinite(R).all():
            raise FilterError(f"{who}: R contains NaN or infinite values")
        if np.any(np.diagonal(R) <= 0.0):
            raise FilterError(f"{who}: R has a non-positive variance on its diagonal")
        return R * self.r_scale if self.r_scale != 1.0 else R

    def _cholesky(self, A: np.ndarray, step: str, matrix: str) -> tuple[np.ndarray, np.ndarray]:
        """Lower Cholesky factor of ``A`` with the filter's failure policy.

        Returns ``(L, A_used)``; ``A_used`` differs from ``A`` only after a clip repair.
        """
        L = cholesky_lower(A) if np.isfinite(A).all() else None
        if L is not None:
            return L, A
        wmin = min_eigenvalue(A)
        if self.psd_fallback == "clip" and math.isfinite(wmin):
            A2, _ = clip_eigenvalues(A)
            L = cholesky_lower(A2)
            if L is not None:
                self.numerics_events.append({"epoch": self.epoch, "step": step,
                                             "matrix": matrix, "min_eigenvalue": wmin,
                                             "action": "eigenvalue clip"})
                return L, A2
        raise CovarianceError(self.name, step, matrix, wmin, self.epoch)

    def _correct(self, z: np.ndarray, R: np.ndarray, mp: MeasurementPrediction) -> None:
        y = z - mp.z_pred
        out = self._correct_by_kernel(y, R, mp) if jit else None
        if out is None:
            S = symmetrize(mp.Pzz + R)
            L, S = self._cholesky(S, "update", "S")
            S_inv = spd_inverse_from_cholesky(L)
            K = mp.Pxz @ S_inv
            x = self.x + K @ y
            P = symmetrize(self.P - K @ mp.Pxz.T)
            Sy = S_inv @ y
            nis = float(y @ Sy)
            log_det_half = float(np.sum(np.log(np.diagonal(L))))
        else:
            x, P, S, S_inv, K, nis, log_det_half = out
        self.log_likelihood = -0.5 * (y.size * _LOG_2PI + 2.0 * log_det_half + nis)
        self.x, self.P = x, P
        self.x_post, self.P_post = x.copy(), P.copy()
        self.y, self.S, self.S_inv, self.K, self.nis = y, S, S_inv, K, nis
        self.R_used = R
        self.residual = z - np.asarray(mp.model.h(x), dtype=float)
        self.last_prediction = mp
        self.epoch += 1

    def _correct_by_kernel(self, y: np.ndarray, R: np.ndarray, mp: MeasurementPrediction
                           ) -> tuple | None:
        """:meth:`_correct`'s numbers by :func:`._numba_correct.correct`: ``(x, P, S,
        S_inv, K, nis, sum of log diag L)``, or None when ``S`` is not positive definite
        (the numpy form then applies the failure policy)."""
        n, m = self.x.size, y.size
        S, L, S_inv = np.empty((m, m)), np.empty((m, m)), np.empty((m, m))
        K, x, P = np.empty((n, m)), np.empty(n), np.empty((n, n))
        ok, nis, log_det_half = _nb.correct(
            self.x, self.P, np.asarray(y, float), np.asarray(mp.Pzz, float),
            np.asarray(mp.Pxz, float), np.asarray(R, float), S, L, S_inv, K, x, P)
        return (x, P, S, S_inv, K, nis, log_det_half) if ok else None

    def _no_measurement(self) -> None:
        n = self.x.size
        self.x_post, self.P_post = self.x.copy(), self.P.copy()
        self.y, self.residual = np.zeros(0), np.zeros(0)
        self.S = self.S_inv = np.zeros((0, 0))
        self.K = np.zeros((n, 0))
        self.R_used = np.zeros((0, 0))
        self.nis, self.log_likelihood = 0.0, 0.0
        self.z = np.zeros(0)

    def __repr__(self) -> str:
        rule = f", rule={self.rule.name}" if self.rule is not None else ""
        return f"<{type(self).__name__} {self.name!r} n={self.x.size}{rule}>"
