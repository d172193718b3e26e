"""Sage-window adaptive UKF, the baseline of paper 004 (section III.B): ``rae-aukf``.

Residual-based adaptive estimation (RAE) of ``R`` and innovation-based adaptive estimation
(IAE) of ``Q`` with a moving window of ``m`` epochs, after Mohamed & Schwarz (1999, J.
Geodesy 73:193-203; paper 004 ref [35], which paper 004 eq 33 quotes for the residual form;
Sage & Husa 1969, ref [20]). Paper 004 gives no equations of its own for the RAE-AUKF::

    v_j^- = z_j - h(x_j^-)   (innovation)          v_j^+ = z_j - h(x_j^+)   (residual)
    C_r = (1/m) sum_{j=k-m+1..k} v_j^+ (v_j^+)^T       R_{k+1} = C_r + H P_k^+ H^T
    C_v = (1/m) sum_{j=k-m+1..k} v_j^- (v_j^-)^T       Q_{k+1} = K_k C_v K_k^T

with full ``m_k x m_k`` covariance matrices by default (``r_form="diagonal"`` keeps the
diagonal of ``R_{k+1}``), ``H P^+ H^T = R - R S^-1 R`` as in :mod:`.ff_aukf` (exact for the
linear update; for the UKF the same identity of its ``P_zz``), and ``Q_{k+1}`` the IAE
approximation that drops ``P^+ - Phi P^+ Phi^T`` (steady state), as paper 004 eq 27 does.
``R_{k+1}`` is used by the next update, ``Q_{k+1}`` by the next predict. What the source
fixes and what is ours: ``docs/filters.md`` (RAE-AUKF).

The rule stores the last ``m`` innovation and residual vectors (ring buffers) and forms the
window covariances with one matrix product each (numpy, ``jit=False``) or in one numba
kernel (:mod:`._numba_rae`; same results to rounding, compiled at bind time with the same
options as ``ff-aukf``'s kernels). By default (``jit=None``) the faster of the two for the
size is used -- the kernel for the receiver's sizes, BLAS for large ``m^2 W`` -- so that
``ff-aukf`` is compared with the baseline at its best.

Positive definiteness (``pd_rule``): by default (``"floor"``) ``R_{k+1}`` gets
``r_floor_rel * diag(R^-)`` added (it is a sum of positive semi-definite terms; the tiny
additive floor makes it definite); ``"clip"`` instead raises ``R_{k+1}`` to at least that
floor in the Loewner order (``_linalg.floor_pd``: unchanged where it already exceeds it,
unit-aware across the pseudorange and rate blocks); ``"none"`` applies the equations bare (a
singular estimate fails the next update's Cholesky, handled by the filter's
``psd_fallback``). ``Q_{k+1}`` keeps the ``Q`` floor of every adaptive rule in all three.
Window ``m`` default 20 epochs (paper 004 gives no value; same default as ``ff-aukf`` so the
two compare at equal memory).

Change of the measurement count N -- the limitation paper 004 states
    "The smoothing method implies that the number of the measurements should have the same
    dimension. Once the number of measurements changes ... the method will fail to work."
    Vectors of different length cannot be averaged, so when ``m_k`` differs from the length
    stored in the window the rule **flushes both windows and restarts** (``n_restarts``
    counts this). Until the window has refilled with ``m`` epochs of the new size, the update
    uses the epoch's prior ``R^-`` (no R adaptation) and ``Q`` keeps its last adapted value
    (no Q adaptation): ``active`` is ``False``. If N changes more often than every ``m``
    epochs the rule never adapts and the filter is a plain UKF. (A change of *which*
    satellites are tracked at constant N cannot be seen without channel identities and is
    averaged across, as a Sage window would.)
"""

from __future__ import annotations

import numpy as np

from ...errors import FilterError
from .._linalg import floor_pd
from . import _numba_rae
from .base import AdaptiveRule, flag

__all__ = ["SageWindowAUKF"]


