"""Nonlinear 17-state INS/clock error model (paper 004 eq 1-5; paper 000 eq 1-7) as a
:class:`~sdr_di.filters.models.ProcessModel`.

State layout (DESIGN section 4, :mod:`sdr_di.filters.state`), errors = *computed minus true*
(the convention of :meth:`sdr_di.ins.mechanization.StrapdownINS.correct`)::

    0-2   phi        misalignment [rad] (ENU), C_b^n' = C_n^n' C_b^n,  C_n^n' = exp(-[phi x])
    3-5   dv         velocity error [m/s] (ENU)
    6-8   dp         (dlat [rad], dlon [rad], dh [m])
    9-11  eps        residual gyro bias [rad/s] (measured - true, after the INS compensation)
    12-14 nabla      residual accel bias [m/s^2]
    15    db_clk     receiver clock bias error [m]
    16    dd_clk     receiver clock drift error [m/s]

Continuous model (eq 2 with large misalignment; eq 3; eq 4). With the computed (INS)
navigation state ``(L^, lambda^, h^, v^, C_b^n')`` and the true one ``= computed - error``:

* attitude (eq 2, first line)::

      phi' = C_w^-1 [ (I - C_n^n') w^_in + C_n^n' dw_in - C_b^n' eps ]

  ``phi`` is a *rotation vector* (so the INS feedback ``C_b^n <- exp([phi x]) C_b^n`` is exact
  for any angle); for it the matrix that maps ``phi'`` to the relative angular velocity is the
  right Jacobian of SO(3), ``C_w = J_r(phi)``, and
  ``C_w^-1 = I + [phi x]/2 + (1/|phi|^2 - (1 + cos|phi|)/(2 |phi| sin|phi|)) [phi x]^2``.
  (Paper 004 uses Euler-angle errors with the corresponding ``C_w``; both reduce to
  ``C_w = I``, ``I - C_n^n' = [phi x]`` for small angles, the linear psi-angle model.)
* velocity (eq 2, second line; paper 000 eq 1)::

      dv' = (I - C_n^n'^T) C_b^n' f^ + C_n^n'^T C_b^n' nabla
            - (2 w^_ie + w^_en) x dv - (2 dw_ie + dw_en) x v + dg

  ``f^`` = compensated specific force the INS used (IMU average over the interval),
  ``dg = g(L^, h^) - g(L, h)`` on the Up axis (normal gravity; the paper omits it, it is the
  term that makes the vertical channel unstable).
* position (eq 2, last three lines), evaluated as the exact difference
  ``dL' = v^_N/(R_M(L^)+h^) - v_N/(R_M(L)+h)``, ``dlambda' = v^_E/((R_N(L^)+h^) cos L^) -
  v_E/((R_N(L)+h) cos L)``, ``dh' = dv_U``; likewise ``dw_ie``, ``dw_en`` are exact
  differences of the rates at the computed and true states. The first-order expansion of these
  differences is eq 2 exactly.
* sensor biases: random constants (eq 3), ``eps' = 0``, ``nabla' = 0``; with
  ``error_states=gm`` first-order Gauss-Markov, ``eps' = -eps / tau_g``,
  ``nabla' = -nabla / tau_a`` (the assumed grade's correlation times).
* scale factors (``error_states=sf``, states 17-22, :mod:`sdr_di.filters.state`): random
  constants ``ds_g' = 0``, ``ds_a' = 0``. The INS compensates ``y^ = (y - b^) / (1 + s^)``
  (:meth:`~sdr_di.ins.mechanization.StrapdownINS.compensate`), so with the truth
  ``y = (1 + s) x + b`` the compensated measurement's error is, to first order,
  ``y^ - x = diag(x) ds + db`` with ``ds = s - s^`` (measured minus true, as the biases):
  the scale factors enter exactly where the biases do, through an effective bias
  ``eps + diag(w^_ib_b) ds_g`` in the attitude line and ``nabla + diag(f^) ds_a`` in the
  velocity line (``w^_ib_b``, ``f^`` the interval's compensated IMU averages). Linearized:
  ``phi' += -C_b^n diag(w_ib_b) ds_g``, ``dv' += C_b^n diag(f_b) ds_a``.
* clock (eq 4): ``db' = dd + w_b``, ``dd' = -dd / tau_clk + w_d``.

Discretization (eq 5): improved Euler (Heun; paper 000 Remark 1) over the filter interval
``h``: ``x_k = x + h/2 [g0(x) + g1(x + h g0(x))]`` where ``g0`` uses the navigation state at
the start of the interval and ``g1`` the one at its end, both with the IMU average over the
interval (:meth:`InsErrorModel.set_interval`). Vectorized over sigma points (``f_batch``);
the EKF Jacobian ``F`` is central differences of ``f_batch`` with per-state steps (one batched
call of 2 n rows), checked in the tests against the analytic small-error Jacobian
:func:`linear_error_matrix`.

Process noise (:func:`process_noise`, discrete, per interval ``h``), decisions documented here:

* attitude: angle random walk ``N_g^2 h`` [rad^2] (white gyro noise ``w_g``; the noise enters
  as ``-C_b^n' w_g`` which keeps an isotropic covariance);
* velocity: velocity random walk ``N_a^2 h`` [(m/s)^2];
* position: 0;
* gyro / accel bias: eq 3 models random constants; a small random walk reaching the 1-sigma
  bias spec in ``bias_time_s`` (default 3600 s) is added so the bias covariance does not
  collapse: ``q = b_spec^2 h / bias_time_s``; with ``gm`` the exact discrete Gauss-Markov
  noise ``q = sigma^2 (1 - exp(-2 h / tau))``, stationary ``sigma^2 = b_spec^2 + b_in^2``
  (turn-on spec and in-run instability of the assumed grade: the bias a unit shows at any
  time), so that with no measurement the bias covariance stays at the grade's level;
* scale factors (``sf``): the bias rule, ``q = s_spec^2 h / bias_time_s`` (0 without
  ``bias_time_s``: the truth's scale factors are constants);
* clock (eq 4): oscillator of Allan-variance coefficients ``h0``, ``h_-2`` (default TCXO
  ``h0 = 2e-19``, ``h_-2 = 2e-20``; Brown and Hwang; an oscillator with flicker noise
  ``h_-1`` is mapped into these two by :meth:`ClockModel.from_oscillator`),
  ``S_b = c^2 h0 / 2`` [m^2/s], ``S_d = 2 pi^2 c^2 h_-2`` [m^2/s^3], ``tau_clk = 3600`` s;
  discrete
  ``[[S_b h + S_d h^3/3, S_d h^2/2], [S_d h^2/2, S_d h]]`` (the Markov damping is neglected
  in Q since ``h << tau_clk``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..constants import A_CGCS, E2_CGCS, OMEGA_E
from ..filters.models import ProcessModel, numerical_jacobian
from ..filters.state import StateLayout
from ..frames import radii_of_curvature, skew
from ..oscillator import two_state_coefficients
from . import _numba_error_model as _nb
from .gravity import normal_gravity
from .rotation import cross_rows

__all__ = [
    "N_STATES",
    "ClockModel",
    "InsErrorModel",
    "NavState",
    "correct_ins",
    "dcm_to_rotvec",
    "jacobian_steps",
    "linear_error_matrix",
    "process_noise",
    "rotvec_to_dcm",
]

N_STATES = 17
C_LIGHT = 299792458.0

_I3 = np.eye(3)
_I3.setflags(write=False)

#: Central-difference steps per state for the numerical Jacobian (state units).
JACOBIAN_STEPS = np.array([1e-6] * 3 + [1e-4] * 3 + [1e-9, 1e-9, 1e-3] + [1e-7] * 3
                          + [1e-5] * 3 + [1e-2, 1e-3])
#: Steps of the scale-factor states (gyro, accel) [-]: 100 ppm, the error of a MEMS unit.
_SCALE_STEPS = np.full(6, 1e-4)

_NONE = StateLayout()


def jacobian_steps(layout: StateLayout = _NONE) -> np.ndarray:
    """Central-difference steps of every state of ``layout`` (state units)."""
    return np.r_[JACOBIAN_STEPS, _SCALE_STEPS] if layout.scale_factors else JACOBIAN_STEPS


@dataclasses.dataclass
class NavState:
    """Computed (INS) navigation state at one instant.

    Attributes
    ----------
    llh : (3,) array
        lat [rad], lon [rad], h [m].
    v_n : (3,) array
        ENU velocity [m/s].
    C_b_n : (3, 3) array
        Body (Right-Front-Up) to ENU rotation.
    """

    llh: np.ndarray
    v_n: np.ndarray
    C_b_n: np.ndarray

    @classmethod
    def from_ins(cls, ins) -> NavState:
        """Snapshot of a :class:`~sdr_di.ins.mechanization.StrapdownINS`."""
        return cls(np.array(ins.llh, float), np.array(ins.v_n, float), np.array(ins.C_b_n))


@dataclasses.dataclass(frozen=True)
class ClockModel:
    """Receiver clock of eq 4 (documented defaults: TCXO).

    Attributes
    ----------
    h0, h_2 : float
        Allan-variance coefficients (white frequency, random-walk frequency) [s, 1/s].
    tau_s : float
        Markov time constant of the drift error [s].
    """

    h0: float = 2e-19
    h_2: float = 2e-20
    tau_s: float = 3600.0

    @classmethod
    def from_oscillator(cls, spec, tau_s: float = 3600.0) -> ClockModel:
        """The two-state clock the filter uses for an oscillator
        (:class:`~sdr_di.oscillator.OscillatorSpec`): its flicker term ``h_-1`` mapped into
        ``h0`` and ``h_-2`` (:func:`~sdr_di.oscillator.two_state_coefficients`); the
        g-sensitivity has no state and is not used."""
        h0, h_2 = two_state_coefficients(spec.h0, spec.h_1, spec.h_2)
        return cls(h0=h0, h_2=h_2, tau_s=tau_s)

    @property
    def S_b(self) -> float:
        """Bias white-noise PSD [m^2/s]."""
        return C_LIGHT**2 * self.h0 / 2.0

    @property
    def S_d(self) -> float:
        """Drift white-noise PSD [m^2/s^3]."""
        return 2.0 * math.pi**2 * C_LIGHT**2 * self.h_2

    def Q(self, dt: float) -> np.ndarray:
        """Discrete clock noise covariance over ``dt`` [s] (2, 2)."""
        Sb, Sd = self.S_b, self.S_d
        return np.array([[Sb * dt + Sd * dt**3 / 3.0, Sd * dt**2 / 2.0],
                         [Sd * dt**2 / 2.0, Sd * dt]])


def rotvec_to_dcm(phi: np.ndarray) -> np.ndarray:
    """``exp([phi x])`` for rotation vectors ``phi`` (..., 3) (Rodrigues)."""
    phi = np.asarray(phi, float)
    th2 = np.sum(phi * phi, axis=-1)[..., None, None]
    K = skew(phi)
    a, b, _ = _so3_coefficients(th2)
    return _I3 + a * K + b * (K @ K)


def _so3_coefficients(th2: np.ndarray, jacobian: bool = False
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Coefficients of ``exp([phi x]) = I + a [phi x] + b [phi x]^2`` (Rodrigues) and, with
    ``jacobian``, of ``C_w^-1 = J_r(phi)^-1 = I + [phi x]/2 + c [phi x]^2`` (module notes),
    from ``|phi|^2`` (..., 1, 1); series below ``|phi|^2 = 1e-12`` (``a``, ``b``) and ``1e-8``
    (``c``). One ``sin`` and one ``cos`` serve both (the error model needs both)."""
    th = np.sqrt(th2)
    if th2.min(initial=1.0) >= 1e-8:
        # no series needed (the usual case): the closed forms the selections below give
        s, co = np.sin(th), np.cos(th)
        return (s / th, (1.0 - co) / th2,
                1.0 / th2 - (1.0 + co) / (2.0 * th * s) if jacobian else None)
    small = th2 < 1e-12
    safe = np.where(small, 1.0, th)
    s, co = np.sin(safe), np.cos(safe)
    a = np.where(small, 1.0 - th2 / 6.0, s / safe)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - co) / np.where(small, 1.0, th2))
    if not jacobian:
        return a, b, None
    # where 1e-12 <= |phi|^2 < 1e-8 the closed form is computed (safe = |phi| >= 1e-6, no
    # division by zero) and discarded for the series
    small = th2 < 1e-8
    c = np.where(small, 1.0 / 12.0 + th2 / 720.0,
                 1.0 / np.where(small, 1.0, th2) - (1.0 + co) / (2.0 * safe * s))
    return a, b, c


