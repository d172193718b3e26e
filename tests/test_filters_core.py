"""Core filters (EKF, UKF, CKF): exactness on a linear-Gaussian problem, interface, numerics,
bad input."""

import math

import numpy as np
import pytest

from sdr_di.errors import SdrDiError
from sdr_di.filters import (
    EKF,
    FILTER_NAMES,
    UKF,
    CovarianceError,
    CubaturePoints,
    FilterError,
    FunctionMeasurementModel,
    FunctionProcessModel,
    LinearMeasurementModel,
    LinearProcessModel,
    MerweScaledSigmaPoints,
    make_filter,
)


def _random_spd(rng, n, scale=1.0, jitter=0.1):
    a = rng.normal(size=(n, n))
    return scale * (a @ a.T / n + jitter * np.eye(n))


def _linear_problem(seed=7, n=5):
    rng = np.random.default_rng(seed)
    dt = 0.5
    F = np.eye(n)
    F[0:2, 2:4] = dt * np.eye(2)                      # constant velocity in 2-D ...
    F = F + 0.05 * rng.normal(size=(n, n))            # ... plus a random coupling
    Q = _random_spd(rng, n, 0.05)
    P0 = _random_spd(rng, n, 4.0)
    x0 = rng.normal(size=n) * 3.0
    return rng, F, Q, P0, x0


def _textbook_kf(x, P, F, Q, H, R, z):
    """Plain textbook Kalman filter step (Gelb): predict then update."""
    x = F @ x
    P = F @ P @ F.T + Q
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    x = x + K @ (z - H @ x)
    I_KH = np.eye(len(x)) - K @ H
    P = I_KH @ P @ I_KH.T + K @ R @ K.T               # Joseph form
    return x, P


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_linear_gaussian_matches_exact_kalman_filter(name):
    rng, F, Q, P0, x0 = _linear_problem()
    n = len(x0)
    kf = make_filter(name, LinearProcessModel(F), None, x0, P0, Q)
    x, P = x0.copy(), P0.copy()
    for k in range(60):
        m = int(rng.integers(1, 7))                   # measurement count changes every epoch
        H = rng.normal(size=(m, n))
        R = _random_spd(rng, m, 0.5)
        z = rng.normal(size=m) * 3.0
        x, P = _textbook_kf(x, P, F, Q, H, R, z)
        kf.predict()
        kf.update(z, R, LinearMeasurementModel(H))
        np.testing.assert_allclose(kf.x, x, rtol=0, atol=1e-9 * max(1.0, np.abs(x).max()))
        np.testing.assert_allclose(kf.P, P, rtol=0, atol=1e-9 * max(1.0, np.abs(P).max()))
        assert np.array_equal(kf.P, kf.P.T)           # symmetric after every step


def test_ukf_small_alpha_still_close_but_loses_digits():
    """alpha = 1e-3 is accepted; it is exact to ~1e-8 (documented precision loss)."""
    rng, F, Q, P0, x0 = _linear_problem(seed=3)
    n = len(x0)
    kf = UKF(LinearProcessModel(F), None, x0, P0, Q, alpha=1e-3)
    x, P = x0.copy(), P0.copy()
    for _ in range(20):
        H = rng.normal(size=(3, n))
        R = _random_spd(rng, 3)
        z = rng.normal(size=3)
        x, P = _textbook_kf(x, P, F, Q, H, R, z)
        kf.predict()
        kf.update(z, R, LinearMeasurementModel(H))
    np.testing.assert_allclose(kf.x, x, atol=1e-6)
    np.testing.assert_allclose(kf.P, P, atol=1e-6)


def test_sigma_point_sets():
    ut = MerweScaledSigmaPoints()                     # documented defaults 0.5, 2, 0
    assert (ut.alpha, ut.beta, ut.kappa) == (0.5, 2.0, 0.0)
    n = 17
    xi = ut.unit_points(n)
    wm, wc = ut.weights(n)
    assert xi.shape == (2 * n + 1, n) and math.isclose(wm.sum(), 1.0)
    lam = 0.25 * n - n
    assert math.isclose(wm[0], lam / (n + lam)) and math.isclose(wc[0], wm[0] + 1 - 0.25 + 2)
    assert math.isclose(np.abs(xi[1:]).max(), math.sqrt(n + lam))
    # weighted points reproduce mean 0 and identity covariance
    np.testing.assert_allclose(wm @ xi, 0, atol=1e-12)
    np.testing.assert_allclose((xi.T * wm) @ xi, np.eye(n), atol=1e-12)
    ck = CubaturePoints()
    xi = ck.unit_points(n)
    wm, wc = ck.weights(n)
    assert xi.shape == (2 * n, n) and np.allclose(wm, 1 / (2 * n))
    np.testing.assert_allclose((xi.T * wm) @ xi, np.eye(n), atol=1e-12)


