"""Noise-statistics estimators: ml-q-ukf (paper 000), sage-husa-ukf (paper 001) and
ml-r-ckf (paper 003) on synthetic problems."""

import numpy as np
import pytest
from filter_problems import cv2d

from sdr_di.filters import (
    FilterError,
    LinearMeasurementModel,
    LinearProcessModel,
    ProcessModel,
    make_filter,
)


def _run_cv2d(names, seed, *, epochs, sa, sr, n_meas, q_factor=1.0, r_factor=1.0,
              fixed_geometry=True, options=None, bias=None, P0=None):
    """2-D constant velocity at 1 Hz, ``n_meas`` projections of the position (pseudorange-like)
    with noise ``sr``; filters get ``q_factor * Q`` and ``r_factor * R``."""
    rng = np.random.default_rng(seed)
    F, Q = cv2d(1.0, sa)
    P0 = np.diag([10.0, 10.0, 1.0, 1.0]) if P0 is None else P0
    x = rng.multivariate_normal(np.zeros(4), P0)
    x0 = x + rng.multivariate_normal(np.zeros(4), P0)
    options = options or {}
    kfs = {n: make_filter(n, LinearProcessModel(F), None, x0, P0, q_factor * Q,
                          **options.get(n, {})) for n in names}
    err = {n: [] for n in names}
    ang = np.linspace(0, 2 * np.pi, n_meas, endpoint=False) + 0.3
    for _ in range(epochs):
        x = F @ x + rng.multivariate_normal(np.zeros(4), Q)
        if not fixed_geometry:
            ang = rng.uniform(0, 2 * np.pi, n_meas)
        H = np.zeros((n_meas, 4))
        H[:, 0], H[:, 1] = np.cos(ang), np.sin(ang)
        z = H @ x + sr * rng.normal(size=n_meas)
        if bias is not None:
            z = z + bias
        for n, kf in kfs.items():
            kf.predict()
            kf.update(z, np.full(n_meas, r_factor * sr ** 2), LinearMeasurementModel(H))
            err[n].append(kf.x - x)
    return kfs, {n: np.array(e) for n, e in err.items()}


def _rmse(e):
    return np.sqrt(np.mean(e ** 2))


# --------------------------------------------------------------------------- ml-q-ukf
def test_ml_q_ukf_beats_ukf_under_a_wrong_Q():
    """Paper 000's case: the filter's Q is 16x the true one; window 25, steady-state gate.
    Position and velocity RMSE after convergence (epochs 100-399, 3 seeds). With a Q 16x too
    small the position also improves, the velocity not (the diagonal eq-49 estimate cannot
    represent the correlated constant-velocity Q): only the position is checked there."""
    for q_factor in (16.0, 1 / 16):
        rm = []
        for seed in range(3):
            kfs, e = _run_cv2d(["ukf", "ml-q-ukf"], seed, epochs=400, sa=0.2, sr=1.0,
                               n_meas=3, q_factor=q_factor, fixed_geometry=False)
            rule = kfs["ml-q-ukf"].rule
            assert rule.window == 25 and rule.n_q_updates > 100
            rm.append([_rmse(e[n][100:, :2]) for n in ("ukf", "ml-q-ukf")]
                      + [_rmse(e[n][100:, 2:]) for n in ("ukf", "ml-q-ukf")])
        pos_ukf, pos_ml, vel_ukf, vel_ml = np.mean(rm, axis=0)
        assert pos_ml < 0.95 * pos_ukf, (q_factor, rm)
        if q_factor > 1:
            assert vel_ml < 0.8 * vel_ukf, (q_factor, rm)


def test_ml_q_steady_state_gate_and_mask():
    kfs, _ = _run_cv2d(["ml-q-ukf"], 0, epochs=60, sa=0.2, sr=1.0, n_meas=3,
                       options={"ml-q-ukf": {"mask": [False, False, True, True],
                                             "steady_test": "nis"}})
    kf = kfs["ml-q-ukf"]
    Q0 = kf.rule.Q_nominal
    np.testing.assert_array_equal(kf.Q[:2, :2], Q0[:2, :2])   # masked states keep Q0
    assert kf.Q[0, 2] == 0.0 and kf.Q[2, 2] != Q0[2, 2]
    with pytest.raises(FilterError, match="steady_test"):
        make_filter("ml-q-ukf", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                    np.eye(2), steady_test="3sigma")