class SageWindowAUKF(AdaptiveRule):
    """RAE (residual-based ``R``) + IAE (innovation-based ``Q``) Sage-window adaptation.

    Parameters
    ----------
    window : int
        Window length ``m`` [epochs] (default 20).
    adapt_q, adapt_r : bool
        Enable the IAE Q- and RAE R-estimation (default both).
    r_floor_rel : float
        ``R`` floor relative to the prior diagonal, added (``pd_rule="floor"``) or as a
        Loewner lower bound (``"clip"``) (default 1e-6).
    r_form : {'full', 'diagonal'}
        Estimate the full ``R`` (the equation as written, default) or only its diagonal.
    pd_rule : {'floor', 'clip', 'none'}
        How ``R_{k+1}`` is kept positive definite (module docstring; default ``'floor'``).
    q_floor : float or array_like, optional
        See :class:`~sdr_di.filters.adaptive.base.AdaptiveRule`.
    jit : bool or None
        Form the window estimates in one compiled kernel (:mod:`._numba_rae`, ``True``; the
        same compiler options as ``ff-aukf``'s kernels) or with numpy/BLAS matrix products
        (``False``); same results to rounding. ``None`` (default) takes the faster for the
        size: the kernel while ``m^2 W <= 10000`` (the receiver's 14 measurements with a
        20-epoch window: ~10 us against ~15 us), BLAS above (e.g. 24 measurements, 64
        epochs: ~19 us against ~35 us).

    Attributes
    ----------
    R_hat : ndarray or None
        ``R`` estimate for the next epoch (``None`` while the window is not full).
    active : bool
        True when the window is full and the estimates are applied.
    n_restarts : int
        Number of window restarts caused by a change of the measurement count.
    """

    name = "rae-aukf"
    reference = "Sage-Husa window (paper 004 refs [20], [35]); baseline of paper 004 Table 6"

    def __init__(self, window: int = 20, adapt_q: bool = True, adapt_r: bool = True,
                 r_floor_rel: float = 1e-6, q_floor=None, jit: bool | None = None,
                 r_form: str = "full", pd_rule: str = "floor") -> None:
        super().__init__(q_floor)
        if r_form not in ("full", "diagonal"):
            raise FilterError(f"rae-aukf: r_form must be 'full' or 'diagonal', got {r_form!r}")
        if pd_rule not in ("floor", "clip", "none"):
            raise FilterError(f"rae-aukf: pd_rule must be 'floor', 'clip' or 'none', got "
                              f"{pd_rule!r}")
        self.r_form, self.pd_rule = r_form, pd_rule
        self.jit = None if jit is None else flag("rae-aukf", "jit", jit)
        if int(window) < 1:
            raise FilterError(f"rae-aukf: window must be >= 1, got {window}")
        self.window = int(window)
        self.adapt_q = flag("rae-aukf", "adapt_q", adapt_q)
        self.adapt_r = flag("rae-aukf", "adapt_r", adapt_r)
        self.r_floor_rel = float(r_floor_rel)
        self.R_hat: np.ndarray | None = None
        self.active = False
        self.n_restarts = 0
        self._m = -1
        self._count = 0
        self._ptr = 0
        self._V = np.zeros((self.window, 0))
        self._E = np.zeros((self.window, 0))

    def on_bind(self, filt) -> None:
        self._Qfloor = np.diag(self.q_floor)
        if self.jit is not False:
            _numba_rae.warm_up()                       # compile outside the timed hooks

    def before_update(self, filt, mp, z, R_prior):
        if self.adapt_r and self.active and z.size == self._m:
            return z, self.R_hat
        return z, R_prior

    def after_update(self, filt, z, R_prior) -> None:
        v, r = filt.y, filt.residual
        m = v.size
        if m != self._m:                   # vectors of another length: restart the window
            if self._m >= 0:
                self.n_restarts += 1
            self._m = m
            self._V = np.zeros((self.window, m))
            self._E = np.zeros((self.window, m))
            self._count = self._ptr = 0
            self.active = False
            self.R_hat = None
        p = self._ptr
        self._V[p] = v
        self._E[p] = r
        self._ptr = (p + 1) % self.window
        self._count += 1
        if self._count < self.window:
            return
        self.active = True
        use_kernel = self.jit if self.jit is not None else m * m * self.window <= 10000
        if use_kernel:
            Ru, S_inv = filt.R_used, filt.S_inv
            if not Ru.flags.c_contiguous:
                Ru = np.ascontiguousarray(Ru)
            R_hat, Q_hat = _numba_rae.rae_window_estimates(
                self._V, self._E, Ru, S_inv, filt.K, R_prior.diagonal(),
                self.r_floor_rel if self.pd_rule == "floor" else 0.0,
                self.q_floor, self.adapt_r, self.adapt_q)
            if self.adapt_r:
                self.R_hat = self._finish_R(R_hat, R_prior)
            if self.adapt_q:
                filt.Q = Q_hat
            self.n_adaptations += 1
            return
        inv_m = 1.0 / self.window
        if self.adapt_r:
            Ru = filt.R_used
            E = self._E
            C_r = (E.T @ E) * inv_m
            R_hat = C_r + (Ru - Ru @ filt.S_inv @ Ru)      # C_r + H P^+ H^T
            if self.pd_rule == "floor":
                R_hat.flat[::m + 1] += self.r_floor_rel * R_prior.diagonal()
            self.R_hat = self._finish_R(R_hat, R_prior)
        if self.adapt_q:
            V, K = self._V, filt.K
            C_v = (V.T @ V) * inv_m
            filt.Q = K @ C_v @ K.T + self._Qfloor
        self.n_adaptations += 1

    def _finish_R(self, R_hat: np.ndarray, R_prior: np.ndarray) -> np.ndarray:
        """``r_form`` and ``pd_rule="clip"`` on a window estimate (the floor is added by
        the caller, before: it is diagonal, so the order does not matter for it)."""
        if self.r_form == "diagonal":
            R_hat = np.diag(np.diagonal(R_hat))
        if self.pd_rule == "clip":
            R_hat = floor_pd(R_hat, self.r_floor_rel * R_prior.diagonal())
        return R_hat
