"""Motion segments: the building blocks of a vehicle trajectory.

A trajectory is a sequence of segments, each lasting ``duration`` seconds. The vehicle is
described by four time functions:

* speed ``V`` [m/s] along the velocity vector (Earth-relative),
* flight-path angle ``gamma`` [rad] (velocity elevation above the local horizontal),
* track ``psi`` [rad] (velocity azimuth, clockwise from North, in the local ENU frame),
* bank angle ``phi`` [rad] (positive right wing down).

so that the ENU velocity is ``v_n = V (cos gamma sin psi, cos gamma cos psi, sin gamma)``.
Attitude follows the flight path: pitch = gamma, yaw = psi, roll = phi (plus the constant
offsets of the initial state, see :func:`sdr_di.sim.trajectory.generate_trajectory`). The
bank angle is always that of a coordinated turn at the current turn rate,
``tan phi = V cos(gamma) psi_dot / g0`` (``g0`` = 9.80665 m/s^2), so it is zero when the
vehicle does not turn.

**Every segment is self-contained.** It starts and ends in steady straight motion: its
manoeuvre (acceleration, flight-path change, turn rate) is switched on over the first
``transition`` seconds and off over the last ``transition`` seconds with a raised-cosine
ramp ``r(s)`` (0 -> 1 -> 0, ``s`` = time since the segment start):

    r(s) = (1 - cos(pi s / tau)) / 2   for 0 <= s < tau,
    r(s) = 1                           for tau <= s <= D - tau,
    r(s) = (1 + cos(pi (s - D + tau) / tau)) / 2 for D - tau < s <= D,

with ``tau = min(transition, D / 2)`` (default transition 1 s). ``r`` and its derivative are
continuous, so acceleration, jerk, angular rate and angular acceleration are all continuous
and bounded: the IMU output is continuous and a strapdown INS fed with it reproduces the
truth. Consequences a scenario writer must know (``tau`` as above):

* :class:`Accelerate` changes the speed by ``accel * (duration - tau)``, not
  ``accel * duration`` (the plateau acceleration is the one given).
* :class:`Turn` / :class:`Circle` change the track by ``rate * (duration - tau)``.
* :class:`Climb` / :class:`Descend` pitch up (down) to the flight-path angle giving the
  requested vertical rate at the speed at the segment start, hold it, and return to the
  flight-path angle of the segment start during the last ``tau``; the height changes by about
  ``vertical_rate * (duration - tau)``.
* Speed, track and height changes persist into the next segment; manoeuvre rates do not.

Segments are plain frozen dataclasses with float arguments in the units of their field names
(seconds, m/s, m/s^2, deg/s, m). Arguments that are invalid in themselves raise
``ValueError`` at construction; arguments that are impossible in the state reached at the
segment start (a climb rate above the speed, a hold while moving, a deceleration below zero
speed, a circle radius at zero speed) raise ``ValueError`` from
:func:`sdr_di.sim.trajectory.generate_trajectory`, naming the segment. The scenario parser
turns both into :class:`sdr_di.errors.ScenarioError`.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

#: Default raised-cosine transition time at each end of a segment [s].
DEFAULT_TRANSITION_S = 1.0
#: Gravity used only to compute the coordinated-turn bank angle [m/s^2].
G0_BANK = 9.80665
#: Speeds below this are "zero" for :class:`Hold` and for the end of a deceleration [m/s].
SPEED_EPS = 1e-6


def _check_pos(name: str, value: float, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        op = ">=" if allow_zero else ">"
        raise ValueError(f"{name} must be finite and {op} 0, got {value!r}")
    return v


def _check_num(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def _check_dir(direction: str) -> str:
    if direction not in ("left", "right"):
        raise ValueError(f"direction must be 'left' or 'right', got {direction!r}")
    return direction


@dataclasses.dataclass(frozen=True)
class MotionState:
    """Steady motion at a segment boundary.

    Attributes
    ----------
    speed : float
        Speed along the velocity vector [m/s], >= 0.
    gamma : float
        Flight-path angle [rad].
    track : float
        Track (velocity azimuth clockwise from North) [rad]; the heading reference when the
        speed is zero.
    """

    speed: float
    gamma: float
    track: float


@dataclasses.dataclass(frozen=True)
class Profile:
    """One segment planned at an absolute start time (internal representation).

    The manoeuvre of every segment kind is one of three amplitudes multiplying the ramp
    ``r(s)`` of the module docstring: plateau along-track acceleration ``accel`` [m/s^2],
    flight-path excursion ``d_gamma`` [rad] (gamma = gamma0 + d_gamma r), plateau turn rate
    ``turn_rate`` [rad/s] (positive = right = clockwise seen from above).
    """

    t0: float
    duration: float
    tau: float
    start: MotionState
    accel: float = 0.0
    d_gamma: float = 0.0
    turn_rate: float = 0.0
    label: str = ""

    @property
    def t_end(self) -> float:
        """End time [s]."""
        return self.t0 + self.duration

    def breakpoints(self) -> tuple[float, ...]:
        """Times [s] where the motion's higher derivatives are discontinuous."""
        return (self.t0, self.t0 + self.tau, self.t_end - self.tau, self.t_end)

    def end_state(self) -> MotionState:
        """Steady state at the segment end."""
        ramp_area = self.duration - self.tau
        return MotionState(
            speed=max(self.start.speed + self.accel * ramp_area, 0.0),
            gamma=self.start.gamma,
            track=self.start.track + self.turn_rate * ramp_area,
        )

    def evaluate(self, s: np.ndarray) -> dict[str, np.ndarray]:
        """Speed, flight-path angle, track and their derivatives at local times ``s`` [s].

        ``s`` is clipped to ``[0, duration]`` (steady motion before and after).

        Returns
        -------
        dict
            ``V, V_dot`` [m/s, m/s^2]; ``gamma, gamma_dot`` [rad, rad/s];
            ``psi, psi_dot, psi_ddot`` [rad, rad/s, rad/s^2].
        """
        s = np.clip(np.asarray(s, float), 0.0, self.duration)
        r, area, dr = ramp(s, self.duration, self.tau)
        st = self.start
        V = st.speed + self.accel * area
        if self.accel < 0:  # numerical floor at the end of a deceleration to standstill
            V = np.maximum(V, 0.0)
        return {
            "V": V,
            "V_dot": self.accel * r,
            "gamma": st.gamma + self.d_gamma * r,
            "gamma_dot": self.d_gamma * dr,
            "psi": st.track + self.turn_rate * area,
            "psi_dot": self.turn_rate * r,
            "psi_ddot": self.turn_rate * dr,
        }


