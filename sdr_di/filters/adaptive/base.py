"""Base class of the pluggable adaptive rules and the shared noise floors.

A rule is attached to a core filter (``filter.attach_rule(rule)``, done by
:func:`~sdr_di.filters.make_filter`) and is called at three points of every cycle:

``after_predict(filt)``
    after the time update (e.g. Sage-Husa adds the process-noise mean ``q``);
``before_update(filt, mp, z, R_prior) -> (z_eff, R_used)``
    after the measurement prediction ``mp`` (``z^-``, ``P_zz``, ``P_xz``) and before the
    correction; returns the measurement and the ``R`` the correction must use (``R_prior`` is
    the epoch's ``R`` given to ``update``, e.g. from the pre-filters: paper 004 eq 34);
``after_update(filt, z_eff, R_prior)``
    after the correction, with ``filt.y``, ``filt.S``, ``filt.S_inv``, ``filt.K``,
    ``filt.residual``, ``filt.x_prior/P_prior/x_post/P_post`` and ``filt.Q_used`` available;
    typically sets ``filt.Q`` for the next predict and prepares the next ``R``.

A rule overrides only the hooks it needs; the filter calls only those. Every call of an
overridden hook is timed with :func:`time.perf_counter` around the hook body only, summed in
:attr:`AdaptiveRule.adaptation_time_s` (the adaptation-time figure of paper 004, section IV.B),
reached from a filter as ``filt.rule.adaptation_time_s`` [s] (cumulative since construction
or :meth:`AdaptiveRule.reset_timer`). Rules with compiled kernels compile them when bound,
so the timer never includes compilation.

Noise floors (positive definiteness)
------------------------------------
Adapted covariances are kept positive definite by floors relative to the nominal values, so
the floors carry the right units per state/measurement:

* ``Q`` floor (per state ``i``): ``q_floor_rel * Q0_ii`` where ``Q0_ii > 0``, else
  ``1e-12 * P0_ii`` (states with no nominal process noise, e.g. random-constant biases);
  ``q_floor_rel = 1e-6`` by default. Diagonal estimates are clipped to the floor;
  full-matrix estimates are raised to ``>= diag(floor)`` in the Loewner order
  (:func:`~sdr_di.filters._linalg.floor_pd`) or get the floor added where noted.
* ``R`` floor (per measurement): ``r_floor_rel * R_prior_ii`` of the epoch's prior ``R``
  (``r_floor_rel = 1e-6``); scale factors are bounded (rule-specific ``*_bounds``).
"""

from __future__ import annotations

import time

import numpy as np

from ...errors import FilterError

__all__ = ["AdaptiveRule", "default_q_floor", "flag"]


def flag(who: str, name: str, value) -> bool:
    """A rule's on/off option: a bool, or ``"true"``/``"false"``/``1``/``0`` as a filter entry
    (``"ff-aukf:adapt_q=false"``) gives it. ``bool("false")`` would be ``True``: anything else
    raises :class:`~sdr_di.errors.FilterError`."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    text = str(value).strip().lower()
    if text in ("true", "1"):
        return True
    if text in ("false", "0"):
        return False
    raise FilterError(f"{who}: {name} must be true or false, got {value!r}")


def default_q_floor(Q0: np.ndarray, P0: np.ndarray, q_floor_rel: float = 1e-6) -> np.ndarray:
    """Per-state floor of an adapted ``Q``: ``q_floor_rel * Q0_ii`` or ``1e-12 * P0_ii``."""
    q = np.diagonal(Q0).astype(float)
    p = np.diagonal(P0).astype(float)
    return np.where(q > 0.0, q_floor_rel * q, 1e-12 * p)


class AdaptiveRule:
    """Base of every adaptive rule (see the module docstring for the hook protocol).

    Parameters
    ----------
    q_floor : float or (n,) array_like, optional
        Absolute per-state floor of the adapted ``Q`` (variance units of each state); default
        :func:`default_q_floor`.

    Attributes
    ----------
    adaptation_time_s : float
        Total wall time [s] spent in the rule's hooks.
    n_adaptations : int
        Number of cycles in which the rule changed ``Q`` or ``R``.
    filter : KalmanFilterBase
        The filter the rule is bound to.
    """

    name = "adaptive rule"
    reference = ""

    def __init__(self, q_floor=None) -> None:
        self.adaptation_time_s = 0.0
        self.n_adaptations = 0
        self.filter = None
        self._q_floor_opt = q_floor
        #: Per-state floor of an adapted ``Q`` (n,), set by :meth:`bind`.
        self.q_floor: np.ndarray = np.empty(0)
        cls = type(self)
        self._has_after_predict = cls.after_predict is not AdaptiveRule.after_predict
        self._has_before_update = cls.before_update is not AdaptiveRule.before_update
        self._has_after_update = cls.after_update is not AdaptiveRule.after_update

    # -- binding -------------------------------------------------------------------------
    def bind(self, filt) -> None:
        """Called once when attached: capture nominal ``Q0``, floors, dimensions."""
        self.filter = filt
        n = filt.x.size
        if self._q_floor_opt is None:
            self.q_floor = default_q_floor(filt.Q, filt.P0)
        else:
            qf = np.broadcast_to(np.asarray(self._q_floor_opt, dtype=float), (n,)).copy()
            if np.any(~np.isfinite(qf)) or np.any(qf <= 0):
                raise FilterError(f"{filt.name}: q_floor must be positive and finite")
            self.q_floor = qf
        self.on_bind(filt)

    def on_bind(self, filt) -> None:
        """Rule-specific initialisation (override)."""

    # -- hooks (override the ones needed) ------------------------------------------------
    def after_predict(self, filt) -> None:
        """Hook after the time update."""

    def before_update(self, filt, mp, z: np.ndarray, R_prior: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        """Hook before the correction; returns ``(z_eff, R_used)``."""
        return z, R_prior

    def after_update(self, filt, z: np.ndarray, R_prior: np.ndarray) -> None:
        """Hook after the correction."""

    # -- timed dispatch (called by the filter) -------------------------------------------
    def _timed_after_predict(self, filt) -> None:
        t0 = time.perf_counter()
        self.after_predict(filt)
        self.adaptation_time_s += time.perf_counter() - t0

    def _timed_before_update(self, filt, mp, z, R_prior):
        t0 = time.perf_counter()
        out = self.before_update(filt, mp, z, R_prior)
        self.adaptation_time_s += time.perf_counter() - t0
        return out

    def _timed_after_update(self, filt, z, R_prior) -> None:
        t0 = time.perf_counter()
        self.after_update(filt, z, R_prior)
        self.adaptation_time_s += time.perf_counter() - t0

    def reset_timer(self) -> None:
        """Zero :attr:`adaptation_time_s` (e.g. after a warm-up)."""
        self.adaptation_time_s = 0.0

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name}>"
