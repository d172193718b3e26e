"""Quaternion and rotation-vector helpers for the strapdown INS.

Quaternions are scalar-first ``q = (q0, q1, q2, q3)``, Hamilton product, and represent the
rotation ``C_b_n`` (body to nav): ``v_n = q * v_b * conj(q)``. A rotation vector ``phi``
[rad] is the axis times the angle; ``quat_from_rotvec(phi)`` is the quaternion of the active
rotation by ``|phi|`` about ``phi``, so that ``C(q_a * q_b) = C(q_a) C(q_b)`` and
``dcm_from_quat(quat_from_rotvec(phi)) = exp([phi x])``.
"""

from __future__ import annotations

import math

import numpy as np


def _floats(v) -> list:
    """Components of a small vector as Python floats: the same IEEE operations as on numpy
    scalars, several times cheaper each (the INS runs these at the IMU rate)."""
    return v.tolist() if isinstance(v, np.ndarray) else v


def quat_mult(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p * q`` of scalar-first quaternions (4,)."""
    p0, p1, p2, p3 = _floats(p)
    q0, q1, q2, q3 = _floats(q)
    return np.array([
        p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3,
        p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
        p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1,
        p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0,
    ])


def quat_from_rotvec(phi: np.ndarray) -> np.ndarray:
    """Quaternion (4,) of the rotation vector ``phi`` [rad] (3,); series below 1e-4 rad."""
    x, y, z = _floats(phi)
    a2 = x * x + y * y + z * z
    if a2 < 1e-8:
        c = 1.0 - a2 / 8.0 + a2 * a2 / 384.0
        s = 0.5 - a2 / 48.0 + a2 * a2 / 3840.0
    else:
        a = math.sqrt(a2)
        c = math.cos(0.5 * a)
        s = math.sin(0.5 * a) / a
    return np.array([c, s * x, s * y, s * z])


def dcm_from_quat(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (4,)."""
    q0, q1, q2, q3 = _floats(q)
    return np.array([
        [q0 * q0 + q1 * q1 - q2 * q2 - q3 * q3, 2 * (q1 * q2 - q0 * q3), 2 * (q1 * q3 + q0 * q2)],
        [2 * (q1 * q2 + q0 * q3), q0 * q0 - q1 * q1 + q2 * q2 - q3 * q3, 2 * (q2 * q3 - q0 * q1)],
        [2 * (q1 * q3 - q0 * q2), 2 * (q2 * q3 + q0 * q1), q0 * q0 - q1 * q1 - q2 * q2 + q3 * q3],
    ])


def quat_from_dcm(C: np.ndarray) -> np.ndarray:
    """Unit quaternion (4,) with non-negative scalar part of a rotation matrix (3, 3)."""
    C = np.asarray(C, float)
    tr = C[0, 0] + C[1, 1] + C[2, 2]
    cand = np.array([tr, C[0, 0], C[1, 1], C[2, 2]])
    i = int(np.argmax(cand))
    if i == 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [0.25 * s, (C[2, 1] - C[1, 2]) / s, (C[0, 2] - C[2, 0]) / s, (C[1, 0] - C[0, 1]) / s]
    elif i == 1:
        s = 2.0 * math.sqrt(1.0 + C[0, 0] - C[1, 1] - C[2, 2])
        q = [(C[2, 1] - C[1, 2]) / s, 0.25 * s, (C[0, 1] + C[1, 0]) / s, (C[0, 2] + C[2, 0]) / s]
    elif i == 2:
        s = 2.0 * math.sqrt(1.0 + C[1, 1] - C[0, 0] - C[2, 2])
        q = [(C[0, 2] - C[2, 0]) / s, (C[0, 1] + C[1, 0]) / s, 0.25 * s, (C[1, 2] + C[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + C[2, 2] - C[0, 0] - C[1, 1])
        q = [(C[1, 0] - C[0, 1]) / s, (C[0, 2] + C[2, 0]) / s, (C[1, 2] + C[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    if q[0] < 0:
        q = -q
    return q / np.linalg.norm(q)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (cheaper than ``np.cross`` for single vectors)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of 3-vectors along the last axis, broadcast like ``np.cross`` (e.g.
    (3,) with (p, 3)): the same products and differences, so bit-equal to ``np.cross``,
    at a fraction of its cost on small arrays (no axis moves)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast(a, b).shape)   # filled in place, not stacked
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out