def ramp(s, duration: float, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Raised-cosine on/off ramp of a segment.

    Parameters
    ----------
    s : array
        Time since the segment start [s], in ``[0, duration]``.
    duration : float
        Segment duration D [s].
    tau : float
        Transition time, ``0 < tau <= D / 2`` [s].

    Returns
    -------
    r, R, dr : arrays
        The ramp ``r(s)`` [-], its integral ``R(s) = int_0^s r`` [s] (``R(D) = D - tau``) and
        its derivative ``dr/ds`` [1/s].
    """
    s = np.asarray(s, float)
    D = duration
    k = math.pi / tau
    rise = s < tau
    fall = s > D - tau
    u = s - (D - tau)
    r = np.where(rise, 0.5 * (1 - np.cos(k * s)), np.where(fall, 0.5 * (1 + np.cos(k * u)), 1.0))
    dr = np.where(rise, 0.5 * k * np.sin(k * s), np.where(fall, -0.5 * k * np.sin(k * u), 0.0))
    R = np.where(
        rise,
        0.5 * s - np.sin(k * s) / (2 * k),
        np.where(fall, 0.5 * tau + (D - 2 * tau) + 0.5 * u + np.sin(k * u) / (2 * k),
                 0.5 * tau + (s - tau)),
    )
    return r, R, dr


@dataclasses.dataclass(frozen=True)
class Segment:
    """Base class: a motion segment of ``duration`` seconds.

    Parameters
    ----------
    duration : float
        Segment length [s], > 0.
    transition : float, keyword-only
        Raised-cosine transition time at each end [s], > 0 (default 1 s); clipped to
        ``duration / 2``.
    """

    duration: float
    transition: float = dataclasses.field(default=DEFAULT_TRANSITION_S, kw_only=True)

    def __post_init__(self) -> None:
        object.__setattr__(self, "duration", _check_pos("duration", self.duration))
        object.__setattr__(self, "transition", _check_pos("transition", self.transition))

    @property
    def tau(self) -> float:
        """Effective transition time ``min(transition, duration / 2)`` [s]."""
        return min(self.transition, 0.5 * self.duration)

    def plan(self, t0: float, start: MotionState) -> Profile:
        """Plan this segment from ``start`` at time ``t0`` [s].

        Raises
        ------
        ValueError
            The segment is impossible from ``start``.
        """
        return Profile(t0, self.duration, self.tau, start, label=type(self).__name__)


@dataclasses.dataclass(frozen=True)
class Uniform(Segment):
    """Uniform motion: constant speed, flight-path angle and track for ``duration`` [s].

    At zero speed it is the same as :class:`Hold`.
    """


@dataclasses.dataclass(frozen=True)
class Hold(Segment):
    """Stationary for ``duration`` [s]; valid only when the speed is zero.

    Raises ``ValueError`` at planning time when the vehicle is moving at the segment start.
    """

    def plan(self, t0: float, start: MotionState) -> Profile:
        if start.speed > SPEED_EPS:
            raise ValueError(
                f"Hold at t = {t0:g} s: the vehicle moves at {start.speed:.6g} m/s; "
                "hold needs zero speed (decelerate to a stop first)")
        return super().plan(t0, MotionState(0.0, start.gamma, start.track))


def _plan_accel(seg: Segment, t0: float, start: MotionState, accel: float) -> Profile:
    end_speed = start.speed + accel * (seg.duration - seg.tau)
    if end_speed < -SPEED_EPS:
        raise ValueError(
            f"{type(seg).__name__} at t = {t0:g} s: speed {start.speed:.6g} m/s would reach "
            f"{end_speed:.6g} m/s (< 0) after {seg.duration:g} s at {accel:g} m/s^2")
    return Profile(t0, seg.duration, seg.tau, start, accel=accel, label=type(seg).__name__)


@dataclasses.dataclass(frozen=True)
class Accelerate(Segment):
    """Along-track acceleration ``accel`` [m/s^2] (negative decelerates) for ``duration`` [s].

    Speed change ``accel * (duration - tau)``. Raises ``ValueError`` at planning time if the
    speed would become negative. From standstill the vehicle accelerates along the track of the
    start state (the initial yaw), horizontally unless the flight-path angle is non-zero.
    """

    accel: float

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "accel", _check_num("accel", self.accel))

    def plan(self, t0: float, start: MotionState) -> Profile:
        return _plan_accel(self, t0, start, self.accel)


@dataclasses.dataclass(frozen=True)
class Decelerate(Segment):
    """Deceleration ``decel`` [m/s^2] (a positive number) for ``duration`` [s].

    Same as ``Accelerate(duration, -decel)``; decelerating below zero speed raises
    ``ValueError`` at planning time (a stop exactly at the end is allowed).
    """

    decel: float

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "decel", _check_pos("decel", self.decel, allow_zero=True))

    def plan(self, t0: float, start: MotionState) -> Profile:
        return _plan_accel(self, t0, start, -self.decel)


@dataclasses.dataclass(frozen=True)
class Climb(Segment):
    """Climb at ``vertical_rate`` [m/s] (> 0 climbs, < 0 descends) for ``duration`` [s].

    The flight-path angle goes to ``asin(vertical_rate / V)`` (``V`` = speed at the segment
    start, which does not change) over the first ``tau`` and back to its start value over the
    last ``tau``; pitch follows the flight path. Raises ``ValueError`` at planning time when
    ``|vertical_rate| >= V``.
    """

    vertical_rate: float

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "vertical_rate", _check_num("vertical_rate", self.vertical_rate))

    def _signed_rate(self) -> float:
        return self.vertical_rate

    def plan(self, t0: float, start: MotionState) -> Profile:
        vr = self._signed_rate()
        if abs(vr) >= start.speed and vr != 0.0:
            raise ValueError(
                f"{type(self).__name__} at t = {t0:g} s: vertical rate {abs(vr):g} m/s needs a "
                f"speed above it; the speed is {start.speed:.6g} m/s")
        gamma_t = math.asin(vr / start.speed) if vr != 0.0 else start.gamma
        return Profile(t0, self.duration, self.tau, start, d_gamma=gamma_t - start.gamma,
                       label=type(self).__name__)


@dataclasses.dataclass(frozen=True)
class Descend(Climb):
    """Descend at ``vertical_rate`` [m/s] (a positive number) for ``duration`` [s].

    Same as ``Climb(duration, -vertical_rate)``.
    """

    def __post_init__(self) -> None:
        vr = _check_pos("vertical_rate", self.vertical_rate, allow_zero=True)
        object.__setattr__(self, "vertical_rate", vr)
        Segment.__post_init__(self)

    def _signed_rate(self) -> float:
        return -self.vertical_rate


@dataclasses.dataclass(frozen=True)
class Turn(Segment):
    """Coordinated turn at ``rate_deg_s`` [deg/s] (> 0) to the ``direction`` for ``duration`` [s].

    Track (and yaw) rate ramps to ``+rate`` (right, clockwise from above) or ``-rate`` (left);
    the vehicle banks to the coordinated angle ``atan(V cos(gamma) rate / g0)``. Track change
    ``rate * (duration - tau)``. At zero speed the vehicle yaws in place without banking.
    """

    rate_deg_s: float
    direction: str

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "rate_deg_s", _check_pos("rate_deg_s", self.rate_deg_s))
        _check_dir(self.direction)

    def plan(self, t0: float, start: MotionState) -> Profile:
        sign = 1.0 if self.direction == "right" else -1.0
        return Profile(t0, self.duration, self.tau, start,
                       turn_rate=sign * math.radians(self.rate_deg_s), label=type(self).__name__)


@dataclasses.dataclass(frozen=True)
class Circle(Segment):
    """Circling: a coordinated turn given by its rate or its radius, for ``duration`` [s].

    Give exactly one of ``rate_deg_s`` [deg/s] (> 0) or ``radius`` [m] (> 0, horizontal
    radius of the steady part: rate = ``V cos(gamma) / radius`` at the segment-start speed).
    ``direction`` (keyword-only, required) is ``'left'`` or ``'right'``. One full circle takes
    ``360 / rate + tau`` seconds. A radius at zero speed raises ``ValueError`` at planning time.
    """

    rate_deg_s: float | None = None
    radius: float | None = None
    direction: str = dataclasses.field(kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if (self.rate_deg_s is None) == (self.radius is None):
            raise ValueError("Circle needs exactly one of rate_deg_s or radius")
        if self.rate_deg_s is not None:
            object.__setattr__(self, "rate_deg_s", _check_pos("rate_deg_s", self.rate_deg_s))
        else:
            object.__setattr__(self, "radius", _check_pos("radius", self.radius))
        _check_dir(self.direction)

    def plan(self, t0: float, start: MotionState) -> Profile:
        sign = 1.0 if self.direction == "right" else -1.0
        if self.rate_deg_s is not None:
            rate = math.radians(self.rate_deg_s)
        else:
            v_h = start.speed * math.cos(start.gamma)
            if v_h <= SPEED_EPS:
                raise ValueError(f"Circle at t = {t0:g} s: a radius needs a non-zero horizontal "
                                 f"speed; the speed is {start.speed:.6g} m/s")
            rate = v_h / float(self.radius)
        return Profile(t0, self.duration, self.tau, start, turn_rate=sign * rate,
                       label=type(self).__name__)


def segment_from_spec(spec: Mapping[str, Any]) -> Segment:
    """Build a segment from a scenario ``[[motion]]`` table (keys of the scenario schema).

    Accepted ``type`` values and keys: ``uniform`` / ``hold`` (``duration_s``);
    ``accelerate`` (``duration_s``, ``accel_mps2``); ``decelerate`` (``duration_s``,
    ``decel_mps2`` > 0); ``climb`` / ``descend`` (``duration_s``, ``vertical_rate_mps``;
    descend takes a positive rate); ``turn_left`` / ``turn_right`` (``duration_s``,
    ``rate_dps``); ``circle`` (``duration_s``, ``direction``, one of ``rate_dps`` /
    ``radius_m``). Optional on all: ``transition_s``.

    Raises
    ------
    ValueError
        Unknown type, missing key or invalid value.
    """
    kind = spec.get("type")
    kw: dict[str, Any] = {}
    if spec.get("transition_s") is not None:
        kw["transition"] = spec["transition_s"]
    try:
        d = spec["duration_s"]
        if kind == "uniform":
            return Uniform(d, **kw)
        if kind == "hold":
            return Hold(d, **kw)
        if kind == "accelerate":
            return Accelerate(d, spec["accel_mps2"], **kw)
        if kind == "decelerate":
            return Decelerate(d, spec["decel_mps2"], **kw)
        if kind == "climb":
            return Climb(d, spec["vertical_rate_mps"], **kw)
        if kind == "descend":
            return Descend(d, spec["vertical_rate_mps"], **kw)
        if kind in ("turn_left", "turn_right"):
            return Turn(d, spec["rate_dps"], kind[5:], **kw)
        if kind == "circle":
            return Circle(d, rate_deg_s=spec.get("rate_dps"), radius=spec.get("radius_m"),
                          direction=spec.get("direction", "left"), **kw)
    except KeyError as exc:
        raise ValueError(f"motion segment {kind!r}: missing key {exc.args[0]!r}") from None
    raise ValueError(f"unknown motion segment type {kind!r}")


def default_segments() -> list[Segment]:
    """Paper 004 (section IV, Fig. 4) motion: 60 s, two circling phases at 20-28 s and 36-44 s.

    Starting at 20 m/s North, level (Table 3), all transitions 1 s:

    ======  ==========  ===========================================================
    t [s]   segment     effect
    ======  ==========  ===========================================================
    0-4     Uniform     20 m/s North, level
    4-10    Accelerate  1 m/s^2 plateau: 20 -> 25 m/s
    10-15   Climb       2 m/s vertical rate (gamma 4.59 deg): height +8 m
    15-20   Turn right  6 deg/s (bank 15.0 deg): track +24 deg
    20-28   Circle left 20 deg/s (bank 41.7 deg, radius 71.6 m): track -140 deg
    28-36   Uniform     25 m/s
    36-44   Circle right 20 deg/s: track +140 deg
    44-60   Uniform     25 m/s, final track 24 deg
    ======  ==========  ===========================================================
    """
    return [
        Uniform(4.0),
        Accelerate(6.0, 1.0),
        Climb(5.0, 2.0),
        Turn(5.0, 6.0, "right"),
        Circle(8.0, rate_deg_s=20.0, direction="left"),
        Uniform(8.0),
        Circle(8.0, rate_deg_s=20.0, direction="right"),
        Uniform(16.0),
    ]
