"""Strapdown inertial navigation: ENU navigation frame, Right-Front-Up body, CGCS2000.

``gravity``        CGCS2000 normal gravity (the project's only gravity model)
``rotation``       quaternion / rotation-vector helpers
``mechanization``  :class:`StrapdownINS` (200 Hz update with coning and sculling), ``navigate``
"""

from .gravity import gravity_n, normal_gravity
from .mechanization import InsSolution, StrapdownINS, navigate

__all__ = ["StrapdownINS", "InsSolution", "navigate", "normal_gravity", "gravity_n"]
