"""State and measurement layout shared by every integration filter (DESIGN section 4).

The 17-state error vector of paper 004 (Table 1), 0-based::

    0-2   attitude error  delta_phi   [rad]   (E, N, U misalignment)
    3-5   velocity error  delta_v^n   [m/s]   (ENU)
    6-8   position error  (dL, dlambda, dh)  [rad, rad, m]
    9-11  gyro bias       eps^b       [rad/s] (Right-Front-Up body)
    12-14 accel bias      nabla^b     [m/s^2]
    15    clock bias      delta_b_clk [m]
    16    clock drift     delta_d_clk [m/s]

Measurement vector of the deep/tight modes (paper 004 eq 7): ``z = [delta_rho_1..N,
delta_rho_dot_1..N]`` -- N_k pseudorange errors [m] then N_k pseudorange-rate errors [m/s];
N_k may change every epoch. The filters themselves are generic (any ``n``, any ``m``); these
constants are for the models that plug into them.
"""

from __future__ import annotations

__all__ = [
    "ACCEL_BIAS",
    "ATT",
    "CLOCK",
    "CLOCK_BIAS",
    "CLOCK_DRIFT",
    "GYRO_BIAS",
    "N_STATES",
    "POS",
    "STATE_NAMES",
    "VEL",
    "measurement_blocks",
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

STATE_NAMES = (
    "att_E", "att_N", "att_U", "vel_E", "vel_N", "vel_U", "lat", "lon", "h",
    "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z", "clk_bias", "clk_drift",
)


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
