"""The pybullet helpers (workers/sim/bullet.py) on a real client: each record reads pybullet's
tuple field by field, and a saved state is put back and freed however its block ends."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PhaseTimes
from graspscape.workers.sim.bullet import (
    ContactPoint,
    get_closest_points,
    get_constraint_info,
    get_dynamics_info,
    get_joint_info,
    get_joint_state,
    get_joint_states,
    get_link_state,
    get_point,
    get_pose,
    matrix_from_quat,
    restore_state,
    restore_state_clean,
    saved_state,
)

FROM_SIDE = Pose(theta=math.pi / 2, phi=0.0, r=0.02)


def _bodies(evaluator) -> np.ndarray:
    """Positions, orientations and joint positions of hand and object: the state to compare."""
    scene, cid = evaluator.scene, evaluator.client
    values = []
    for body in (scene.hand.body, scene.object_body):
        values += [*get_point(cid, body), *get_pose(cid, body).orientation]
    values += [s.joint_position for s in get_joint_states(cid, scene.hand.body,
                                                          scene.hand.movable)]
    return np.array(values)


def _grasped(evaluator) -> None:
    evaluator._reset()
    position, rotation, target, _ = evaluator._start_pose(FROM_SIDE)
    assert evaluator.policy.synthesize(evaluator.scene, position, rotation, target,
                                       evaluator.settings, PhaseTimes()) is None


def test_records_name_pybullets_fields(sphere_evaluator):
    _grasped(sphere_evaluator)
    scene, cid, hand = sphere_evaluator.scene, sphere_evaluator.client, sphere_evaluator.scene.hand
    contacts = scene.contacts()
    assert contacts and all(isinstance(c, ContactPoint) for c in contacts)
    raw = p.getContactPoints(hand.body, scene.object_body, physicsClientId=cid)
    first = contacts[0]
    assert tuple(first) in [tuple(r) for r in raw]
    assert first.body_unique_id_a == hand.body and first.body_unique_id_b == scene.object_body
    assert first.link_index_a in hand.link_names and first.normal_force >= 0.0
    assert np.linalg.norm(first.contact_normal_on_b) == pytest.approx(1.0)

    joint = hand.finger_joints[0]
    info = get_joint_info(cid, hand.body, joint)
    assert info.joint_index == joint and info.joint_type == p.JOINT_REVOLUTE
    assert info.joint_name.decode() in hand.joint_by_name
    assert info.joint_lower_limit < info.joint_upper_limit
    state = get_joint_state(cid, hand.body, joint)
    assert state == p.getJointState(hand.body, joint, physicsClientId=cid)
    link = get_link_state(cid, hand.body, joint)
    assert len(link.link_world_orientation) == 4
    dynamics = get_dynamics_info(cid, scene.object_body)
    assert dynamics.mass > 0.0 and dynamics.lateral_friction > 0.0
    constraint = get_constraint_info(cid, scene.drive_constraint)
    assert constraint.parent_body_unique_id == hand.body
    assert constraint.constraint_type == p.JOINT_FIXED
    np.testing.assert_array_equal(matrix_from_quat([0.0, 0.0, 0.0, 1.0]), np.eye(3))


def test_closest_points_of_one_link(sphere_evaluator):
    _grasped(sphere_evaluator)
    scene, cid = sphere_evaluator.scene, sphere_evaluator.client
    every = get_closest_points(cid, scene.hand.body, scene.object_body, 0.5)
    palm = get_closest_points(cid, scene.hand.body, scene.object_body, 0.5, link_a=-1)
    assert palm and {pt.link_index_a for pt in palm} == {-1}
    assert len({pt.link_index_a for pt in every}) > 1


def test_saved_state_puts_the_state_back_even_when_the_block_raises(sphere_evaluator):
    _grasped(sphere_evaluator)
    scene, cid = sphere_evaluator.scene, sphere_evaluator.client
    before = _bodies(sphere_evaluator)
    with pytest.raises(RuntimeError), saved_state(cid):
        for _ in range(20):
            scene.step()
        assert not np.array_equal(_bodies(sphere_evaluator), before)
        raise RuntimeError("interrupted")
    np.testing.assert_array_equal(_bodies(sphere_evaluator), before)


def test_saved_state_is_freed_on_leaving(sphere_evaluator):
    cid = sphere_evaluator.client
    with saved_state(cid) as state:
        restore_state(cid, state)
    with pytest.raises(p.error):
        restore_state(cid, state)  # removed: pybullet no longer knows it
    with saved_state(cid, restore=False) as kept:
        pass
    with pytest.raises(p.error):
        restore_state(cid, kept)


def test_clean_restore_puts_the_state_back_and_rollouts_repeat(sphere_evaluator):
    _grasped(sphere_evaluator)
    scene, cid = sphere_evaluator.scene, sphere_evaluator.client
    start = _bodies(sphere_evaluator)
    with saved_state(cid) as state:
        runs = []
        for _ in range(2):
            restore_state_clean(cid, state, contact_free=sphere_evaluator.pristine)
            np.testing.assert_array_equal(_bodies(sphere_evaluator), start)
            for _ in range(30):
                scene.step()
            runs.append(_bodies(sphere_evaluator))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert not np.array_equal(runs[0], start)
