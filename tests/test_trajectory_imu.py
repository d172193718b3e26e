"""Acceptance: the error-free IMU of a generated trajectory, integrated by the strapdown INS,
reproduces the truth (generator kinematics and INS mechanization agree).

Measured on the default paper-004 scenario (60 s, 200 Hz, numpy 2.4, x86-64):
max position error 1.9e-5 m (6.4e-6 m at 60 s), max velocity error 4.0e-7 m/s,
max attitude error 3.5e-7 deg. The bounds below are ~50x those figures.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sdr_di.frames import C_b_n_to_euler, llh_to_ecef, radii_of_curvature, skew
from sdr_di.frames import earth_rate_n, transport_rate_n
from sdr_di.ins import navigate
from sdr_di.sim import motion as mo
from sdr_di.sim.trajectory import build_model, default_segments, generate_trajectory, sample_truth

LAT0, LON0, H0 = math.radians(40.0), math.radians(116.0), 100.0
V0 = (0.0, 20.0, 0.0)
ATT0 = (0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def truth():
    return generate_trajectory(LAT0, LON0, H0, V0, ATT0, default_segments(), rate_hz=200.0)


def _errors(sol, tr):
    R_M, R_N = radii_of_curvature(tr.llh[:, 0])
    dp = np.stack([
        (sol.llh[:, 0] - tr.llh[:, 0]) * (R_M + tr.llh[:, 2]),
        (sol.llh[:, 1] - tr.llh[:, 1]) * (R_N + tr.llh[:, 2]) * np.cos(tr.llh[:, 0]),
        sol.llh[:, 2] - tr.llh[:, 2],
    ], axis=1)
    dv = sol.v_n - tr.v_n
    # attitude error: rotation angle of C_true^T C_ins (from its antisymmetric part: small angles)
    D = np.einsum("nji,njk->nik", tr.C_b_n, sol.C_b_n)
    ax = 0.5 * np.stack([D[:, 2, 1] - D[:, 1, 2], D[:, 0, 2] - D[:, 2, 0], D[:, 1, 0] - D[:, 0, 1]], 1)
    ang = np.arcsin(np.clip(np.linalg.norm(ax, axis=1), 0, 1))
    return np.linalg.norm(dp, axis=1), np.linalg.norm(dv, axis=1), np.degrees(ang)


def _ins(tr, f_b=None, w_ib_b=None):
    return navigate(tr.t, tr.f_b if f_b is None else f_b, tr.w_ib_b if w_ib_b is None else w_ib_b,
                    tr.llh[0], tr.v_n[0], att0=tr.att[0])


def test_default_scenario_shape(truth):
    tr = truth
    assert len(tr) == 12001 and tr.t[-1] == pytest.approx(60.0)
    assert tr.llh.shape == tr.v_n.shape == tr.att.shape == tr.f_b.shape == (12001, 3)
    assert tr.C_b_n.shape == (12001, 3, 3)
    # schedule: 20 -> 25 m/s, +8 m climb, heading 0 -> +24 -> -116 -> +24 deg
    speed = np.linalg.norm(tr.v_n, axis=1)
    assert speed[0] == pytest.approx(20.0) and speed[-1] == pytest.approx(25.0, abs=1e-9)
    assert tr.llh[-1, 2] - H0 == pytest.approx(8.0, abs=0.01)
    yaw = np.degrees(tr.att[:, 2])
    assert yaw[int(20 * 200)] == pytest.approx(24.0, abs=1e-6)
    assert yaw[int(28 * 200)] == pytest.approx(360 - 116.0, abs=1e-6)
    assert yaw[-1] == pytest.approx(24.0, abs=1e-6)
    # circling 20-28 s: steady coordinated left turn, bank atan(25*0.349/g0) = -41.7 deg
    k = int(24 * 200)
    assert np.degrees(tr.att[k, 1]) == pytest.approx(-math.degrees(math.atan(25 * math.radians(20) / 9.80665)), abs=1e-9)
    assert abs(tr.f_b[k, 0]) < 0.01  # coordinated: no lateral specific force
    # ECEF consistent with geodetic
    np.testing.assert_allclose(tr.r_e, llh_to_ecef(*tr.llh.T), atol=1e-6)


def test_free_inertial_reproduces_truth(truth):
    """Main acceptance test: 60 s of error-free IMU through StrapdownINS."""
    sol = _ins(truth)
    dp, dv, da = _errors(sol, truth)
    # measured: 1.9e-5 m, 4.0e-7 m/s, 3.5e-7 deg (required: 0.1 m at 60 s)
    assert dp.max() < 1e-3
    assert dv.max() < 2e-5
    assert da.max() < 2e-5


def test_kinematics_finite_differences():
    """Instantaneous f_b and w_ib_b agree with differentiated position and attitude."""
    model = build_model(LAT0, LON0, H0, V0, ATT0, default_segments())
    t = np.array([2.0, 4.5, 7.0, 10.4, 12.0, 15.7, 17.0, 20.5, 24.0, 27.7, 39.0])
    h = 1e-3
    e0 = model.evaluate(t)
    ev = {j: model.evaluate(t + j * h) for j in (-2, -1, 1, 2)}

    def deriv(key):  # 4th-order central difference
        return (ev[-2][key] - 8 * ev[-1][key] + 8 * ev[1][key] - ev[2][key]) / (12 * h)

    # attitude: dC/dt = C [w_nb_b x]
    np.testing.assert_allclose(deriv("C_b_n"), e0["C_b_n"] @ skew(e0["w_nb_b"]), atol=1e-8)
    # velocity derivative and position derivative (llh' from v_n)
    np.testing.assert_allclose(deriv("v_n"), e0["a_n"], atol=1e-8)
    R_M, R_N = radii_of_curvature(e0["llh"][:, 0])
    lat, hh = e0["llh"][:, 0], e0["llh"][:, 2]
    llh_dot = deriv("llh")  # rounding of lat (1e-16 rad = 0.7 nm) limits this to ~1e-6 m/s
    np.testing.assert_allclose(llh_dot[:, 0] * (R_M + hh), e0["v_n"][:, 1], atol=1e-6)
    np.testing.assert_allclose(llh_dot[:, 1] * (R_N + hh) * np.cos(lat), e0["v_n"][:, 0], atol=1e-6)
    np.testing.assert_allclose(llh_dot[:, 2], e0["v_n"][:, 2], atol=1e-6)
    # attitude angles round trip
    np.testing.assert_allclose(C_b_n_to_euler(e0["C_b_n"]), e0["att"], atol=1e-12)


def test_imu_samples_are_interval_averages():
    model = build_model(LAT0, LON0, H0, V0, ATT0, default_segments())
    tr = sample_truth(model, 200.0)
    k = np.array([1, 2100, 4001, 4800, 5601, 11999])
    # brute-force average over (t_{k-1}, t_k] with a fine midpoint rule
    m = 400
    for kk in k:
        s = tr.t[kk] - tr.dt + (np.arange(m) + 0.5) * tr.dt / m
        ev = model.evaluate(s)
        np.testing.assert_allclose(tr.f_b[kk], ev["f_b"].mean(0), atol=1e-8)
        np.testing.assert_allclose(tr.w_ib_b[kk], ev["w_ib_b"].mean(0), atol=1e-10)


@pytest.mark.parametrize("drop", ["earth_rate", "transport_rate", "coriolis"])
def test_inconsistent_imu_fails_the_bound(truth, drop):
    """The acceptance bound is tight enough to catch a generator missing a term."""
    tr = truth
    lat, h = tr.llh[:, 0], tr.llh[:, 2]
    C_n_b = np.swapaxes(tr.C_b_n, 1, 2)
    w_ie, w_en = earth_rate_n(lat), transport_rate_n(lat, h, tr.v_n)
    f_b, w_ib_b = tr.f_b, tr.w_ib_b
    if drop == "earth_rate":
        w_ib_b = w_ib_b - np.einsum("nij,nj->ni", C_n_b, w_ie)
    elif drop == "transport_rate":
        w_ib_b = w_ib_b - np.einsum("nij,nj->ni", C_n_b, w_en)
    else:
        f_b = f_b - np.einsum("nij,nj->ni", C_n_b, np.cross(2 * w_ie + w_en, tr.v_n))
    dp, _, _ = _errors(_ins(tr, f_b, w_ib_b), tr)
    assert dp[-1] > 0.1, f"dropping {drop} gave only {dp[-1]:.3g} m"


def test_perturbed_imu_fails_the_bound(truth):
    w = truth.w_ib_b + np.array([0.0, 0.0, math.radians(1.0) / 3600.0])  # 1 deg/h on z
    f = truth.f_b + np.array([1e-3, 0.0, 0.0])  # 0.1 mg on x
    dp, _, _ = _errors(_ins(truth, f, w), truth)
    assert dp[-1] > 0.1


def test_hermite_interpolation_of_ecef():
    model = build_model(LAT0, LON0, H0, V0, ATT0, default_segments())
    tr = sample_truth(model, 200.0)
    t = np.linspace(0.0, 60.0, 3001)[:-1] + 0.0021  # between samples, through all manoeuvres
    r, v = tr.ecef_at(t)
    ev = model.evaluate(t)
    r_true = llh_to_ecef(*ev["llh"].T)
    assert np.abs(r - r_true).max() < 1e-6
    from sdr_di.frames import enu_velocity_to_ecef
    v_true = enu_velocity_to_ecef(ev["v_n"], ev["llh"][:, 0], ev["llh"][:, 1])
    # velocity from the quintic's derivative: limited by the rounding of ECEF coordinates
    # (1e-9 m / 5 ms), measured 4.7e-6 m/s
    assert np.abs(v - v_true).max() < 2e-5
    with pytest.raises(ValueError):
        tr.ecef_at([61.0])


def test_segments_stop_hold_and_attitude_offsets():
    """Decelerate to a stop, hold, turn in place, accelerate again; non-zero initial offsets."""
    segs = [mo.Decelerate(6.0, 2.0), mo.Hold(3.0), mo.Turn(4.0, 30.0, "left"),
            mo.Accelerate(4.0, 1.5), mo.Descend(4.0, 1.0), mo.Circle(6.0, radius=20.0, direction="right")]
    att0 = (math.radians(2.0), math.radians(1.0), math.radians(95.0))
    tr = generate_trajectory(LAT0, LON0, H0, (10.0, 0.0, 0.0), att0, segs, rate_hz=200.0,
                             duration=30.0)
    speed = np.linalg.norm(tr.v_n, axis=1)
    assert speed[int(6.5 * 200)] == pytest.approx(0.0, abs=1e-9)
    assert np.ptp(tr.llh[int(6 * 200):int(13 * 200), 2]) < 1e-9  # stationary
    assert speed[-1] == pytest.approx(1.5 * 3.0, abs=1e-9)
    # offsets kept: pitch - gamma = 2 deg, yaw - track = 5 deg
    assert np.degrees(tr.att[-1, 0]) == pytest.approx(2.0, abs=1e-9)
    sol = _ins(tr)
    dp, dv, da = _errors(sol, tr)
    assert dp.max() < 1e-3 and dv.max() < 2e-5 and da.max() < 2e-5


def test_segment_validation():
    with pytest.raises(ValueError, match="hold needs zero speed"):
        generate_trajectory(LAT0, LON0, H0, V0, ATT0, [mo.Hold(2.0)])
    with pytest.raises(ValueError, match="segment 1"):
        generate_trajectory(LAT0, LON0, H0, V0, ATT0, [mo.Uniform(1.0), mo.Climb(3.0, 25.0)])
    with pytest.raises(ValueError, match="< 0"):
        generate_trajectory(LAT0, LON0, H0, V0, ATT0, [mo.Decelerate(5.0, 10.0)])
    with pytest.raises(ValueError, match="radius"):
        generate_trajectory(LAT0, LON0, H0, (0, 0, 0), ATT0, [mo.Circle(5.0, radius=10.0, direction="left")])
    for bad in (lambda: mo.Uniform(0.0), lambda: mo.Uniform(float("nan")),
                lambda: mo.Turn(3.0, 5.0, "up"), lambda: mo.Turn(3.0, -5.0, "left"),
                lambda: mo.Circle(3.0, direction="left"),
                lambda: mo.Circle(3.0, rate_deg_s=5.0, radius=3.0, direction="left"),
                lambda: mo.Decelerate(3.0, -1.0), lambda: mo.Accelerate(2.0, 1.0, transition=0.0)):
        with pytest.raises(ValueError):
            bad()
    assert mo.segment_from_spec({"type": "turn_left", "duration_s": 3, "rate_dps": 5}) == \
        mo.Turn(3.0, 5.0, "left")
    assert mo.segment_from_spec({"type": "circle", "duration_s": 8, "direction": "right",
                                 "radius_m": 50.0}) == mo.Circle(8.0, radius=50.0, direction="right")
    assert mo.segment_from_spec({"type": "decelerate", "duration_s": 3, "decel_mps2": 1}).decel == 1.0
    with pytest.raises(ValueError, match="missing key"):
        mo.segment_from_spec({"type": "climb", "duration_s": 3})
    with pytest.raises(ValueError, match="unknown"):
        mo.segment_from_spec({"type": "loop", "duration_s": 3})


def test_duration_extends_with_uniform_motion():
    tr = generate_trajectory(LAT0, LON0, H0, V0, ATT0, [mo.Accelerate(2.0, 1.0)], rate_hz=50.0,
                             duration=5.0)
    assert tr.t[-1] == pytest.approx(5.0)
    np.testing.assert_allclose(tr.v_n[-1], (0.0, 21.0, 0.0), atol=1e-12)
