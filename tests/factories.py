"""Factories of test data: realistic worker results, an oracle standing in for pybullet where a
test is about the store's decisions rather than physics, meshes and explorations."""

from __future__ import annotations

import math
import random

import trimesh
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.store.models import ObjectRow, PoseRow
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import (
    ContactPoint,
    GraspConfiguration,
    GraspSignature,
    Outcome,
    PhaseTimes,
    PoseResult,
)
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

# What a simulation can end in (an `error` pose is a worker fault, made where a test wants it).
_SIMULATED = [o for o in Outcome if o != Outcome.ERROR]
LINKS = ("palm", "finger_1_prox", "finger_1_dist", "finger_2_prox", "finger_2_dist", "thumb")


def fake_result(pose: Pose, rng: random.Random) -> PoseResult:
    """A plausible evaluation of one pose (random outcome, contacts, joint angles)."""
    outcome = rng.choice(_SIMULATED)
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


def box_stl(extents: tuple[float, float, float] = (0.05, 0.05, 0.1)) -> bytes:
    return trimesh.creation.box(extents=extents).export(file_type="stl")


def make_exploration(session: Session, *, dtheta: float = 0.6, target: int = 20) -> int:
    """A sphere exploration with its coarse tiles queued."""
    obj = ObjectRow(kind="named", name="sphere", properties={})
    session.add(obj)
    session.commit()
    spec = ExplorationSpec(
        object_id=obj.id, gripper="robotiq_3f", grid=PoseGridSpec(dtheta=dtheta, r_max=0.02)
    )
    return create_exploration(session, spec=spec, tile_target_poses=target, max_poses=10**6).id


def explore_with_oracle(sessions: sessionmaker[Session], spec: ExplorationSpec, *,
                        workers: int = 2, seed: int = 1) -> tuple[int, list[str], list[str]]:
    """Run an exploration to its end in this process with `oracle_result` as the evaluator:
    (id, pose keys evaluated in order, stored pose keys sorted)."""
    from graspscape.services.local.run import run_local

    evaluated: list[str] = []

    def evaluate(poses, match=None):  # type: ignore[no-untyped-def]
        evaluated.extend(p.key() for p in poses)
        return [oracle_result(p) for p in poses]

    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
    run_local(sessions, evaluate, workers=workers, seed=seed, split=2)
    with sessions() as s:
        stored = sorted(s.scalars(select(PoseRow.pose_key)
                                  .where(PoseRow.exploration_id == eid)))
    return eid, evaluated, stored


# Hand-made label fields on a real lattice (the robust map's and its scoring's tests).
POWER = frozenset({"A", "B", "C", "palm"})
PINCH = frozenset({"A", "B"})


def lattice_pose(lattice: Lattice, p: Point, digits: frozenset[str] | None,
                 mu: float = 0.5) -> StoredPose:
    """The stored pose at lattice point p: held with `digits` in contact and μs `mu`, or
    dropped where `digits` is None."""
    x = lattice.pose(p)
    return StoredPose(
        key=f"{p.ring}.{p.azimuth}.{p.r_index}.{p.attitude}", theta=x.theta, phi=x.phi,
        r=x.r, roll=x.roll, pitch=x.pitch, yaw=x.yaw, viable=digits is not None,
        outcome="held" if digits is not None else "dropped", mu_s=mu if digits else 0.0,
        digits=digits or frozenset(),
    )
