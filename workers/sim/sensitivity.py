"""Probes G(t) = ∂η̈_o/∂η̈_r at one instant of the trajectory, in the simulator.

From a saved state, one unperturbed rollout and six perturbed ones run for a short window. A
perturbed rollout adds a constant acceleration ε along one axis to the commanded base motion,
through the same drive constraint the trajectory uses (linear axes: a ½εt² offset; angular
axes: a ½(ε/L)t² turn about the object's centre of mass). Responses are the changes, versus
the unperturbed rollout, of the window-mean accelerations actually realised: of the gripper
(at the gripper-fixed point that coincides with the object's centre of mass at the instant,
so a rigid grasp gives G = I) and of the object. The state is restored afterwards.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as p
from graspscape.workers.sim.geometry import axis_rotation
from graspscape.workers.sim.metric import instant_quality, sensitivity_matrix

DriveFn = Callable[[np.ndarray, np.ndarray], None]
TargetFn = Callable[[int], tuple[np.ndarray, np.ndarray]]


@dataclass
class ProbeContext:
    client: int
    hand_body: int
    object_body: int
    drive: DriveFn  # sets the drive constraint's target (gripper frame position, rotation)
    target: TargetFn  # reference gripper frame pose at a step index


def _velocities(ctx: ProbeContext, point_local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cid = ctx.client
    _, orn = p.getBasePositionAndOrientation(ctx.hand_body, physicsClientId=cid)
    v_b, w_b = p.getBaseVelocity(ctx.hand_body, physicsClientId=cid)
    rot = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
    w_b = np.array(w_b)
    v_point = np.array(v_b) + np.cross(w_b, rot @ point_local)
    v_o, w_o = p.getBaseVelocity(ctx.object_body, physicsClientId=cid)
    return np.concatenate([v_point, w_b]), np.concatenate([v_o, w_o])


def probe_instant(ctx: ProbeContext, step: int, window: int, dt: float,
                  epsilon: float, length: float, central: bool = False) -> float:
    """Quality 1 − σ_max(G − I) at trajectory step `step` (the state is left as found)."""
    cid = ctx.client
    state = p.saveState(physicsClientId=cid)
    com, orn = p.getBasePositionAndOrientation(ctx.hand_body, physicsClientId=cid)
    rot0 = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
    pivot = np.array(p.getBasePositionAndOrientation(ctx.object_body, physicsClientId=cid)[0])
    point_local = rot0.T @ (pivot - np.array(com))  # the gripper-fixed point at the object COM

    def rollout(axis: int | None, sign: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        p.restoreState(state, physicsClientId=cid)
        for j in range(1, window + 1):
            position, rotation = ctx.target(step + j)
            if axis is not None:
                amount = sign * 0.5 * (j * dt) ** 2
                if axis < 3:
                    offset = np.zeros(3)
                    offset[axis] = epsilon * amount
                    position = position + offset
                else:
                    turn = axis_rotation(axis - 3, epsilon / length * amount)
                    position = pivot + turn @ (position - pivot)
                    rotation = turn @ rotation
            ctx.drive(position, rotation)
            p.stepSimulation(physicsClientId=cid)
        return _velocities(ctx, point_local)

    try:
        span = window * dt
        d_ref = np.empty((6, 6))
        d_obj = np.empty((6, 6))
        if not central:
            ref0, obj0 = rollout(None)
        for axis in range(6):
            ref, obj = rollout(axis)
            if central:  # ±ε: even-order effects of the perturbation cancel
                ref0, obj0 = rollout(axis, -1.0)
                ref, obj = (ref - ref0) / 2, (obj - obj0) / 2
            else:
                ref, obj = ref - ref0, obj - obj0
            d_ref[:, axis] = ref / span
            d_obj[:, axis] = obj / span
    finally:
        p.restoreState(state, physicsClientId=cid)
        p.removeState(state, physicsClientId=cid)
    return instant_quality(sensitivity_matrix(d_ref, d_obj, length))
