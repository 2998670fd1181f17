"""pybullet, named: small verb-noun functions on an explicit physics client, and records for
the raw tuples pybullet returns (in the style of caelan/pybullet-planning's
`pybullet_tools/utils.py`). The rest of workers/sim reads pybullet's answers through these, so
no code outside this module indexes a pybullet tuple by position.

Record fields are pybullet's own names (its quickstart guide), snake_cased:
`contactNormalOnB` is `contact_normal_on_b`. Only the calls the simulation makes are here.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import NamedTuple

import numpy as np
import pybullet as p

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


class ContactPoint(NamedTuple):
    """One point of getContactPoints or getClosestPoints (the same 14 fields; closest points
    carry no forces)."""

    contact_flag: int
    body_unique_id_a: int
    body_unique_id_b: int
    link_index_a: int
    link_index_b: int
    position_on_a: Vec3
    position_on_b: Vec3
    contact_normal_on_b: Vec3  # from B toward A
    contact_distance: float  # negative: penetration
    normal_force: float
    lateral_friction_1: float
    lateral_friction_dir_1: Vec3
    lateral_friction_2: float
    lateral_friction_dir_2: Vec3


class JointInfo(NamedTuple):
    joint_index: int
    joint_name: bytes
    joint_type: int
    q_index: int
    u_index: int
    flags: int
    joint_damping: float
    joint_friction: float
    joint_lower_limit: float
    joint_upper_limit: float
    joint_max_force: float
    joint_max_velocity: float
    link_name: bytes
    joint_axis: Vec3
    parent_frame_pos: Vec3
    parent_frame_orn: Quat
    parent_index: int


class JointState(NamedTuple):
    joint_position: float
    joint_velocity: float
    joint_reaction_forces: tuple[float, ...]
    applied_joint_motor_torque: float


class LinkState(NamedTuple):
    """getLinkState without link velocities (computeLinkVelocity=0)."""

    link_world_position: Vec3
    link_world_orientation: Quat
    local_inertial_frame_position: Vec3
    local_inertial_frame_orientation: Quat
    world_link_frame_position: Vec3
    world_link_frame_orientation: Quat


class DynamicsInfo(NamedTuple):
    mass: float
    lateral_friction: float
    local_inertia_diagonal: Vec3
    local_inertial_pos: Vec3  # the inertial frame in the link (base: COM) frame
    local_inertial_orn: Quat
    restitution: float
    rolling_friction: float
    spinning_friction: float
    contact_damping: float
    contact_stiffness: float
    body_type: int
    collision_margin: float


class ConstraintInfo(NamedTuple):
    parent_body_unique_id: int
    parent_joint_index: int
    child_body_unique_id: int
    child_link_index: int
    constraint_type: int
    joint_axis: Vec3
    joint_pivot_in_parent: Vec3
    joint_pivot_in_child: Vec3
    joint_frame_orientation_parent: Quat
    joint_frame_orientation_child: Quat
    max_applied_force: float
    gear_ratio: float
    gear_aux_link: int
    relative_position_target: float
    erp: float


class BodyPose(NamedTuple):
    """getBasePositionAndOrientation: the base's centre-of-mass frame, world."""

    position: Vec3
    orientation: Quat


# --- saved states --------------------------------------------------------------------------


def save_state(client: int) -> int:
    return p.saveState(physicsClientId=client)


def restore_state(client: int, state: int) -> None:
    p.restoreState(state, physicsClientId=client)


def remove_state(client: int, state: int) -> None:
    p.removeState(state, physicsClientId=client)


@contextmanager
def saved_state(client: int, *, restore: bool = True) -> Iterator[int]:
    """Saves the state, yields its id, and on leaving (also by an exception) restores it and
    frees it. With `restore=False` the state is only freed: for a state the block rolls out
    from and restores its own way (`restore_state_clean`)."""
    state = save_state(client)
    try:
        yield state
    finally:
        if restore:
            restore_state(client, state)
        remove_state(client, state)


def restore_state_clean(client: int, state: int, *, contact_free: int) -> None:
    """Restores `state` with no contact history: a saved state holds positions and velocities,
    not the solver's contact cache, so the manifolds of whatever ran last would survive a
    plain restore. Passing through `contact_free` (a state where nothing touches) and a
    collision pass there drops them all."""
    restore_state(client, contact_free)
    p.performCollisionDetection(physicsClientId=client)
    restore_state(client, state)


# --- queries ---------------------------------------------------------------------------


def get_contact_points(client: int, body_a: int, body_b: int) -> list[ContactPoint]:
    return [ContactPoint(*c) for c in
            p.getContactPoints(body_a, body_b, physicsClientId=client)]


def touching_link_indices(client: int, body_a: int, body_b: int,
                          max_distance: float) -> list[int]:
    """Body A's link of every contact point with body B no further apart than
    `max_distance`: what `get_contact_points` filtered by distance gives, without a record
    per point (the approach and closing phases ask this every step or check)."""
    return [c[3] for c in p.getContactPoints(body_a, body_b, physicsClientId=client)
            if c[8] <= max_distance]  # linkIndexA, contactDistance


def get_closest_points(client: int, body_a: int, body_b: int, distance: float, *,
                       link_a: int | None = None) -> list[ContactPoint]:
    """Point pairs closer than `distance` (of link `link_a` of body A only, if given)."""
    links = {} if link_a is None else {"linkIndexA": link_a}
    return [ContactPoint(*c) for c in
            p.getClosestPoints(body_a, body_b, distance, physicsClientId=client, **links)]


def get_num_joints(client: int, body: int) -> int:
    return p.getNumJoints(body, physicsClientId=client)


def get_joint_info(client: int, body: int, joint: int) -> JointInfo:
    return JointInfo(*p.getJointInfo(body, joint, physicsClientId=client))


def get_joint_state(client: int, body: int, joint: int) -> JointState:
    return JointState(*p.getJointState(body, joint, physicsClientId=client))


def get_joint_states(client: int, body: int, joints: list[int]) -> list[JointState]:
    return [JointState(*s) for s in p.getJointStates(body, joints, physicsClientId=client)]


def max_abs_motor_torque(client: int, body: int, joints: list[int]) -> float:
    """The largest |appliedJointMotorTorque| of `joints` (the trajectory reads it every
    step: no record per joint)."""
    return max(abs(s[3]) for s in p.getJointStates(body, joints, physicsClientId=client))


def get_joint_positions(client: int, body: int, joints: list[int]) -> list[float]:
    return [s.joint_position for s in get_joint_states(client, body, joints)]


def get_link_state(client: int, body: int, link: int) -> LinkState:
    return LinkState(*p.getLinkState(body, link, physicsClientId=client))


def get_dynamics_info(client: int, body: int, link: int = -1) -> DynamicsInfo:
    return DynamicsInfo(*p.getDynamicsInfo(body, link, physicsClientId=client))


def get_constraint_info(client: int, constraint: int) -> ConstraintInfo:
    return ConstraintInfo(*p.getConstraintInfo(constraint, physicsClientId=client))


def get_pose(client: int, body: int) -> BodyPose:
    return BodyPose(*p.getBasePositionAndOrientation(body, physicsClientId=client))


def get_point(client: int, body: int) -> Vec3:
    return get_pose(client, body).position


def matrix_from_quat(quat: Quat | list[float]) -> np.ndarray:
    """Unit quaternion (x, y, z, w) → 3×3 rotation matrix, as pybullet computes it."""
    return np.array(p.getMatrixFromQuaternion(quat)).reshape(3, 3)