# --------------------------------------------------------------------------- sage-husa
@pytest.mark.parametrize("r_factor", [0.25, 4.0])
def test_sage_husa_recovers_a_wrong_R(r_factor):
    """R^- 4x too small / too large, measurement noise dominating the prediction: the
    eq-33 estimate recovers the true R (its documented bias H P^- H^T is ~10 % here) and the
    estimation error is not worse than the UKF with the wrong R."""
    ratios, rm = [], []
    for seed in range(3):
        kfs, e = _run_cv2d(["ukf", "sage-husa-ukf"], seed, epochs=400, sa=0.02, sr=2.0,
                           n_meas=6, r_factor=r_factor,
                           options={"sage-husa-ukf": {"estimate": ("R",)}})
        ratios.append(np.diag(kfs["sage-husa-ukf"].rule.R_hat) / 4.0)
        rm.append([_rmse(e["ukf"][50:, :2]), _rmse(e["sage-husa-ukf"][50:, :2])])
    ratios = np.array(ratios)
    assert np.all((ratios > 0.8) & (ratios < 1.35)), ratios
    assert abs(ratios.mean() - 1.0) < 0.2
    rm = np.mean(rm, axis=0)
    assert rm[1] <= 1.01 * rm[0], rm


def test_sage_husa_recovers_a_measurement_bias_and_Q():
    """With a well-known, slowly varying state the bias r of eq 32 is observable: the
    estimate converges to it. Q (eq 31) of a random walk in steady state is unbiased."""
    bias = np.array([3.0, -2.0, 1.0, 0.5])
    P0 = np.diag([1e-4, 1e-4, 1e-6, 1e-6])
    kfs, _ = _run_cv2d(["sage-husa-ukf"], 4, epochs=300, sa=1e-4, sr=0.5, n_meas=4,
                       bias=bias, P0=P0, options={"sage-husa-ukf": {"estimate": ("r",)}})
    np.testing.assert_allclose(kfs["sage-husa-ukf"].rule.r_hat, bias, atol=0.25)

    # random walk x_k = x_k-1 + w (F = I), direct measurement: Q_hat -> Q
    rng = np.random.default_rng(5)
    q_true, r_true = 0.04, 0.01
    kf = make_filter("sage-husa-ukf", LinearProcessModel(np.eye(1)),
                     LinearMeasurementModel(np.eye(1)), [0.0], [[1.0]], [[16 * q_true]],
                     [[r_true]], estimate=("Q",))
    x = 0.0
    for _ in range(3000):
        x += np.sqrt(q_true) * rng.normal()
        kf.predict()
        kf.update([x + np.sqrt(r_true) * rng.normal()])
    assert abs(kf.Q[0, 0] / q_true - 1.0) < 0.15, kf.Q


def test_sage_husa_restarts_measurement_statistics_when_N_changes():
    pm = LinearProcessModel(np.eye(2))
    kf = make_filter("sage-husa-ukf", pm, None, np.zeros(2), np.eye(2), 0.01 * np.eye(2),
                     warmup=5)
    rng = np.random.default_rng(0)
    for k in range(40):
        m = 3 if k < 20 else 4
        H = rng.normal(size=(m, 2))
        kf.predict()
        kf.update(rng.normal(size=m), np.ones(m), LinearMeasurementModel(H))
        if k == 20:                                   # new size: prior R^- used again
            np.testing.assert_array_equal(kf.R_used, np.eye(4))
    assert kf.rule.n_restarts == 1 and kf.rule.R_hat.shape == (4, 4)
    assert kf.rule.r_hat.shape == (4,)
    assert not np.array_equal(kf.R_used, np.eye(4))   # adapting again after warm-up
    assert np.all(np.linalg.eigvalsh(kf.R_used) > 0)
    with pytest.raises(FilterError, match="estimate"):
        make_filter("sage-husa-ukf", pm, None, np.zeros(2), np.eye(2), np.eye(2),
                    estimate=("x",))


