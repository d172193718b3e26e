"""IMU error model: scale factor, constant bias and white noise (angle/velocity random walk).

Measurement model per axis (body Right-Front-Up), for accelerometers and gyros alike::

    y[k] = (1 + s) * x[k] + b + n[k]

with ``x[k]`` the true interval-average specific force [m/s^2] or angular rate [rad/s]
(:mod:`sdr_di.sim.trajectory` convention: average over ``(t_{k-1}, t_k]``), ``s`` the scale
factor error [-], ``b`` the constant bias, and ``n[k]`` the average over the interval of a
white noise of (two-sided) spectral density ``N^2`` — the random-walk coefficient ``N``:

    std(n[k]) = N / sqrt(dt),          dt = 1 / rate

so the integrated noise (velocity or angle random walk) has ``std = N sqrt(T)`` after ``T``
seconds *whatever the sample rate*. Units: ``N`` given as m/s/sqrt(h) becomes
``N / 60`` (m/s)/sqrt(s); deg/sqrt(h) becomes ``radians(N) / 60`` rad/sqrt(s).

The scale factor and bias of each axis are random constants drawn once per run:
``draw="gaussian"`` (default) draws them zero-mean Gaussian with the specified value as the
standard deviation (1-sigma spec, as a Monte Carlo campaign wants); ``draw="fixed"`` sets
every axis to exactly +spec (deterministic, e.g. to reproduce a fixed 4 mg bias). Defaults are
paper 004 Table 4 (MEMS): 100 ppm, 4 mg, 8 deg/h, 0.05 m/s/sqrt(h), 0.04 deg/sqrt(h).

Randomness comes only from the ``numpy.random.Generator`` passed to :meth:`ImuErrorModel.apply`,
drawn in a fixed order (accel scale, gyro scale, accel bias, gyro bias: each (3,); then accel
noise (n, 3), gyro noise (n, 3)), so the same seed gives the same record.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Protocol

import numpy as np

#: Standard gravity for milli-g conversions [m/s^2].
G_STANDARD = 9.80665


class _HasImuSignals(Protocol):
    t: np.ndarray
    f_b: np.ndarray
    w_ib_b: np.ndarray
    rate_hz: float


@dataclasses.dataclass
class ImuData:
    """IMU record (measured or true) at the IMU rate.

    Attributes
    ----------
    t : (n,) array
        Time of sample ``k`` = end of its averaging interval [s since scenario start].
    f_b : (n, 3) array
        Specific force, body Right-Front-Up axes, average over (t_{k-1}, t_k] [m/s^2].
    w_ib_b : (n, 3) array
        Angular rate w.r.t. inertial space, body axes, average over (t_{k-1}, t_k] [rad/s].
    rate_hz : float
        Nominal sample rate [Hz].
    accel_bias, gyro_bias : (3,) arrays or None
        The true constant biases drawn for this record [m/s^2], [rad/s] (None if unknown).
    accel_scale, gyro_scale : (3,) arrays or None
        The true scale factor errors drawn [-] (1e-6 = 1 ppm; None if unknown).
    week, sow : int or None, float or None
        BDT week and seconds of week of ``t = 0`` (None if unknown).
    """

    t: np.ndarray
    f_b: np.ndarray
    w_ib_b: np.ndarray
    rate_hz: float
    accel_bias: np.ndarray | None = None
    gyro_bias: np.ndarray | None = None
    accel_scale: np.ndarray | None = None
    gyro_scale: np.ndarray | None = None
    week: int | None = None
    sow: float | None = None

    def __len__(self) -> int:
        return len(self.t)

    @property
    def dt(self) -> float:
        """Nominal sample interval [s]."""
        return 1.0 / self.rate_hz


@dataclasses.dataclass(frozen=True)
class ImuErrorModel:
    """IMU error specification (user units) and its application to a true IMU signal.

    Parameters
    ----------
    accel_scale_factor_ppm, gyro_scale_factor_ppm : float
        Scale factor error [ppm] (1-sigma for ``draw="gaussian"``).
    accel_bias_mg : float
        Accelerometer constant bias [mg] (1 mg = 9.80665e-3 m/s^2).
    gyro_bias_deg_h : float
        Gyro constant bias [deg/h].
    accel_random_walk : float
        Velocity random walk [m/s/sqrt(h)].
    gyro_random_walk : float
        Angle random walk [deg/sqrt(h)].
    draw : {"gaussian", "fixed"}
        How the per-axis constants are set (module docstring).
    """

    accel_scale_factor_ppm: float = 100.0
    gyro_scale_factor_ppm: float = 100.0
    accel_bias_mg: float = 4.0
    gyro_bias_deg_h: float = 8.0
    accel_random_walk: float = 0.05
    gyro_random_walk: float = 0.04
    draw: str = "gaussian"

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name == "draw":
                continue
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"ImuErrorModel.{f.name} must be a finite number >= 0, got {v!r}")
        if self.draw not in ("gaussian", "fixed"):
            raise ValueError(f"ImuErrorModel.draw must be 'gaussian' or 'fixed', got {self.draw!r}")

    @classmethod
    def from_spec(cls, spec, draw: str = "gaussian") -> ImuErrorModel:
        """Build from a scenario ``ImuSpec`` (:mod:`sdr_di.scenario.schema`; same units)."""
        return cls(
            accel_scale_factor_ppm=spec.accel_scale_factor_ppm,
            gyro_scale_factor_ppm=spec.gyro_scale_factor_ppm,
            accel_bias_mg=spec.accel_bias_mg,
            gyro_bias_deg_h=spec.gyro_bias_deg_h,
            accel_random_walk=spec.accel_random_walk_mps_sqrth,
            gyro_random_walk=spec.gyro_random_walk_deg_sqrth,
            draw=draw,
        )

    @classmethod
    def perfect(cls) -> ImuErrorModel:
        """The error-free IMU."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def is_perfect(self) -> bool:
        """True when every error term is zero."""
        return all(getattr(self, f.name) == 0 for f in dataclasses.fields(self) if f.name != "draw")

    # SI conversions ----------------------------------------------------------------------
    @property
    def accel_bias_si(self) -> float:
        """Accelerometer bias [m/s^2]."""
        return self.accel_bias_mg * 1e-3 * G_STANDARD

    @property
    def gyro_bias_si(self) -> float:
        """Gyro bias [rad/s]."""
        return math.radians(self.gyro_bias_deg_h) / 3600.0

    @property
    def accel_random_walk_si(self) -> float:
        """Velocity random walk [(m/s)/sqrt(s)] = white-noise density [(m/s^2)/sqrt(Hz)]."""
        return self.accel_random_walk / 60.0

    @property
    def gyro_random_walk_si(self) -> float:
        """Angle random walk [rad/sqrt(s)] = white-noise density [(rad/s)/sqrt(Hz)]."""
        return math.radians(self.gyro_random_walk) / 60.0

    def apply(self, truth: _HasImuSignals, rng: np.random.Generator | None) -> ImuData:
        """Corrupt a true IMU signal.

        Parameters
        ----------
        truth : Truth or ImuData
            Anything with ``t`` (n,), ``f_b`` (n,3) [m/s^2], ``w_ib_b`` (n,3) [rad/s]
            (interval averages) and ``rate_hz``.
        rng : numpy.random.Generator
            The only source of randomness. May be None for a perfect model.

        Returns
        -------
        ImuData
            Measured ``f_b``, ``w_ib_b`` and the drawn constants (SI).
        """
        n = len(truth.t)
        f = np.asarray(truth.f_b, float)
        w = np.asarray(truth.w_ib_b, float)
        dt = 1.0 / float(truth.rate_hz)
        if self.is_perfect:
            z = np.zeros(3)
            return ImuData(t=np.array(truth.t, float), f_b=f.copy(), w_ib_b=w.copy(),
                           rate_hz=float(truth.rate_hz), accel_bias=z, gyro_bias=z.copy(),
                           accel_scale=z.copy(), gyro_scale=z.copy())
        if not isinstance(rng, np.random.Generator):
            raise TypeError("ImuErrorModel.apply needs a numpy.random.Generator")
        def const(sigma):
            """One draw of a per-axis constant: N(0, sigma^2) per axis, or sigma itself."""
            if self.draw == "gaussian":
                return sigma * rng.standard_normal(3)
            return np.full(3, float(sigma))
        s_a = const(self.accel_scale_factor_ppm * 1e-6)
        s_g = const(self.gyro_scale_factor_ppm * 1e-6)
        b_a = const(self.accel_bias_si)
        b_g = const(self.gyro_bias_si)
        n_a = rng.standard_normal((n, 3)) * (self.accel_random_walk_si / math.sqrt(dt))
        n_g = rng.standard_normal((n, 3)) * (self.gyro_random_walk_si / math.sqrt(dt))
        return ImuData(
            t=np.array(truth.t, float),
            f_b=(1.0 + s_a) * f + b_a + n_a,
            w_ib_b=(1.0 + s_g) * w + b_g + n_g,
            rate_hz=float(truth.rate_hz),
            accel_bias=b_a, gyro_bias=b_g, accel_scale=s_a, gyro_scale=s_g,
        )
