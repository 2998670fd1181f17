"""Objects at rest on a table (support 'plane'): physical facts of the simulation.

The Robotiq 3F's open fingers reach ~12.7 cm past its palm and its palm is 11 cm across, so
on a table a start with the palm close above a small object puts the fingertips into the
table, and a side start needs an object taller than half the palm."""

from __future__ import annotations

import math

import numpy as np
import pybullet
import pytest
import trimesh
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.resting import chosen_resting_poses
from graspscape.shared.specs.results import Outcome
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.specs.support import RestingPose, TableScene
from graspscape.workers.sim.evaluate import evaluate_pose
from graspscape.workers.sim.objects import prepare_object


def _on_table(height: float) -> SimSettings:
    """The object upright (its frame the table's) with its centre of mass `height` up."""
    rest = RestingPose(index=0, probability=1.0, position=(0.0, 0.0, height),
                       quaternion=(0.0, 0.0, 0.0, 1.0))
    return SimSettings(table=TableScene(resting=rest))


def test_an_approach_from_below_the_mug_is_infeasible_without_a_step(tmp_path, monkeypatch):
    mug = ObjectSpec(name="mug")
    mesh = prepare_object(mug, tmp_path / "objects").mesh
    upright = next(r for r in chosen_resting_poses(mesh, min_probability=0.05, max_poses=4)
                   if r.up()[2] > 0.99)
    settings = SimSettings(table=TableScene(resting=upright))
    steps = []
    real_step = pybullet.stepSimulation
    monkeypatch.setattr(pybullet, "stepSimulation",
                        lambda *a, **k: (steps.append(1), real_step(*a, **k))[1])
    for r in (0.0, 0.03):
        result = evaluate_pose(Pose(theta=math.pi, phi=0.0, r=r), obj=mug, settings=settings,
                               cache_dir=tmp_path)
        assert result.outcome is Outcome.INFEASIBLE_TABLE
        assert not result.viable
    assert steps == []
    # The same start on the free mug is simulated.
    free = evaluate_pose(Pose(theta=math.pi, phi=0.0, r=0.03), obj=mug, cache_dir=tmp_path)
    assert free.outcome is not Outcome.INFEASIBLE_TABLE and steps


def test_a_sphere_on_a_table_is_held_from_above(tmp_path):
    # The fingertips reach the table first; the hand closes from there.
    sphere = ObjectSpec(name="sphere")
    result = evaluate_pose(Pose(theta=0.0, phi=0.0, r=0.06), obj=sphere,
                           settings=_on_table(0.0398), cache_dir=tmp_path)
    assert result.outcome is Outcome.HELD and result.mu_s > 0.3
    # The lift-off and the task ran: the object left the table in the hand.
    assert result.phases.trajectory_steps > 0


def test_a_large_sphere_on_a_table_is_held_from_the_side(tmp_path):
    # 14 cm across: taller than half the palm, so a horizontal start clears the table with
    # the fingers closing in the horizontal plane (roll π/2); with the fingers one above the
    # other (roll 0) the lower one is in the table.
    sphere = ObjectSpec(name="sphere", scale=1.75)
    settings = _on_table(0.07)
    side = evaluate_pose(Pose(theta=math.pi / 2, phi=0.0, r=0.03, roll=math.pi / 2),
                         obj=sphere, settings=settings, cache_dir=tmp_path)
    assert side.outcome is Outcome.HELD and side.mu_s > 0.3
    upright = evaluate_pose(Pose(theta=math.pi / 2, phi=0.0, r=0.03), obj=sphere,
                            settings=settings, cache_dir=tmp_path)
    assert upright.outcome is Outcome.INFEASIBLE_TABLE


def test_a_tall_box_pushed_from_the_side_is_knocked_over_not_held(tmp_path):
    # A 5 × 5 × 20 cm box standing on its end, approached from the side with the fingers
    # one above the other: the hand tips it over. Free, the same start forms no grasp either;
    # on the table it is told apart as knocked.
    path = tmp_path / "tall_box.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.2)).export(path)
    box = ObjectSpec(mesh_path=str(path), mass_kg=0.2)
    result = evaluate_pose(Pose(theta=math.pi / 2, phi=0.0, r=0.04), obj=box,
                           settings=_on_table(0.1), cache_dir=tmp_path)
    assert result.outcome is Outcome.KNOCKED and not result.viable
    assert result.phases.trajectory_steps == 0  # never lifted


def test_resting_poses_of_the_cube_and_the_sphere():
    cube = chosen_resting_poses(trimesh.creation.box(extents=(0.06, 0.06, 0.06)),
                                min_probability=0.05, max_poses=6)
    assert len(cube) == 6
    assert all(abs(r.probability - 1 / 6) < 1e-3 for r in cube)
    assert all(abs(r.position[2] - 0.03) < 1e-6 for r in cube)
    # Equally likely faces in the module's own order (+z, +y, +x up first), whatever order
    # trimesh lists its facets in.
    ups = [tuple(round(float(v), 6) + 0.0 for v in r.up()) for r in cube]
    assert ups == [(0, 0, 1), (0, 1, 0), (1, 0, 0), (-1, 0, 0), (0, -1, 0), (0, 0, -1)]
    # A polyhedral sphere rests on any of its 1,280 facets: one resting pose, merged.
    sphere = chosen_resting_poses(trimesh.creation.icosphere(subdivisions=3, radius=0.04),
                                  min_probability=0.05, max_poses=4)
    assert len(sphere) == 1 and sphere[0].probability == pytest.approx(1.0)
    assert np.linalg.norm(sphere[0].up()) == pytest.approx(1.0)


def test_a_draw_of_p_success_on_the_table_tells_the_same(tmp_path):
    # The outcome-only draws of the certification race meet the same table.
    from graspscape.workers.sim.evaluate import _evaluator
    from graspscape.workers.sim.samples import sample

    sphere = ObjectSpec(name="sphere")
    evaluator = _evaluator(sphere, "robotiq_3f", _on_table(0.0398), tmp_path)
    below = sample(evaluator, Pose(theta=math.pi, phi=0.0, r=0.03))
    assert below.outcome is Outcome.INFEASIBLE_TABLE
    above = sample(evaluator, Pose(theta=0.0, phi=0.0, r=0.06), mass_scale=1.2)
    assert above.held
