"""Nonlinear 17-state error model (paper 004 eq 1-5) against the difference of two INS runs."""

import numpy as np
import pytest

from sdr_di.filters import make_filter
from sdr_di.ins import StrapdownINS
from sdr_di.ins.error_model import (
    JACOBIAN_STEPS,
    ClockModel,
    InsErrorModel,
    NavState,
    dcm_to_rotvec,
    linear_error_matrix,
    process_noise,
    rotvec_to_dcm,
)
from sdr_di.scenario import DEFAULT_SCENARIO, load_scenario
from sdr_di.sim.generate import simulate_truth


@pytest.fixture(scope="module")
def truth():
    return simulate_truth(load_scenario(DEFAULT_SCENARIO).with_overrides(duration_s=20.0))


def _run(tr, x0, T=20.0, step=1.0, linear=False):
    """Perturbed INS vs truth; error model propagated in parallel. Returns [(model, actual)]."""
    phi0, dv0, dp0, eps, nab = x0[0:3], x0[3:6], x0[6:9], x0[9:12], x0[12:15]
    ins = StrapdownINS(tr.llh[0] + dp0, tr.v_n[0] + dv0,
                       C_b_n=rotvec_to_dcm(-phi0) @ tr.C_b_n[0])
    ins.set_previous_increments(tr.f_b[0] + nab, tr.w_ib_b[0] + eps, tr.dt)
    model = InsErrorModel()
    x = np.array(x0, float)
    n = round(step * tr.rate_hz)
    k, out = 0, []
    while k + n < len(tr.t) and tr.t[k + n] <= T + 1e-9:
        nav0 = NavState.from_ins(ins)
        fs, ws = tr.f_b[k + 1:k + n + 1] + nab, tr.w_ib_b[k + 1:k + n + 1] + eps
        for j in range(n):
            ins.step(fs[j], ws[j], tr.dt)
        k += n
        nav1 = NavState.from_ins(ins)
        model.set_interval(nav0, nav1, fs.mean(0), ws.mean(0))
        if linear:
            F0 = linear_error_matrix(nav0, fs.mean(0))
            F1 = linear_error_matrix(nav1, fs.mean(0))
            x = x + 0.5 * step * (F0 @ x + F1 @ (x + step * F0 @ x))
        else:
            x = model.f(x, step)
        act = np.zeros(17)
        act[0:3] = dcm_to_rotvec(tr.C_b_n[k] @ ins.C_b_n.T)
        act[3:6] = ins.v_n - tr.v_n[k]
        act[6:9] = ins.llh - tr.llh[k]
        act[9:15] = x0[9:15]
        out.append((x.copy(), act))
    return out


def test_small_errors_first_order(truth):
    x0 = np.zeros(17)
    x0[0:3] = [1e-3, -1e-3, 2e-3]
    x0[3:6] = [0.1, -0.1, 0.05]
    x0[6:9] = [1e-7, -1e-7, 2.0]
    x0[9:12] = np.radians(8.0) / 3600.0
    x0[12:15] = 4e-3 * 9.80665
    for x, act in _run(truth, x0):
        # second-order residuals: attitude << 1e-3 of the error, velocity mm/s, position cm
        assert np.max(np.abs(x[0:3] - act[0:3])) < 2e-6
        assert np.max(np.abs(x[3:6] - act[3:6])) < 3e-3
        assert np.max(np.abs(x[6:8] - act[6:8])) * 6.4e6 < 0.05
        assert abs(x[8] - act[8]) < 0.05
    # the errors did grow (the comparison is not trivial)
    assert np.linalg.norm(act[3:6] - x0[3:6]) > 0.1


def test_large_yaw_misalignment_nonlinear_beats_linear(truth):
    x0 = np.zeros(17)
    x0[2] = np.radians(10.0)
    nl = _run(truth, x0)
    lin = _run(truth, x0, linear=True)
    err_nl = max(np.linalg.norm(x[3:6] - a[3:6]) for x, a in nl)
    err_lin = max(np.linalg.norm(x[3:6] - a[3:6]) for x, a in lin)
    vmax = max(np.linalg.norm(a[3:6]) for _, a in nl)
    assert vmax > 1.0                       # a 10 deg yaw error gives m/s velocity errors
    assert err_nl < 0.02 * vmax             # nonlinear model tracks it within 2 %
    assert err_lin > 5 * err_nl             # the small-angle model does not
    att_nl = max(np.linalg.norm(x[0:3] - a[0:3]) for x, a in nl)
    assert att_nl < np.radians(0.01)


def test_jacobian_matches_analytic_linear_model(truth):
    k = 4000
    nav = NavState(truth.llh[k], truth.v_n[k], truth.C_b_n[k])
    f = truth.f_b[k]
    model = InsErrorModel()
    model.set_interval(nav, nav, f, truth.w_ib_b[k])
    dt = 0.01
    F = model.F(np.zeros(17), dt)
    A = linear_error_matrix(nav, f)
    F_ref = np.eye(17) + dt * A + 0.5 * dt * dt * A @ A      # improved Euler of xdot = A x
    scale = np.maximum(np.abs(F_ref), 1e-12)
    big = np.abs(F_ref) > 1e-9
    rel = np.abs(F - F_ref)[big] / scale[big]
    assert np.max(rel) < 1e-2
    assert np.max(np.abs(F - F_ref)[~big]) < 1e-9


