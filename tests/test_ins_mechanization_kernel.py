"""The strapdown INS kernel (``ins/_numba_mechanization.py``, :meth:`StrapdownINS.step_many`)
against the Python reference (:meth:`StrapdownINS.step`): the same state bit for bit.

Both make the same IEEE operations in the same order, with every sum written out (no BLAS,
no SIMD reduction), so they agree on any machine whose ``sin``, ``cos`` and ``sqrt`` are the
same function for Python's ``math`` and for numba (both call the C library)."""

import numpy as np
import pytest

from sdr_di.ins.mechanization import StrapdownINS


def _imu(rng, n, turning):
    """``n`` IMU samples at 200 Hz: gravity and noise, a turn and an acceleration when
    ``turning``, slow rates otherwise (the series branch of Savage's coefficients)."""
    f = np.tile([0.0, 0.0, 9.79], (n, 1)) + rng.normal(size=(n, 3)) * 0.05
    w = rng.normal(size=(n, 3)) * 1e-5
    if turning:
        f[:, 1] += 2.0 * np.sin(np.arange(n) / 50.0)
        w[:, 2] += 0.6 * np.sin(np.arange(n) / 80.0)      # |dtheta|^2 above 1e-6
        w[:, 0] += 0.3
    dt = np.full(n, 0.005) * (1.0 + 1e-4 * rng.normal(size=n))
    return f, w, dt


def _pair(prev):
    """A reference INS and a kernel INS in the same start state."""
    out = []
    for jit in (False, True):
        ins = StrapdownINS([0.52, 2.0, 80.0], [12.0, -3.0, 0.2],
                           att=[0.02, -0.01, 1.1], t=10.0)
        ins.jit = jit
        if prev:
            ins.set_previous_increments([0.1, 0.0, 9.8], [0.0, 0.01, 0.02], 0.005)
        out.append(ins)
    return out


def _same(a, b):
    for name in ("q_b_n", "v_n", "llh", "_v_prev", "_llh_prev", "_dth_prev", "_dv_prev"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.t == b.t and a._dt_prev == b._dt_prev


@pytest.mark.parametrize("turning", [False, True])
@pytest.mark.parametrize("prev", [False, True])
def test_kernel_equals_reference(turning, prev):
    """Batches of 1-7 samples, closed-loop corrections with bias and scale-factor
    feedback between them: the kernel's state is the reference's, bit for bit."""
    rng = np.random.default_rng(3 + 2 * turning + prev)
    f, w, dt = _imu(rng, 2000, turning)
    ref, jit = _pair(prev)
    k = 0
    while k < len(dt):
        m = int(rng.integers(1, 8))
        for ins in (ref, jit):
            ins.step_many(f[k:k + m], w[k:k + m], dt[k:k + m])
        _same(ref, jit)
        k += m
        if rng.random() < 0.3:
            d = rng.normal(size=6) * [1e-4, 1e-4, 1e-4, 0.01, 0.01, 0.01]
            kw = {}
            if k > 1000:             # scale factors fed back: the scaled arithmetic
                kw = dict(d_gyro_scale=rng.normal(size=3) * 1e-4,
                          d_accel_scale=rng.normal(size=3) * 1e-4)
            for ins in (ref, jit):
                ins.correct(d[:3], d[3:], [1e-8, -1e-8, 0.1], rng.normal(size=3) * 0.0,
                            [1e-4, 0.0, -1e-4], **kw)
    assert ref._scaled and jit._scaled
    _same(ref, jit)


def test_kernel_keeps_holders_arrays():
    """The kernel gives the INS new arrays: a state read before a step keeps its values."""
    _, ins = _pair(True)
    v, llh, q = ins.v_n, ins.llh, ins.q_b_n
    v0, llh0, q0 = v.copy(), llh.copy(), q.copy()
    f, w, dt = _imu(np.random.default_rng(0), 4, True)
    ins.step_many(f, w, dt)
    np.testing.assert_array_equal(v, v0)
    np.testing.assert_array_equal(llh, llh0)
    np.testing.assert_array_equal(q, q0)
    assert not np.array_equal(ins.v_n, v0)
