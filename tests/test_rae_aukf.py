"""``rae-aukf`` against a hand computation of the residual-based R and innovation-based Q
window estimates (Mohamed & Schwarz 1999) on a small linear problem (issue 26 item 2)."""

from __future__ import annotations

import numpy as np
import pytest

from sdr_di.errors import FilterError
from sdr_di.filters import LinearMeasurementModel, LinearProcessModel, make_filter

DT, W = 0.1, 4
PHI = np.array([[1.0, DT], [0.0, 1.0]])
H = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 0.5]])
R_PRIOR = np.diag([0.5, 0.2, 0.8])


@pytest.mark.parametrize("jit", [False, True])
@pytest.mark.parametrize("r_form, pd_rule", [("full", "floor"), ("diagonal", "floor"),
                                             ("full", "none"), ("full", "clip")])
def test_window_estimates_match_the_equations(jit, r_form, pd_rule):
    rng = np.random.default_rng(3)
    Q0 = np.diag([1e-3, 1e-2])
    kf = make_filter("rae-aukf", LinearProcessModel(PHI), LinearMeasurementModel(H),
                     np.zeros(2), np.eye(2), Q0, dt=DT, window=W, jit=jit, r_form=r_form,
                     pd_rule=pd_rule)
    rule = kf.rule
    q_floor = np.diag(rule.q_floor)
    x_true = np.array([0.0, 1.0])
    innov, resid = [], []
    R_next = None
    for k in range(12):
        x_true = PHI @ x_true
        z = H @ x_true + rng.normal(size=3) * np.sqrt(np.diag(R_PRIOR)) * 2.0
        kf.predict()
        kf.update(z, R_PRIOR)
        # the update used the previous epoch's estimate once the window was full
        assert np.allclose(kf.R_used, R_PRIOR if R_next is None else R_next, rtol=1e-12)
        innov.append(z - H @ kf.x_prior)                    # v^- = z - H x^-
        resid.append(z - H @ kf.x_post)                     # v^+ = z - H x^+
        assert np.allclose(kf.y, innov[-1]) and np.allclose(kf.residual, resid[-1])
        if k < W - 1:
            assert not rule.active and rule.R_hat is None
            continue
        C_r = sum(np.outer(r, r) for r in resid[-W:]) / W
        C_v = sum(np.outer(v, v) for v in innov[-W:]) / W
        R_hat = C_r + H @ kf.P_post @ H.T                    # RAE: R = C_r + H P+ H^T
        if pd_rule == "floor":
            R_hat = R_hat + 1e-6 * np.diag(np.diag(R_PRIOR))
        if r_form == "diagonal":
            R_hat = np.diag(np.diag(R_hat))
        Q_hat = kf.K @ C_v @ kf.K.T + q_floor                # IAE: Q = K C_v K^T
        assert rule.active
        np.testing.assert_allclose(rule.R_hat, R_hat, rtol=1e-9, atol=1e-14)
        np.testing.assert_allclose(kf.Q, Q_hat, rtol=1e-9, atol=1e-14)
        R_next = R_hat


def test_q_adaptation_off_keeps_q_and_options_are_checked():
    kf = make_filter("rae-aukf", LinearProcessModel(PHI), LinearMeasurementModel(H),
                     np.zeros(2), np.eye(2), np.diag([1e-3, 1e-2]), dt=DT, window=2,
                     adapt_q=False)
    rng = np.random.default_rng(0)
    for _ in range(5):
        kf.predict()
        kf.update(rng.normal(size=3), R_PRIOR)
    assert kf.rule.active and np.array_equal(kf.Q, np.diag([1e-3, 1e-2]))
    for bad in ({"r_form": "block"}, {"pd_rule": "eig"}):
        with pytest.raises(FilterError, match="rae-aukf"):
            make_filter("rae-aukf", LinearProcessModel(PHI), None, np.zeros(2), np.eye(2),
                        np.eye(2), **bad)


@pytest.mark.parametrize("entry, want", [("ff-aukf:adapt_q=false", (False, True)),
                                         ("ff-aukf:adapt_r=false", (True, False)),
                                         ("rae-aukf:adapt_q=0", (False, True)),
                                         ("rae-aukf:adapt_r=true", (True, True))])
def test_on_off_options_from_a_filter_entry_are_read_as_written(entry, want):
    # a filter entry gives "false" as a string; bool("false") is True
    from sdr_di.experiments.entries import check_filter_entry

    name, opts = check_filter_entry("t", entry)
    kf = make_filter(name, LinearProcessModel(PHI), None, np.zeros(2), np.eye(2), np.eye(2),
                     **opts)
    assert (kf.rule.adapt_q, kf.rule.adapt_r) == want
    with pytest.raises(FilterError, match="adapt_q must be true or false"):
        make_filter(name, LinearProcessModel(PHI), None, np.zeros(2), np.eye(2), np.eye(2),
                    adapt_q="no")