def test_jacobian_vs_finer_numerical_at_large_error(truth):
    k = 3000
    nav0 = NavState(truth.llh[k], truth.v_n[k], truth.C_b_n[k])
    nav1 = NavState(truth.llh[k + 200], truth.v_n[k + 200], truth.C_b_n[k + 200])
    model = InsErrorModel()
    model.set_interval(nav0, nav1, truth.f_b[k:k + 200].mean(0), truth.w_ib_b[k:k + 200].mean(0))
    x = np.zeros(17)
    x[0:3] = [0.02, -0.01, np.radians(20)]
    x[3:6] = [0.5, -0.3, 0.2]
    x[6:9] = [2e-6, -1e-6, 10.0]
    F = model.F(x, 1.0)
    F2 = model.F_numerical(x, 1.0, scale=0.1)
    col = np.max(np.abs(F2), axis=0)                          # per-state scale
    assert np.all(np.abs(F - F2) <= 1e-5 * col + 1e-12)
    # large-angle Jacobian differs from the small-angle one
    F0 = model.F(np.zeros(17), 1.0)
    assert np.max(np.abs(F[3:6, 0:3] - F0[3:6, 0:3])) > 1e-2


def test_batch_equals_single_and_zero_is_fixed_point(truth):
    model = InsErrorModel()
    nav = NavState(truth.llh[100], truth.v_n[100], truth.C_b_n[100])
    model.set_interval(nav, nav, truth.f_b[100], truth.w_ib_b[100])
    rng = np.random.default_rng(1)
    X = rng.standard_normal((5, 17)) * np.r_[[1e-2] * 3, [1] * 3, [1e-6] * 2, 5, [1e-5] * 3,
                                             [1e-2] * 3, 10, 1]
    Y = model.f_batch(X, 1.0)
    for i in range(5):
        assert np.allclose(Y[i], model.f(X[i], 1.0), rtol=1e-12, atol=1e-15)
    assert np.allclose(model.f(np.zeros(17), 1.0), 0.0, atol=1e-15)
    # clock eq 4: bias integrates drift
    x = np.zeros(17)
    x[16] = 2.0
    y = model.f(x, 1.0)
    assert y[15] == pytest.approx(2.0, rel=1e-3)
    assert y[16] == pytest.approx(2.0 * (1 - 1 / 3600.0), rel=1e-6)


def test_f_and_F_is_f_and_F_bit_for_bit(truth):
    """The EKF's one-batch time update (``f_and_F``: 2 n + 1 rows) gives exactly the
    ``f`` of a one-row batch and the ``F`` of the 2 n-row one, at the zero state the
    closed loop predicts from and at large errors, with the start and end states apart."""
    model = InsErrorModel()
    rng = np.random.default_rng(7)
    scale = np.r_[[1e-2] * 3, [1] * 3, [1e-6] * 2, 5, [1e-5] * 3, [1e-2] * 3, 10, 1]
    for i in range(0, 3000, 150):
        model.set_interval(NavState(truth.llh[i], truth.v_n[i], truth.C_b_n[i]),
                           NavState(truth.llh[i + 4], truth.v_n[i + 4], truth.C_b_n[i + 4]),
                           truth.f_b[i + 1], truth.w_ib_b[i + 1])
        for x in (np.zeros(17), rng.standard_normal(17) * scale):
            f, F = model.f_and_F(x, 0.02)
            # F of the 2 n-row batch alone (as F was computed before it called f_and_F)
            E = np.diag(JACOBIAN_STEPS)
            Y = model.f_batch(np.vstack([x + E, x - E]), 0.02)
            F1 = ((Y[:17] - Y[17:]) / (2.0 * JACOBIAN_STEPS[:, None])).T
            f1 = model.f(x, 0.02)
            assert f.tobytes() == f1.tobytes() and F.tobytes() == F1.tobytes()
            assert model.F(x, 0.02).tobytes() == F.tobytes()


def test_process_noise_and_ekf_runs(truth):
    Q = process_noise(1.0, gyro_random_walk_si=np.radians(0.04) / 60,
                      accel_random_walk_si=0.05 / 60, gyro_bias_si=np.radians(8) / 3600,
                      accel_bias_si=4e-3 * 9.80665)
    assert Q.shape == (17, 17) and np.all(np.linalg.eigvalsh(Q) >= 0)
    assert Q[0, 0] == pytest.approx((np.radians(0.04) / 60) ** 2)
    assert Q[15:17, 15:17] == pytest.approx(ClockModel().Q(1.0))
    model = InsErrorModel()
    nav = NavState(truth.llh[0], truth.v_n[0], truth.C_b_n[0])
    model.set_interval(nav, nav, truth.f_b[0], truth.w_ib_b[0])
    for name in ("ekf", "ukf", "ckf"):
        kf = make_filter(name, model, None, np.zeros(17), np.eye(17) * 1e-4, Q)
        kf.predict(1.0)
        assert np.all(np.isfinite(kf.P))
