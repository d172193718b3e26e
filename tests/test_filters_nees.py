"""NEES consistency of EKF, UKF and CKF on a nonlinear range/bearing tracking problem.

Constant-velocity target in 2-D observed in range and bearing from the origin (range ~420 m,
bearing noise 0.02 rad -> ~8 m cross-range, comparable with the 30 m prior), 50 seeded Monte
Carlo runs of 100 steps. The normalized estimation error squared ``e^T P^-1 e`` averaged over
the runs must lie in the two-sided 95 % chi-square band of 50 runs x 4 states (Bar-Shalom):
overall and at (almost) every step.
"""

import numpy as np
import pytest
from filter_problems import cv2d
from scipy.stats import chi2

from sdr_di.filters import FunctionMeasurementModel, LinearProcessModel, make_filter

RUNS, STEPS, DT = 50, 100, 1.0
SIG_R, SIG_B, SIG_A = 5.0, 0.02, 0.1          # m, rad, m/s^2




def _h(x):
    return np.array([np.hypot(x[0], x[1]), np.arctan2(x[1], x[0])])


def _h_batch(X):
    return np.column_stack([np.hypot(X[:, 0], X[:, 1]), np.arctan2(X[:, 1], X[:, 0])])


def _H(x):
    r2 = x[0] ** 2 + x[1] ** 2
    r = np.sqrt(r2)
    return np.array([[x[0] / r, x[1] / r, 0, 0], [-x[1] / r2, x[0] / r2, 0, 0]])


def _nees(name):
    F, Q = cv2d(DT, SIG_A)
    R = np.diag([SIG_R ** 2, SIG_B ** 2])
    P0 = np.diag([30.0, 30.0, 3.0, 3.0]) ** 2
    mm = FunctionMeasurementModel(_h, _H, _h_batch)
    out = np.zeros((RUNS, STEPS))
    for r in range(RUNS):
        rng = np.random.default_rng(1000 + r)
        x = np.array([300.0, 300.0, 10.0, 5.0])
        kf = make_filter(name, LinearProcessModel(F), mm,
                         x + rng.multivariate_normal(np.zeros(4), P0), P0, Q, R)
        for k in range(STEPS):
            x = F @ x + rng.multivariate_normal(np.zeros(4), Q)
            kf.predict()
            kf.update(_h(x) + rng.normal(size=2) * [SIG_R, SIG_B])
            e = x - kf.x
            out[r, k] = e @ np.linalg.solve(kf.P, e)
    return out


@pytest.mark.parametrize("name", ["ekf", "ukf", "ckf"])
def test_mean_nees_in_chi_square_band(name):
    nees = _nees(name)
    lo, hi = chi2.ppf([0.025, 0.975], 4 * RUNS) / RUNS
    per_step = nees.mean(axis=0)
    assert lo <= nees.mean() <= hi, (name, nees.mean(), lo, hi)
    assert np.mean((per_step >= lo) & (per_step <= hi)) >= 0.9, per_step
