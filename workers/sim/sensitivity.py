"""Probes S(t) = G(t) − I = ∂(η̈_o − η̈_r)/∂η̈_r at one instant of the trajectory, in the simulator.

From a saved state, one unperturbed rollout and six perturbed ones run for a short window of T
seconds. A perturbed rollout adds a constant acceleration ε along one axis to the commanded
base motion, through the same drive constraint the trajectory uses (linear axes: a ½εt²
offset; angular axes: a ½(ε/L)t² turn about the object's centre of mass). Each rollout ends
with a snapshot of poses, and the responses are the changes of the snapshot against the
unperturbed rollout's:

- the base's realised perturbation: the displacement of the gripper-fixed anchor (the point
  that coincides with the object's centre of mass at the instant) and the base's turn;
- the object's motion *relative to the hand*: the displacement of its centre of mass from the
  anchor and its turn relative to the base, both read in the hand's frame and expressed in
  world axes with the unperturbed end orientation.

A displacement δ after a window from the same state is ½·ā·T² for the window's (triangle-
weighted) mean acceleration ā, so the ratio of the two responses is the ratio of mean
accelerations: S = Δ_rel Δ_base⁻¹ (metric.deviation_matrix).

Why relative poses and not absolute velocities (docs/concepts/quality.md, "The estimator"): G − I
taken as the difference of two absolute responses reads the gripper's velocity at the anchor with
one orientation while the solver enforced contacts with another, a centripetal term of second
order in ε that a one-sided difference keeps; an object welded to the palm scored 0.85–0.94
(0.51 for a 3 cm ball, the error growing as 1/L²). The relative pose of a welded object does
not change, whatever the base does, so the weld reads S = 0 (μs = 1) by construction, and
relative poses do not depend on where the object is in the world.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pybullet as p
from graspscape.shared.specs.sim import MetricSettings
from graspscape.workers.sim.bullet import (
    get_point,
    get_pose,
    matrix_from_quat,
    restore_state_clean,
    saved_state,
)
from graspscape.workers.sim.geometry import axis_rotation, rotation_vector
from graspscape.workers.sim.metric import deviation_matrix, instant_quality_of_deviation

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
    contact_free_state: int
    # Optional shortcut for the rollouts that drive to the reference rotation (the unperturbed
    # and the linear ones): the drive's position list and quaternion of a step, converted once
    # (trajectory.ReferencePath.drive), and a drive that takes them (Scene.drive_to_quat).
    target_drive: Callable[[int], tuple[list[float], list[float]]] | None = None
    drive_quat: Callable[[list[float], list[float]], None] | None = None


def restore_clean(ctx: ProbeContext, state: int) -> None:
    """Restores `state` with no contact history carried over.

    pybullet's saved state holds positions and velocities, not the solver's contact cache
    (the persistent manifolds and their warm-start impulses): a rollout from a restored state
    starts from whatever contacts the previous rollout left, so two rollouts from the same
    state differ. Passing through a contact-free state drops every manifold, so each rollout
    starts from the same (empty) cache and repeats exactly, whatever ran before it.
    """
    restore_state_clean(ctx.client, state, contact_free=ctx.contact_free_state)


@dataclass(frozen=True)
class Snapshot:
    """Where a rollout ended, in world axes: the anchor and the base's rotation, the object's
    rotation and its centre's offset from the anchor."""

    anchor: np.ndarray
    base_rotation: np.ndarray
    object_rotation: np.ndarray
    relative_offset: np.ndarray


def anchor_point(ctx: ProbeContext) -> np.ndarray:
    """The anchor of the instant the simulation is at now, in the base's COM frame."""
    com, orn = get_pose(ctx.client, ctx.hand_body)
    pivot = get_point(ctx.client, ctx.object_body)
    return matrix_from_quat(orn).T @ (np.array(pivot) - np.array(com))


def snapshot(ctx: ProbeContext, anchor_local: np.ndarray) -> Snapshot:
    com, orn = get_pose(ctx.client, ctx.hand_body)
    o_pos, o_orn = get_pose(ctx.client, ctx.object_body)
    rot = matrix_from_quat(orn)
    anchor = np.array(com) + rot @ anchor_local
    return Snapshot(anchor=anchor, base_rotation=rot, object_rotation=matrix_from_quat(o_orn),
                    relative_offset=np.array(o_pos) - anchor)


