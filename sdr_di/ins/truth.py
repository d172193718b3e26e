"""Reference trajectory record ("truth"): position, velocity, attitude and IMU signals.

Written by the generator (:mod:`sdr_di.sim.trajectory`), read back from ``*_truth.csv``
(:func:`sdr_di.io.imu_files.read_truth`) and used as the reference of the receivers' error
columns and of the ``align="truth"`` INS initialization; it lives here, below the simulator,
so that the readers and receivers need not import the simulator. Frames: ENU navigation,
body Right-Front-Up, ECEF CGCS2000.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["Truth"]


@dataclasses.dataclass
class Truth:
    """Reference trajectory sampled at ``rate_hz``.

    Attributes
    ----------
    t : (n,) array
        Time since the scenario start [s], ``t[k] = k / rate_hz``.
    llh : (n, 3) array
        Geodetic latitude [rad], longitude [rad], ellipsoidal height [m] (CGCS2000).
    v_n : (n, 3) array
        Earth-relative velocity in ENU [m/s].
    att : (n, 3) array
        Pitch, roll, yaw [rad] (yaw clockwise from North, in [0, 2 pi)).
    C_b_n : (n, 3, 3) array
        Body (Right-Front-Up) to ENU rotation.
    f_b : (n, 3) array
        Specific force in body axes [m/s^2], **average over (t_{k-1}, t_k]**.
    w_ib_b : (n, 3) array
        Angular rate of body w.r.t. inertial space, body axes [rad/s], **average over
        (t_{k-1}, t_k]**.
    r_e, v_e, a_e : (n, 3) arrays
        ECEF position [m], velocity [m/s] and acceleration [m/s^2] (time derivatives in the
        rotating ECEF frame, not inertial), instantaneous at ``t``.
    rate_hz : float
        Sample rate [Hz].
    clock_bias_s, clock_drift_s_s : (n,) arrays or None
        True receiver clock at ``t``: bias = receiver time - true time [s] and drift
        (fractional frequency, average over ``(t_{k-1}, t_k]``) [s/s]
        (:mod:`sdr_di.sim.oscillator`); None in a truth file without the clock columns.
    """

    t: np.ndarray
    llh: np.ndarray
    v_n: np.ndarray
    att: np.ndarray
    C_b_n: np.ndarray
    f_b: np.ndarray
    w_ib_b: np.ndarray
    r_e: np.ndarray
    v_e: np.ndarray
    a_e: np.ndarray
    rate_hz: float
    clock_bias_s: np.ndarray | None = None
    clock_drift_s_s: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    @property
    def dt(self) -> float:
        """Sample interval [s]."""
        return 1.0 / self.rate_hz

    def at_times(self, t, atol_s: float = 1e-6) -> Truth | None:
        """The rows at the times ``t`` [s] (every ``t`` one of :attr:`t` within ``atol_s``:
        a 200 Hz reference on a 50 Hz IMU's grid); None when some ``t`` is not a sample
        time. ``f_b`` and ``w_ib_b`` keep their own (shorter) averaging intervals."""
        t = np.asarray(t, float)
        idx = np.clip(np.searchsorted(self.t, t - atol_s), 0, len(self.t) - 1)
        if not np.all(np.abs(self.t[idx] - t) <= atol_s):
            return None
        rate = self.rate_hz * (len(t) - 1) / max(int(idx[-1] - idx[0]), 1) if len(t) > 1 \
            else self.rate_hz

        def take(a):
            return None if a is None else np.asarray(a)[idx]

        return Truth(t=self.t[idx], llh=take(self.llh), v_n=take(self.v_n), att=take(self.att),
                     C_b_n=take(self.C_b_n), f_b=take(self.f_b), w_ib_b=take(self.w_ib_b),
                     r_e=take(self.r_e), v_e=take(self.v_e), a_e=take(self.a_e),
                     rate_hz=float(rate), clock_bias_s=take(self.clock_bias_s),
                     clock_drift_s_s=take(self.clock_drift_s_s))

    def ecef_at(self, t) -> tuple[np.ndarray, np.ndarray]:
        """ECEF position [m] and velocity [m/s] at times ``t`` [s] by quintic Hermite interpolation.

        Uses ``r_e``, ``v_e``, ``a_e`` at the two samples around each time (C2 interpolant).
        For the default scenario at 200 Hz the position error is at the rounding level of
        float64 ECEF coordinates (4e-9 m) and the velocity error below 1e-5 m/s (limited by
        that rounding divided by the 5 ms interval); a cubic Hermite spline of ``r_e``,
        ``v_e`` alone does as well here. Times outside ``[t0, t_end]`` raise ``ValueError``.
        """
        t = np.asarray(t, float)
        if np.any(t < self.t[0] - 1e-12) or np.any(t > self.t[-1] + 1e-12):
            raise ValueError(f"ecef_at: times outside [{self.t[0]}, {self.t[-1]}] s")
        h = self.dt
        k = np.clip(np.floor((t - self.t[0]) / h).astype(int), 0, len(self.t) - 2)
        u = ((t - self.t[k]) / h)[..., None]
        u2, u3, u4, u5 = u * u, u**3, u**4, u**5
        p0, v0, a0 = self.r_e[k], self.v_e[k], self.a_e[k]
        p1, v1, a1 = self.r_e[k + 1], self.v_e[k + 1], self.a_e[k + 1]
        H0 = 1 - 10 * u3 + 15 * u4 - 6 * u5
        H1 = u - 6 * u3 + 8 * u4 - 3 * u5
        H2 = 0.5 * u2 - 1.5 * u3 + 1.5 * u4 - 0.5 * u5
        H3 = 10 * u3 - 15 * u4 + 6 * u5
        H4 = -4 * u3 + 7 * u4 - 3 * u5
        H5 = 0.5 * u3 - u4 + 0.5 * u5
        r = H0 * p0 + H1 * h * v0 + H2 * h * h * a0 + H3 * p1 + H4 * h * v1 + H5 * h * h * a1
        D0 = -30 * u2 + 60 * u3 - 30 * u4
        D1 = 1 - 18 * u2 + 32 * u3 - 15 * u4
        D2 = u - 4.5 * u2 + 6 * u3 - 2.5 * u4
        D4 = -12 * u2 + 28 * u3 - 15 * u4
        D5 = 1.5 * u2 - 4 * u3 + 2.5 * u4
        v = (D0 * (p0 - p1) / h + D1 * v0 + D2 * h * a0 + D4 * v1 + D5 * h * a1)
        return r, v
