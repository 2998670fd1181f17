"""The robustness margins and grasp tests in MuJoCo (workers/sim/mj/robustness.py): the same
code as pybullet's (workers/sim/grasp_tests.py) through MuJoCo's trials, and the same anchors:
an object welded to the palm passes everything, one the hand cannot touch fails everything, a
grasp squeezed with a few per cent of its effort slips under the tug and falls in the shake."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import pytest
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import Outcome, RobustnessReport
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.engine import make_evaluator
from graspscape.workers.sim.mj.calibration import _weld_here
from graspscape.workers.sim.mj.evaluate import MjEvaluator
from graspscape.workers.sim.mj.robustness import restore, run_tests
from graspscape.workers.sim.mj.world import HAND_GROUP, OBJECT_GROUP
from graspscape.workers.sim.objects import prepare_object

EVERY = RobustnessSettings.every_test()
FROM_ABOVE = Pose(theta=0.3, phi=0.0, r=0.02)
TUG_AND_SHAKE = RobustnessSettings(tests=("tug", "shake"))


@pytest.fixture(scope="module")
def mj_own(sim_cache, object_cache) -> MjEvaluator:
    """Its own evaluator: these tests weld the object and switch collisions off."""
    prepared = prepare_object(ObjectSpec(name="sphere"), object_cache)
    return make_evaluator(prepared, load_gripper("robotiq_3f"), SimSettings(engine="mujoco"),
                          work_dir=sim_cache)


def test_no_test_chosen_runs_nothing_in_mujoco(mj_own) -> None:
    with mj_own.synthesized(FROM_ABOVE) as (result, grasp):
        assert result.outcome is Outcome.HELD and grasp is not None
        assert run_tests(mj_own, grasp, RobustnessSettings()) == RobustnessReport()


def test_object_the_hand_cannot_touch_fails_everything_in_mujoco(mj_own) -> None:
    model = mj_own.world.model
    hand = mj_own.world.geom_link != -2
    with mj_own.synthesized(FROM_ABOVE) as (result, grasp):
        assert result.outcome is Outcome.HELD
        model.geom_contype[hand], model.geom_conaffinity[hand] = 0, 0
        try:
            report = run_tests(mj_own, grasp, EVERY)
        finally:
            model.geom_contype[hand], model.geom_conaffinity[hand] = HAND_GROUP, OBJECT_GROUP
    assert report.torque_margin_nm is None and report.friction_margin is None
    assert report.gravity_test_share == 0.0 and report.force_test_share == 0.0
    assert report.tug_force_n == 0.0
    assert report.shake_survival_s == pytest.approx(0.0, abs=0.02)


def test_a_loose_grasp_slips_under_the_tug_and_falls_in_the_shake(mj_own) -> None:
    """The same synthesized grasp, its fingers' forces cut to 3 %: the pull it resists drops
    and it falls out of the shake, which the full grasp survives."""
    with mj_own.synthesized(FROM_ABOVE) as (result, grasp):
        assert result.outcome is Outcome.HELD
        fingers = set(mj_own.scene.hand.finger_joints)
        loose = dataclasses.replace(grasp, commands={
            j: (mode, target, force * (0.03 if j in fingers else 1.0))
            for j, (mode, target, force) in grasp.commands.items()})
        full = run_tests(mj_own, grasp, TUG_AND_SHAKE)
        weak = run_tests(mj_own, loose, TUG_AND_SHAKE)
    duration = 3 * EVERY.shake_axis_s
    assert full.shake_survival_s == pytest.approx(duration)
    assert 0.0 < weak.shake_survival_s < duration
    assert 0.0 < weak.tug_force_n < 0.5 * full.tug_force_n


@pytest.mark.slow
def test_object_welded_to_the_palm_passes_everything_in_mujoco(mj_own) -> None:
    with mj_own.synthesized(Pose(theta=1.0, phi=0.5, r=0.02)) as (_, grasp):
        assert grasp is not None
        # The weld where synthesis left the object, kept in the grasp every trial restores.
        restore(mj_own, grasp)
        _weld_here(mj_own)
        mujoco.mj_copyData(grasp.state, mj_own.world.model, mj_own.data)
        report = run_tests(mj_own, grasp, EVERY)
    assert report.torque_margin_nm == pytest.approx(EVERY.torque_lo_fraction * grasp.effort)
    assert report.friction_margin == pytest.approx(EVERY.friction_lo)
    assert report.gravity_test_share == 1.0 and report.force_test_share == 1.0
    top = EVERY.tug_max_weights * grasp.mass_kg * EVERY.gravity_m_s2
    assert report.tug_force_n == pytest.approx(top)
    assert report.shake_survival_s == pytest.approx(3 * EVERY.shake_axis_s)


@pytest.mark.slow
def test_every_test_runs_in_mujoco_and_leaves_nothing_behind(sim_cache, object_cache) -> None:
    prepared = prepare_object(ObjectSpec(name="sphere"), object_cache)
    settings = SimSettings(engine="mujoco", robustness=EVERY)
    evaluator = make_evaluator(prepared, load_gripper("robotiq_3f"), settings,
                               work_dir=sim_cache)
    first = evaluator.evaluate(FROM_ABOVE)
    report = first.robustness
    assert first.outcome is Outcome.HELD and report is not None
    effort = load_gripper("robotiq_3f").closing_effort
    assert EVERY.torque_lo_fraction * effort < report.torque_margin_nm < effort
    assert EVERY.friction_lo < report.friction_margin < prepared.friction
    assert 0.0 < report.gravity_test_share <= 1.0 and 0.0 < report.force_test_share <= 1.0
    top = EVERY.tug_max_weights * prepared.mass_kg * EVERY.gravity_m_s2
    assert 0.0 < report.tug_force_n <= top
    assert 0.0 < report.shake_survival_s <= 3 * EVERY.shake_axis_s
    again = evaluator.evaluate(FROM_ABOVE)
    assert again.robustness == report and again.mu_s == first.mu_s
    assert math.isfinite(again.mu_s)