def test_interface_attributes_innovation_residual_likelihood():
    rng, F, Q, P0, x0 = _linear_problem(seed=11)
    n = len(x0)
    H = rng.normal(size=(4, n))
    R = _random_spd(rng, 4)
    for name in ("ekf", "ukf", "ckf"):
        kf = make_filter(name, LinearProcessModel(F), LinearMeasurementModel(H), x0, P0, Q, R)
        kf.predict()
        x_prior, P_prior = kf.x.copy(), kf.P.copy()
        np.testing.assert_array_equal(kf.x_prior, x_prior)
        z = rng.normal(size=4)
        kf.update(z)
        S = H @ P_prior @ H.T + R
        np.testing.assert_allclose(kf.y, z - H @ x_prior, atol=1e-10)
        np.testing.assert_allclose(kf.S, S, atol=1e-10)
        np.testing.assert_allclose(kf.S_inv, np.linalg.inv(S), atol=1e-10)
        np.testing.assert_allclose(kf.K, P_prior @ H.T @ np.linalg.inv(S), atol=1e-10)
        np.testing.assert_allclose(kf.residual, z - H @ kf.x, atol=1e-10)
        np.testing.assert_array_equal(kf.x_post, kf.x)
        y = kf.y
        ll = -0.5 * (4 * math.log(2 * math.pi) + math.log(np.linalg.det(S))
                     + y @ np.linalg.solve(S, y))
        assert math.isclose(kf.log_likelihood, ll, rel_tol=1e-10)
        assert math.isclose(kf.nis, y @ np.linalg.solve(S, y), rel_tol=1e-10)
        assert kf.epoch == 1 and kf.name == name


def test_empty_measurement_vector_leaves_state():
    _, F, Q, P0, x0 = _linear_problem()
    for name in FILTER_NAMES:
        kf = make_filter(name, LinearProcessModel(F), LinearMeasurementModel(np.zeros((0, 5))),
                         x0, P0, Q)
        kf.predict()
        x, P = kf.x.copy(), kf.P.copy()
        kf.update(np.zeros(0))                        # all channels lost
        np.testing.assert_array_equal(kf.x, x)
        np.testing.assert_array_equal(kf.P, P)
        assert kf.y.size == 0 and kf.epoch == 0


def test_ekf_default_jacobians_are_central_differences_of_the_model():
    def f(x, dt):
        return np.array([x[0] + dt * x[1], x[1] - dt * 0.1 * np.sin(x[0])])

    def h(x):
        return np.array([np.hypot(x[0], 2.0)])

    pm = FunctionProcessModel(f, dim_x=2)
    mm = FunctionMeasurementModel(h)
    x = np.array([0.3, -0.2])
    F_ana = np.array([[1.0, 0.1], [-0.1 * 0.1 * np.cos(0.3), 1.0]])
    np.testing.assert_allclose(pm.F(x, 0.1), F_ana, atol=1e-9)
    np.testing.assert_allclose(mm.H(x), [[0.3 / np.hypot(0.3, 2.0), 0.0]], atol=1e-9)
    kf = EKF(pm, mm, x, np.eye(2), 0.01 * np.eye(2), np.eye(1), dt=0.1)
    kf.predict()
    kf.update([2.1])
    assert np.all(np.isfinite(kf.x))


# --------------------------------------------------------------------------- bad input
def test_unknown_filter_name_lists_valid_names():
    with pytest.raises(FilterError) as exc:
        make_filter("kalman", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                    np.eye(2))
    msg = str(exc.value)
    assert "kalman" in msg
    for name in FILTER_NAMES:
        assert name in msg
    assert isinstance(exc.value, SdrDiError)
    assert set(FILTER_NAMES) == {"ekf", "ukf", "ckf", "ff-aukf", "rae-aukf", "ml-q-ukf",
                                 "sage-husa-ukf", "q-scaling-ekf", "q-scaling-ukf", "ml-r-ckf"}


