"""Trajectory truth: kinematically exact position, velocity, attitude and IMU signals.

Frames (see :mod:`sdr_di.frames`): navigation frame ENU (``n``), body Right-Front-Up
(``b``), ECEF CGCS2000 (``e``); ``C_b_n`` rotates body vectors into ENU. Attitude is
(pitch, roll, yaw) [rad], yaw clockwise from North in [0, 2 pi).

How the truth is made
---------------------
The motion segments (:mod:`sdr_di.sim.motion`) give speed ``V``, flight-path angle
``gamma``, track ``psi`` and bank ``phi`` and their time derivatives in closed form. The ENU
velocity ``v_n = V (cos g sin psi, cos g cos psi, sin g)`` and its derivative are therefore
analytic; the geodetic position obeys

    lat' = v_N / (R_M + h),   lon' = v_E / ((R_N + h) cos lat),   h' = v_U

on the CGCS2000 ellipsoid, integrated with scipy's 8th-order Dormand-Prince (DOP853,
rtol 1e-13) between the break points of the motion (segment ends and ramp ends, where
higher derivatives jump), with its dense output. Attitude is pitch = gamma + pitch_off,
roll = phi + roll_off, yaw = psi + yaw_off (constant offsets from the initial state, zero for
the paper scenario). From these, at any instant,

    f_b    = C_n_b (dv_n/dt + (2 w_ie^n + w_en^n) x v_n - g_n)      (specific force)
    w_ib_b = w_nb_b + C_n_b (w_ie^n + w_en^n)                        (inertial angular rate)

with ``w_nb_b`` from the Euler angle rates, ``g_n`` CGCS2000 normal gravity
(:mod:`sdr_di.ins.gravity`), ``w_en^n`` the transport rate.

IMU sample convention
---------------------
Sample ``k`` of ``f_b`` and ``w_ib_b`` is the **average over the preceding interval**
``(t_{k-1}, t_k]`` (``dt = 1 / rate_hz``): ``f_b[k] = dv_k / dt`` and
``w_ib_b[k] = dtheta_k / dt`` with the body-frame integrals ``dv_k = int f_b dt`` and
``dtheta_k = int w_ib_b dt`` — the increments an integrating IMU delivers and what coning and
sculling algorithms expect. They are computed from the instantaneous values by 4-point
Gauss-Legendre quadrature on each interval split at the motion break points (exact to
rounding). Sample 0 is the average over ``(-dt, 0]`` of the steady motion before the start;
an INS started at ``t_0`` uses it only as the "previous increment". Position, velocity,
attitude, ``r_e``, ``v_e``, ``a_e`` are **instantaneous** values at ``t_k``.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.integrate import solve_ivp

from ..frames import (
    C_e_n,
    earth_rate_n,
    euler_to_C_b_n,
    llh_to_ecef,
    radii_of_curvature,
    transport_rate_n,
)
from ..ins.gravity import gravity_n
from ..ins.truth import Truth
from .motion import G0_BANK, MotionState, Profile, Segment, Uniform, default_segments

__all__ = ["Truth", "TrajectoryModel", "generate_trajectory", "build_model", "sample_truth",
           "default_segments"]

_GL_X, _GL_W = np.polynomial.legendre.leggauss(4)


class TrajectoryModel:
    """The continuous-time motion behind a :class:`Truth` (evaluable at any instant).

    Built by :func:`generate_trajectory`; :meth:`evaluate` gives the exact instantaneous
    state at arbitrary times in ``[-1 s, t_end]`` (before 0 and after the last segment the
    motion is steady).
    """

    def __init__(self, lat0: float, lon0: float, h0: float, v_n0, att0,
                 segments: Sequence[Segment], duration: float | None = None):
        v0 = np.asarray(v_n0, float).reshape(3)
        pitch0, roll0, yaw0 = (float(a) for a in np.asarray(att0, float).reshape(3))
        speed0 = float(np.linalg.norm(v0))
        if speed0 > 1e-9:
            gamma0 = math.asin(max(-1.0, min(1.0, v0[2] / speed0)))
            track0 = math.atan2(v0[0], v0[1])
        else:
            speed0, gamma0, track0 = 0.0, 0.0, yaw0
        self.offsets = (pitch0 - gamma0, roll0, yaw0 - track0)
        segs = list(segments)
        total = sum(s.duration for s in segs)
        if duration is not None:
            if not (duration > 0 and math.isfinite(duration)):
                raise ValueError(f"duration must be finite and > 0, got {duration!r}")
            if duration > total + 1e-9:
                segs.append(Uniform(duration - total))  # the last state is held
            total = duration
        if not segs:
            raise ValueError("no motion segments and no duration")
        self.t_end = float(total)
        profiles: list[Profile] = []
        state = MotionState(speed0, gamma0, track0)
        t0 = 0.0
        for i, seg in enumerate(segs):
            try:
                prof = seg.plan(t0, state)
            except ValueError as exc:
                raise ValueError(f"motion segment {i} ({type(seg).__name__}): {exc}") from None
            profiles.append(prof)
            state = prof.end_state()
            t0 = prof.t_end
        self.profiles = profiles
        self._starts = np.array([p.t0 for p in profiles])
        bps = sorted({b for p in profiles for b in p.breakpoints() if b < self.t_end} | {self.t_end})
        self.breakpoints = np.array(bps)
        self._integrate_position(lat0, lon0, h0)

    # --- closed-form motion --------------------------------------------------------------
    def motion(self, t) -> dict[str, np.ndarray]:
        """Speed, flight-path angle, track and derivatives at times ``t`` [s] (see Profile)."""
        t = np.atleast_1d(np.asarray(t, float))
        idx = np.clip(np.searchsorted(self._starts, t, side="right") - 1, 0, len(self.profiles) - 1)
        out = {k: np.empty_like(t) for k in
               ("V", "V_dot", "gamma", "gamma_dot", "psi", "psi_dot", "psi_ddot")}
        for i in np.unique(idx):
            m = idx == i
            p = self.profiles[i]
            for k, v in p.evaluate(t[m] - p.t0).items():
                out[k][m] = v
        return out

    def velocity(self, t) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """ENU velocity [m/s], its time derivative [m/s^2] and the motion dict at ``t``."""
        m = self.motion(t)
        cg, sg = np.cos(m["gamma"]), np.sin(m["gamma"])
        cp, sp = np.cos(m["psi"]), np.sin(m["psi"])
        u = np.stack([cg * sp, cg * cp, sg], axis=-1)
        du_dg = np.stack([-sg * sp, -sg * cp, cg], axis=-1)
        du_dp = np.stack([cg * cp, -cg * sp, np.zeros_like(cg)], axis=-1)
        V = m["V"][:, None]
        v_n = V * u
        a_n = (m["V_dot"][:, None] * u + V * (m["gamma_dot"][:, None] * du_dg
                                              + m["psi_dot"][:, None] * du_dp))
        return v_n, a_n, m

    def _rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        v, _, _ = self.velocity(t)
        ve, vn, vu = v[0]
        R_M, R_N = radii_of_curvature(y[0])
        return np.array([vn / (R_M + y[2]), ve / ((R_N + y[2]) * math.cos(y[0])), vu])

    def _integrate_position(self, lat0: float, lon0: float, h0: float) -> None:
        y0 = np.array([lat0, lon0, h0], float)
        opts = dict(method="DOP853", rtol=1e-13, atol=[1e-15, 1e-15, 1e-9], dense_output=True)
        # backward piece [-1 s, 0] (steady motion before the start: IMU sample 0)
        back = solve_ivp(self._rhs, (0.0, -1.0), y0, **opts)
        pieces = [(-1.0, 0.0, back.sol)]
        y = y0
        edges = np.concatenate([[0.0], self.breakpoints[self.breakpoints > 0]])
        for a, b in zip(edges[:-1], edges[1:]):
            if b - a < 1e-12:
                continue
            sol = solve_ivp(self._rhs, (a, b), y, **opts)
            if not sol.success:  # pragma: no cover - DOP853 on a smooth RHS
                raise RuntimeError(f"trajectory integration failed on [{a}, {b}]: {sol.message}")
            pieces.append((a, b, sol.sol))
            y = sol.y[:, -1]
        self._pieces = pieces
        self._piece_starts = np.array([p[0] for p in pieces])

    def position(self, t) -> np.ndarray:
        """Geodetic (lat [rad], lon [rad], h [m]) at times ``t`` in [-1, t_end] [s], (n, 3)."""
        t = np.atleast_1d(np.asarray(t, float))
        if np.any(t < -1.0 - 1e-9) or np.any(t > self.t_end + 1e-9):
            raise ValueError(f"position requested outside [-1, {self.t_end}] s")
        idx = np.clip(np.searchsorted(self._piece_starts, t, side="right") - 1, 0,
                      len(self._pieces) - 1)
        out = np.empty((len(t), 3))
        for i in np.unique(idx):
            m = idx == i
            a, b, sol = self._pieces[i]
            out[m] = sol(np.clip(t[m], a, b)).T
        return out

    # --- full instantaneous state ----------------------------------------------------------
    def evaluate(self, t) -> dict[str, np.ndarray]:
        """Exact instantaneous state at times ``t`` [s].

        Returns
        -------
        dict
            ``llh`` (n,3), ``v_n`` (n,3), ``a_n`` (n,3) = dv_n/dt [m/s^2], ``att`` (n,3),
            ``C_b_n`` (n,3,3), ``f_b`` (n,3) [m/s^2], ``w_ib_b`` (n,3) [rad/s],
            ``w_nb_b`` (n,3) [rad/s].
        """
        t = np.atleast_1d(np.asarray(t, float))
        llh = self.position(t)
        v_n, a_n, m = self.velocity(t)
        lat, h = llh[:, 0], llh[:, 2]
        # coordinated bank angle and its rate
        cg, sg = np.cos(m["gamma"]), np.sin(m["gamma"])
        x = m["V"] * cg * m["psi_dot"] / G0_BANK
        x_dot = (m["V_dot"] * cg * m["psi_dot"] - m["V"] * sg * m["gamma_dot"] * m["psi_dot"]
                 + m["V"] * cg * m["psi_ddot"]) / G0_BANK
        d_pitch, d_roll, d_yaw = self.offsets
        pitch = m["gamma"] + d_pitch
        roll = np.arctan(x) + d_roll
        yaw = m["psi"] + d_yaw
        pitch_dot, roll_dot, yaw_dot = m["gamma_dot"], x_dot / (1 + x * x), m["psi_dot"]
        C = euler_to_C_b_n(pitch, roll, yaw)
        # w_nb^n = -yaw' e_z + pitch' R_z(-yaw) e_x + roll' R_z(-yaw) R_x(pitch) e_y, in body:
        cp, sp, cr, sr = np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
        w_nb_b = np.stack([pitch_dot * cr + yaw_dot * cp * sr,
                           roll_dot - yaw_dot * sp,
                           pitch_dot * sr - yaw_dot * cp * cr], axis=-1)
        w_ie = earth_rate_n(lat)
        w_en = transport_rate_n(lat, h, v_n)
        f_n = a_n + np.cross(2 * w_ie + w_en, v_n) - gravity_n(lat, h)
        f_b = np.einsum("nji,nj->ni", C, f_n)
        w_ib_b = w_nb_b + np.einsum("nji,nj->ni", C, w_ie + w_en)
        att = np.stack([pitch, roll, np.mod(yaw, 2 * np.pi)], axis=-1)
        return {"llh": llh, "v_n": v_n, "a_n": a_n, "att": att, "C_b_n": C, "f_b": f_b,
                "w_ib_b": w_ib_b, "w_nb_b": w_nb_b}

    def imu_averages(self, t_edges: np.ndarray, chunk: int = 100_000) -> tuple[np.ndarray, np.ndarray]:
        """Average ``f_b`` and ``w_ib_b`` over consecutive intervals ``(t_edges[k], t_edges[k+1]]``.

        Exact body-frame integrals (4-point Gauss-Legendre on sub-intervals split at the
        motion break points) divided by the interval length. Returns two (n-1, 3) arrays.
        """
        t_edges = np.asarray(t_edges, float)
        inner = self.breakpoints[(self.breakpoints > t_edges[0]) & (self.breakpoints < t_edges[-1])]
        sub = np.union1d(t_edges, inner)
        sub = sub[np.concatenate([[True], np.diff(sub) > 1e-12])]
        a, b = sub[:-1], sub[1:]
        owner = np.searchsorted(t_edges, 0.5 * (a + b)) - 1
        n_int = len(t_edges) - 1
        acc_f = np.zeros((n_int, 3))
        acc_w = np.zeros((n_int, 3))
        for s0 in range(0, len(a), chunk):
            aa, bb, oo = a[s0:s0 + chunk], b[s0:s0 + chunk], owner[s0:s0 + chunk]
            half = 0.5 * (bb - aa)
            nodes = (0.5 * (aa + bb))[:, None] + half[:, None] * _GL_X[None, :]
            ev = self.evaluate(nodes.ravel())
            wts = (half[:, None] * _GL_W[None, :]).ravel()[:, None]
            f_int = (ev["f_b"] * wts).reshape(len(aa), len(_GL_X), 3).sum(axis=1)
            w_int = (ev["w_ib_b"] * wts).reshape(len(aa), len(_GL_X), 3).sum(axis=1)
            np.add.at(acc_f, oo, f_int)
            np.add.at(acc_w, oo, w_int)
        dt = np.diff(t_edges)[:, None]
        return acc_f / dt, acc_w / dt


def generate_trajectory(lat0: float, lon0: float, h0: float, v_n0, att0,
                        segments: Sequence[Segment] | None = None, rate_hz: float = 200.0,
                        duration: float | None = None) -> Truth:
    """Generate the kinematically exact truth of a segmented motion.

    Parameters
    ----------
    lat0, lon0 : float
        Initial geodetic latitude and longitude [rad] (CGCS2000).
    h0 : float
        Initial ellipsoidal height [m].
    v_n0 : array_like (3,)
        Initial ENU velocity [m/s]; its direction gives the initial track and flight-path
        angle. At zero speed the track is the initial yaw and the flight path is level.
    att0 : array_like (3,)
        Initial pitch, roll, yaw [rad]. Differences pitch - gamma, yaw - track and roll
        (the initial motion is not turning) are kept constant through the trajectory (a
        fixed angle of attack / crab / roll offset); they are zero when the attitude is
        aligned with the initial velocity, as in the paper scenario.
    segments : sequence of Segment, optional
        Motion segments (:mod:`sdr_di.sim.motion`); default :func:`default_segments`.
    rate_hz : float
        Output (IMU) rate [Hz], default 200.
    duration : float, optional
        Total length [s]; default the sum of the segment durations. A longer duration
        holds the last state (uniform motion); a shorter one truncates.

    Returns
    -------
    Truth
        Samples at ``t_k = k / rate_hz``, ``k = 0 .. floor(duration * rate_hz)``; ``f_b`` and
        ``w_ib_b`` are averages over ``(t_{k-1}, t_k]`` (module docstring).

    Raises
    ------
    ValueError
        A segment impossible from the state reached at its start (message names the segment
        index), or an invalid rate / duration.
    """
    model = build_model(lat0, lon0, h0, v_n0, att0, segments, duration)
    return sample_truth(model, rate_hz)


def build_model(lat0: float, lon0: float, h0: float, v_n0, att0,
                segments: Sequence[Segment] | None = None,
                duration: float | None = None) -> TrajectoryModel:
    """Build the continuous :class:`TrajectoryModel` (arguments as :func:`generate_trajectory`)."""
    if segments is None:
        segments = default_segments()
    return TrajectoryModel(lat0, lon0, h0, v_n0, att0, segments, duration)


def sample_truth(model: TrajectoryModel, rate_hz: float = 200.0) -> Truth:
    """Sample a :class:`TrajectoryModel` at ``rate_hz`` into a :class:`Truth`."""
    if not (rate_hz > 0 and math.isfinite(rate_hz)):
        raise ValueError(f"rate_hz must be finite and > 0, got {rate_hz!r}")
    dt = 1.0 / rate_hz
    if dt > 1.0:
        raise ValueError(f"rate_hz must be >= 1 Hz, got {rate_hz!r}")
    n = int(math.floor(model.t_end * rate_hz + 1e-9)) + 1
    t = np.arange(n) * dt
    keys = ("llh", "v_n", "a_n", "att", "C_b_n")
    parts = {k: [] for k in keys}
    for i0 in range(0, n, 50_000):  # bounded temporaries for long scenarios
        ev = model.evaluate(t[i0:i0 + 50_000])
        for k in keys:
            parts[k].append(ev[k])
    ev = {k: np.concatenate(v) for k, v in parts.items()}
    edges = np.concatenate([[-dt], t])
    f_b, w_ib_b = model.imu_averages(edges, chunk=25_000)
    llh, v_n = ev["llh"], ev["v_n"]
    lat, lon, h = llh[:, 0], llh[:, 1], llh[:, 2]
    C_n_e = np.swapaxes(C_e_n(lat, lon), -1, -2)
    w_en = transport_rate_n(lat, h, v_n)
    r_e = llh_to_ecef(lat, lon, h)
    v_e = np.einsum("nij,nj->ni", C_n_e, v_n)
    a_e = np.einsum("nij,nj->ni", C_n_e, ev["a_n"] + np.cross(w_en, v_n))
    return Truth(t=t, llh=llh, v_n=v_n, att=ev["att"], C_b_n=ev["C_b_n"], f_b=f_b,
                 w_ib_b=w_ib_b, r_e=r_e, v_e=v_e, a_e=a_e, rate_hz=float(rate_hz))
