"""Process and measurement models: the objects the filters call.

A filter never sees physics; it calls

* a **process model** with ``f(x, dt) -> x_next`` (discrete-time, additive noise ``Q``), its
  Jacobian ``F(x, dt)`` (EKF) and optionally a vectorized ``f_batch(X, dt)`` for sigma points;
* a **measurement model** with ``h(x) -> z_pred``, its Jacobian ``H(x)`` (EKF) and optionally
  ``h_batch(X)``.

Both are plain objects: subclass :class:`ProcessModel` / :class:`MeasurementModel` and override
``f`` / ``h`` (the defaults give a loop for the batch form and central differences for the
Jacobian), or wrap plain functions with :class:`FunctionProcessModel` /
:class:`FunctionMeasurementModel`, or use the linear ones. The EKF uses the Jacobians *of the
same model*, so EKF, UKF and CKF always see identical physics.

Per-epoch geometry
------------------
The measurement dimension may change every epoch (deep/tight mode: ``N_k`` channels ->
``m_k = 2 N_k`` measurements, pseudorange errors then pseudorange-rate errors). The model
object carries the epoch's geometry (line-of-sight vectors, channel list...): either the
caller updates it before ``update`` (e.g. ``model.set_geometry(...)``), or passes a fresh
model to ``update(z, R, measurement_model=...)``. ``h(x)`` then returns ``m_k`` values and
the filter checks ``z`` against that size. The 17-state INS error model (process) and the
pseudorange/rate model (measurement) of the receiver are such objects.

Units are those of the state layout (:mod:`sdr_di.filters.state`); ``dt`` in seconds.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = [
    "FunctionMeasurementModel",
    "FunctionProcessModel",
    "LinearMeasurementModel",
    "LinearProcessModel",
    "MeasurementModel",
    "ProcessModel",
    "numerical_jacobian",
]


def numerical_jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray,
                       step: float | np.ndarray | None = None) -> np.ndarray:
    """Central-difference Jacobian ``d fun / d x`` at ``x``.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> (m,)``.
    x : (n,) ndarray
        Linearization point.
    step : float or (n,) ndarray, optional
        Perturbation per state, in the state's units. Default
        ``eps**(1/3) * max(|x_i|, 1)`` (~6e-6 for small ``x``), adequate for smooth models
        whose states are O(1) or smaller; override it (or ``F``/``H``) for states of very
        different scales (e.g. latitude error in radians).

    Returns
    -------
    (m, n) ndarray
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    if step is None:
        hs = np.cbrt(np.finfo(float).eps) * np.maximum(np.abs(x), 1.0)
    else:
        hs = np.broadcast_to(np.asarray(step, dtype=float), (n,))
    cols = []
    for i in range(n):
        e = np.zeros(n)
        e[i] = hs[i]
        cols.append((np.asarray(fun(x + e), float) - np.asarray(fun(x - e), float))
                    / (2.0 * hs[i]))
    return np.column_stack(cols) if cols else np.zeros((0, 0))


