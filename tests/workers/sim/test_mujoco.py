"""The MuJoCo engine beside pybullet: the same pose, object, gripper and settings give the same
kind of result in both (workers/sim/engine.py, workers/sim/mj/)."""

from __future__ import annotations

import math
import typing

import pytest
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.shared.specs.sim import ENGINE_NAMES, EngineName, SimSettings
from graspscape.workers.sim.engine import available_engines, make_evaluator
from graspscape.workers.sim.metric import mu_s
from graspscape.workers.sim.mj.calibration import weld_reading
from graspscape.workers.sim.mj.evaluate import MjEvaluator
from graspscape.workers.sim.objects import prepare_object
from pydantic import ValidationError

FROM_SIDE = Pose(theta=math.pi / 2, phi=0.0, r=0.01)
FACING_AWAY = Pose(theta=math.pi / 2, phi=0.0, r=0.02, pitch=math.pi)
MUJOCO = SimSettings(engine="mujoco")


@pytest.fixture(scope="module")
def mj_sphere(sim_cache, object_cache) -> MjEvaluator:
    prepared = prepare_object(ObjectSpec(name="sphere"), object_cache)
    return make_evaluator(prepared, load_gripper("robotiq_3f"), MUJOCO, work_dir=sim_cache)


def test_engine_names_are_the_settings_choices() -> None:
    assert typing.get_args(EngineName) == ENGINE_NAMES
    assert SimSettings().engine == "pybullet"
    with pytest.raises(ValidationError):
        SimSettings(engine="physx")
    assert set(available_engines()) == set(ENGINE_NAMES)  # both are installed here


def test_a_sphere_gripped_from_the_side_is_held_in_both_engines(sphere_evaluator,
                                                                mj_sphere) -> None:
    for result in (sphere_evaluator.evaluate(FROM_SIDE), mj_sphere.evaluate(FROM_SIDE)):
        assert result.outcome is Outcome.HELD, result.outcome
        assert result.viable and 0.5 < result.mu_s <= 1.0
        assert result.signature is not None
        # Fingers on both sides: finger A opposes B and C.
        fingers = {link[0] for link in result.signature.links_in_contact if link != "palm"}
        assert fingers == {"A", "B", "C"}
        assert result.effort_max_nm is not None and result.effort_max_nm > 0.5


def test_a_palm_facing_away_grasps_nothing_in_both_engines(sphere_evaluator,
                                                           mj_sphere) -> None:
    for result in (sphere_evaluator.evaluate(FACING_AWAY), mj_sphere.evaluate(FACING_AWAY)):
        assert result.outcome is not Outcome.HELD
        assert not result.viable and result.mu_s == 0.0


def test_a_weld_scores_mu_s_at_least_0_97_in_mujoco(mj_sphere) -> None:
    qualities = weld_reading(mj_sphere, Pose(theta=1.57, phi=0.0, r=0.02))
    assert len(qualities) == MUJOCO.metric.instants
    assert mu_s(qualities) >= 0.97


def test_the_same_pose_gives_the_same_result_twice_in_mujoco(mj_sphere) -> None:
    skip = {"eval_time_s", "phases"}
    first = mj_sphere.evaluate(FROM_SIDE).model_dump(exclude=skip)
    mj_sphere.evaluate(Pose(theta=1.0, phi=2.0, r=0.02, roll=0.7))  # something in between
    assert mj_sphere.evaluate(FROM_SIDE).model_dump(exclude=skip) == first


@pytest.mark.slow
@pytest.mark.parametrize("gripper", ["robotiq_3f_urdf", "franka_hand"])
def test_urdf_grippers_grasp_the_sphere_in_mujoco(gripper, sim_cache, object_cache) -> None:
    prepared = prepare_object(ObjectSpec(name="sphere"), object_cache)
    evaluator = make_evaluator(prepared, load_gripper(gripper), MUJOCO, work_dir=sim_cache)
    results = [evaluator.evaluate(Pose(theta=math.pi / 2, phi=phi, r=0.01, roll=roll))
               for phi in (0.0, 2.0) for roll in (0.0, math.pi / 2)]
    assert any(r.outcome is Outcome.HELD for r in results), [r.outcome for r in results]


@pytest.mark.slow
def test_mujoco_measures_the_torque_and_friction_margins(sim_cache, object_cache) -> None:
    prepared = prepare_object(ObjectSpec(name="sphere"), object_cache)
    settings = SimSettings(engine="mujoco", robustness=RobustnessSettings(
        tests=("torque_margin", "friction_margin")))
    evaluator = make_evaluator(prepared, load_gripper("robotiq_3f"), settings,
                               work_dir=sim_cache)
    first = evaluator.evaluate(FROM_SIDE)
    assert first.outcome is Outcome.HELD and first.robustness is not None
    effort = load_gripper("robotiq_3f").closing_effort
    tau = first.robustness.torque_margin_nm
    assert tau is not None and 0.0 < tau < effort
    mu = first.robustness.friction_margin
    assert mu is not None and 0.0 < mu < prepared.friction
    assert first.robustness.gravity_test_share is None  # not chosen
    # The trials leave nothing behind: the next evaluation is the same.
    again = evaluator.evaluate(FROM_SIDE)
    assert again.robustness == first.robustness and again.mu_s == first.mu_s