# --------------------------------------------------------------------------- ml-r-ckf
class _Ins2D(ProcessModel):
    """Loosely-coupled-like error model: [psi, dvE, dvN, dpE, dpN, baE, baN] (rad, m/s, m,
    m/s^2); the heading error rotates the specific force (nonlinear), improved Euler."""

    dim_x = 7

    def __init__(self):
        self.f_n = np.array([0.0, 2.0])

    def _xdot(self, X):
        c, s = np.cos(X[:, 0]), np.sin(X[:, 0])
        fE, fN = self.f_n
        xd = np.zeros_like(X)
        xd[:, 1] = (c - 1) * fE - s * fN + X[:, 5]
        xd[:, 2] = s * fE + (c - 1) * fN + X[:, 6]
        xd[:, 3], xd[:, 4] = X[:, 1], X[:, 2]
        return xd

    def f_batch(self, X, dt):
        k1 = self._xdot(X)
        return X + 0.5 * dt * (k1 + self._xdot(X + dt * k1))

    def f(self, x, dt):
        return self.f_batch(x[None, :], dt)[0]


def test_ml_r_ckf_tracks_a_16x_measurement_noise_window():
    """Paper 003 Table 1 style: velocity/position measurements (0.05 m/s, 5 m), the true R is
    16x larger during epochs 100-199 while the filters keep the nominal R. ML-R-CKF's mean
    estimate over the second half of the window is within 25 % of 16 R and its RMSE in the
    window is below the CKF's."""
    H = np.zeros((4, 7))
    H[0, 1] = H[1, 2] = H[2, 3] = H[3, 4] = 1.0
    R = np.diag([0.05 ** 2, 0.05 ** 2, 5.0 ** 2, 5.0 ** 2])
    q = np.array([np.radians(0.01), 0.02, 0.02, 0.0, 0.0, 1e-4, 1e-4])
    P0 = np.diag(np.array([np.radians(1.0), 0.3, 0.3, 5.0, 5.0, 1e-2, 1e-2]) ** 2)
    est, rm = [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        pm = _Ins2D()
        x = rng.multivariate_normal(np.zeros(7), P0)
        kfs = {n: make_filter(n, pm, LinearMeasurementModel(H), np.zeros(7), P0,
                              np.diag(q ** 2), R) for n in ("ckf", "ml-r-ckf")}
        err = {n: [] for n in kfs}
        r_hat = []
        for k in range(220):
            pm.f_n = np.array([2 * np.sin(0.05 * k), 2 * np.cos(0.03 * k)])
            x = pm.f(x, 1.0) + rng.normal(size=7) * q
            z = H @ x + rng.multivariate_normal(np.zeros(4), R * (16.0 if 100 <= k < 200
                                                                  else 1.0))
            for n, kf in kfs.items():
                kf.predict()
                kf.update(z)
                err[n].append(kf.x - x)
            r_hat.append(np.diag(kfs["ml-r-ckf"].R_used).copy())
        rule = kfs["ml-r-ckf"].rule
        assert rule.n_solves > 150 and rule.last_result is not None
        est.append(np.mean(r_hat[150:200], axis=0))
        e = {n: np.array(v)[100:200] for n, v in err.items()}
        rm.append([_rmse(e[n][:, 3:5]) for n in kfs] + [_rmse(e[n][:, 1:3]) for n in kfs])
    ratio = np.mean(est, axis=0) / (16.0 * np.diag(R))
    assert np.all(np.abs(ratio - 1.0) < 0.25), ratio
    pos_ckf, pos_ml, vel_ckf, vel_ml = np.mean(rm, axis=0)
    assert pos_ml < pos_ckf and vel_ml < vel_ckf, rm


def test_ml_r_ckf_restarts_when_N_changes_and_uses_prior_meanwhile():
    pm = LinearProcessModel(np.eye(2))
    kf = make_filter("ml-r-ckf", pm, None, np.zeros(2), np.eye(2), 0.01 * np.eye(2),
                     window=20, min_samples=5)
    rng = np.random.default_rng(1)
    for k in range(30):
        m = 4 if k < 15 else 6
        H = rng.normal(size=(m, 2))
        kf.predict()
        kf.update(rng.normal(size=m) * 2.0, np.ones(m), LinearMeasurementModel(H))
        if 15 <= k < 19:
            np.testing.assert_array_equal(kf.R_used, np.eye(6))
    assert kf.rule.n_restarts == 1 and kf.rule.r_hat.shape == (6,)
    assert np.all(kf.rule.r_hat > 0) and not np.allclose(kf.rule.r_hat, 1.0)
