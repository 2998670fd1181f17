"""The reference trajectory of the gripper base during the task (pure functions).

From the grasp pose at release, the base lifts along world +z, moves along world +x and turns
about the world z axis through the object's centre of mass at release, all on one
minimum-jerk profile (zero velocity and acceleration at both ends)."""

from __future__ import annotations

import numpy as np
from graspscape.shared.specs.sim import TrajectorySpec
from graspscape.workers.sim.geometry import axis_rotation


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
