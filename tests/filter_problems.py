"""Shared test problems of the filter tests."""

import numpy as np


def cv2d(dt: float, sa: float) -> tuple[np.ndarray, np.ndarray]:
    """2-D constant-velocity model [x, y, vx, vy]: transition F and process noise Q for white
    acceleration of standard deviation ``sa`` [m/s^2/sqrt(Hz)] over ``dt`` [s]."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    q1 = np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]]) * sa ** 2
    Q = np.zeros((4, 4))
    Q[np.ix_([0, 2], [0, 2])] = q1
    Q[np.ix_([1, 3], [1, 3])] = q1
    return F, Q
