"""Adaptive rules on synthetic problems: registry smoke test with a changing channel count,
ff-aukf (paper 004), rae-aukf (Sage window baseline), q-scaling (paper 002), timing hooks.

The deep/tight-like problem: 8 states (ENU position and velocity error, clock bias and drift)
at 10 Hz, ``N_k`` channels with random lines of sight, ``z = [drho_1..N, drho_dot_1..N]``
(pseudorange errors, sigma 2 m, then pseudorange-rate errors, sigma 0.1 m/s), the epoch's prior
``R^-`` passed to every update as the pre-filters would.
"""

import numpy as np
import pytest
from filter_problems import cv2d

from sdr_di.filters import (
    FILTER_NAMES,
    LinearMeasurementModel,
    LinearProcessModel,
    make_filter,
)
from sdr_di.filters.adaptive import forgetting_weights

DT = 0.1          # 10 Hz
SIG_RHO, SIG_RATE = 2.0, 0.1


def _cv_clock(dt, sa=0.5, sc=0.2):
    F = np.eye(8)
    F[0:3, 3:6] = dt * np.eye(3)
    F[6, 7] = dt
    q1 = np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    Q = np.zeros((8, 8))
    for ax in range(3):
        Q[np.ix_([ax, ax + 3], [ax, ax + 3])] = sa ** 2 * q1
    Q[np.ix_([6, 7], [6, 7])] = sc ** 2 * q1
    return F, Q


def _geometry(rng, N):
    az = rng.uniform(0, 2 * np.pi, N)
    el = rng.uniform(0.2, 1.4, N)
    u = np.column_stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)])
    H = np.zeros((2 * N, 8))
    H[:N, 0:3], H[:N, 6] = -u, 1.0
    H[N:, 3:6], H[N:, 7] = -u, 1.0
    return H


def _run_deep(name, seed, epochs=300, change_every=None, rho_factor=lambda k: 1.0,
              prior_factor=1.0, record=None, **options):
    """Run ``name`` on the deep-like problem; ``rho_factor(k)`` scales the true pseudorange
    noise variance, ``prior_factor`` the R^- given to the filter."""
    rng = np.random.default_rng(seed)
    F, Q = _cv_clock(DT)
    P0 = np.diag([25.0] * 3 + [1.0] * 3 + [25.0, 1.0])
    x = rng.multivariate_normal(np.zeros(8), P0)
    kf = make_filter(name, LinearProcessModel(F), None, np.zeros(8), P0, Q, dt=DT, **options)
    N = 7
    H = _geometry(rng, N)
    out = []
    for k in range(epochs):
        x = F @ x + rng.multivariate_normal(np.zeros(8), Q)
        if change_every and k % change_every == 0:
            N = int(rng.integers(4, 10))
            H = _geometry(rng, N)
        var = np.r_[np.full(N, SIG_RHO ** 2 * rho_factor(k)), np.full(N, SIG_RATE ** 2)]
        z = H @ x + np.sqrt(var) * rng.normal(size=2 * N)
        R_prior = prior_factor * np.r_[np.full(N, SIG_RHO ** 2), np.full(N, SIG_RATE ** 2)]
        kf.predict()
        kf.update(z, R_prior, LinearMeasurementModel(H))
        assert np.all(np.isfinite(kf.x)) and np.array_equal(kf.P, kf.P.T)
        if record is not None:
            out.append(record(kf, R_prior))
    return kf, out


# --------------------------------------------------------------------------- all filters
@pytest.mark.parametrize("name", FILTER_NAMES)
def test_every_filter_runs_with_changing_channel_count(name):
    kf, _ = _run_deep(name, seed=1, epochs=120, change_every=3)
    assert np.all(np.linalg.eigvalsh(kf.P) > 0)
    assert np.all(np.linalg.eigvalsh(kf.Q) >= 0)
    if kf.rule is not None:
        assert kf.rule.adaptation_time_s > 0.0
        t = kf.rule.adaptation_time_s
        kf.rule.reset_timer()
        assert kf.rule.adaptation_time_s == 0.0 and t < 5.0


