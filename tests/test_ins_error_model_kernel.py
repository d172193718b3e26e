"""The error model's numba kernels (``ins/_numba_error_model.py``) against the numpy
reference :func:`error_derivative`, in every state layout.

On the development machine (AVX-512, session 24) the two agree bit for bit and a deep run
writes the same bytes with and without the kernels. The kernels reproduce numpy's order of
operations, but numpy's reductions and transcendental loops dispatch on the CPU's SIMD
features, so on another machine the last bits may differ: the tests allow 1e-12 of the
largest value (a wrong order of terms or a wrong term is far above it)."""

import numpy as np
import pytest

from sdr_di.filters.state import state_layout
from sdr_di.ins.error_model import (ClockModel, InsErrorModel, NavState, error_derivative,
                                    error_derivative_kernel, jacobian_steps, rotvec_to_dcm)


def _same(got, ref):
    ref = np.asarray(ref)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12 * float(np.abs(ref).max()))



def _nav(rng):
    lat = rng.uniform(-1.4, 1.4)
    llh = np.array([lat, rng.uniform(-3, 3), rng.uniform(-100.0, 9000.0)])
    v = rng.normal(size=3) * rng.choice([0.0, 1.0, 30.0, 250.0])
    C = rotvec_to_dcm(rng.normal(size=3))
    return NavState(llh, v, C)


def _rows(rng, n, p):
    """Error states of many sizes: zero rows, tiny attitude errors (the series branches of
    the SO(3) coefficients), large ones (tens of degrees) and mixtures."""
    scale = np.r_[[1e-3] * 3, [0.5] * 3, [1e-6, 1e-6, 5.0], [1e-4] * 3, [1e-2] * 3,
                  [10.0, 0.1], [1e-4] * (n - 17)]
    X = rng.normal(size=(p, n)) * scale * np.exp(rng.normal(size=(p, n)))
    X[0] = 0.0
    X[1, 0:3] = [1e-8, 0.0, 0.0]             # |phi|^2 below 1e-12
    X[2, 0:3] = [3e-5, 1e-5, 0.0]            # between 1e-12 and 1e-8
    X[3, 0:3] = [0.4, -0.3, 0.5]             # large misalignment
    return X


@pytest.mark.parametrize("error_states", ["none", "gm", "sf", "sf+gm"])
def test_kernel_rows_equal_numpy_rows(error_states):
    rng = np.random.default_rng(47)
    layout = state_layout(error_states)
    clock = ClockModel(tau_s=1800.0)
    tau = (3000.0, 1200.0)
    for _ in range(60):
        nav = _nav(rng)
        f_b = rng.normal(size=3) * 3.0 + [0.0, 0.0, 9.8]
        w_ib_b = rng.normal(size=3) * 0.2
        for X in (_rows(rng, layout.n, 35), _rows(rng, layout.n, 35)[4:5]):
            ref = error_derivative(X, nav, f_b, w_ib_b, clock, layout, tau)
            got = error_derivative_kernel(X, nav, f_b, w_ib_b, clock, layout, tau)
            _same(got, ref)
            # one row (numpy's products of one row take other BLAS paths)
            one = error_derivative_kernel(X[-1:], nav, f_b, w_ib_b, clock, layout, tau)
            _same(one, error_derivative(X[-1:], nav, f_b, w_ib_b, clock, layout, tau))


def test_ekf_time_update_same_with_and_without_kernels():
    rng = np.random.default_rng(3)
    for error_states in ("none", "sf"):
        layout = state_layout(error_states)
        on, off = InsErrorModel(layout=layout), InsErrorModel(layout=layout)
        off.jit = False
        for _ in range(10):
            nav0, nav1 = _nav(rng), _nav(rng)
            f_b, w = rng.normal(size=3) + [0, 0, 9.8], rng.normal(size=3) * 0.1
            for m in (on, off):
                m.set_interval(nav0, nav1, f_b, w)
            x = rng.normal(size=layout.n) * jacobian_steps(layout) * 100.0
            fx_on, F_on = on.f_and_F(x, 0.02)
            fx_off, F_off = off.f_and_F(x, 0.02)
            _same(fx_on, fx_off)
            _same(F_on, F_off)
            # set_interval renews the computed states' terms
            nav1.llh = nav1.llh + [1e-5, 0.0, 3.0]
            for m in (on, off):
                m.set_interval(nav0, nav1, f_b, w)
            _same(on.f(x, 0.02), off.f(x, 0.02))


def test_interval_terms_equal_the_computed_state_terms():
    """The kernel's computed-state terms of both interval ends (``interval_terms``, the
    one call ``InsErrorModel`` makes) against the numpy form ``computed_state_terms``:
    every term, with the transposed ``C_b^n``, over navigation states from rest to 250 m/s
    and latitudes to 80 degrees."""
    from sdr_di.ins import _numba_error_model as nb
    from sdr_di.ins.error_model import computed_state_terms

    rng = np.random.default_rng(28)
    for _ in range(200):
        nav0, nav1 = _nav(rng), _nav(rng)
        f_b = rng.normal(size=3) * 3.0 + [0.0, 0.0, 9.8]
        cs0, cs1 = np.empty(nb.CS_LEN), np.empty(nb.CS_LEN)
        C0T, C1T = np.empty((3, 3)), np.empty((3, 3))
        nb.interval_terms(nav0.llh, nav0.v_n, nav0.C_b_n, nav1.llh, nav1.v_n, nav1.C_b_n,
                          f_b, cs0, cs1, C0T, C1T)
        _same(cs0, computed_state_terms(nav0, f_b))
        _same(cs1, computed_state_terms(nav1, f_b))
        assert np.array_equal(C0T, nav0.C_b_n.T) and np.array_equal(C1T, nav1.C_b_n.T)
