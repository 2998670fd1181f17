"""Gripper specs → URDF → pybullet bodies, for both shipped grippers."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import pybullet as p
import pytest
from graspscape.shared.specs.gripper import list_grippers, load_gripper
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import PhaseTimes
from graspscape.shared.specs.sim import PhysicsSettings, SimSettings
from graspscape.workers.sim.bullet import get_joint_state
from graspscape.workers.sim.gripper.hand import Hand
from graspscape.workers.sim.gripper.urdf import gripper_urdf


def test_both_grippers_ship():
    assert {"robotiq_3f", "parallel_jaw"} <= set(list_grippers())


def test_robotiq_urdf_has_three_fingers_of_three_phalanges_and_the_scissor():
    root = ET.fromstring(gripper_urdf(load_gripper("robotiq_3f")))
    joints = {j.get("name"): j for j in root.iter("joint")}
    for finger in "ABC":
        for k in "123":
            assert joints[f"{finger}_{k}_joint"].get("type") == "revolute"
    assert "B_spread_joint" in joints and "C_spread_joint" in joints
    assert "A_spread_joint" not in joints  # finger A is fixed to the palm
    # The open hand reaches about 12 cm past the palm, as the real one does.
    assert 0.10 < load_gripper("robotiq_3f").reach() < 0.14


@pytest.mark.parametrize("name", ["robotiq_3f", "parallel_jaw"])
def test_fingers_close_to_their_limits_on_nothing(name, tmp_path):
    cid = p.connect(p.DIRECT)
    try:
        spec = load_gripper(name)
        hand = Hand(cid, spec, tmp_path)
        p.createConstraint(hand.body, -1, -1, -1, p.JOINT_FIXED, [0, 0, 0], [0, 0, 0], [0, 0, 1],
                           physicsClientId=cid)
        hand.reset_open(0.0, spec.closing_effort, 3.0)
        hand.begin_closing(6.0)
        for step in range(1, 481):
            p.stepSimulation(physicsClientId=cid)
            if step % 6 == 0 and hand.update_closing(0.01):
                break
        for finger in hand.fingers:
            angles = hand.finger_angles(finger)
            # Closing in free air, the first phalanx runs to its limit (and never past it).
            assert angles[0] == pytest.approx(finger.uppers[0], abs=0.02)
            assert all(a <= u + 0.02 for a, u in zip(angles, finger.uppers, strict=True))
    finally:
        p.disconnect(cid)


def test_parallel_jaw_gripper_holds_the_cube(make_evaluator):
    evaluator = make_evaluator("cube", gripper="parallel_jaw")
    result = evaluator.evaluate(Pose(theta=math.pi / 2, phi=0.0, r=0.02))
    assert result.viable
    assert {"L_pad", "R_pad"} <= set(result.signature.links_in_contact)


@pytest.mark.parametrize("iterations", [50, 10])
def test_a_blocked_phalanx_pushes_with_its_full_share_of_the_closing_effort(make_evaluator,
                                                                           iterations):
    # G_c closes with a constant torque τ_c. A velocity motor aimed at the closing speed reached
    # only part of its force cap within the solver's iterations when blocked; a blocked phalanx
    # must push with its whole share, whatever the iteration count.
    settings = SimSettings(physics=PhysicsSettings(solver_iterations=iterations))
    evaluator = make_evaluator("sphere", settings=settings)
    scene, hand = evaluator.scene, evaluator.scene.hand
    evaluator._reset()
    position, rotation, target, _ = evaluator._start_pose(Pose(theta=0.0, phi=0.0, r=0.02))
    assert evaluator.policy.synthesize(scene, position, rotation, target, settings,
                                       PhaseTimes()) is None
    scene.step()
    touching = {c.link_index_a for c in scene.contacts()}
    pushing = 0
    for finger in hand.fingers:
        for k in range(finger.active):
            if finger.joints[k] in touching:
                torque = get_joint_state(scene.client, hand.body,
                                         finger.joints[k]).applied_joint_motor_torque
                assert torque == pytest.approx(hand.effort * finger.shares[k], rel=0.01)
                pushing += 1
    assert pushing >= 3
