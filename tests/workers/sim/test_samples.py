"""Outcome-only draws: the same outcome and grasp as a full evaluation, the scales applied
and put back."""

from __future__ import annotations

import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim.bullet import get_dynamics_info
from graspscape.workers.sim.samples import sample

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
