"""Improved AUKF of paper 004 (Sun et al. 2020), eq 26-39 / Table 2: ``ff-aukf``.

Q-adaptation (eq 26-31)
    innovation ``v_k^- = z_k - z_k^-`` (eq 26); current estimate
    ``Q_cur,k = K_k diag(v^- o v^-) K_k^T`` (eq 27-29, diagonal innovation covariance);
    only its diagonal ``(K o K)(v o v)`` is kept and smoothed (the paper smooths "the diagonal
    elements of Q whose dimension is constant")::

        Q_{k+1} = sum_j mu_j Q_cur,k-j+1 / sum_j mu_j,   mu_j = (1 - d) / (1 - d^(j+1))   (30-31)

    ``j = 1..m`` (``j = 1`` newest), forgetting constant ``d`` (default 0.95, paper value) and
    window ``m`` (paper: not given; default 20 epochs = 2 s at 10 Hz, 0.4 s at the deep
    receiver's 50 Hz). The adapted ``Q`` is diagonal, each element clipped to the ``Q`` floor.

    Option ``q_states="nominal"`` (ours, not the paper's): adapt only the states whose
    nominal ``Q0`` diagonal is positive and keep ``Q0``'s value (zero) on the others. Eq 27
    is the innovation-based estimator without its ``P^+_k - Phi P^+_{k-1} Phi^T`` term, so
    on average it returns ``Phi P^+ Phi^T - P^+ + Q``, positive wherever ``Phi`` couples
    states: position, which integrates velocity and has no process noise of its own in the
    INS error model, receives a random walk and the filter follows the pseudorange noise.
    Measured on the deep receiver (2.5 MHz, 40 dB-Hz, 15 s of vector loop): position error
    std 0.22/0.44/0.36 m ENU with the paper's rule, 0.03/0.05/0.06 m with ``"nominal"``
    (EKF: 0.03/0.04/0.06 m).

R-adaptation (eq 32-39)
    residual ``v_k^+ = z_k - h(x_k^+)`` (eq 32); the measurement vector is split into
    ``n_blocks`` equal contiguous blocks (default 2: pseudorange ``1:N``, pseudorange rate
    ``N+1:2N``; eq 34-35), each scaled by its own factor ``s_b`` (``R^+ = S_k R^-``, eq 36).
    The smoothed block trace of the residual covariance is (eq 39)::

        tr(C_v+)_b = N_k * sum_j mu_j (v_j^+)_b^T (v_j^+)_b / N_j  /  sum_j mu_j

    and the factor for the next epoch (eq 37-38)::

        s_b,k+1 = [ tr(H P^+ H^T)_b + tr(C_v+)_b ] / tr(R^-_b,k)

    with ``s_b,1 = 1``. (Eq 38 prints ``tr(R_rho)`` in both denominators and eq 36
    ``s_2 R_rho``: typos -- the rate factor is referred to the rate block ``R_rho_dot``.)
    ``H P^+ H^T`` is obtained without ``H`` as ``R - R S^-1 R`` (exact for a linear
    measurement model; the statistical linearization for the UKF). ``S_k R^-`` is applied as
    ``sqrt(S) R^- sqrt(S)`` so it stays symmetric if a non-diagonal ``R^-`` is passed (equal
    to ``S R^-`` for the diagonal ``R^-`` of eq 34). Factors are bounded to ``s_bounds``.

Change of the measurement count N
    Robust, as the paper designs it: the window holds, per epoch, the ``n`` diagonal
    elements of ``Q_cur`` (state-sized, independent of N) and one *per-channel* residual power
    per block (``v^T v / N_j``); eq 39 rescales by the current ``N_k``. The prior ``R^-`` of
    the epoch (any size ``2 N_k``) is scaled by the current factors. Nothing is reset.

Storage per epoch: ``n + n_blocks`` numbers (vs. two ``m``-vectors for the Sage window of
:mod:`.rae_aukf`, which also forms full ``m x m`` and ``n x n`` products). Work per epoch:
``O(n m)`` for ``(K o K)(v o v)``, ``O(W (n + n_blocks))`` for the weighted window sums
(eq 30 and 39 share one pass over the ring; the weights depend on the age, so the sums are
re-formed each epoch), ``O(m)`` for the block traces (``R^-`` diagonal as in eq 34; a full
``R^-`` costs ``O(m^3)``) -- against ``O(W m^2 + n m^2 + n^2 m + m^3)`` for the Sage window.

Implementation: each hook is one numba kernel (:mod:`._numba_ff`; ``jit=True``, default),
compiled when the rule is bound, so the timed hooks never compile. Written as numpy
expressions (``jit=False``, kept as the tested reference) the after-update hook is about
twenty small array calls whose fixed cost (~0.5 us each) exceeds the arithmetic at the
receiver's size (``n = 17``, ``m = 14``, ``W = 20``), and its adaptation time is then no lower
than the Sage window's (a dozen calls); with both rules compiled alike (``rae-aukf`` has the
same option) the timing compares the arithmetic (``scripts/bench_filters.py``).
"""

