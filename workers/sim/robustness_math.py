"""The pure arithmetic of the robustness margins and grasp tests (workers/sim/robustness.py
defines them): the load directions, the object's motion in the hand, the bisection, the tug's
ramp and the shake's path."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation


def directions() -> np.ndarray:
    """The six unit directions +x, −x, +y, −y, +z, −z (rows)."""
    return np.vstack([sign * axis for axis in np.eye(3) for sign in (1.0, -1.0)])


def relative_pose(hand_pos: np.ndarray, hand_rot: np.ndarray, obj_pos: np.ndarray,
                  obj_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The object's pose in the hand frame."""
    return hand_rot.T @ (obj_pos - hand_pos), hand_rot.T @ obj_rot


def displacement(rest: tuple[np.ndarray, np.ndarray],
                 now: tuple[np.ndarray, np.ndarray]) -> tuple[float, float]:
    """Distance (m) and angle (rad) between two relative poses of the object in the hand."""
    moved = float(np.linalg.norm(now[0] - rest[0]))
    turned = float(Rotation.from_matrix(now[1] @ rest[1].T).magnitude())
    return moved, turned


def lowest_holding(holds: Callable[[float], bool], lo: float, hi: float, trials: int,
                   hi_holds: bool | None = None) -> float | None:
    """The lowest value in [lo, hi] at which `holds`, by bisection in at most `trials` trials
    (a known `hi_holds` counts as the first, run elsewhere): None if `hi` does not hold, `lo`
    if `lo` does, else the lowest value seen to hold. Assumes holding is monotone in it."""
    if hi_holds is None:
        hi_holds = holds(hi)
    if not hi_holds:
        return None
    used = 2  # hi (run here or known) and lo
    if holds(lo):
        return lo
    while used < trials:
        mid = 0.5 * (lo + hi)
        used += 1
        if holds(mid):
            hi = mid
        else:
            lo = mid
    return hi


def torque_ratio(tau_min: float | None, tau_c: float) -> float | None:
    """1 − τ_min/τ_c: 1 holds with almost no effort, 0 needs all of it."""
    return None if tau_min is None else 1.0 - tau_min / tau_c


def ramp(t: float, top: float, ramp_s: float) -> float:
    """A linear ramp from 0 at t = 0 to `top` at `ramp_s`, flat after."""
    return top * min(1.0, max(0.0, t / ramp_s))


def shake_timing(frequency_hz: float, axis_s: float) -> float:
    """Time per axis, rounded to whole periods (at least one)."""
    return max(1, round(axis_s * frequency_hz)) / frequency_hz


def shake_offset(t: float, amplitude_m: float, frequency_hz: float, axis_s: float) -> np.ndarray:
    """World displacement of the hand at time t into the shake: A(1 − cos 2πft) along x, then
    y, then z, `axis_s` (rounded to whole periods) each; zero before and after."""
    per_axis = shake_timing(frequency_hz, axis_s)
    axis = math.floor(t / per_axis) if t >= 0.0 else 3
    offset = np.zeros(3)
    if axis < 3:
        tau = t - axis * per_axis
        offset[axis] = amplitude_m * (1.0 - math.cos(2.0 * math.pi * frequency_hz * tau))
    return offset
