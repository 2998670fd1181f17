"""Fixtures: the coordinator's database fixtures (SQLite and PostgreSQL), an object, oracles.

The store fixtures are the coordinator suite's own (migrated schema per backend, tables
emptied around each test). `oracle` is a pure function of the pose standing in for pybullet
where a test is about the store's decisions rather than the physics (determinism, dedupe).
"""

from __future__ import annotations

import math

import pytest
from graspscape.services.coordinator.objects.service import create_named
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    ContactPoint,
    GraspConfiguration,
    GraspSignature,
    Outcome,
    PoseResult,
)
from sqlalchemy.orm import Session, sessionmaker

from tests.coordinator.conftest import (  # noqa: F401
    _empty,
    client,
    db_url,
    engine,
    session,
    sessions,
    settings,
)


@pytest.fixture
def named_object(sessions: sessionmaker[Session]):  # noqa: F811
    def make(name: str) -> int:
        with sessions() as s:
            row, _ = create_named(s, name=name, properties={}, shared_dir=None)
            return row.id

    return make


def oracle_result(pose: Pose) -> PoseResult:
    """Two grasp types split at φ = π, nothing held below θ = 2.2 rad or far out on one side."""
    held = pose.theta < 2.2 and not (pose.r > 0.012 and 0.5 < pose.phi < 1.5)
    if not held:
        return PoseResult(pose=pose, pose_key=pose.key(), outcome=Outcome.NO_GRASP,
                          viable=False, mu_s=0.0)
    angle = 0.2 if pose.phi < math.pi else 1.0
    joints = {f"{d}_{i}": angle for d in "ABC" for i in (1, 2, 3)}
    u = (math.sin(pose.theta) * math.cos(pose.phi), math.sin(pose.theta) * math.sin(pose.phi),
         math.cos(pose.theta))
    contacts = tuple(
        ContactPoint(link=f"{d}_3", position_object=tuple(0.04 * c for c in u),
                     normal_force_n=1.0)
        for d in "ABC"
    )
    return PoseResult(
        pose=pose, pose_key=pose.key(), outcome=Outcome.HELD, viable=True,
        mu_s=round(0.5 + 0.3 * math.cos(pose.theta) * math.sin(pose.phi), 9),
        effort_max_nm=1.0 + pose.theta,
        grasp=GraspConfiguration(base_position=tuple(0.06 * c for c in u),
                                 base_orientation=(0.0, 0.0, 0.0, 1.0), joint_angles=joints),
        signature=GraspSignature(links_in_contact=tuple(f"{d}_3" for d in "ABC"),
                                 contacts=contacts, joint_angles=joints),
    )