def test_unknown_option_rejected():
    with pytest.raises(FilterError, match="unknown option.*windw"):
        make_filter("ff-aukf", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                    np.eye(2), windw=3)


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf", "ff-aukf"])
def test_non_positive_definite_P0_rejected_at_construction(name):
    pm = LinearProcessModel(np.eye(3))
    P0 = np.diag([1.0, 0.0, 1.0])
    with pytest.raises(FilterError, match="P0 is not positive definite"):
        make_filter(name, pm, None, np.zeros(3), P0, np.eye(3))
    P0 = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(FilterError, match="P0 is not positive definite"):
        make_filter(name, pm, None, np.zeros(3), P0, np.eye(3))
    with pytest.raises(FilterError, match="P0 is not symmetric"):
        make_filter(name, pm, None, np.zeros(3), np.triu(np.ones((3, 3))) + np.eye(3),
                    np.eye(3))
    with pytest.raises(FilterError, match="P0 is 2x2 but 3x3"):
        make_filter(name, pm, None, np.zeros(3), np.eye(2), np.eye(3))


def test_other_bad_construction_input():
    pm = LinearProcessModel(np.eye(3))
    with pytest.raises(FilterError, match="Q0 is not positive semi-definite"):
        make_filter("ukf", pm, None, np.zeros(3), np.eye(3), -np.eye(3))
    with pytest.raises(FilterError, match="x0 has 2 states but the process model has 3"):
        make_filter("ukf", pm, None, np.zeros(2), np.eye(2), np.eye(2))
    with pytest.raises(FilterError, match="x0 contains NaN"):
        make_filter("ekf", pm, None, [0.0, np.nan, 0.0], np.eye(3), np.eye(3))
    with pytest.raises(FilterError, match="R0 is not positive definite"):
        make_filter("ckf", pm, None, np.zeros(3), np.eye(3), np.eye(3), R0=-np.eye(2))
    with pytest.raises(FilterError, match="alpha"):
        make_filter("ukf", pm, None, np.zeros(3), np.eye(3), np.eye(3), alpha=0.0)
    with pytest.raises(FilterError, match="psd_fallback"):
        make_filter("ukf", pm, None, np.zeros(3), np.eye(3), np.eye(3), psd_fallback="fix")


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf", "ff-aukf", "ml-r-ckf"])
def test_wrong_size_or_bad_z_and_R(name):
    pm = LinearProcessModel(np.eye(3))
    mm = LinearMeasurementModel(np.eye(4, 3))
    kf = make_filter(name, pm, mm, np.zeros(3), np.eye(3), 0.1 * np.eye(3), R0=np.eye(4))
    kf.predict()
    with pytest.raises(FilterError, match="z has 5 elements but the measurement model "
                                          "predicts 4"):
        kf.update(np.zeros(5))
    with pytest.raises(FilterError, match="z has 3 elements"):
        kf.update(np.zeros(3))
    with pytest.raises(FilterError, match="NaN"):
        kf.update([0.0, np.nan, 0.0, 0.0])
    with pytest.raises(FilterError, match="1-D"):
        kf.update(np.zeros((4, 1)))
    with pytest.raises(FilterError, match="R has shape"):
        kf.update(np.zeros(4), R=np.eye(3))
    with pytest.raises(FilterError, match="non-positive variance"):
        kf.update(np.zeros(4), R=np.zeros(4))
    kf.update(np.zeros(4))                            # the filter is still usable
    assert kf.epoch == 1


def test_missing_R_when_count_changes():
    kf = make_filter("ukf", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                     np.eye(2), R0=np.eye(2))
    kf.predict()
    with pytest.raises(FilterError, match="pass R for this epoch"):
        kf.update(np.zeros(3), measurement_model=LinearMeasurementModel(np.ones((3, 2))))
    kf2 = make_filter("ukf", LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                      np.eye(2))
    with pytest.raises(FilterError, match="no R given"):
        kf2.update(np.zeros(2), measurement_model=LinearMeasurementModel(np.eye(2)))


