"""G_s on a parallel jaw whose second finger follows the first through a gear (the WSG-50),
with real pybullet: the policy senses the coupled finger and closes the hand on the object."""

from __future__ import annotations

import math

import numpy as np
import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.policies.haptic import ProximitySensors, joint_jacobian

HAPTIC = SimSettings(policy_name="haptic")


@pytest.fixture(scope="module")
def wsg_sphere(make_evaluator):
    return make_evaluator("sphere", gripper="wsg50", settings=HAPTIC)


@pytest.mark.parametrize("pose", [
    Pose(theta=math.pi / 2, phi=0.0, r=0.02, roll=0.0),
    Pose(theta=math.pi / 2, phi=0.0, r=0.02, roll=math.pi / 2),
    # From above at a slant: step 2 stalls with the palm < 1 nm short of the contact band.
    Pose(theta=0.8, phi=0.0, r=0.02, roll=math.pi / 2),
])
def test_the_wsg50_closes_on_the_sphere_with_both_fingers(wsg_sphere, pose):
    # 2 cm out: the open jaw (11 cm) straddles the 8 cm sphere, nothing touches at the start.
    # Before, step 2 brought palm and left jaw into the contact band without touching, the
    # unsensed right jaw stayed off, and the pose ended with no contact; now both jaws press
    # on the sphere and it stays held.
    result = wsg_sphere.evaluate(pose)
    assert result.outcome is Outcome.HELD and result.viable
    assert {"L_1", "R_1"} <= set(result.contacts_per_link)


def test_a_probe_of_the_driver_moves_the_coupled_finger(wsg_sphere):
    ev = wsg_sphere
    ev._reset()
    ev._start_pose(Pose(theta=math.pi / 2, phi=0.0, r=0.02))
    hand = ev.scene.hand
    sensors = ProximitySensors(ev.scene, HAPTIC.haptic, seed=0)
    right = hand.joint_by_name["R_1_joint"]
    assert right in sensors.links  # the follower is sensed
    before = [hand.joint_angles()[name] for name in ("L_1", "R_1")]
    jac = joint_jacobian(sensors, hand.finger_joints, 0.005)
    # Closing the left jaw (the only actuated joint) brings both jaws nearer the sphere by
    # about the probe's travel: the follower's row is not zero.
    left_row, right_row = sensors.index[hand.finger_joints[0]], sensors.index[right]
    assert jac[left_row, 0] == pytest.approx(-1.0, abs=0.2)
    assert jac[right_row, 0] == pytest.approx(-1.0, abs=0.2)
    # and the probe put both joints back.
    assert np.allclose([hand.joint_angles()[name] for name in ("L_1", "R_1")], before)