def responses(perturbed: Snapshot, reference: Snapshot) -> tuple[np.ndarray, np.ndarray]:
    """(base, relative) 6-vectors [linear; angular] of one perturbed rollout, world axes.

    The relative pose is kept in world axes, not the hand's: every pybullet constraint and
    contact lags its load by about a·dt² (the velocity-level solver corrects positions a step
    late), a world-fixed sag under gravity that a hand-frame reading would turn with the
    hand's angular probe and report as relative motion (0.01–0.02 of μs on a weld)."""
    base_turn = perturbed.base_rotation @ reference.base_rotation.T
    object_turn = perturbed.object_rotation @ reference.object_rotation.T
    base = np.concatenate([perturbed.anchor - reference.anchor, rotation_vector(base_turn)])
    relative = np.concatenate([
        perturbed.relative_offset - reference.relative_offset,
        rotation_vector(object_turn @ base_turn.T),  # identity for an object fixed to the hand
    ])
    return base, relative


@lru_cache(maxsize=1024)
def _turn(axis: int, angle: float) -> np.ndarray:
    """axis_rotation, kept: an angular rollout's turns depend on the window step alone, so
    every instant of every grasp uses the same few (read-only: shared)."""
    turn = axis_rotation(axis, angle)
    turn.setflags(write=False)
    return turn


def probe_instant(ctx: ProbeContext, step: int, dt: float, metric: MetricSettings,
                  length: float, *, state: int | None = None, restore: bool = True) -> float:
    """Quality 1 − σ_max(S) at trajectory step `step`.

    `state`: a saved state of this instant to roll out from (otherwise the present state is
    saved first). Every rollout, the unperturbed one included, starts from it through
    `restore_clean`, so all see the same start; the state is restored at the end, unless
    `restore` is False and an exception did not cut the probe short (for a caller that
    restores a state of its own next: the evaluator's probes, after the trajectory).
    With `metric.differences == "central"`, ±ε rollouts instead of +ε and an unperturbed one:
    the perturbation's even-order effects cancel (12 rollouts instead of 7).
    """
    if state is None:
        with saved_state(ctx.client, restore=False) as own:  # restored below, cleanly
            return probe_instant(ctx, step, dt, metric, length, state=own)
    cid = ctx.client
    window = metric.window_steps
    central = metric.differences == "central"
    linear = metric.perturbation_m_s2
    angular = metric.angular_perturbation_rad_s2
    # The instant's anchor and the object's centre, read once the first rollout has restored
    # the state (every rollout restores the same one, so no restore of their own is needed).
    start: list[np.ndarray] = []

    quick = ctx.target_drive is not None and ctx.drive_quat is not None

    def rollout(axis: int | None, sign: float = 1.0) -> Snapshot:
        restore_clean(ctx, state)
        if not start:
            start.extend((anchor_point(ctx), np.array(get_point(cid, ctx.object_body))))
        anchor_local, pivot = start
        if quick and (axis is None or axis < 3):
            target_drive, drive_quat = ctx.target_drive, ctx.drive_quat
            for j in range(1, window + 1):
                position_list, quaternion = target_drive(step + j)  # type: ignore[misc]
                if axis is not None:
                    # As drive_to would list (position + offset), offset 0 but on `axis`: in
                    # Python floats, the same IEEE sums (x + 0.0 included, which maps -0 to 0).
                    moved = [x + 0.0 for x in position_list]
                    moved[axis] = position_list[axis] + linear * (sign * 0.5 * (j * dt) ** 2)
                    position_list = moved
                drive_quat(position_list, quaternion)  # type: ignore[misc]
                p.stepSimulation(physicsClientId=cid)
            return snapshot(ctx, anchor_local)
        for j in range(1, window + 1):
            position, rotation = ctx.target(step + j)
            if axis is not None:
                amount = sign * 0.5 * (j * dt) ** 2
                if axis < 3:
                    offset = np.zeros(3)
                    offset[axis] = linear * amount
                    position = position + offset
                else:
                    turn = _turn(axis - 3, angular * amount)
                    position = pivot + turn @ (position - pivot)
                    rotation = turn @ rotation
            ctx.drive(position, rotation)
            p.stepSimulation(physicsClientId=cid)
        return snapshot(ctx, anchor_local)

    try:
        d_base = np.empty((6, 6))
        d_rel = np.empty((6, 6))
        reference = None if central else rollout(None)
        for axis in range(6):
            if central:
                reference = rollout(axis, -1.0)
            d_base[:, axis], d_rel[:, axis] = responses(rollout(axis), reference)
    except BaseException:
        restore_clean(ctx, state)
        raise
    if restore:
        restore_clean(ctx, state)
    return instant_quality_of_deviation(deviation_matrix(d_base, d_rel, length))
