"""Strapdown inertial navigation: ENU navigation frame, Right-Front-Up body, CGCS2000.

``gravity``        CGCS2000 normal gravity (the project's only gravity model)
``imu``            IMU record (:class:`ImuData`) and error model (:class:`ImuErrorModel`:
                   scale factor, turn-on and in-run bias, misalignment, g-sensitivity,
                   random walks; generator and filter ``Q`` alike; one drawn unit
                   :class:`ImuUnit`)
``grades``         IMU grades: 1-sigma tables from named datasheets (``IMU_GRADES``)
``rotation``       quaternion / rotation-vector helpers
``truth``          reference trajectory record (:class:`Truth`: PVA, IMU signals, ECEF
                   interpolation), as generated and as read back
``mechanization``  :class:`StrapdownINS` (200 Hz update with coning and sculling), ``navigate``
"""

from .gravity import gravity_n, normal_gravity
from .mechanization import InsSolution, StrapdownINS, navigate

__all__ = ["StrapdownINS", "InsSolution", "navigate", "normal_gravity", "gravity_n"]
