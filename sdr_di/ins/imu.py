"""IMU error model: scale factor, biases (turn-on and in-run), misalignment, gyro
g-sensitivity and white noise (angle/velocity random walk).

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

Unit errors of a grade (issue 46; the grade tables and their datasheets are
:mod:`sdr_di.ins.grades`). A model with any of the terms below is *extended*; its full
measurement model, vector form, body axes::

    f~_b[k]    = (I + S_a + M_a) f_b[k] + b_a + d_a[k] + n_a[k]
    w~_ib_b[k] = (I + S_g + M_g) w_ib_b[k] + b_g + d_g[k] + G_g f_b[k] + n_g[k]

* ``S_a, S_g`` diagonal scale-factor errors and ``b_a, b_g`` turn-on biases: as above;
* ``M_a, M_g`` misalignment (axis non-orthogonality and mounting), zero diagonal, each of the
  six off-diagonal elements a random constant of 1-sigma ``*_misalignment_mrad`` [rad];
* ``G_g`` gyro g-sensitivity [rad/s per m/s^2]: each of the nine elements a random constant
  of 1-sigma ``gyro_g_sensitivity_deg_h_per_g``;
* ``d_a, d_g`` in-run bias: a first-order Gauss-Markov process per axis of stationary 1-sigma
  ``*_bias_instability_*`` and correlation time ``*_bias_tau_s``, *starting from zero at
  switch-on* (the switch-on value is the turn-on bias ``b``; the in-run term is the wander
  since): ``d[k] = a d[k-1] + sigma sqrt(1 - a^2) w[k]``, ``a = exp(-dt / tau)``,
  ``d[-1] = 0``, so ``var d[k] = sigma^2 (1 - a^(2 (k + 1)))``.

Extended draws follow the legacy constants in the same generator: accel scale, gyro scale,
accel bias, gyro bias (as above), then ``M_a`` and ``M_g`` (six each, row-major off-diagonal
order), ``G_g`` (nine, row-major), then one row of twelve unit normals per sample (accel
noise, gyro noise, accel and gyro Gauss-Markov drives, three each). The unit's constants are
drawn before anything whose count depends on the record length, and the per-sample draws
row by row, so the same seed gives the same unit, and the same noise and in-run bias over
the common span, whatever the duration.
A model without extended terms draws exactly as before (the default scenario's files are
unchanged byte for byte).
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
    unit : ImuUnit or None
        All the constants drawn for an extended model (misalignment, g-sensitivity too) and
        its in-run bias paths (None for a legacy model or a record read from a file).
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
    unit: ImuUnit | None = None

    def __len__(self) -> int:
        return len(self.t)

    @property
    def dt(self) -> float:
        """Nominal sample interval [s]."""
        return 1.0 / self.rate_hz


@dataclasses.dataclass
class ImuUnit:
    """The errors of one IMU unit and switch-on, as drawn by :meth:`ImuErrorModel.draw_unit`
    (SI, body Right-Front-Up axes; module docstring for the measurement model).

    Attributes
    ----------
    accel_scale, gyro_scale : (3,) arrays
        Scale-factor errors ``diag(S_a)``, ``diag(S_g)`` [-].
    accel_bias, gyro_bias : (3,) arrays
        Turn-on biases ``b_a`` [m/s^2], ``b_g`` [rad/s].
    M_a, M_g : (3, 3) arrays
        Misalignment matrices (zero diagonal) [rad].
    G_g : (3, 3) array
        Gyro g-sensitivity [(rad/s) / (m/s^2)].
    d_a, d_g : (n, 3) arrays or None
        In-run (Gauss-Markov) bias paths at the record's samples [m/s^2], [rad/s] (set by
        :meth:`ImuErrorModel.apply`).
    """

    accel_scale: np.ndarray
    gyro_scale: np.ndarray
    accel_bias: np.ndarray
    gyro_bias: np.ndarray
    M_a: np.ndarray
    M_g: np.ndarray
    G_g: np.ndarray
    d_a: np.ndarray | None = None
    d_g: np.ndarray | None = None

    def record(self) -> dict:
        """The draws as plain lists (sidecar ``imu_unit``, truth-file header): constants in
        SI, and the in-run biases at the first and last sample and their RMS over the record
        (the paths themselves follow from the seed)."""
        out = {k: np.asarray(getattr(self, k), float).tolist()
               for k in ("accel_bias", "gyro_bias", "accel_scale", "gyro_scale", "M_a", "M_g",
                         "G_g")}
        for k in ("d_a", "d_g"):
            d = getattr(self, k)
            if d is not None and len(d):
                out[f"{k}_first"] = d[0].tolist()
                out[f"{k}_last"] = d[-1].tolist()
                out[f"{k}_rms"] = np.sqrt(np.mean(d * d, axis=0)).tolist()
        return out


#: One milliradian [rad] (the misalignment keys are in mrad).
_MRAD = 1e-3


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
    accel_bias_instability_mg : float
        In-run accelerometer bias instability [mg]: stationary 1-sigma of the Gauss-Markov
        in-run bias (module docstring).
    gyro_bias_instability_deg_h : float
        In-run gyro bias instability [deg/h], likewise.
    accel_bias_tau_s, gyro_bias_tau_s : float
        Correlation times of the in-run biases [s] (> 0).
    accel_misalignment_mrad, gyro_misalignment_mrad : float
        1-sigma of each off-diagonal element of the misalignment matrices [mrad].
    gyro_g_sensitivity_deg_h_per_g : float
        1-sigma of each element of the gyro g-sensitivity matrix [deg/h per g].
    """

    accel_scale_factor_ppm: float = 100.0
    gyro_scale_factor_ppm: float = 100.0
    accel_bias_mg: float = 4.0
    gyro_bias_deg_h: float = 8.0
    accel_random_walk: float = 0.05
    gyro_random_walk: float = 0.04
    draw: str = "gaussian"
    accel_bias_instability_mg: float = 0.0
    gyro_bias_instability_deg_h: float = 0.0
    accel_bias_tau_s: float = 3600.0
    gyro_bias_tau_s: float = 3600.0
    accel_misalignment_mrad: float = 0.0
    gyro_misalignment_mrad: float = 0.0
    gyro_g_sensitivity_deg_h_per_g: float = 0.0

    #: The extended terms (module docstring); a model with all of them zero is a legacy one.
    EXTENDED = ("accel_bias_instability_mg", "gyro_bias_instability_deg_h",
                "accel_misalignment_mrad", "gyro_misalignment_mrad",
                "gyro_g_sensitivity_deg_h_per_g")
    _TAUS = ("accel_bias_tau_s", "gyro_bias_tau_s")

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name == "draw":
                continue
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool)
                    and math.isfinite(v) and v >= 0):
                raise ValueError(f"ImuErrorModel.{f.name} must be a finite number >= 0, got {v!r}")
            if f.name in self._TAUS and v <= 0:
                raise ValueError(f"ImuErrorModel.{f.name} must be > 0, got {v!r}")
        if self.draw not in ("gaussian", "fixed"):
            raise ValueError(f"ImuErrorModel.draw must be 'gaussian' or 'fixed', got {self.draw!r}")

    @classmethod
    def from_spec(cls, spec, draw: str = "gaussian") -> ImuErrorModel:
        """Build from a scenario ``ImuSpec`` (:mod:`sdr_di.scenario.schema`; same units)."""
        ext = {name: getattr(spec, name) for name in cls.EXTENDED + cls._TAUS
               if hasattr(spec, name)}
        return cls(
            accel_scale_factor_ppm=spec.accel_scale_factor_ppm,
            gyro_scale_factor_ppm=spec.gyro_scale_factor_ppm,
            accel_bias_mg=spec.accel_bias_mg,
            gyro_bias_deg_h=spec.gyro_bias_deg_h,
            accel_random_walk=spec.accel_random_walk_mps_sqrth,
            gyro_random_walk=spec.gyro_random_walk_deg_sqrth,
            draw=draw, **ext,
        )

    @classmethod
    def perfect(cls) -> ImuErrorModel:
        """The error-free IMU."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)

    @property
    def is_perfect(self) -> bool:
        """True when every error term is zero (the correlation times do not count)."""
        return all(getattr(self, f.name) == 0 for f in dataclasses.fields(self)
                   if f.name != "draw" and f.name not in self._TAUS)

    @property
    def is_extended(self) -> bool:
        """True when any term beyond paper 004's six is set (module docstring)."""
        return any(getattr(self, name) != 0 for name in self.EXTENDED)

    def as_dict(self) -> dict:
        """The fields for summaries: all of an extended model, paper 004's six and ``draw``
        otherwise (the summaries of legacy runs keep their keys)."""
        d = dataclasses.asdict(self)
        if not self.is_extended:
            for name in self.EXTENDED + self._TAUS:
                del d[name]
        return d

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

    @property
    def accel_bias_instability_si(self) -> float:
        """In-run accelerometer bias 1-sigma [m/s^2]."""
        return self.accel_bias_instability_mg * 1e-3 * G_STANDARD

    @property
    def gyro_bias_instability_si(self) -> float:
        """In-run gyro bias 1-sigma [rad/s]."""
        return math.radians(self.gyro_bias_instability_deg_h) / 3600.0

    @property
    def gyro_g_sensitivity_si(self) -> float:
        """Gyro g-sensitivity 1-sigma per element [(rad/s) / (m/s^2)]."""
        return math.radians(self.gyro_g_sensitivity_deg_h_per_g) / 3600.0 / G_STANDARD

    def draw_unit(self, rng: np.random.Generator) -> ImuUnit:
        """The constants of one unit and switch-on (module docstring: order of the draws).

        Parameters
        ----------
        rng : numpy.random.Generator
            The only source of randomness (untouched by a ``draw="fixed"`` model).

        Returns
        -------
        ImuUnit
            Scale factors, turn-on biases and, for an extended model, the misalignment and
            g-sensitivity matrices (zero for a legacy one); no in-run paths yet.
        """
        def const(sigma, n=3):
            """One draw of ``n`` constants: N(0, sigma^2) each, or sigma itself."""
            if self.draw == "gaussian":
                return sigma * rng.standard_normal(n)
            return np.full(n, float(sigma))
        s_a = const(self.accel_scale_factor_ppm * 1e-6)
        s_g = const(self.gyro_scale_factor_ppm * 1e-6)
        b_a = const(self.accel_bias_si)
        b_g = const(self.gyro_bias_si)
        M_a, M_g, G_g = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
        if self.is_extended:
            off = ~np.eye(3, dtype=bool)
            M_a[off] = const(self.accel_misalignment_mrad * _MRAD, 6)
            M_g[off] = const(self.gyro_misalignment_mrad * _MRAD, 6)
            G_g[:] = const(self.gyro_g_sensitivity_si, 9).reshape(3, 3)
        return ImuUnit(s_a, s_g, b_a, b_g, M_a, M_g, G_g)

    @staticmethod
    def gauss_markov(w: np.ndarray, sigma: float, tau_s: float, dt: float) -> np.ndarray:
        """First-order Gauss-Markov paths from zero, driven by unit white samples ``w``
        (n, k): ``d[j] = a d[j-1] + sigma sqrt(1 - a^2) w[j]``, ``d[-1] = 0``,
        ``a = exp(-dt / tau_s)`` (exact discretization; stationary 1-sigma ``sigma``)."""
        from scipy.signal import lfilter

        a = math.exp(-dt / tau_s)
        return lfilter([sigma * math.sqrt(1.0 - a * a)], [1.0, -a], w, axis=0)

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
        u = self.draw_unit(rng)
        s_a, s_g, b_a, b_g = u.accel_scale, u.gyro_scale, u.accel_bias, u.gyro_bias
        if not self.is_extended:
            # the legacy draws and formula, operation for operation (byte-identical records)
            n_a = rng.standard_normal((n, 3)) * (self.accel_random_walk_si / math.sqrt(dt))
            n_g = rng.standard_normal((n, 3)) * (self.gyro_random_walk_si / math.sqrt(dt))
            return ImuData(
                t=np.array(truth.t, float),
                f_b=(1.0 + s_a) * f + b_a + n_a,
                w_ib_b=(1.0 + s_g) * w + b_g + n_g,
                rate_hz=float(truth.rate_hz),
                accel_bias=b_a, gyro_bias=b_g, accel_scale=s_a, gyro_scale=s_g,
            )
        # one row of twelve per sample: a longer record extends a shorter one's noise
        z = rng.standard_normal((n, 12))
        n_a = z[:, 0:3] * (self.accel_random_walk_si / math.sqrt(dt))
        n_g = z[:, 3:6] * (self.gyro_random_walk_si / math.sqrt(dt))
        u.d_a = self.gauss_markov(z[:, 6:9], self.accel_bias_instability_si,
                                  self.accel_bias_tau_s, dt)
        u.d_g = self.gauss_markov(z[:, 9:12], self.gyro_bias_instability_si,
                                  self.gyro_bias_tau_s, dt)
        K_a = np.diag(s_a) + u.M_a
        K_g = np.diag(s_g) + u.M_g
        return ImuData(
            t=np.array(truth.t, float),
            f_b=f + f @ K_a.T + b_a + u.d_a + n_a,
            w_ib_b=w + w @ K_g.T + b_g + u.d_g + f @ u.G_g.T + n_g,
            rate_hz=float(truth.rate_hz),
            accel_bias=b_a, gyro_bias=b_g, accel_scale=s_a, gyro_scale=s_g, unit=u,
        )
