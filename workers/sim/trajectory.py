"""The reference trajectory of the gripper base during the task (pure functions).

From the grasp pose at release, the base lifts along world +z, moves along world +x and turns
about the world z axis through the object's centre of mass at release, all on one
minimum-jerk profile (zero velocity and acceleration at both ends)."""

from __future__ import annotations

import math

import numpy as np
from graspscape.shared.specs.sim import TrajectorySpec
from graspscape.workers.sim.geometry import axis_rotation, quat_from_matrix


def min_jerk(tau: float) -> float:
    tau = min(max(tau, 0.0), 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


def reference_pose(spec: TrajectorySpec, start_position: np.ndarray, start_rotation: np.ndarray,
                   pivot: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    s = min_jerk(t / spec.duration_s)
    turn = axis_rotation(2, spec.turn_rad * s)
    position = pivot + turn @ (start_position - pivot)
    position = position + np.array([spec.lateral_m * s, 0.0, spec.lift_m * s])
    return position, turn @ start_rotation


class ReferencePath:
    """`reference_pose` at step k (time k·dt), computed the first time a step is asked for and
    kept: the trajectory reads each step once and every μs probe window reads its steps again
    (7–12 rollouts each), while a grasp that drops early needs only the steps it ran. The
    drive's quaternion and position list of a step are kept too, so a rollout that drives to
    the unperturbed rotation does not convert the same matrix again."""

    def __init__(self, spec: TrajectorySpec, start_position: np.ndarray,
                 start_rotation: np.ndarray, pivot: np.ndarray, dt: float) -> None:
        self._args = (spec, start_position, start_rotation, pivot)
        self._dt = dt
        self._poses: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._drives: dict[int, tuple[list[float], list[float]]] = {}

    def pose(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """(position, rotation matrix) of the gripper frame at `step`."""
        pose = self._poses.get(step)
        if pose is None:
            pose = self._poses[step] = reference_pose(*self._args, step * self._dt)
        return pose

    def drive(self, step: int) -> tuple[list[float], list[float]]:
        """(position as a list, quaternion x, y, z, w) of `step`: what the drive is set to."""
        drive = self._drives.get(step)
        if drive is None:
            position, rotation = self.pose(step)
            drive = self._drives[step] = (position.tolist(), quat_from_matrix(rotation))
        return drive


def rotation_angle(m: np.ndarray) -> float:
    """Angle of a rotation matrix, rad in [0, π] (the slip check's; scipy's Rotation took
    ~0.5 ms a call here): 2·atan2(|v|, |w|) of its unit quaternion (v, w)."""
    x, y, z, w = quat_from_matrix(m)
    return 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), abs(w))
