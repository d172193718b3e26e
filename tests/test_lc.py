"""Loosely coupled runs (papers 000, 003) and the integration measurement models."""

import math

import numpy as np
import pytest

from sdr_di.frames import C_e_n, llh_to_ecef
from sdr_di.integration import (
    GnssNoise,
    LooseMeasurementModel,
    NoiseWindow,
    RangeRateMeasurementModel,
    load_lc_scenario,
    loose_measurement,
    predicted_observables,
    rmse_max,
)
from sdr_di.integration.loose import run_loose
from sdr_di.sim.lc_inputs import make_inputs
from sdr_di.scenario import DEFAULT_SCENARIO, REPO_ROOT

PAPER003 = REPO_ROOT / "signals" / "lc_paper003.toml"
PAPER000 = REPO_ROOT / "signals" / "lc_paper000.toml"


# ---------------------------------------------------------------- measurement models
def _sats(r_rx, n, rng):
    """n satellites at ~20000 km altitude above the receiver's horizon."""
    up = r_rx / np.linalg.norm(r_rx)
    out_p, out_v = [], []
    for _ in range(n):
        d = up + 0.8 * rng.standard_normal(3)
        d /= np.linalg.norm(d)
        out_p.append(r_rx + 2.2e7 * d)
        out_v.append(rng.standard_normal(3) * 2500.0)
    return np.array(out_p), np.array(out_v)


@pytest.mark.parametrize("n_sat", [4, 7, 11])
def test_range_rate_model_is_first_order_of_exact_ranges(n_sat):
    rng = np.random.default_rng(n_sat)
    llh_true = np.array([math.radians(40), math.radians(116), 100.0])
    v_true = np.array([3.0, 20.0, -1.0])
    sp, sv = _sats(llh_to_ecef(*llh_true), n_sat, rng)
    x = np.zeros(17)
    x[3:6] = [0.2, -0.1, 0.05]
    x[6:9] = [3e-7, -2e-7, 4.0]
    x[15], x[16] = 12.0, -0.7
    llh_c, v_c = llh_true + x[6:9], v_true + x[3:6]
    model = RangeRateMeasurementModel(llh_c, v_c, sp, sv)
    assert model.matrix.shape == (2 * n_sat, 17) and model.n_sat == n_sat
    # measured observables: truth ranges + true clock; the INS predicts with clock estimate
    rho_t, rate_t, _ = predicted_observables(llh_true, v_true, sp, sv, 100.0, 5.0)
    model.set_epoch(llh_c, v_c, sp, sv, 100.0 + x[15], 5.0 + x[16])
    z = model.measurement(rho_t, rate_t)
    hz = model.h(x)
    # position/clock part exact to mm (range curvature ~ |dr|^2 / 2e7)
    assert np.max(np.abs(z[:n_sat] - hz[:n_sat])) < 1e-3
    # rate part: neglects the line-of-sight change from a 4 m position error (~ mm/s)
    assert np.max(np.abs(z[n_sat:] - hz[n_sat:])) < 2e-3
    # the rows are those of eq 10-12: zeros where the paper has zero blocks
    H = model.matrix
    assert np.all(H[:n_sat, 0:6] == 0) and np.all(H[:n_sat, 9:15] == 0)
    assert np.all(H[n_sat:, 0:3] == 0) and np.all(H[n_sat:, 6:15] == 0)
    assert np.all(H[:n_sat, 15] == 1) and np.all(H[:n_sat, 16] == 0)
    assert np.all(H[n_sat:, 16] == 1) and np.all(H[n_sat:, 15] == 0)


@pytest.mark.parametrize("jit", [False, True])
def test_range_rate_geometry_is_that_of_its_position_every_time(jit, monkeypatch):
    """set_geometry keeps the last position's C1, C2 (the deep loop sets two models at one
    position per interval): H is the one made from dr_e_dllh and C_e_n at the position of
    each call, also when positions alternate between two models: bit for bit in the numpy
    form, to an ulp of H's largest entry by the kernel (its sums left to right, numpy's
    ``matmul`` BLAS's)."""
    from sdr_di.coupling.measurements import dr_e_dllh

    monkeypatch.setattr(RangeRateMeasurementModel, "jit", jit)
    rng = np.random.default_rng(5)
    a, b = RangeRateMeasurementModel(), RangeRateMeasurementModel()
    llhs = [np.array([math.radians(40), math.radians(116), 100.0]),
            np.array([math.radians(40) + 1e-9, math.radians(116), 100.0]),
            np.array([math.radians(40), math.radians(116), 100.5])]
    for k in (0, 0, 1, 1, 0, 2, 2, 1):
        llh = llhs[k]
        U = rng.standard_normal((6, 3))
        U /= np.linalg.norm(U, axis=1)[:, None]
        for model in (a, b):
            model.set_geometry(llh, U)
            H = np.zeros((12, 17))
            H[:6, 6:9] = -U @ dr_e_dllh(llh)
            H[:6, 15] = 1.0
            H[6:, 3:6] = -U @ C_e_n(llh[0], llh[1]).T
            H[6:, 16] = 1.0
            if jit:
                np.testing.assert_allclose(model.matrix, H, rtol=0.0,
                                           atol=1e-15 * np.max(np.abs(H)))
                assert np.array_equal(model.matrix == 0.0, H == 0.0)
            else:
                assert model.matrix.tobytes() == H.tobytes()


