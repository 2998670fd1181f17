"""Shortcut 2: reuse the trajectory outcome of a pose whose synthesized grasp matches.

Many start poses are driven by the policy into the same grasp configuration (the paper's
observation IV.1). What follows synthesis (release, trajectory, μs probes; about two thirds
of a held grasp's cost) depends only on the configuration, so a pose whose synthesized grasp
matches one already taken through the trajectory can reuse that outcome, μs and effort.

Matching (pure): the same links in contact; base positions in the object frame within
`position_m`, base orientations within `angle_rad`, every joint angle within `joint_rad`.
A match is approximate: the states also differ in velocities and contact forces, so μs is
copied, not recomputed (measured in benchmarks/bench_exploration_accuracy.py).

Donors are sought only among poses on the same normal (same direction and attitude, another
r): between directions a grid step apart the base orientations differ by that step, far beyond
any tolerance here, so nothing is lost. A DonorPool lives for one tile and is filled in the
tile's pose order. Coarse tiles hold whole normals, in a fixed order; every other tile holds
one r per normal (see exploration/tiling.py). What is inferred is therefore the same however
tiles are leased, split or re-run, and whichever worker runs them.
"""

from __future__ import annotations

import math

from graspscape.shared.specs.exploration import ConfigurationMatch
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import GraspConfiguration, PoseResult


def orientation_angle(a: tuple[float, ...], b: tuple[float, ...]) -> float:
    """Angle of the rotation between two unit quaternions (x, y, z, w), rad."""
    dot = abs(sum(x * y for x, y in zip(a, b, strict=True)))
    return 2.0 * math.acos(min(1.0, dot))


def configuration_gap(a: GraspConfiguration, b: GraspConfiguration,
                      tolerance: ConfigurationMatch) -> float | None:
    """The largest deviation as a fraction of its tolerance (≤ 1: they match); None when the
    joints differ."""
    if set(a.joint_angles) != set(b.joint_angles):
        return None
    joints = max((abs(a.joint_angles[k] - b.joint_angles[k]) for k in a.joint_angles),
                 default=0.0)
    return max(math.dist(a.base_position, b.base_position) / tolerance.position_m,
               orientation_angle(a.base_orientation, b.base_orientation) / tolerance.angle_rad,
               joints / tolerance.joint_rad)


class DonorPool:
    """Poses of one tile that went through the trajectory, per normal, in evaluation order."""

    def __init__(self, tolerance: ConfigurationMatch) -> None:
        self.tolerance = tolerance
        self.donors: dict[tuple[float, ...], list[PoseResult]] = {}

    def add(self, result: PoseResult) -> None:
        if result.grasp is not None and result.signature is not None \
                and result.inferred_from is None:
            self.donors.setdefault(result.pose.normal(), []).append(result)

    def find(self, pose: Pose, grasp: GraspConfiguration,
             links: tuple[str, ...]) -> PoseResult | None:
        """The closest matching donor on the pose's normal (the earliest among equals)."""
        candidates = self.donors.get(pose.normal(), [])
        best: tuple[float, int] | None = None
        for index, donor in enumerate(candidates):
            if donor.signature.links_in_contact != links:  # type: ignore[union-attr]
                continue
            gap = configuration_gap(grasp, donor.grasp, self.tolerance)  # type: ignore[arg-type]
            if gap is not None and gap <= 1.0 and (best is None or gap < best[0]):
                best = (gap, index)
        return None if best is None else candidates[best[1]]


def inferred(result: PoseResult, donor: PoseResult) -> PoseResult:
    """`result` (synthesized, not taken through the trajectory) completed from `donor`."""
    return result.model_copy(update={
        "outcome": donor.outcome, "viable": donor.viable, "mu_s": donor.mu_s,
        "effort_max_nm": donor.effort_max_nm, "inferred_from": donor.pose_key,
    })
