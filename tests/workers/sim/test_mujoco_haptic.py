"""The haptic policy G_s in MuJoCo: the same policy code (workers/sim/policies/haptic.py) on the
MuJoCo scene's proximity sensors and probes (workers/sim/mj/scene.py)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.engine import make_evaluator
from graspscape.workers.sim.mj.evaluate import MjEvaluator
from graspscape.workers.sim.objects import prepare_object
from graspscape.workers.sim.policies.haptic import (
    ProximitySensors,
    base_jacobian,
    joint_jacobian,
)

HAPTIC = SimSettings(engine="mujoco", policy_name="haptic")
FROM_SIDE = Pose(theta=math.pi / 2, phi=0.0, r=0.02)


@pytest.fixture(scope="module")
def mj_haptic_sphere(sim_cache, object_cache) -> MjEvaluator:
    prepared = prepare_object(ObjectSpec(name="sphere"), object_cache)
    return make_evaluator(prepared, load_gripper("robotiq_3f"), HAPTIC, work_dir=sim_cache)


@pytest.mark.parametrize("pose", [FROM_SIDE, Pose(theta=0.5, phi=1.0, r=0.03)])
def test_haptic_policy_holds_the_sphere_in_mujoco(mj_haptic_sphere, pose) -> None:
    result = mj_haptic_sphere.evaluate(pose)
    assert result.outcome is Outcome.HELD, result.outcome
    assert result.viable and result.mu_s > 0.0
    fingers = {link[0] for link in result.contacts_per_link if link != "palm"}
    assert fingers == {"A", "B", "C"}


def test_haptic_policy_facing_away_grasps_nothing_in_mujoco(mj_haptic_sphere) -> None:
    result = mj_haptic_sphere.evaluate(Pose(theta=math.pi / 2, phi=0.0, r=0.02, pitch=math.pi))
    assert result.outcome is not Outcome.HELD and result.mu_s == 0.0


def test_mujoco_proximity_reads_what_pybullet_reads(mj_haptic_sphere, make_evaluator) -> None:
    """The same open hand at the same start pose: every link's distance to the sphere agrees
    between the engines' closest-point queries within pybullet's collision margin (MuJoCo reads
    the palm's start gap as placed, 20 mm; pybullet 1 mm less)."""
    readings = []
    for ev in (mj_haptic_sphere, make_evaluator("sphere", settings=SimSettings(
            policy_name="haptic"))):
        ev._reset()
        position, rotation, *_ = ev._start_pose(FROM_SIDE)
        ev.scene.place_hand(position, rotation)
        sensors = ProximitySensors(ev.scene, HAPTIC.haptic, seed=0)
        readings.append(sensors.exact())
    assert readings[0][0] == pytest.approx(FROM_SIDE.r, abs=1e-6)
    np.testing.assert_allclose(readings[0], readings[1], atol=1.2e-3)


def test_jacobian_probes_leave_the_mujoco_simulation_untouched(mj_haptic_sphere) -> None:
    ev = mj_haptic_sphere
    ev._reset()
    ev._start_pose(FROM_SIDE)
    hand, m = ev.scene.hand, ev.world.model
    hand.begin_closing(6.0)
    for _ in range(30):
        ev.scene.step()
    saved = mujoco.MjData(m)
    mujoco.mj_copyData(saved, m, ev.data)
    runs = []
    for probe in (False, True):
        mujoco.mj_copyData(ev.data, m, saved)
        if probe:
            sensors = ProximitySensors(ev.scene, HAPTIC.haptic, seed=0)
            jac = np.hstack([base_jacobian(sensors, 0.002, 0.02),
                             joint_jacobian(sensors, hand.finger_joints, 0.01)])
            assert np.abs(jac[:, :6]).max() > 0.1 and np.abs(jac[:, 6:]).max() > 0.01
        trace = []
        for _ in range(60):
            ev.scene.step()
            trace.append(np.concatenate([ev.data.qpos, ev.data.qvel]))
        runs.append(np.array(trace))
    np.testing.assert_array_equal(runs[0], runs[1])
