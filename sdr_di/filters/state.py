"""State and measurement layout shared by every integration filter (DESIGN section 4).

The 17-state error vector of paper 004 (Table 1), 0-based::

    0-2   attitude error  delta_phi   [rad]   (E, N, U misalignment)
    3-5   velocity error  delta_v^n   [m/s]   (ENU)
    6-8   position error  (dL, dlambda, dh)  [rad, rad, m]
    9-11  gyro bias       eps^b       [rad/s] (Right-Front-Up body)
    12-14 accel bias      nabla^b     [m/s^2]
    15    clock bias      delta_b_clk [m]
    16    clock drift     delta_d_clk [m/s]

Optional error states (``error_states=`` of every filter, :func:`state_layout`;
docs/filters.md, *Error states*). ``none`` is the 17 states above. ``sf`` appends the IMU
scale-factor errors after the clock, so that every index above keeps its meaning::

    17-19 gyro scale factor   ds_g [-]   (Right-Front-Up body; 1e-6 = 1 ppm)
    20-22 accel scale factor  ds_a [-]

``gm`` keeps 17 states and makes the bias states first-order Gauss-Markov processes (their
dynamics and ``Q`` change, not the layout); ``sf+gm`` is both.

Measurement vector of the deep/tight modes (paper 004 eq 7): ``z = [delta_rho_1..N,
delta_rho_dot_1..N]`` -- N_k pseudorange errors [m] then N_k pseudorange-rate errors [m/s];
N_k may change every epoch. The filters themselves are generic (any ``n``, any ``m``); these
constants are for the models that plug into them.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

from ..errors import FilterError

__all__ = [
    "ACCEL_BIAS",
    "ACCEL_SCALE",
    "ATT",
    "CLOCK",
    "CLOCK_BIAS",
    "CLOCK_DRIFT",
    "ERROR_STATES",
    "GYRO_BIAS",
    "GYRO_SCALE",
    "N_STATES",
    "POS",
    "STATE_NAMES",
    "StateLayout",
    "VEL",
    "layout_of_options",
    "measurement_blocks",
    "state_layout",
]

N_STATES = 17
ATT = slice(0, 3)
VEL = slice(3, 6)
POS = slice(6, 9)
GYRO_BIAS = slice(9, 12)
ACCEL_BIAS = slice(12, 15)
CLOCK_BIAS = 15
CLOCK_DRIFT = 16
CLOCK = slice(15, 17)
GYRO_SCALE = slice(17, 20)
ACCEL_SCALE = slice(20, 23)

#: Values of the ``error_states`` option (:func:`state_layout`).
ERROR_STATES = ("none", "sf", "gm", "sf+gm")

STATE_NAMES = (
    "att_E", "att_N", "att_U", "vel_E", "vel_N", "vel_U", "lat", "lon", "h",
    "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z", "clk_bias", "clk_drift",
)


_SCALE_NAMES = ("sf_gyro_x", "sf_gyro_y", "sf_gyro_z", "sf_accel_x", "sf_accel_y",
                "sf_accel_z")


@dataclasses.dataclass(frozen=True)
class StateLayout:
    """Where each quantity sits in the error-state vector of one ``error_states`` choice.

    The process model carries it (``InsErrorModel.layout``), so a filter or a plugin learns
    the layout from ``process_model.layout`` (and ``x0.size``); the loops feed back through
    it. The first 17 states are those of paper 004 Table 1 for every choice.

    Attributes
    ----------
    error_states : str
        One of :data:`ERROR_STATES`.
    n : int
        State dimension (17, or 23 with scale factors).
    scale_factors : bool
        Gyro and accelerometer scale-factor states present (``sf``).
    gauss_markov : bool
        Bias states are first-order Gauss-Markov processes (``gm``), else random constants
        with a small random walk.
    att, vel, pos, gyro_bias, accel_bias, clock : slice
        The blocks of the module table; ``clock_bias``, ``clock_drift`` the clock indices.
    gyro_scale, accel_scale : slice or None
        The scale-factor blocks (None without ``sf``).
    names : tuple of str
        A short name per state (``STATE_NAMES`` then ``sf_gyro_x`` ... ``sf_accel_z``).
    """

    error_states: str = "none"
    # the blocks every choice shares (paper 004 Table 1)
    att: ClassVar[slice] = ATT
    vel: ClassVar[slice] = VEL
    pos: ClassVar[slice] = POS
    gyro_bias: ClassVar[slice] = GYRO_BIAS
    accel_bias: ClassVar[slice] = ACCEL_BIAS
    clock: ClassVar[slice] = CLOCK
    clock_bias: ClassVar[int] = CLOCK_BIAS
    clock_drift: ClassVar[int] = CLOCK_DRIFT

    @property
    def scale_factors(self) -> bool:
        return "sf" in self.error_states.split("+")

    @property
    def gauss_markov(self) -> bool:
        return "gm" in self.error_states.split("+")

    @property
    def n(self) -> int:
        return ACCEL_SCALE.stop if self.scale_factors else N_STATES

    @property
    def gyro_scale(self) -> slice | None:
        return GYRO_SCALE if self.scale_factors else None

    @property
    def accel_scale(self) -> slice | None:
        return ACCEL_SCALE if self.scale_factors else None

    @property
    def names(self) -> tuple[str, ...]:
        return STATE_NAMES + (_SCALE_NAMES if self.scale_factors else ())


def state_layout(error_states: str = "none") -> StateLayout:
    """The layout of an ``error_states`` option value (module notes).

    Parameters
    ----------
    error_states : str
        ``none``, ``sf``, ``gm`` or ``sf+gm`` (case-insensitive; ``gm+sf`` is ``sf+gm``).

    Raises
    ------
    FilterError
        Any other value, naming the valid ones.
    """
    text = str(error_states).strip().lower()
    parts = set(text.split("+"))
    if text in ERROR_STATES:
        key = text
    elif parts == {"sf", "gm"}:
        key = "sf+gm"
    else:
        raise FilterError(f"error_states={error_states!r} is not one of "
                          f"{', '.join(ERROR_STATES)}")
    return StateLayout(key)


def layout_of_options(options: dict) -> StateLayout:
    """The layout of a filter entry's options (``error_states``, default ``none``)."""
    return state_layout(options.get("error_states", "none"))


def measurement_blocks(m: int, n_blocks: int = 2) -> list[slice]:
    """Split a measurement vector of length ``m`` into ``n_blocks`` equal contiguous blocks.

    With the default 2 blocks of a deep/tight-mode vector this gives the pseudorange block
    ``0:N`` and the pseudorange-rate block ``N:2N`` (``N = m // 2``).

    Raises
    ------
    ValueError
        If ``m`` is not a multiple of ``n_blocks``.
    """
    if n_blocks < 1 or m % n_blocks:
        raise ValueError(f"measurement vector of length {m} cannot be split into "
                         f"{n_blocks} equal blocks")
    b = m // n_blocks
    return [slice(i * b, (i + 1) * b) for i in range(n_blocks)]
