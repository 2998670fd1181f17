"""Realistic pose results for store tests and the benchmark: what a worker would send."""

from __future__ import annotations

import random

from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    ContactPoint,
    GraspConfiguration,
    GraspSignature,
    Outcome,
    PhaseTimes,
    PoseResult,
)

LINKS = ("palm", "finger_1_prox", "finger_1_dist", "finger_2_prox", "finger_2_dist", "thumb")


def fake_result(pose: Pose, rng: random.Random) -> PoseResult:
    """A plausible evaluation of one pose (random outcome, contacts, joint angles)."""
    outcome = rng.choice(list(Outcome))
    grasped = outcome in (Outcome.HELD, Outcome.DROPPED)
    links = tuple(sorted(rng.sample(LINKS, rng.randint(2, 4)))) if grasped else ()
    joints = {f"j{i}": rng.uniform(0.0, 1.5) for i in range(8)}
    return PoseResult(
        pose=pose,
        pose_key=pose.key(),
        outcome=outcome,
        viable=outcome == Outcome.HELD,
        mu_s=rng.random() if outcome == Outcome.HELD else 0.0,
        effective_r=pose.r,
        effort_max_nm=rng.uniform(0.0, 3.0),
        contacts_per_link={link: rng.randint(1, 3) for link in links},
        grasp=GraspConfiguration(
            base_position=(rng.random(), rng.random(), rng.random()),
            base_orientation=(0.0, 0.0, 0.0, 1.0),
            joint_angles=joints,
        )
        if grasped
        else None,
        signature=GraspSignature(
            links_in_contact=links,
            contacts=tuple(
                ContactPoint(
                    link=link,
                    position_object=(rng.random(), 0.0, 0.01),
                    normal_force_n=rng.uniform(0, 20),
                )
                for link in links
            ),
            joint_angles=joints,
        )
        if grasped
        else None,
        eval_time_s=rng.uniform(0.2, 2.0),
        phases=PhaseTimes(approach_s=0.1, closing_s=0.2, trajectory_s=0.5),
    )


def fake_results(poses: list[Pose], seed: int = 0) -> list[PoseResult]:
    rng = random.Random(seed)
    return [fake_result(p, rng) for p in poses]
