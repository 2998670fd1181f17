"""Small rotation helpers for the per-step hot path (scipy's Rotation costs ~100 µs a call,
more than a physics step's worth of Python overhead)."""

from __future__ import annotations

import math

import numpy as np


def quat_from_matrix(m: np.ndarray) -> list[float]:
    """Rotation matrix → unit quaternion (x, y, z, w), stable for any angle."""
    # Python floats, not numpy scalars: the same IEEE operations in the same order (so the
    # very same quaternion), at a third of the cost of indexing an array nine times.
    m = m.tolist() if isinstance(m, np.ndarray) else m
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s)
    elif m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2])
        q = (0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s)
    elif m[1][1] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2])
        q = ((m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1])
        q = ((m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s, (m[1][0] - m[0][1]) / s)
    n = math.sqrt(sum(c * c for c in q))
    return [float(c / n) for c in q]


def axis_rotation(axis: int, angle: float) -> np.ndarray:
    """Rotation by `angle` about coordinate axis 0 (x), 1 (y) or 2 (z)."""
    c, s = math.cos(angle), math.sin(angle)
    if axis == 0:  # the identity with its (i, j) block set, written out: np.eye costs more
        rows = [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]
    elif axis == 1:
        rows = [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]
    else:
        rows = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    return np.array(rows)


def rotation_vector(m: np.ndarray) -> np.ndarray:
    """Rotation matrix → axis × angle (the log map), exact for angles below π."""
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    c = min(1.0, max(-1.0, 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)))
    angle = math.acos(c)
    if angle < 1e-6:
        return 0.5 * w  # sin θ ≈ θ: the skew part is θ·axis
    return w * (angle / (2.0 * math.sin(angle)))