def test_loose_model_matches_differences():
    llh_true = np.array([math.radians(34.2), math.radians(109.0), 500.0])
    v_true = np.array([1.0, 10.0, 0.0])
    x = np.zeros(17)
    x[3:6] = [0.1, -0.2, 0.3]
    x[6:9] = [1e-6, -2e-6, 7.0]
    llh_c = llh_true + x[6:9]
    z = loose_measurement(llh_c, v_true + x[3:6], llh_true, v_true)
    m = LooseMeasurementModel(llh_c)
    assert np.allclose(m.h(x), z, rtol=1e-9, atol=1e-9)
    # position rows are metres North, East, Up
    d = C_e_n(*llh_true[:2]) @ (llh_to_ecef(*llh_c) - llh_to_ecef(*llh_true))
    assert np.allclose(z[3:6], [d[1], d[0], d[2]], atol=0.01)


def test_noise_schedule():
    nz = GnssNoise(5.0, 8.0, 0.05, (NoiseWindow(500, 700, 16),))
    assert np.allclose(nz.true_diag(600), 16 * nz.nominal_diag())
    assert np.allclose(nz.true_diag(499.9), nz.nominal_diag())
    with pytest.raises(ValueError):
        NoiseWindow(10, 5, 2)
    rng = np.random.default_rng(0)
    llh = np.array([0.6, 1.9, 100.0])
    e = np.array([nz.sample(600.0, llh, np.zeros(3), rng)[1] for _ in range(4000)])
    assert np.std(e) == pytest.approx(0.2, rel=0.05)
    assert rmse_max(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]])) == (math.sqrt(12.5), 5.0)


# ---------------------------------------------------------------- closed-loop runs
@pytest.fixture(scope="module")
def default_inputs():
    sc, st = load_lc_scenario(DEFAULT_SCENARIO)
    truth, imu, model = make_inputs(sc, st)
    return sc, st, truth, imu, model


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf", "ff-aukf"])
def test_lc_default_trajectory_converges(default_inputs, name):
    sc, st, truth, imu, model = default_inputs
    st = st.replace(filter=name, init_att_err_arcmin=(10.0, 10.0, 30.0))
    res = run_loose(truth, imu, model, st, seed=sc.seed)
    m = res.metrics()
    assert m["n"] == 60
    assert m["pos_m_rmse"] < 4.0                        # GNSS 2 m / 3 m
    assert res.metrics(30, None)["vel_mps_rmse"] < 0.15
    att0 = np.linalg.norm(st.init_att_err_arcmin) / 60.0
    late = res.metrics(40, None)["att_deg_rmse"]
    assert late < 0.5 * att0                            # attitude (with yaw) converging
    assert np.all(np.isfinite(res.att_err))


def test_lc_free_ins_would_drift(default_inputs):
    """Sanity: with R huge the filter ignores GNSS and the errors grow (test can fail)."""
    sc, st, truth, imu, model = default_inputs
    res = run_loose(truth, imu, model, st.replace(filter="ekf", r_scale=1e8), seed=sc.seed)
    assert res.metrics(50, None)["pos_m_rmse"] > 10.0


def test_ml_r_ckf_paper003_window():
    """Paper 003 section 4.1: true R x16 during 500-700 s, the filter given the nominal R.

    Scenario seed as shipped (not chosen from results). Over scenario seeds 2021-2030
    (scripts/reproduce_paper003.py) the R estimates over 550-700 s stayed within 25 % of the
    truth 10/10 times, the window attitude and velocity RMSE were lower than the CKF's 10/10
    times but the window position RMSE only 4/10 times (docs/filters.md explains why); the
    position assertion below holds for the shipped seed only.
    """
    sc, st = load_lc_scenario(PAPER003)
    sc = sc.with_overrides(duration_s=700.0)
    truth, imu, model = make_inputs(sc, st)
    ml = run_loose(truth, imu, model, st.replace(filter="ml-r-ckf"), seed=sc.seed)
    ck = run_loose(truth, imu, model, st.replace(filter="ckf"), seed=sc.seed)
    sel = (ml.t >= 550) & (ml.t <= 700)                 # after one 50-epoch window
    ratio = ml.r_diag[sel].mean(axis=0) / ml.r_true[sel].mean(axis=0)
    assert np.all(np.abs(ratio - 1.0) < 0.25), ratio
    pre = (ml.t >= 100) & (ml.t < 490)
    ratio_pre = ml.r_diag[pre].mean(axis=0) / ml.r_true[pre].mean(axis=0)
    assert np.all(np.abs(ratio_pre - 1.0) < 0.25), ratio_pre
    assert 0.0 < ml.adaptation_time_s < ml.elapsed_s and math.isnan(ck.adaptation_time_s)
    assert ml.metrics(500, 700)["pos_m_rmse"] < ck.metrics(500, 700)["pos_m_rmse"]
    assert ml.metrics(500, 700)["vel_mps_rmse"] < ck.metrics(500, 700)["vel_mps_rmse"]


