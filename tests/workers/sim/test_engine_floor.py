"""The evaluation's shortcuts (issue 21 item 5) give the very numbers of what they replace."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PhaseTimes
from graspscape.shared.specs.sim import TrajectorySpec
from graspscape.workers.sim.bullet import get_constraint_info, max_abs_motor_torque
from graspscape.workers.sim.geometry import axis_rotation, quat_from_matrix
from graspscape.workers.sim.grasp_metrics import Contact, mu_f, mu_m
from graspscape.workers.sim.trajectory import ReferencePath, reference_pose, rotation_angle
from scipy.spatial.transform import Rotation

FROM_SIDE = Pose(theta=math.pi / 2, phi=0.0, r=0.02)


def test_reference_path_is_reference_pose_bit_for_bit() -> None:
    spec = TrajectorySpec()
    rng = np.random.default_rng(3)
    start, pivot = rng.normal(size=3), rng.normal(size=3)
    rotation = Rotation.random(random_state=4).as_matrix()
    dt = 1 / 240
    path = ReferencePath(spec, start, rotation, pivot, dt)
    for step in (5, 0, 5, 700, 1, 10_000):  # any order, again, and past the trajectory's end
        position, turned = path.pose(step)
        want_position, want_rotation = reference_pose(spec, start, rotation, pivot, step * dt)
        assert position.tobytes() == want_position.tobytes()
        assert turned.tobytes() == want_rotation.tobytes()
        assert path.drive(step) == (want_position.tolist(), quat_from_matrix(want_rotation))


def test_rotation_angle_is_scipys_magnitude() -> None:
    for seed in range(50):
        m = Rotation.random(random_state=seed).as_matrix()
        assert math.isclose(rotation_angle(m), Rotation.from_matrix(m).magnitude(),
                            rel_tol=0.0, abs_tol=1e-12)
    assert rotation_angle(np.eye(3)) == 0.0
    assert math.isclose(rotation_angle(np.diag([1.0, -1.0, -1.0])), math.pi, abs_tol=1e-12)


def test_mu_m_is_zero_wherever_mu_f_is() -> None:
    """scene_metrics skips μm's hull when μf = 0: the force-scaled wrenches never enclose
    the origin where the unit ones do not."""
    rng = np.random.default_rng(5)
    zeros = 0
    for _ in range(60):
        n = int(rng.integers(2, 5))
        contacts = []
        for _ in range(n):
            position = rng.normal(size=3) * 0.03
            normal = -position / np.linalg.norm(position) + rng.normal(size=3) * 0.6
            contacts.append(Contact(position=position, normal=normal / np.linalg.norm(normal),
                                    friction=float(rng.uniform(0.1, 0.8)),
                                    force=float(rng.choice([0.0, rng.uniform(0.1, 20.0)]))))
        if mu_f(contacts, 0.05) == 0.0:
            zeros += 1
            assert mu_m(contacts, 0.05, 1.0) == 0.0
    assert 5 < zeros < 60  # both cases occur


def _quat_from_matrix_on_numpy_scalars(m: np.ndarray) -> list[float]:
    """geometry.quat_from_matrix as it was before it read the matrix as Python floats."""
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = (0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s)
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = ((m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = ((m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s)
    n = math.sqrt(sum(c * c for c in q))
    return [float(c / n) for c in q]


def test_quat_from_matrix_on_python_floats_is_the_numpy_one_bit_for_bit() -> None:
    matrices = [Rotation.random(random_state=seed).as_matrix() for seed in range(300)]
    # every branch: trace > 0, and each diagonal entry the largest with trace ≤ 0
    matrices += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]),
                 np.diag([-1.0, -1.0, 1.0]), np.eye(3)]
    for m in matrices:
        assert quat_from_matrix(m) == _quat_from_matrix_on_numpy_scalars(m)


def test_axis_rotation_is_the_identity_with_its_block_set() -> None:
    for axis, (i, j) in enumerate([(1, 2), (2, 0), (0, 1)]):
        for angle in (0.0, 0.3, -2.0, math.pi):
            want = np.eye(3)
            c, s = math.cos(angle), math.sin(angle)
            want[i, i] = want[j, j] = c
            want[i, j], want[j, i] = -s, s
            got = axis_rotation(axis, angle)
            assert got.tobytes() == want.tobytes() and got.dtype == want.dtype


def test_scene_queries_without_records_read_what_the_records_do(sphere_evaluator) -> None:
    """The link lists, the drive's kept quaternion and the torque read without records
    (bullet.touching_link_indices, Scene.drive_to, bullet.max_abs_motor_torque)."""
    scene, cid = sphere_evaluator.scene, sphere_evaluator.client
    sphere_evaluator._reset()
    position, rotation, target, _ = sphere_evaluator._start_pose(FROM_SIDE)
    assert sphere_evaluator.policy.synthesize(scene, position, rotation, target,
                                              sphere_evaluator.settings, PhaseTimes()) is None
    hand = scene.hand
    points = scene.contacts()
    assert points and scene.in_contact()
    assert scene.touching_links() == frozenset(c.link_index_a for c in points)
    assert scene.palm_in_contact() == any(c.link_index_a == -1 for c in points)
    assert max_abs_motor_torque(cid, hand.body, hand.finger_joints) == \
        hand.max_finger_torque() > 0.0
    turned = axis_rotation(2, 0.4) @ rotation
    for r in (rotation, turned, turned.copy()):  # new rotations, then the kept one's twin
        scene.drive_to(position, r)
        orientation = get_constraint_info(cid, scene.drive_constraint) \
            .joint_frame_orientation_child
        p.changeConstraint(scene.drive_constraint, jointChildPivot=position.tolist(),
                           jointChildFrameOrientation=quat_from_matrix(r),
                           physicsClientId=cid)
        assert get_constraint_info(cid, scene.drive_constraint) \
            .joint_frame_orientation_child == orientation
