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
    # A saved state in which nothing touches (the evaluator's pristine one); see restore_clean.
    contact_free_state: int | None = None


def restore_clean(ctx: ProbeContext, state: int) -> None:
    """Restores `state` with no contact history carried over.

    pybullet's saved state holds positions and velocities, not the solver's contact cache
    (the persistent manifolds and their warm-start impulses): a rollout from a restored state
    starts from whatever contacts the previous rollout left, so two rollouts from the same
    state differ by up to 0.03 m/s in the window's response (of ~0.3 m/s). Passing through a
    contact-free state drops every manifold, so each rollout starts from the same (empty)
    cache and repeats exactly, whatever ran before it.
    """
    cid = ctx.client
    if ctx.contact_free_state is not None:
        p.restoreState(ctx.contact_free_state, physicsClientId=cid)
        p.performCollisionDetection(physicsClientId=cid)
    p.restoreState(state, physicsClientId=cid)


def _velocities(ctx: ProbeContext, point_local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cid = ctx.client
    _, orn = p.getBasePositionAndOrientation(ctx.hand_body, physicsClientId=cid)
    v_b, w_b = p.getBaseVelocity(ctx.hand_body, physicsClientId=cid)
    rot = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
    w_b = np.array(w_b)
    v_point = np.array(v_b) + np.cross(w_b, rot @ point_local)
    v_o, w_o = p.getBaseVelocity(ctx.object_body, physicsClientId=cid)
    return np.concatenate([v_point, w_b]), np.concatenate([v_o, w_o])


@dataclass(frozen=True)
class ProbeAnchor:
    """Where the responses of one instant are read: the gripper-fixed point (in the base's COM
    frame) that coincides with the object's centre of mass at the instant, and that centre."""

    point_local: np.ndarray
    pivot: np.ndarray


def probe_anchor(ctx: ProbeContext) -> ProbeAnchor:
    """The anchor of the instant the simulation is at now."""
    cid = ctx.client
    com, orn = p.getBasePositionAndOrientation(ctx.hand_body, physicsClientId=cid)
    rot0 = np.array(p.getMatrixFromQuaternion(orn)).reshape(3, 3)
    pivot = np.array(p.getBasePositionAndOrientation(ctx.object_body, physicsClientId=cid)[0])
    return ProbeAnchor(point_local=rot0.T @ (pivot - np.array(com)), pivot=pivot)


def response(ctx: ProbeContext, anchor: ProbeAnchor) -> tuple[np.ndarray, np.ndarray]:
    """Velocities now of the gripper (at the anchor point) and of the object."""
    return _velocities(ctx, anchor.point_local)


def probe_instant(ctx: ProbeContext, step: int, window: int, dt: float,
                  epsilon: float, length: float, central: bool = False, *,
                  state: int | None = None) -> float:
    """Quality 1 − σ_max(G − I) at trajectory step `step`.

    `state`: a saved state of this instant to roll out from (otherwise the present state is
    saved first). Every rollout, the unperturbed one included, starts from it through
    `restore_clean`, so all seven see the same start; the state is restored at the end.
    """
    cid = ctx.client
    own_state = state is None
    if own_state:
        state = p.saveState(physicsClientId=cid)
    restore_clean(ctx, state)
    anchor = probe_anchor(ctx)
    pivot = anchor.pivot

    def rollout(axis: int | None, sign: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        restore_clean(ctx, state)
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
        return response(ctx, anchor)

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
        restore_clean(ctx, state)
        if own_state:
            p.removeState(state, physicsClientId=cid)
    return instant_quality(sensitivity_matrix(d_ref, d_obj, length))