class ProcessModel:
    """Discrete-time process model ``x_k = f(x_{k-1}, dt) + w_k``, ``w_k ~ N(0, Q)``.

    Subclasses override :meth:`f`; :meth:`f_batch` (sigma points) and :meth:`F` (EKF) have
    generic defaults that subclasses should override for speed/accuracy.

    Attributes
    ----------
    dim_x : int or None
        State dimension, checked against ``x0`` when known.
    """

    dim_x: int | None = None

    def f(self, x: np.ndarray, dt: float) -> np.ndarray:
        """Propagate one state vector over ``dt`` [s]."""
        raise NotImplementedError

    def f_batch(self, X: np.ndarray, dt: float) -> np.ndarray:
        """Propagate each row of ``X`` (shape ``(p, n)``); default loops over :meth:`f`."""
        return np.array([self.f(xi, dt) for xi in X], dtype=float)

    def F(self, x: np.ndarray, dt: float) -> np.ndarray:
        """State-transition Jacobian ``df/dx`` at ``x`` (default: central differences)."""
        return numerical_jacobian(lambda v: self.f(v, dt), x)

    def f_and_F(self, x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(f(x, dt), F(x, dt))``, what the EKF's time update needs; subclasses whose
        ``F`` evaluates ``f_batch`` may return both from one batch."""
        return self.f(x, dt), self.F(x, dt)


class MeasurementModel:
    """Measurement model ``z_k = h(x_k) + v_k``, ``v_k ~ N(0, R_k)``; ``len(z_k)`` may vary.

    Subclasses override :meth:`h`; :meth:`h_batch` and :meth:`H` have generic defaults.
    """

    def h(self, x: np.ndarray) -> np.ndarray:
        """Predicted measurement for one state vector, shape ``(m_k,)``."""
        raise NotImplementedError

    def h_batch(self, X: np.ndarray) -> np.ndarray:
        """Predicted measurements for each row of ``X``: shape ``(p, m_k)``."""
        return np.array([self.h(xi) for xi in X], dtype=float).reshape(len(X), -1)

    def H(self, x: np.ndarray) -> np.ndarray:
        """Measurement Jacobian ``dh/dx`` at ``x`` (default: central differences)."""
        return numerical_jacobian(self.h, x)


class LinearProcessModel(ProcessModel):
    """``f(x, dt) = Phi x`` with a fixed transition matrix ``Phi`` (``dt`` ignored)."""

    def __init__(self, Phi: np.ndarray) -> None:
        self.Phi = np.asarray(Phi, dtype=float)
        self.dim_x = self.Phi.shape[0]

    def f(self, x: np.ndarray, dt: float) -> np.ndarray:
        return self.Phi @ x

    def f_batch(self, X: np.ndarray, dt: float) -> np.ndarray:
        return X @ self.Phi.T

    def F(self, x: np.ndarray, dt: float) -> np.ndarray:
        return self.Phi


class LinearMeasurementModel(MeasurementModel):
    """``h(x) = H x``; assign :attr:`matrix` each epoch when the geometry or count changes."""

    def __init__(self, H: np.ndarray) -> None:
        self.matrix = np.atleast_2d(np.asarray(H, dtype=float))

    def h(self, x: np.ndarray) -> np.ndarray:
        return self.matrix @ x

    def h_batch(self, X: np.ndarray) -> np.ndarray:
        return X @ self.matrix.T

    def H(self, x: np.ndarray) -> np.ndarray:
        return self.matrix


class FunctionProcessModel(ProcessModel):
    """Wrap plain callables ``f(x, dt)``, optional ``F(x, dt)`` and ``f_batch(X, dt)``."""

    def __init__(self, f: Callable, F: Callable | None = None, f_batch: Callable | None = None,
                 dim_x: int | None = None) -> None:
        self._f, self._F, self._fb = f, F, f_batch
        self.dim_x = dim_x

    def f(self, x: np.ndarray, dt: float) -> np.ndarray:
        return np.asarray(self._f(x, dt), dtype=float)

    def f_batch(self, X: np.ndarray, dt: float) -> np.ndarray:
        if self._fb is not None:
            return np.asarray(self._fb(X, dt), dtype=float)
        return super().f_batch(X, dt)

    def F(self, x: np.ndarray, dt: float) -> np.ndarray:
        if self._F is not None:
            return np.asarray(self._F(x, dt), dtype=float)
        return super().F(x, dt)


class FunctionMeasurementModel(MeasurementModel):
    """Wrap plain callables ``h(x)``, optional ``H(x)`` and ``h_batch(X)``."""

    def __init__(self, h: Callable, H: Callable | None = None,
                 h_batch: Callable | None = None) -> None:
        self._h, self._H, self._hb = h, H, h_batch

    def h(self, x: np.ndarray) -> np.ndarray:
        return np.atleast_1d(np.asarray(self._h(x), dtype=float))

    def h_batch(self, X: np.ndarray) -> np.ndarray:
        if self._hb is not None:
            return np.asarray(self._hb(X), dtype=float).reshape(len(X), -1)
        return super().h_batch(X)

    def H(self, x: np.ndarray) -> np.ndarray:
        if self._H is not None:
            return np.atleast_2d(np.asarray(self._H(x), dtype=float))
        return super().H(x)