from __future__ import annotations

import numpy as np

from ...errors import FilterError
from . import _numba_ff
from .base import AdaptiveRule, flag

__all__ = ["ForgettingFactorAUKF", "forgetting_weights"]


def forgetting_weights(m: int, d: float) -> np.ndarray:
    """Paper 004 eq 31: ``mu_j = (1 - d) / (1 - d^(j+1))``, ``j = 1..m`` (newest first)."""
    j = np.arange(1, m + 1, dtype=float)
    return (1.0 - d) / (1.0 - d ** (j + 1.0))


class ForgettingFactorAUKF(AdaptiveRule):
    """Forgetting-factor Q adaptation and trace-based multi-factor R adaptation (paper 004).

    Parameters
    ----------
    window : int
        Smoothing window ``m`` [epochs] (default 20).
    d : float
        Forgetting constant, ``0.90 < d < 0.99`` in the paper (default 0.95).
    n_blocks : int
        Number of equal measurement blocks with their own factor (default 2:
        pseudorange / pseudorange rate).
    adapt_q, adapt_r : bool
        Enable the Q- and R-adaptation (default both).
    s_bounds : (float, float)
        Bounds of the R scale factors (default (1e-3, 1e6)).
    q_floor : float or array_like, optional
        See :class:`~sdr_di.filters.adaptive.base.AdaptiveRule`.
    jit : bool
        Run each hook as one compiled kernel (:mod:`._numba_ff`, default) or as plain numpy
        expressions (the reference the kernels are tested against; same results to rounding).
    q_states : str
        ``"all"`` (paper 004, default): every diagonal element of ``Q`` adapted;
        ``"nominal"``: only those whose nominal ``Q0`` element is positive (module notes).

    Attributes
    ----------
    s : (n_blocks,) ndarray
        Factors ``s_b`` that will scale the next epoch's ``R^-``.
    s_applied : (n_blocks,) ndarray
        Factors used in the last update.
    """

    name = "ff-aukf"
    reference = "Sun et al., IEEE Access 2020 (paper 004), eq 26-39, Table 2"

    def __init__(self, window: int = 20, d: float = 0.95, n_blocks: int = 2,
                 adapt_q: bool = True, adapt_r: bool = True,
                 s_bounds: tuple[float, float] = (1e-3, 1e6), q_floor=None,
                 jit: bool = True, q_states: str = "all") -> None:
        super().__init__(q_floor)
        if q_states not in ("all", "nominal"):
            raise FilterError(f"ff-aukf: q_states must be 'all' or 'nominal', got {q_states!r}")
        self.q_states = q_states
        self.jit = flag("ff-aukf", "jit", jit)
        if int(window) < 1:
            raise FilterError(f"ff-aukf: window must be >= 1, got {window}")
        if not 0.0 < d < 1.0:
            raise FilterError(f"ff-aukf: forgetting constant d must be in (0, 1), got {d}")
        if int(n_blocks) < 1:
            raise FilterError(f"ff-aukf: n_blocks must be >= 1, got {n_blocks}")
        self.window, self.d, self.n_blocks = int(window), float(d), int(n_blocks)
        self.adapt_q = flag("ff-aukf", "adapt_q", adapt_q)
        self.adapt_r = flag("ff-aukf", "adapt_r", adapt_r)
        self.s_bounds = (float(s_bounds[0]), float(s_bounds[1]))
        self.mu = forgetting_weights(self.window, self.d)
        # weight of ring slot j when the newest sample sits in slot p: mu[(p - j) mod m]
        m = self.window
        age = (np.arange(m)[:, None] - np.arange(m)[None, :]) % m
        self._wtab = self.mu[age]
        self._wcum = np.cumsum(self.mu)
        self.s = np.ones(self.n_blocks)
        self.s_applied = np.ones(self.n_blocks)

    def on_bind(self, filt) -> None:
        n = filt.x.size
        self._n = n
        self._buf = np.zeros((self.window, n + self.n_blocks))
        self._ptr = -1
        self._count = 0
        self._wnorm = self._wtab
        self._diag_r = True
        self._per_m: dict[int, tuple] = {}
        q0 = np.diag(filt.Q).copy()
        self._fixed = (np.flatnonzero(q0 <= 0.0) * (n + 1) if self.q_states == "nominal"
                       else np.zeros(0, np.int64))
        self._fixed_q = q0[q0 <= 0.0] if self.q_states == "nominal" else q0[:0]
        if self.jit:
            _numba_ff.warm_up()                        # compile outside the timed hooks

    def before_update(self, filt, mp, z, R_prior):
        m = z.size
        if m % self.n_blocks:
            raise FilterError(f"{filt.name}: measurement vector of length {m} cannot be "
                              f"split into {self.n_blocks} equal blocks (pseudorange / rate)")
        self.s_applied = self.s
        if self.jit and not R_prior.flags.c_contiguous:
            R_prior = np.ascontiguousarray(R_prior)    # the kernels are compiled for C order
        if not self.adapt_r:
            return z, R_prior
        if self.jit:
            # R^+ = S_k R^- (eq 35-36); notes whether R^- is diagonal (eq 34)
            R_used, self._diag_r = _numba_ff.scale_r(R_prior, self.s, self.n_blocks)
            return z, R_used
        e2 = self.s.take(self._blocks(m)[0])           # diagonal of S_k (eq 35)
        self._diag_r = np.count_nonzero(R_prior) <= m
        if self._diag_r:                               # paper eq 34: diagonal R^-
            return z, R_prior * e2                     # = S_k R^- (eq 36)
        e = np.sqrt(e2)                                # sqrt(S) R^- sqrt(S) for a full R^-
        return z, R_prior * np.outer(e, e)

    def after_update(self, filt, z, R_prior) -> None:
        p = self._ptr + 1
        if p == self.window:
            p = 0
        self._ptr = p
        if self._count < self.window:                  # eq 30 normalization while filling
            self._count += 1
            self._wnorm = self._wtab / self._wcum[self._count - 1]
        if self.jit:
            Q, s = _numba_ff.ff_after_update(
                filt.K, filt.y, filt.residual, filt.R_used, filt.S_inv, R_prior.diagonal(),
                self._diag_r or not self.adapt_r, self._buf, p, self._wnorm[p],
                self.n_blocks, self.q_floor, self.adapt_q, self.adapt_r, self.s_applied,
                self.s_bounds[0], self.s_bounds[1])
            if self.adapt_q:
                if self._fixed.size:
                    Q.ravel()[self._fixed] = self._fixed_q
                filt.Q = Q
            self.s = s
        else:
            self._after_update_numpy(filt, R_prior, p)
        self.n_adaptations += 1

    # -- plain numpy version (jit=False) -------------------------------------------------
    def _blocks(self, m: int) -> tuple:
        """Per measurement size ``m``: block index of each element, block-mean matrix, work
        arrays (built once per size and cached)."""
        got = self._per_m.get(m)
        if got is None:
            nb = self.n_blocks
            N = m // nb
            idx = np.repeat(np.arange(nb), N)
            B = np.zeros((m, nb))
            B[np.arange(m), idx] = 1.0 / N               # per-channel block means
            got = self._per_m[m] = (idx, B, np.empty((3, m)), np.empty((3, nb)))
        return got

    def _after_update_numpy(self, filt, R_prior, p: int) -> None:
        n = self._n
        v = filt.y
        _, B, wk, sums = self._blocks(v.size)
        row = self._buf[p]
        K = filt.K
        np.dot(K * K, v * v, out=row[:n])              # diag(K diag(v o v) K^T), eq 27-29
        r = filt.residual
        np.multiply(r, r, out=wk[0])                   # residual powers (eq 39 summands)
        if self.adapt_r:
            Ru = filt.R_used
            ru = Ru.diagonal()
            wk[1] = R_prior.diagonal()                 # -> tr(R^-_b), eq 38 denominators
            if self._diag_r:                           # diag(R S^-1 R), R = S_k R^- diagonal
                np.multiply(ru, ru, out=wk[2])
                wk[2] *= filt.S_inv.diagonal()
            else:
                np.sum((Ru @ filt.S_inv) * Ru, axis=1, out=wk[2])
            np.subtract(ru, wk[2], out=wk[2])          # diag(H P+ H^T) = diag(R - R S^-1 R)
        np.dot(wk, B, out=sums)                        # per-channel block means, (3, n_blocks)
        row[n:] = sums[0]                              # (v_j^+)^T v_j^+ / N_j per block
        avg = self._wnorm[p] @ self._buf               # eq 30 and eq 39 (normalized sums)
        if self.adapt_q:
            Q = np.zeros((n, n))
            np.maximum(avg[:n], self.q_floor, out=Q.ravel()[::n + 1])
            if self._fixed.size:
                Q.ravel()[self._fixed] = self._fixed_q
            filt.Q = Q
        if self.adapt_r:
            # per block, divided by N_k (eq 37-39):
            #   s_b,k+1 = [tr(H P+ H^T)_b / N_k + tr(C)_b / N_k] / [tr(R^-_b) / N_k]
            s = sums[2] + avg[n:]
            s /= sums[1]
            lo, hi = self.s_bounds
            np.maximum(s, lo, out=s)
            np.minimum(s, hi, out=s)
            self.s = s