def test_ml_q_ukf_paper000_setup():
    """Paper 000 section 4.1 as shipped: the filters get 16 x the eq 57 Q (gyro and
    accelerometer white noise only, constant biases), and ml-q-ukf estimates only those terms
    (attitude and velocity states) with window 25; the other diagonal terms stay nominal.

    The Table 1 direction (ml-q-ukf better than ukf) is checked on a synthetic problem in
    tests/test_filters_noise_estimation.py; in this closed loop it holds on average but not
    on every seed (scripts/reproduce_paper000.py, seeds 2000-2009, 100-1000 s: velocity
    better 7/10 east and 9/10 north, position 6/10 each; the shipped seed 2000 is one of the
    exceptions in velocity), so it is not asserted here for one seed.
    """
    sc, st = load_lc_scenario(PAPER000)
    assert st.q_scale == 16.0 and st.bias_noise is False
    mask = np.asarray(st.options_by_filter["ml-q-ukf"]["mask"])
    assert mask.tolist() == [True] * 6 + [False] * 11
    sc = sc.with_overrides(duration_s=120.0)
    truth, imu, model = make_inputs(sc, st)
    ml = run_loose(truth, imu, model, st.replace(filter="ml-q-ukf"), seed=sc.seed)
    uk = run_loose(truth, imu, model, st.replace(filter="ukf"), seed=sc.seed)
    np.testing.assert_array_equal(uk.q_diag[0], ml.q_diag[0])
    assert np.all(ml.q_diag[0, 9:15] < 1e-12)    # only the PD floor: no bias noise (eq 57)
    # the unmasked terms keep their nominal value, the masked ones are re-estimated
    np.testing.assert_array_equal(ml.q_diag[:, 6:], np.broadcast_to(uk.q_diag[0, 6:],
                                                                   ml.q_diag[:, 6:].shape))
    assert np.any(ml.q_diag[30:, :6] != ml.q_diag[0, :6])
    assert ml.adaptation_time_s > 0.0
    assert np.mean(ml.nis[20:]) < 2.0 * 6                # consistent enough to keep running


@pytest.mark.parametrize("name", ["ekf", "ukf"])
def test_lc_large_yaw_misalignment_converges(default_inputs, name):
    """30 deg initial yaw error (large-misalignment model, rotation-vector feedback)."""
    sc, st, truth, imu, model = default_inputs
    st = st.replace(filter=name, init_att_err_arcmin=(10.0, 10.0, 1800.0))
    res = run_loose(truth, imu, model, st, seed=sc.seed)
    assert abs(res.att_err[0, 2]) > 5.0               # still degrees off after the 1st epoch
    assert res.metrics(40, None)["att_deg_rmse"] < 0.1
    assert res.metrics()["pos_m_rmse"] < 4.0


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_tight_model_in_filters_with_changing_satellite_count(name):
    """Eq 6-12 plugged into the filters: one update recovers position/clock errors; N_k varies."""
    from sdr_di.filters import LinearProcessModel, make_filter

    rng = np.random.default_rng(7)
    llh_true = np.array([math.radians(40), math.radians(116), 100.0])
    v_true = np.array([0.0, 20.0, 0.0])
    sp, sv = _sats(llh_to_ecef(*llh_true), 7, rng)
    x_true = np.zeros(17)
    x_true[3:6] = [0.3, -0.2, 0.1]
    x_true[6:9] = [5.0 / 6.37e6, -4.0 / 4.9e6, 6.0]
    x_true[15], x_true[16] = 30.0, 1.5
    llh_c, v_c = llh_true + x_true[6:9], v_true + x_true[3:6]
    rho_t, rate_t, _ = predicted_observables(llh_true, v_true, sp, sv)
    sig = np.r_[[1e-2] * 3, [10.0] * 3, 1e-4, 1e-4, 100.0, [1e-5] * 3, [1e-2] * 3, 100.0, 10.0]
    kf = make_filter(name, LinearProcessModel(np.eye(17)), None, np.zeros(17), sig**2,
                     np.eye(17) * 1e-12)
    for n in (7, 5):
        model = RangeRateMeasurementModel()
        # receiver clock: true 0, estimate x_true[15] m / x_true[16] m/s (computed - true)
        model.set_epoch(llh_c, v_c, sp[:n], sv[:n], x_true[15], x_true[16])
        z = model.measurement(rho_t[:n], rate_t[:n])
        kf.update(z, R=np.r_[[0.01] * n, [1e-4] * n], measurement_model=model)
        assert kf.y.size == 2 * n
    pos_err_m = (kf.x[6:8] - x_true[6:8]) * 6.37e6
    assert np.max(np.abs(pos_err_m)) < 0.5 and abs(kf.x[8] - x_true[8]) < 0.5
    assert abs(kf.x[15] - x_true[15]) < 0.5 and abs(kf.x[16] - x_true[16]) < 0.05
    assert np.max(np.abs(kf.x[3:6] - x_true[3:6])) < 0.05