# --------------------------------------------------------------------------- ff-aukf
def test_ff_aukf_forgetting_weights_eq31():
    mu = forgetting_weights(5, 0.95)
    expected = [(1 - 0.95) / (1 - 0.95 ** (j + 1)) for j in range(1, 6)]
    np.testing.assert_allclose(mu, expected, rtol=1e-14)
    assert np.all(np.diff(mu) < 0)                    # newest epoch weighs most


def test_ff_aukf_factors_follow_step_in_pseudorange_noise_with_changing_N():
    """10 Hz, N changes every 3 epochs; at t = 10 s the true pseudorange noise variance steps
    x16 while the prior R^- stays nominal: s1 must reach the new level within 2 s (20 epochs),
    s2 (rates, unchanged) must stay near 1."""
    step = 100

    def rec(kf, R_prior):
        return kf.rule.s.copy()

    runs = [np.array(_run_deep("ff-aukf", seed, epochs=step + 60, change_every=3,
                               rho_factor=lambda k: 16.0 if k >= step else 1.0,
                               record=rec)[1]) for seed in range(4)]
    s = np.mean(runs, axis=0)                         # (epochs, 2), Monte Carlo mean
    before = s[step - 50:step].mean(axis=0)
    assert 0.7 < before[0] < 1.3 and 0.7 < before[1] < 1.3, before
    two_s = s[step + 19]                              # 20 noisy epochs = 2 s at 10 Hz
    assert 0.75 * 16 < two_s[0] < 1.3 * 16, two_s
    assert s[step + 5, 0] > 4.0                       # already responding after 0.5 s
    after = s[step + 20:].mean(axis=0)
    assert 0.75 * 16 < after[0] < 1.3 * 16 and 0.7 < after[1] < 1.3, after


def test_ff_aukf_scales_a_wrong_prior_R_back():
    """Prior R^- 4x too large: R^+ = S_k R^- comes back to the true noise (R-adaptation only)."""
    def rec(kf, R_prior):
        return np.diag(kf.R_used) / (R_prior / 4.0)

    ratios = np.vstack([np.array(_run_deep("ff-aukf", seed, epochs=250, prior_factor=4.0,
                                           record=rec, adapt_q=False)[1])[100:].mean(axis=0)
                        for seed in range(3)])
    np.testing.assert_allclose(ratios.mean(axis=0), 1.0, atol=0.15)


def test_ff_aukf_q_is_diagonal_and_floored():
    kf, _ = _run_deep("ff-aukf", seed=2, epochs=80)
    Q = kf.Q
    assert np.count_nonzero(Q - np.diag(np.diagonal(Q))) == 0
    assert np.all(np.diagonal(Q) >= kf.rule.q_floor) and np.all(kf.rule.q_floor > 0)


def test_ff_aukf_rejects_odd_measurement_vector():
    from sdr_di.filters import FilterError
    kf = make_filter("ff-aukf", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                     np.eye(2))
    kf.predict()
    with pytest.raises(FilterError, match="cannot be split into 2 equal blocks"):
        kf.update(np.zeros(3), np.ones(3), LinearMeasurementModel(np.ones((3, 2))))


