"""Shortcut 2 in the worker: a synthesized grasp that matches one already taken through the
trajectory reuses its outcome, μs and effort."""

from __future__ import annotations

import math

import pytest
from graspscape.shared.specs.exploration import ConfigurationMatch
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    GraspConfiguration,
    GraspSignature,
    Outcome,
    PoseResult,
)
from graspscape.workers.sim.configuration_inference import (
    DonorPool,
    configuration_gap,
    orientation_angle,
)

TOLERANCE = ConfigurationMatch()


def _grasp(x: float = 0.0, turn: float = 0.0, joint: float = 0.5) -> GraspConfiguration:
    return GraspConfiguration(base_position=(x, 0.0, 0.05),
                              base_orientation=(0.0, 0.0, math.sin(turn / 2), math.cos(turn / 2)),
                              joint_angles={"A_1": joint, "B_1": 0.4})


def _result(key: str, grasp: GraspConfiguration, links=("A_1", "B_1"), phi: float = 0.0,
            **kw) -> PoseResult:
    return PoseResult(pose=Pose(theta=1.0, phi=phi, r=0.01), pose_key=key,
                      outcome=kw.pop("outcome", Outcome.HELD), viable=kw.pop("viable", True),
                      mu_s=kw.pop("mu_s", 0.7), grasp=grasp,
                      signature=GraspSignature(links_in_contact=links, contacts=(),
                                               joint_angles=grasp.joint_angles), **kw)


def test_orientation_angle_ignores_the_quaternion_sign():
    q = (0.0, 0.0, math.sin(0.05), math.cos(0.05))
    assert orientation_angle(q, tuple(-c for c in q)) == pytest.approx(0.0, abs=1e-6)
    assert orientation_angle((0, 0, 0, 1), q) == pytest.approx(0.1)


def test_gap_is_the_worst_deviation_over_its_tolerance():
    assert configuration_gap(_grasp(), _grasp(x=0.001), TOLERANCE) == pytest.approx(0.5)
    assert configuration_gap(_grasp(), _grasp(turn=0.04), TOLERANCE) == pytest.approx(2.0)
    assert configuration_gap(_grasp(), _grasp(joint=0.6), TOLERANCE) == pytest.approx(2.0)
    other_hand = GraspConfiguration(base_position=(0, 0, 0.05), base_orientation=(0, 0, 0, 1),
                                    joint_angles={"left": 0.1})
    assert configuration_gap(_grasp(), other_hand, TOLERANCE) is None


def test_pool_gives_the_closest_donor_on_the_normal_with_the_same_links():
    pool = DonorPool(TOLERANCE)
    pool.add(_result("far", _grasp(x=0.0018)))
    pool.add(_result("near", _grasp(x=0.0005)))
    pool.add(_result("other-links", _grasp(), links=("A_1", "B_1", "palm")))
    pool.add(_result("copy", _grasp(), inferred_from="near"))  # never a donor
    pool.add(_result("other-normal", _grasp(), phi=0.5))
    here = Pose(theta=1.0, phi=0.0, r=0.015)
    assert pool.find(here, _grasp(), ("A_1", "B_1")).pose_key == "near"
    assert pool.find(here, _grasp(), ("A_1", "B_1", "palm")).pose_key == "other-links"
    assert pool.find(here, _grasp(x=0.01), ("A_1", "B_1")) is None
    assert pool.find(Pose(theta=1.0, phi=0.5, r=0.0), _grasp(), ("A_1", "B_1")).pose_key == (
        "other-normal")
    assert pool.find(Pose(theta=1.2, phi=0.0, r=0.0), _grasp(), ("A_1", "B_1")) is None


@pytest.mark.slow
def test_sphere_poses_along_one_normal_reuse_the_matching_grasp(sphere_evaluator):
    # Approached along one direction from different distances, the hand closes on the sphere
    # the same way: later poses match an earlier one and skip the trajectory.
    poses = [Pose(theta=1.57, phi=0.0, r=r) for r in (0.0, 0.005, 0.01, 0.015, 0.02)]
    pool = DonorPool(TOLERANCE)
    shortcut = [sphere_evaluator.evaluate(pose, donors=pool) for pose in poses]
    full = [sphere_evaluator.evaluate(pose) for pose in poses]
    reused = [(s, f) for s, f in zip(shortcut, full, strict=True) if s.inferred_from]
    assert reused, "no pose along the normal matched an earlier grasp"
    keys = {p.key() for p in poses}
    for s, f in reused:
        assert s.inferred_from in keys and s.inferred_from != s.pose_key
        assert s.outcome == f.outcome == Outcome.HELD
        assert s.mu_s == pytest.approx(f.mu_s, abs=0.1)
        assert s.phases.trajectory_steps == 0 and s.phases.sensitivity_steps == 0
        assert s.grasp == f.grasp  # its own synthesis, not the donor's
    for s, f in zip(shortcut, full, strict=True):
        if not s.inferred_from:  # taken through the trajectory: exactly the plain result
            assert (s.outcome, s.mu_s, s.signature) == (f.outcome, f.mu_s, f.signature)
