"""The start gap (`placement.start_gap`): the stepped search with bisection, and the
"clearance" mode in pybullet — the open hand starts r away from touching along its approach
axis, at r levels that stay r apart instead of repeating one backed-off start."""

from __future__ import annotations

import math

import pybullet as p
import pytest
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import PlacementSettings, SimSettings
from graspscape.workers.sim.start_gap import first_clear_gap


def test_the_palm_mode_stops_at_the_first_clear_step() -> None:
    assert first_clear_gap(lambda d: d >= 0.0123, 0.0, 0.005, 0.1) == pytest.approx(0.015)
    assert first_clear_gap(lambda d: d >= 0.5, 0.0, 0.005, 0.1) is None
    assert first_clear_gap(lambda d: True, 0.01, 0.005, 0.1) == 0.01


def test_bisection_ends_within_the_tolerance_above_where_it_clears() -> None:
    calls: list[float] = []

    def clear(d: float) -> bool:
        calls.append(d)
        return d >= 0.0123

    gap = first_clear_gap(clear, 0.0, 0.005, 0.1, 1e-4)
    assert 0.0123 <= gap <= 0.0123 + 1e-4
    assert len(calls) <= 4 + 7  # three steps out, then log2(5 mm / 0.1 mm) halvings
    assert first_clear_gap(clear, 0.0, 0.005, 0.1, 1e-4) == gap  # deterministic


@pytest.fixture(scope="module")
def clearance_mug(make_evaluator):
    return make_evaluator("mug", settings=SimSettings(
        placement=PlacementSettings(start_gap="clearance")))


def _min_distance(evaluator, position, rotation) -> float:
    evaluator._place(position, rotation)
    points = p.getClosestPoints(evaluator.scene.hand.body, evaluator.scene.object_body, 0.05,
                                physicsClientId=evaluator.client)
    return min((pt[8] for pt in points), default=0.05)


def test_clearance_r_levels_are_r_apart_and_the_hand_just_clears(clearance_mug,
                                                                  mug_evaluator) -> None:
    # From the side of the mug, the open fingers meet the body before the palm does: the
    # palm mode backs every r level off to the same 5 mm step; the clearance mode keeps them
    # r apart (the Euclidean gap of fingers alongside the body grows more slowly).
    tolerance = clearance_mug.settings.placement.clearance_tolerance_m
    gaps, palm_gaps = [], []
    for r in (0.0, 0.01, 0.02):
        pose = Pose(theta=math.pi / 2, phi=0.5, r=r)
        clearance_mug._reset()
        position, rotation, target, gap = clearance_mug._start_pose(pose)
        gaps.append(gap)
        # Clear where it starts, and touching once moved r (and a little) toward x_c
        # ("touching": deeper than the back-off's penetration tolerance).
        touch = clearance_mug.settings.placement.penetration_tolerance_m
        assert _min_distance(clearance_mug, position, rotation) >= -touch
        normal = (position - target) / gap
        assert _min_distance(clearance_mug, position - normal * (r + 2 * tolerance),
                             rotation) < -touch
        mug_evaluator._reset()
        palm_gaps.append(mug_evaluator._start_pose(pose)[3])
    assert gaps[0] > 0.03  # the fingers, not the palm, set the start
    assert gaps[1] - gaps[0] == pytest.approx(0.01, abs=0.001)
    assert gaps[2] - gaps[1] == pytest.approx(0.01, abs=0.001)
    assert max(palm_gaps) - min(palm_gaps) < 1e-4  # one start: what the clearance mode fixes
