"""Outcome-only draws: the same outcome and grasp as a full evaluation, the scales applied
and put back, in pybullet and MuJoCo: a twentieth of the friction loses a side grasp of the
sphere that holds; at half the friction a tenth of the closing effort still holds it, but
not at ten times its mass; a draw in both engines holds only where each holds."""

from __future__ import annotations

import importlib.util
import math

import pytest
from graspscape.shared.specs.gripper import load_gripper
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import DrawScales, Outcome
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.bullet import get_dynamics_info
from graspscape.workers.sim.engine import make_evaluator as engine_evaluator
from graspscape.workers.sim.objects import prepare_object
from graspscape.workers.sim.samples import sample, sample_result

POSES = [Pose(theta=t, phi=f, r=0.01, roll=0.0, pitch=0.0, yaw=0.0)
         for t, f in ((0.6, 0.0), (1.2, 1.5), (1.8, 3.0), (2.4, 4.5), (1.2, 4.5))]


def test_sample_matches_a_full_evaluation(mug_evaluator) -> None:
    for pose in POSES:
        full = mug_evaluator.evaluate(pose)
        got = sample(mug_evaluator, pose)
        assert got.outcome == full.outcome
        if full.signature is not None:
            assert set(got.links) == set(full.signature.links_in_contact)


@pytest.mark.slow  # ~20 more simulations
def test_scales_change_the_outcome_and_are_put_back(mug_evaluator) -> None:
    cid, body = mug_evaluator.client, mug_evaluator.scene.object_body
    before = get_dynamics_info(cid, body)
    held = [q for q in POSES if sample(mug_evaluator, q).held]
    assert len(held) >= 3
    # A twentieth of the friction and ten times the mass: nothing holds.
    assert not any(sample(mug_evaluator, q, friction_scale=0.05, mass_scale=10.0).held
                   for q in held)
    after = get_dynamics_info(cid, body)
    assert (after.lateral_friction, after.mass, after.local_inertia_diagonal) == (
        before.lateral_friction, before.mass, before.local_inertia_diagonal)
    # ... and the next plain draw is the plain one again.
    assert all(sample(mug_evaluator, q).held for q in held)


# --- the uncertainty model's scales, physically, in both engines ---------------------------
SIDE = Pose(theta=math.pi / 2, phi=0.0, r=0.01)  # the sphere (0.2 kg) gripped from the side


@pytest.fixture(scope="module", params=["pybullet", "mujoco"])
def sphere_in(request, sim_cache, object_cache):
    if request.param == "mujoco" and importlib.util.find_spec("mujoco") is None:
        pytest.skip("mujoco is not installed")
    prepared = prepare_object(ObjectSpec(name="sphere"), object_cache)
    return engine_evaluator(prepared, load_gripper("robotiq_3f"),
                            SimSettings(engine=request.param), work_dir=sim_cache)


def test_a_twentieth_of_the_friction_loses_a_side_grasp_that_holds(sphere_in) -> None:
    assert sample(sphere_in, SIDE).held
    assert not sample(sphere_in, SIDE, friction_scale=0.05).held
    # The object's friction is put back: the next plain draw holds again.
    assert sample(sphere_in, SIDE).held


def test_a_tenth_of_the_effort_holds_the_sphere_but_not_ten_times_its_mass(sphere_in) -> None:
    # At half the friction (at full friction the closed hand cages even 2 kg).
    assert sample(sphere_in, SIDE, friction_scale=0.5, effort_scale=0.1).held
    assert not sample(sphere_in, SIDE, friction_scale=0.5, mass_scale=10.0,
                      effort_scale=0.1).held
    assert sample(sphere_in, SIDE).held


@pytest.mark.skipif(importlib.util.find_spec("mujoco") is None, reason="mujoco is not installed")
def test_a_draw_in_both_engines_holds_only_where_each_holds(sim_cache) -> None:
    both = sample_result(SIDE, obj=ObjectSpec(name="sphere"), gripper="robotiq_3f",
                         settings=SimSettings(), engines=["pybullet", "mujoco"],
                         cache_dir=sim_cache)
    assert both.viable and both.sample is not None and both.mu_s == 0.0
    assert [e.outcome for e in both.sample.engines.values()] == [Outcome.HELD] * 2
    slippery = sample_result(SIDE, obj=ObjectSpec(name="sphere"), gripper="robotiq_3f",
                             settings=SimSettings(), engines=["pybullet", "mujoco"],
                             scales=DrawScales(friction=0.05), cache_dir=sim_cache)
    assert not slippery.viable and slippery.outcome is Outcome.DROPPED
    assert "mu_s" in slippery.sample.absent