# --------------------------------------------------------------------------- numerics
def test_covariance_failure_names_filter_and_step():
    pm = LinearProcessModel(np.eye(2))
    mm = LinearMeasurementModel(np.eye(2))
    bad_R = np.array([[1.0, 3.0], [3.0, 1.0]])        # positive variances, indefinite
    for name in ("ekf", "ukf", "ckf"):
        kf = make_filter(name, pm, mm, np.zeros(2), 1e-6 * np.eye(2), 1e-6 * np.eye(2))
        kf.predict()
        with pytest.raises(CovarianceError) as exc:
            kf.update(np.zeros(2), R=bad_R)
        e = exc.value
        assert (e.filter_name, e.step, e.matrix) == (name, "update", "S")
        assert e.min_eigenvalue < 0 and name in str(e) and "update" in str(e)
    # a negative-definite Q in predict makes P indefinite: the sigma points cannot be drawn
    kf = make_filter("ukf", pm, mm, np.zeros(2), np.eye(2), np.eye(2))
    kf.predict(Q=-3.0 * np.eye(2))
    with pytest.raises(CovarianceError, match="ukf update .* covariance P is not positive"):
        kf.update(np.zeros(2), R=np.eye(2))
    kf.P = np.diag([1.0, -1.0])
    with pytest.raises(CovarianceError, match="ukf predict"):
        kf.predict()


def test_clip_fallback_is_recorded():
    pm = LinearProcessModel(np.eye(2))
    mm = LinearMeasurementModel(np.eye(2))
    kf = make_filter("ckf", pm, mm, np.zeros(2), np.eye(2), np.eye(2), psd_fallback="clip")
    kf.P = np.array([[1.0, 2.0], [2.0, 1.0]])
    kf.predict()
    kf.update(np.ones(2), R=np.eye(2))
    assert kf.numerics_events and kf.numerics_events[0]["step"] == "predict"
    assert kf.numerics_events[0]["matrix"] == "P" and kf.numerics_events[0]["min_eigenvalue"] < 0
    assert np.all(np.linalg.eigvalsh(kf.P) > 0) and np.all(np.isfinite(kf.x))


@pytest.mark.parametrize("points", ["ukf", "ckf"])
def test_sigma_moment_kernels_equal_the_numpy_forms(points, monkeypatch):
    """``weighted_moments`` and the measurement prediction's cross covariance by their
    kernels (``sigma_filter.jit``) against the numpy forms: UKF weights (negative centre
    weight) and cubature weights, points about a large mean (the deviations' purpose),
    17 and 23 states; agreement to rounding of the covariance's scale."""
    from sdr_di.filters import sigma_filter
    from sdr_di.filters.sigma_points import CubaturePoints, MerweScaledSigmaPoints

    pts = MerweScaledSigmaPoints() if points == "ukf" else CubaturePoints()
    rng = np.random.default_rng(28)
    for n in (17, 23):
        wm, wc = pts.weights(n)
        xi = pts.unit_points(n)
        for _ in range(20):
            A = rng.normal(size=(n, n)) * np.exp(rng.normal(size=n))
            L = np.linalg.cholesky(A @ A.T + np.eye(n))
            x = rng.normal(size=n) * 1e4
            dX = xi @ L.T
            Z = np.sin(x + dX)[:, :14] * 3.0 + (x + dX)[:, :14] ** 2 * 1e-3
            out = {}
            for jit in (True, False):
                monkeypatch.setattr(sigma_filter, "jit", jit)
                mean, cov, D, delta = sigma_filter.weighted_moments(x + dX, wm, wc)
                zm, Pzz, DZ, dz = sigma_filter.weighted_moments(Z, wm, wc)
                out[jit] = (mean, cov, D, delta, zm, Pzz, DZ, dz)
            # rounding scales: the sums' terms (weights times deviations, and squares)
            for k, (a, b) in enumerate(zip(out[True], out[False])):
                D_ = out[False][2] if k < 4 else out[False][6]
                dev = np.max(np.abs(D_)) * np.sum(np.abs(wm))
                scale = {0: np.max(np.abs(b)), 1: dev * np.max(np.abs(D_)), 2: dev,
                         3: dev}[k % 4]
                np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-13 * scale)
            assert np.array_equal(out[True][1], out[True][1].T)
        # the cross covariance, through a filter's measurement prediction
        model = LinearMeasurementModel(rng.normal(size=(6, n)))
        preds = {}
        for jit in (True, False):
            monkeypatch.setattr(sigma_filter, "jit", jit)
            kf = sigma_filter.UKF(LinearProcessModel(np.eye(n)), model, x, L @ L.T, np.eye(n)) \
                if points == "ukf" else sigma_filter.CKF(LinearProcessModel(np.eye(n)), model, x, L @ L.T,
                                                           np.eye(n))
            preds[jit] = kf.predict_measurement()
        scale = np.max(np.abs(preds[False].Pxz))
        np.testing.assert_allclose(preds[True].Pxz, preds[False].Pxz, rtol=0.0,
                                   atol=1e-12 * scale)