def test_ff_aukf_matches_a_literal_transcription_of_eq_27_to_39():
    """Q_{k+1} and s_{b,k+1} of the rule against paper 004 eq 27-31 and 37-39 written out with
    full matrices (Q_cur = K diag(v o v) K^T, H P+ H^T from the known linear H), N changing
    every 3 epochs, window 8 (so it wraps)."""
    W, d = 8, 0.95
    mu = forgetting_weights(W, d)
    hist = []

    def rec(kf, R_prior):
        H = kf.last_prediction.model.matrix
        hist.append({"K": kf.K.copy(), "v": kf.y.copy(), "r": kf.residual.copy(),
                     "rho": R_prior, "HPH": H @ kf.P @ H.T, "Q": kf.Q.copy(),
                     "s": kf.rule.s.copy(), "floor": kf.rule.q_floor})

    _run_deep("ff-aukf", 3, epochs=40, change_every=3, record=rec, window=W, d=d)
    for k, e in enumerate(hist):
        recent = hist[max(0, k - W + 1):k + 1][::-1]         # newest first: j = 1, 2, ...
        w = mu[:len(recent)]
        Q_cur = [h["K"] @ np.diag(h["v"] ** 2) @ h["K"].T for h in recent]     # eq 27-29
        Q_next = sum(wj * Qj for wj, Qj in zip(w, Q_cur)) / w.sum()            # eq 30
        np.testing.assert_allclose(e["Q"], np.diag(np.maximum(np.diag(Q_next), e["floor"])),
                                   rtol=1e-10, atol=1e-300)
        N = e["v"].size // 2
        for b in range(2):
            tr_c = N * sum(wj * np.sum(np.split(h["r"], 2)[b] ** 2) / (h["r"].size // 2)
                           for wj, h in zip(w, recent)) / w.sum()               # eq 39
            blk = slice(b * N, (b + 1) * N)
            s_next = (np.trace(e["HPH"][blk, blk]) + tr_c) / np.sum(e["rho"][blk])  # eq 38
            np.testing.assert_allclose(e["s"][b], s_next, rtol=1e-8)


@pytest.mark.parametrize("name", ["ff-aukf", "rae-aukf"])
@pytest.mark.parametrize("full_r", [False, True])
def test_compiled_and_numpy_rules_agree(name, full_r):
    """jit=True (numba kernels) and jit=False (numpy) give the same filter to rounding, with a
    diagonal or a full prior R^-, N constant then changing."""
    def run(jit):
        rng = np.random.default_rng(5)
        F, Q = _cv_clock(DT)
        P0 = np.diag([25.0] * 3 + [1.0] * 3 + [25.0, 1.0])
        x = rng.multivariate_normal(np.zeros(8), P0)
        kf = make_filter(name, LinearProcessModel(F), None, np.zeros(8), P0, Q, dt=DT,
                         window=10, jit=jit)
        out = []
        for k in range(90):
            N = 7 if k < 60 else int(rng.integers(4, 10))
            H = _geometry(rng, N)
            x = F @ x + rng.multivariate_normal(np.zeros(8), Q)
            R = np.diag(np.r_[np.full(N, SIG_RHO ** 2), np.full(N, SIG_RATE ** 2)])
            if full_r:
                R[:N, :N] += 0.3 * SIG_RHO ** 2 * (np.ones((N, N)) - np.eye(N))
            z = H @ x + rng.multivariate_normal(np.zeros(2 * N), R)
            kf.predict()
            kf.update(z, R, LinearMeasurementModel(H))
            out.append((kf.x, kf.P, kf.Q, kf.R_used))
        return out

    # summation order differs (loops vs BLAS); the rounding differences pass through the
    # adaptive feedback for 90 epochs (and K C K^T has cancelling off-diagonal terms), hence
    # 1e-7 of each matrix's scale rather than 1e-12
    for epoch_a, epoch_b in zip(run(True), run(False)):
        for a, b in zip(epoch_a, epoch_b):
            np.testing.assert_allclose(a, b, rtol=1e-7, atol=1e-7 * np.abs(b).max())


def test_adaptation_time_excludes_kernel_compilation():
    """The kernels are compiled when the rule is bound, so no compilation happens in the timed
    hooks (a new specialization there would add ~1 s to adaptation_time_s)."""
    from sdr_di.filters.adaptive import _numba_ff, _numba_rae
    kernels = (_numba_ff.scale_r, _numba_ff.ff_after_update, _numba_rae.rae_window_estimates)
    for name in ("ff-aukf", "rae-aukf"):
        make_filter(name, LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                    np.eye(2))
        before = [len(k.signatures) for k in kernels]
        kf, _ = _run_deep(name, seed=1, epochs=40, change_every=25, window=5)
        assert [len(k.signatures) for k in kernels] == before
        assert 0.0 < kf.rule.adaptation_time_s < 0.5
        assert kf.adaptation_time_s == kf.rule.adaptation_time_s
    assert make_filter("ukf", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                       np.eye(2)).adaptation_time_s == 0.0


# --------------------------------------------------------------------------- rae-aukf
def test_rae_aukf_constant_N_estimates_R():
    """Constant N: after the window fills, R_hat (residual-based) replaces the prior R^-,
    which is 4x too large, and matches the true noise."""
    def rec(kf, R_prior):
        return np.diag(kf.R_used) / (R_prior / 4.0)

    ratios = []
    for seed in range(3):
        kf, out = _run_deep("rae-aukf", seed, epochs=250, prior_factor=4.0, record=rec,
                            adapt_q=False)
        assert kf.rule.active and kf.rule.n_restarts == 0
        np.testing.assert_allclose(out[5], 4.0)       # window (20) not full yet: prior used
        ratios.append(np.array(out)[100:].mean(axis=0))
    r = np.mean(ratios, axis=0)
    assert abs(r[:7].mean() - 1.0) < 0.2 and abs(r[7:].mean() - 1.0) < 0.2, r


def test_rae_aukf_restarts_when_N_changes():
    """The documented limitation: a change of N flushes the Sage window; the prior R^- is used
    until `window` epochs of the new size are stored. With N changing every 3 epochs it never
    adapts."""
    def rec(kf, R_prior):
        return (kf.rule.active, np.array_equal(kf.R_used, np.diag(R_prior)), kf.rule.n_restarts)

    kf, out = _run_deep("rae-aukf", 0, epochs=120, change_every=3, record=rec, window=10)
    restarts = out[-1][2]
    assert restarts >= 20
    assert not any(a for a, _, _ in out) and all(p for _, p, _ in out)
    assert kf.rule.n_adaptations == 0

    kf, out = _run_deep("rae-aukf", 0, epochs=120, change_every=40, record=rec, window=10)
    active = [a for a, _, _ in out]
    # epochs 0-8 inactive; active from the 10th epoch; after each change at k = 40, 80
    # (when N really changed) inactive again for 9 epochs
    assert not any(active[:9]) and active[9] and active[39]
    assert kf.rule.n_restarts == out[-1][2] >= 1
    for k0 in (40, 80):
        if out[k0][2] > out[k0 - 1][2]:               # a restart happened at k0
            assert not any(active[k0:k0 + 9]) and active[k0 + 9]


# --------------------------------------------------------------------------- q-scaling


def _run_qscaling(name, seed, q_factor, epochs=600, change_every=None):
    """Process-noise dominated 2-D problem (1 Hz, sigma_a 1 m/s^2, 0.5 m measurements of the
    position along random directions), so the innovation trace is informative about Q."""
    rng = np.random.default_rng(seed)
    F, Q = cv2d(1.0, 1.0)
    P0 = np.diag([10.0, 10.0, 1.0, 1.0])
    x = rng.multivariate_normal(np.zeros(4), P0)
    kf = make_filter(name, LinearProcessModel(F), None, np.zeros(4), P0, q_factor * Q)
    alpha, scale = [], []
    N = 3
    for k in range(epochs):
        x = F @ x + rng.multivariate_normal(np.zeros(4), Q)
        if change_every and k % change_every == 0:
            N = int(rng.integers(2, 6))
        ang = rng.uniform(0, 2 * np.pi, N)
        H = np.zeros((N, 4))
        H[:, 0], H[:, 1] = np.cos(ang), np.sin(ang)
        kf.predict()
        kf.update(H @ x + 0.5 * rng.normal(size=N), np.full(N, 0.25),
                  LinearMeasurementModel(H))
        alpha.append(kf.rule.alpha)
        scale.append(kf.rule.scale)
    return kf, np.array(alpha), np.array(scale)


@pytest.mark.parametrize("name", ["q-scaling-ekf", "q-scaling-ukf"])
def test_q_scaling_settles_near_one_with_right_Q_and_grows_when_too_small(name):
    a_ok, s_ok, s_small = [], [], []
    for seed in range(3):
        kf, alpha, scale = _run_qscaling(name, seed, 1.0)
        assert np.isnan(alpha[62]) and not np.isnan(alpha[63])   # window of 64 first
        a_ok.append(np.mean(alpha[300:]))
        s_ok.append(np.median(scale[300:]))
        kf, alpha, scale = _run_qscaling(name, seed, 0.01)
        s_small.append(np.median(scale[300:]))
        np.testing.assert_allclose(kf.Q, kf.rule.scale * kf.rule.Q_nominal)
    assert 0.9 < np.mean(a_ok) < 1.15, a_ok
    assert 0.6 < np.mean(s_ok) < 1.6, s_ok
    assert min(s_small) > 30.0, s_small               # Q 100x too small -> scaled up ~100x


def test_q_scaling_keeps_adapting_when_N_changes():
    _, alpha, scale = _run_qscaling("q-scaling-ukf", 0, 1.0, change_every=3)
    assert 0.8 < np.nanmean(alpha[300:]) < 1.25 and 0.3 < np.median(scale[300:]) < 3.0


def _run_zero_position_q(seed, epochs=400, **options):
    """The deep-like problem with the receiver's process model structure: no process noise
    on position and clock bias (they integrate velocity and drift), white noise on the
    velocity and drift. Returns the filter and the position error RMS [m] after epoch 100."""
    rng = np.random.default_rng(seed)
    F, _ = _cv_clock(DT)
    Q = np.diag([0.0] * 3 + [0.05 ** 2 * DT] * 3 + [0.0, 0.02 ** 2 * DT])
    P0 = np.diag([25.0] * 3 + [1.0] * 3 + [25.0, 1.0])
    x = rng.multivariate_normal(np.zeros(8), P0)
    kf = make_filter("ff-aukf", LinearProcessModel(F), None, np.zeros(8), P0, Q, dt=DT,
                     **options)
    H = _geometry(rng, 7)
    R = np.r_[np.full(7, SIG_RHO ** 2), np.full(7, SIG_RATE ** 2)]
    err = []
    for k in range(epochs):
        x = F @ x + np.sqrt(np.diagonal(Q)) * rng.normal(size=8)
        z = H @ x + np.sqrt(R) * rng.normal(size=14)
        kf.predict()
        kf.update(z, R, LinearMeasurementModel(H))
        if k >= 100:
            err.append(kf.x[:3] - x[:3])
    return kf, float(np.sqrt(np.mean(np.sum(np.square(err), axis=1))))


def test_ff_aukf_q_states_nominal_keeps_unmodelled_states_out_of_q():
    """Eq 27's innovation-based Q (no P^+ - Phi P^+ Phi^T term) puts noise on states whose
    nominal Q is zero (position integrates velocity): the filter then follows the noisy
    pseudoranges. ``q_states='nominal'`` adapts only states with a positive nominal Q: their
    zero entries stay zero and the position error is markedly lower (docs/filters.md)."""
    rms_all, rms_nom = [], []
    for seed in range(3):
        kf_a, e_a = _run_zero_position_q(seed)
        kf_n, e_n = _run_zero_position_q(seed, q_states="nominal")
        assert np.all(np.diagonal(kf_a.Q)[[0, 1, 2, 6]] > 0)
        assert np.all(np.diagonal(kf_n.Q)[[0, 1, 2, 6]] == 0)
        assert np.all(np.diagonal(kf_n.Q)[[3, 4, 5, 7]] >= kf_n.rule.q_floor[[3, 4, 5, 7]])
        rms_all.append(e_a)
        rms_nom.append(e_n)
    assert np.mean(rms_nom) < 0.7 * np.mean(rms_all), (rms_nom, rms_all)
    with pytest.raises(Exception, match="q_states"):
        make_filter("ff-aukf", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                    np.eye(2), q_states="some")