def dcm_to_rotvec(C: np.ndarray) -> np.ndarray:
    """Rotation vector ``phi`` with ``exp([phi x]) = C`` (angle < pi), (..., 3)."""
    C = np.asarray(C, float)
    tr = np.trace(C, axis1=-2, axis2=-1)
    cth = np.clip((tr - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(cth)
    w = np.stack([C[..., 2, 1] - C[..., 1, 2], C[..., 0, 2] - C[..., 2, 0],
                  C[..., 1, 0] - C[..., 0, 1]], axis=-1)
    s = np.sin(th)
    k = np.where(th < 1e-6, 0.5 + th**2 / 12.0, th / (2.0 * np.where(th < 1e-6, 1.0, s)))
    return k[..., None] * w


def _radii(lat) -> tuple[np.ndarray, np.ndarray]:
    """Meridian and prime-vertical radii [m] at latitude [rad], vectorized, in the scalar
    form of the INS (``mechanization._radii``: ``R_M = R_N (1 - e^2) / w``, no power), which
    the error model's kernel repeats bit for bit; :func:`~sdr_di.frames.radii_of_curvature`
    takes ``w^1.5`` from numpy's ``power``, a SIMD library's on AVX-512 that no kernel
    can follow. (The two agree to a few ulp.)"""
    sl = np.sin(np.asarray(lat, float))
    w = 1.0 - E2_CGCS * (sl * sl)
    R_N = A_CGCS / np.sqrt(w)
    return R_N * (1.0 - E2_CGCS) / w, R_N


def _rates(lat, h, v):
    """w_ie^n, w_en^n (..., 3), ``R_N + h`` and ``cos(lat)``, vectorized."""
    R_M, R_N = _radii(lat)
    sl, cl = np.sin(lat), np.cos(lat)
    RN_h = R_N + h
    w_ie = np.zeros(np.shape(lat) + (3,))            # filled in place: cheaper than stacking
    w_ie[..., 1] = OMEGA_E * cl
    w_ie[..., 2] = OMEGA_E * sl
    w_en = np.empty_like(w_ie)
    w_en[..., 0] = -v[..., 1] / (R_M + h)
    w_en[..., 1] = v[..., 0] / RN_h
    w_en[..., 2] = v[..., 0] * sl / cl / RN_h
    return w_ie, w_en, RN_h, cl


def residual_biases(X: np.ndarray, layout: StateLayout, f_b: np.ndarray,
                    w_ib_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The gyro [rad/s] and accelerometer [m/s^2] residual biases of error rows ``X`` (p, n):
    the bias states, plus with scale-factor states the scale factors times the compensated
    rate ``w_ib_b`` and specific force ``f_b`` (the effective residual biases of the
    compensated IMU, module notes)."""
    L = layout
    eps, nab = X[:, L.gyro_bias], X[:, L.accel_bias]
    if L.scale_factors:
        eps = eps + X[:, L.gyro_scale] * np.asarray(w_ib_b, float)
        nab = nab + X[:, L.accel_scale] * np.asarray(f_b, float)
    return eps, nab


def _skew_squares(K: np.ndarray) -> np.ndarray:
    """``K @ K`` of 3x3 matrices (p, 3, 3), each entry summed left to right (the kernels'
    order; numpy's ``matmul`` calls BLAS, whose fused multiply-adds follow the CPU)."""
    return (K[:, :, 0, None] * K[:, None, 0, :] + K[:, :, 1, None] * K[:, None, 1, :]) \
        + K[:, :, 2, None] * K[:, None, 2, :]


def _matrix_times_vector(C: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``C @ f`` of a 3x3 matrix and a 3-vector, summed left to right (as
    :func:`_skew_squares`: ``matmul`` would call BLAS)."""
    return (C[:, 0] * f[0] + C[:, 1] * f[1]) + C[:, 2] * f[2]


def _rows_times_transpose(r: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``r @ C.T`` of rows ``r`` (p, 3), summed left to right (as :func:`_skew_squares`)."""
    return (r[:, 0, None] * C[:, 0] + r[:, 1, None] * C[:, 1]) + r[:, 2, None] * C[:, 2]


def error_derivative(X: np.ndarray, nav: NavState, f_b: np.ndarray, w_ib_b: np.ndarray,
                     clock: ClockModel, layout: StateLayout = _NONE,
                     bias_tau_s: tuple[float, float] = (3600.0, 3600.0)) -> np.ndarray:
    """Continuous error dynamics ``xdot = fbar(x)`` (eq 2-4) for rows of ``X`` (p, n).

    ``f_b``, ``w_ib_b`` are the compensated specific force [m/s^2] and angular rate [rad/s]
    the INS integrates (``w_ib_b`` enters only through the gyro scale factors: the attitude
    error equation otherwise needs only ``C_b^n'`` and the nav-frame rates). ``layout``: the
    states (:mod:`sdr_di.filters.state`); ``bias_tau_s``: the gyro and accelerometer
    Gauss-Markov correlation times [s] when ``layout.gauss_markov``.
    """
    X = np.atleast_2d(X)
    L = layout
    phi, dv, dp = X[:, L.att], X[:, L.vel], X[:, L.pos]
    eps, nab = residual_biases(X, L, f_b, w_ib_b)
    Cb = nav.C_b_n
    lat_c, h_c = nav.llh[0], nav.llh[2]
    v_c = nav.v_n
    # computed-state quantities (scalars/3-vectors)
    wie_c, wen_c, RNh_c, _ = _rates(np.array(lat_c), np.array(h_c), v_c)
    win_c = wie_c + wen_c
    # true state = computed - error
    lat_t = lat_c - dp[:, 0]
    h_t = h_c - dp[:, 2]
    v_t = v_c - dv
    wie_t, wen_t, RNh_t, cl_t = _rates(lat_t, h_t, v_t)
    d_wie = wie_c - wie_t
    d_wen = wen_c - wen_t
    # C_n^n' = exp(-[phi x]) (p, 3, 3) with the skew matrix, |phi|^2 and trigonometry that
    # C_w^-1 also needs (negation is exact: the same values as rotvec_to_dcm(-phi))
    th2 = np.sum(phi * phi, axis=-1)[..., None, None]
    K = skew(phi)
    KK = _skew_squares(K)
    a, b, c = _so3_coefficients(th2, jacobian=True)
    A = _I3 - a * K + b * KK
    At = np.swapaxes(A, -1, -2)
    I = _I3
    # attitude (eq 2, line 1)
    u = (np.einsum("pij,j->pi", I - A, win_c) + np.einsum("pij,pj->pi", A, d_wie + d_wen)
         - _rows_times_transpose(eps, Cb))
    phi_dot = np.einsum("pij,pj->pi", _I3 + 0.5 * K + c * KK, u)
    # velocity (eq 2, line 2)
    Cf = _matrix_times_vector(Cb, f_b)
    dv_dot = (np.einsum("pij,j->pi", I - At, Cf) + np.einsum("pij,pj->pi", At,
                                                              _rows_times_transpose(nab, Cb))
              - cross_rows(2.0 * wie_c + wen_c, dv) - cross_rows(2.0 * d_wie + d_wen, v_t))
    g_c = float(normal_gravity(lat_c, h_c))
    dv_dot[:, 2] -= g_c - normal_gravity(lat_t, h_t)
    # position (eq 2, lines 3-5): dlat' = v_N/(R_M + h), computed minus true, is -dw_en_E
    out = np.zeros_like(X)
    out[:, 0:3] = phi_dot
    out[:, 3:6] = dv_dot
    out[:, 6] = -d_wen[:, 0]
    out[:, 7] = v_c[0] / (RNh_c * math.cos(lat_c)) - v_t[:, 0] / (RNh_t * cl_t)
    out[:, 8] = dv[:, 2]
    if L.gauss_markov:
        out[:, L.gyro_bias] = -X[:, L.gyro_bias] / bias_tau_s[0]
        out[:, L.accel_bias] = -X[:, L.accel_bias] / bias_tau_s[1]
    # clock (eq 4); the scale factors are constants (zero rows)
    out[:, L.clock_bias] = X[:, L.clock_drift]
    out[:, L.clock_drift] = -X[:, L.clock_drift] / clock.tau_s
    return out


def computed_state_terms(nav: NavState, f_b: np.ndarray) -> np.ndarray:
    """The computed (INS) state's quantities every row of :func:`error_derivative` shares,
    packed for the kernels (``_numba_error_model.CS_*`` offsets): the same numpy operations
    as :func:`error_derivative`'s, so the same values."""
    lat_c, h_c = nav.llh[0], nav.llh[2]
    v_c = nav.v_n
    wie_c, wen_c, RNh_c, _ = _rates(np.array(lat_c), np.array(h_c), v_c)
    cs = np.empty(_nb.CS_LEN)
    cs[_nb.CS_WIN:_nb.CS_WIN + 3] = wie_c + wen_c
    cs[_nb.CS_WIE:_nb.CS_WIE + 3] = wie_c
    cs[_nb.CS_WEN:_nb.CS_WEN + 3] = wen_c
    cs[_nb.CS_W2:_nb.CS_W2 + 3] = 2.0 * wie_c + wen_c
    cs[_nb.CS_CF:_nb.CS_CF + 3] = _matrix_times_vector(nav.C_b_n, f_b)
    cs[_nb.CS_V:_nb.CS_V + 3] = v_c
    cs[_nb.CS_LAT], cs[_nb.CS_H] = lat_c, h_c
    cs[_nb.CS_G] = float(normal_gravity(lat_c, h_c))
    cs[_nb.CS_LONDOT] = v_c[0] / (RNh_c * math.cos(lat_c))
    return cs


def error_derivative_kernel(X: np.ndarray, nav: NavState, f_b: np.ndarray,
                            w_ib_b: np.ndarray, clock: ClockModel, layout: StateLayout = _NONE,
                            bias_tau_s: tuple[float, float] = (3600.0, 3600.0),
                            cs: np.ndarray | None = None) -> np.ndarray:
    """:func:`error_derivative` by the numba kernels (:mod:`sdr_di.ins._numba_error_model`):
    the same rows bit for bit. ``cs``: the computed state's :func:`computed_state_terms`
    when the caller already has them."""
    X = np.ascontiguousarray(np.atleast_2d(X), dtype=float)
    L = layout
    if cs is None:
        cs = computed_state_terms(nav, f_b)
    out = np.empty(X.shape)
    _nb.derivative_rows(X, cs, np.ascontiguousarray(nav.C_b_n.T),
                        np.asarray(w_ib_b, float), np.asarray(f_b, float),
                        _scale_start(L), L.gauss_markov, float(bias_tau_s[0]),
                        float(bias_tau_s[1]), float(clock.tau_s), out)
    return out


def _scale_start(layout: StateLayout) -> int:
    """First scale-factor state (gyro; the accelerometer's follow), -1 without them (the
    kernels' ``scale_start``)."""
    return layout.gyro_scale.start if layout.gyro_scale is not None else -1


class InsErrorModel(ProcessModel):
    """Discrete nonlinear error model (eq 5) for one filter interval: 17 states, or the
    layout of an ``error_states`` option.

    Call :meth:`set_interval` before each ``predict`` with the INS state at the start and the
    end of the interval and the IMU averages over it; then ``f(x, dt)`` is the improved-Euler
    step (paper 000 Remark 1) of :func:`error_derivative`.

    Parameters
    ----------
    clock : ClockModel, optional
        Clock model of eq 4 (default :class:`ClockModel`).
    layout : StateLayout, optional
        The states (:func:`~sdr_di.filters.state.state_layout`; default the 17 of paper
        004). A filter, a plugin included, learns the layout from this attribute.
    bias_tau_s : (float, float)
        Gyro and accelerometer bias correlation times [s] (used with ``gm``).

    Attributes
    ----------
    dim_x : int
        ``layout.n``.
    """

    dim_x = N_STATES
    #: Whether :meth:`f_batch` and :meth:`f_and_F` run the numba kernels (one call each:
    #: ``_numba_error_model.improved_euler``, ``f_and_jacobian``); False: the numpy
    #: reference :func:`error_derivative` (the same values, tested).
    jit = True

    def __init__(self, clock: ClockModel | None = None, layout: StateLayout | None = None,
                 bias_tau_s: tuple[float, float] = (3600.0, 3600.0)) -> None:
        self.clock = clock or ClockModel()
        self.layout = layout if layout is not None else _NONE
        self.dim_x = self.layout.n
        self.bias_tau_s = (float(bias_tau_s[0]), float(bias_tau_s[1]))
        self._steps = jacobian_steps(self.layout)
        self.nav0: NavState | None = None
        self.nav1: NavState | None = None
        self.f_b = np.zeros(3)
        self._cs: tuple | None = None   # the kernels' arguments of the interval
        self.w_ib_b = np.zeros(3)

    def set_interval(self, nav0: NavState, nav1: NavState, f_b, w_ib_b) -> None:
        """Navigation state at the interval start/end and compensated IMU averages."""
        self.nav0, self.nav1 = nav0, nav1
        self.f_b = np.asarray(f_b, float).reshape(3)
        self.w_ib_b = np.asarray(w_ib_b, float).reshape(3)
        self._cs = None

    def f_batch(self, X: np.ndarray, dt: float) -> np.ndarray:
        if self.nav0 is None:
            raise RuntimeError("InsErrorModel: call set_interval() before propagating")
        X = np.atleast_2d(np.asarray(X, float))
        args = (self.f_b, self.w_ib_b, self.clock, self.layout, self.bias_tau_s)
        if not self.jit:
            g0 = error_derivative(X, self.nav0, *args)
            g1 = error_derivative(X + dt * g0, self.nav1, *args)
            return X + 0.5 * dt * (g0 + g1)
        out = np.empty(X.shape)
        # both derivatives and the step in one kernel call (the numpy form's values, bit
        # for bit: tests/test_ins_error_model_kernel.py)
        _nb.improved_euler(np.ascontiguousarray(X), float(dt), *self._kernel_args(), out)
        return out

    def _kernel_args(self) -> tuple:
        """The kernels' arguments of the interval after ``X, dt``: the computed states'
        terms and ``C_b^n^T`` at both ends (made once per interval, :meth:`set_interval`),
        the IMU averages and the layout's and clock's constants."""
        if self._cs is None:
            n0, n1 = self.nav0, self.nav1
            cs0, cs1 = np.empty(_nb.CS_LEN), np.empty(_nb.CS_LEN)
            C0T, C1T = np.empty((3, 3)), np.empty((3, 3))
            # both ends in one call (computed_state_terms' values, bit for bit)
            _nb.interval_terms(n0.llh, n0.v_n, n0.C_b_n, n1.llh, n1.v_n, n1.C_b_n, self.f_b,
                               cs0, cs1, C0T, C1T)
            self._cs = (cs0, cs1, C0T, C1T,
                        self.w_ib_b, self.f_b, _scale_start(self.layout),
                        self.layout.gauss_markov, self.bias_tau_s[0], self.bias_tau_s[1],
                        float(self.clock.tau_s))
        return self._cs

    def f(self, x: np.ndarray, dt: float) -> np.ndarray:
        return self.f_batch(np.asarray(x, float)[None, :], dt)[0]

    def F(self, x: np.ndarray, dt: float) -> np.ndarray:
        """Jacobian by central differences of one batched ``f_batch`` call (that of
        :meth:`f_and_F`, whose extra centre row does not change the others)."""
        return self.f_and_F(x, dt)[1]

    def f_and_F(self, x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``f(x, dt)`` and :meth:`F` from one ``f_batch`` call of ``2 n + 1`` rows (the
        EKF's time update: half the error-model evaluations of calling both). Every
        operation of :func:`error_derivative` is row by row, so each row is the value a
        batch of its own gives, bit for bit (tested)."""
        x = np.asarray(x, float)
        n = x.size
        steps = self._steps
        if self.jit and self.nav0 is not None:
            # the rows, the step and the differences in one kernel call (the same values)
            fx, F = np.empty(n), np.empty((n, n))
            _nb.f_and_jacobian(np.ascontiguousarray(x), steps, float(dt), *self._kernel_args(),
                               fx, F)
            return fx, F
        E = np.diag(steps)
        Y = self.f_batch(np.vstack([x + E, x - E, x[None, :]]), dt)
        return Y[2 * n], ((Y[:n] - Y[n:2 * n]) / (2.0 * steps[:, None])).T

    def F_numerical(self, x: np.ndarray, dt: float, scale: float = 1.0) -> np.ndarray:
        """Reference Jacobian with :func:`numerical_jacobian` (steps scaled by ``scale``)."""
        return numerical_jacobian(lambda v: self.f(v, dt), x, step=self._steps * scale)


def correct_ins(ins, x: np.ndarray, layout: StateLayout = _NONE) -> None:
    """Closed-loop feedback of the INS part of an error state ``x`` (the clock is the
    caller's): attitude, velocity, position, IMU biases and, with ``sf``, scale factors
    (:meth:`~sdr_di.ins.mechanization.StrapdownINS.correct`)."""
    L = layout
    if L.scale_factors:
        ins.correct(x[L.att], x[L.vel], x[L.pos], x[L.gyro_bias], x[L.accel_bias],
                    d_gyro_scale=x[L.gyro_scale], d_accel_scale=x[L.accel_scale])
    else:
        ins.correct(x[L.att], x[L.vel], x[L.pos], x[L.gyro_bias], x[L.accel_bias])


def linear_error_matrix(nav: NavState, f_b, clock: ClockModel | None = None,
                        layout: StateLayout = _NONE, w_ib_b=None,
                        bias_tau_s: tuple[float, float] = (3600.0, 3600.0)) -> np.ndarray:
    """Analytic small-error Jacobian ``d fbar / d x`` at ``x = 0`` (classical psi model).

    ``phi' = -w_in x phi + dw_in(dv, dp) - C eps``,
    ``dv' = (C f) x phi + C nabla + v x (2 dw_ie + dw_en) - (2 w_ie + w_en) x dv + dg``,
    position rows of eq 2; ``dg = 2 g / R * dh`` (Up; R = sqrt(R_M R_N)). With the
    ``layout``'s scale factors ``phi' += -C diag(w_ib_b) ds_g``, ``dv' += C diag(f_b) ds_a``;
    with Gauss-Markov biases ``eps' = -eps / tau_g``, ``nabla' = -nabla / tau_a``.
    """
    clock = clock or ClockModel()
    L = layout
    lat, h = float(nav.llh[0]), float(nav.llh[2])
    vE, vN, _ = nav.v_n
    C = nav.C_b_n
    R_M, R_N = (float(r) for r in radii_of_curvature(lat))
    sl, cl = math.sin(lat), math.cos(lat)
    tl = sl / cl
    RMh, RNh = R_M + h, R_N + h
    w_ie = np.array([0.0, OMEGA_E * cl, OMEGA_E * sl])
    w_en = np.array([-vN / RMh, vE / RNh, vE * tl / RNh])
    # d(w_ie)/d(dp), d(w_en)/d(dv), d(w_en)/d(dp)
    Mie_p = np.zeros((3, 3))
    Mie_p[1, 0] = -OMEGA_E * sl
    Mie_p[2, 0] = OMEGA_E * cl
    Men_v = np.array([[0, -1 / RMh, 0], [1 / RNh, 0, 0], [tl / RNh, 0, 0]])
    Men_p = np.array([[0, 0, vN / RMh**2], [0, 0, -vE / RNh**2],
                      [vE / (cl * cl * RNh), 0, -vE * tl / RNh**2]])
    F = np.zeros((L.n, L.n))
    F[0:3, 0:3] = -skew(w_ie + w_en)
    F[0:3, 3:6] = Men_v
    F[0:3, 6:9] = Mie_p + Men_p
    F[0:3, 9:12] = -C
    F[3:6, 0:3] = skew(C @ np.asarray(f_b, float))
    # -(2 dw_ie + dw_en) x v = v x (2 dw_ie + dw_en)
    F[3:6, 3:6] = -skew(2 * w_ie + w_en) + skew(nav.v_n) @ Men_v
    F[3:6, 6:9] = skew(nav.v_n) @ (2 * Mie_p + Men_p)
    g = float(normal_gravity(lat, h))
    F[5, 8] += 2.0 * g / math.sqrt(R_M * R_N)
    F[5, 6] -= float(normal_gravity(lat + 1e-6, h) - normal_gravity(lat - 1e-6, h)) / 2e-6
    F[3:6, 12:15] = C
    F[6, 4] = 1 / RMh
    F[6, 8] = -vN / RMh**2
    F[7, 3] = 1 / (RNh * cl)
    F[7, 6] = vE * tl / (RNh * cl)
    F[7, 8] = -vE / (RNh**2 * cl)
    F[8, 5] = 1.0
    F[15, 16] = 1.0
    F[16, 16] = -1.0 / clock.tau_s
    if L.scale_factors:
        w = np.zeros(3) if w_ib_b is None else np.asarray(w_ib_b, float)
        F[L.att, L.gyro_scale] = -C * w            # -C diag(w): column j scaled by w_j
        F[L.vel, L.accel_scale] = C * np.asarray(f_b, float)
    if L.gauss_markov:
        F[L.gyro_bias, L.gyro_bias] = -np.eye(3) / bias_tau_s[0]
        F[L.accel_bias, L.accel_bias] = -np.eye(3) / bias_tau_s[1]
    return F


def process_noise(dt: float, *, gyro_random_walk_si: float, accel_random_walk_si: float,
                  gyro_bias_si: float = 0.0, accel_bias_si: float = 0.0,
                  bias_time_s: float | None = 3600.0, clock: ClockModel | None = None,
                  with_clock: bool = True, layout: StateLayout = _NONE,
                  gyro_scale: float = 0.0, accel_scale: float = 0.0,
                  bias_tau_s: tuple[float, float] = (3600.0, 3600.0),
                  bias_instability_si: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Discrete process-noise covariance (n, n) over ``dt`` [s] (module docstring).

    Parameters
    ----------
    gyro_random_walk_si : float
        Angle random walk [rad/sqrt(s)].
    accel_random_walk_si : float
        Velocity random walk [(m/s)/sqrt(s)].
    gyro_bias_si, accel_bias_si : float
        1-sigma bias specs [rad/s], [m/s^2] for the bias random walk.
    bias_time_s : float or None
        Time for the bias random walk to reach the spec (None: biases are pure constants).
    clock : ClockModel, optional
    with_clock : bool
        False leaves the clock block at a tiny value (loosely coupled runs have no clock
        measurement; keeps ``Q`` positive semi-definite and ``P`` bounded).
    layout : StateLayout
        The states (default the 17 of paper 004).
    gyro_scale, accel_scale : float
        1-sigma scale-factor specs [-] (``sf``: their random walk).
    bias_tau_s : (float, float)
        Gyro, accelerometer bias correlation times [s] (``gm``).
    bias_instability_si : (float, float)
        Gyro [rad/s], accelerometer [m/s^2] in-run bias instability (``gm``: added to the
        turn-on spec in the stationary variance).
    """
    L = layout
    q = np.zeros(L.n)
    q[0:3] = gyro_random_walk_si**2 * dt
    q[3:6] = accel_random_walk_si**2 * dt
    if L.gauss_markov:
        for blk, b_on, b_in, tau in ((L.gyro_bias, gyro_bias_si, bias_instability_si[0],
                                      bias_tau_s[0]),
                                     (L.accel_bias, accel_bias_si, bias_instability_si[1],
                                      bias_tau_s[1])):
            q[blk] = (b_on**2 + b_in**2) * -math.expm1(-2.0 * dt / tau)
    elif bias_time_s:
        q[9:12] = gyro_bias_si**2 * dt / bias_time_s
        q[12:15] = accel_bias_si**2 * dt / bias_time_s
    if L.scale_factors and bias_time_s:
        q[L.gyro_scale] = gyro_scale**2 * dt / bias_time_s
        q[L.accel_scale] = accel_scale**2 * dt / bias_time_s
    Q = np.diag(q)
    clock = clock or ClockModel()
    Q[15:17, 15:17] = clock.Q(dt) if with_clock else np.diag([1e-6, 1e-8]) * dt
    return Q