@pytest.mark.parametrize("name", ["ekf", "ukf"])
def test_correction_kernel_equals_the_numpy_form(name, monkeypatch):
    """The Kalman correction by its kernel (``base.jit``) against the numpy form: state,
    covariance, gain, ``S^-1``, NIS and log-likelihood of updates with 2 to 28 measurements
    of 17 states, over covariances spread across eight orders of magnitude."""
    from sdr_di.filters import base

    rng = np.random.default_rng(47)
    n = 17
    for m in (2, 7, 14, 28):
        for _ in range(10):
            scales = np.exp(rng.uniform(-9.0, 9.0, n))
            P0 = _random_spd(rng, n) * np.outer(scales, scales)
            H = rng.normal(size=(m, n)) / scales
            R = _random_spd(rng, m, scale=0.5)
            x0 = rng.normal(size=n) * scales
            z = H @ x0 + rng.normal(size=m)
            got = {}
            for on in (True, False):
                monkeypatch.setattr(base, "jit", on)
                kf = make_filter(name, LinearProcessModel(np.eye(n)),
                                 LinearMeasurementModel(H), x0, P0, np.eye(n), R)
                kf.update(z)
                got[on] = kf
            a, b = got[True], got[False]
            for attr in ("x", "P", "K", "S", "S_inv"):
                ref = getattr(b, attr)
                np.testing.assert_allclose(getattr(a, attr), ref, rtol=1e-9,
                                           atol=1e-9 * np.max(np.abs(ref)), err_msg=attr)
            assert a.nis == pytest.approx(b.nis, rel=1e-9)
            assert a.log_likelihood == pytest.approx(b.log_likelihood, rel=1e-9, abs=1e-9)
            assert np.array_equal(a.P, a.P.T)


def test_correction_kernel_leaves_a_singular_s_to_the_failure_policy(monkeypatch):
    """With ``S`` not positive definite the kernel declines and the numpy form raises the
    CovarianceError (``psd_fallback='raise'``) or clips (``'clip'``), as without it."""
    from sdr_di.filters import base

    monkeypatch.setattr(base, "jit", True)
    H = np.array([[1.0, 0.0], [1.0, 0.0]])
    for fallback in ("raise", "clip"):
        kf = make_filter("ekf", LinearProcessModel(np.eye(2)), LinearMeasurementModel(H),
                         np.zeros(2), np.diag([1.0, 1.0]), np.eye(2),
                         np.zeros((2, 2)) + 1e-300 * np.eye(2), psd_fallback=fallback)
        if fallback == "raise":
            with pytest.raises(CovarianceError):
                kf.update(np.array([1.0, 1.0]))
        else:
            kf.update(np.array([1.0, 1.0]))
            assert kf.numerics_events and kf.numerics_events[-1]["matrix"] == "S"


@pytest.mark.parametrize("name", ["ukf", "ckf"])
def test_sigma_point_draw_kernel_equals_the_numpy_form(name, monkeypatch):
    """The points ``x + L xi_i`` by the kernel (its own Cholesky factor) against the numpy
    form (LAPACK's), over covariances spread across eight orders of magnitude; a ``P`` that
    is not positive definite still meets the failure policy."""
    from sdr_di.filters import sigma_filter

    rng = np.random.default_rng(7)
    n = 17
    for _ in range(20):
        scales = np.exp(rng.uniform(-9.0, 9.0, n))
        P = _random_spd(rng, n) * np.outer(scales, scales)
        x = rng.normal(size=n) * scales * 100.0
        kf = make_filter(name, LinearProcessModel(np.eye(n)), None, x, P, np.eye(n))
        got = {}
        for on in (True, False):
            monkeypatch.setattr(sigma_filter, "jit", on)
            got[on] = kf._draw(x, P, "predict")
        for a, b in zip(got[True], got[False]):
            np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12 * np.max(np.abs(b)))
    monkeypatch.setattr(sigma_filter, "jit", True)
    kf = make_filter(name, LinearProcessModel(np.eye(2)), None, np.zeros(2), np.eye(2),
                     np.zeros((2, 2)))
    kf.P = np.array([[1.0, 1.0], [1.0, 1.0]])
    with pytest.raises(CovarianceError):
        kf.predict(1.0)
