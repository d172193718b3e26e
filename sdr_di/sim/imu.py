"""IMU error model of the generator: re-exported from :mod:`sdr_di.ins.imu`.

The model moved to the INS layer, which the receiver and the integration filters use
without importing the simulator (lower layers never import upper ones).
"""

from ..ins.imu import G_STANDARD, ImuData, ImuErrorModel

__all__ = ["G_STANDARD", "ImuData", "ImuErrorModel"]
