"""Stored results by lattice point: what strategies and the manifold map read of the poses.

Only poses on the exploration's lattice are read (a pose whose key is its lattice point's
key); poses off the lattice, such as those of the random strategy, are stored and listed but
take no part in lattice decisions or manifolds (docs/design/exploration.md, "Strategies").
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.services.coordinator.mapspace.pose import StoredPose
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.pose import Pose
from sqlalchemy import select
from sqlalchemy.orm import Session

_KEY_CHUNK = 500


def lattice_of(spec: ExplorationSpec) -> Lattice:
    return Lattice(spec.grid, spec.refinement.levels)


_SAMPLE_COLUMNS = (
    PoseRow.pose_key,
    PoseRow.theta,
    PoseRow.phi,
    PoseRow.r,
    PoseRow.roll,
    PoseRow.pitch,
    PoseRow.yaw,
    PoseRow.viable,
    PoseRow.outcome,
    PoseRow.mu_s,
    PoseRow.effort_max_nm,
    PoseRow.signature,
    PoseRow.grasp,
    PoseRow.worker_id,
    PoseRow.inferred_from,
)


def point_or_none(lattice: Lattice, pose: Pose) -> Point | None:
    """The lattice point of a pose, or None when the pose is not on the lattice."""
    try:
        p = lattice.point(pose)
        return p if lattice.pose(p).key() == pose.key() else None
    except ValueError:
        return None


def load_samples(
    session: Session, exploration_id: int, lattice: Lattice, keys: Iterable[str] | None = None
) -> dict[Point, StoredPose]:
    """Stored poses of an exploration (all, or those with the given keys) by lattice point."""
    out: dict[Point, StoredPose] = {}
    base = select(*_SAMPLE_COLUMNS).where(PoseRow.exploration_id == exploration_id)
    if keys is None:
        batches = [session.execute(base).all()]
    else:
        wanted = sorted(set(keys))
        batches = [
            session.execute(base.where(PoseRow.pose_key.in_(wanted[i : i + _KEY_CHUNK]))).all()
            for i in range(0, len(wanted), _KEY_CHUNK)
        ]
    for rows in batches:
        for row in rows:
            sample = StoredPose.from_row(row)
            pose = Pose(theta=row.theta, phi=row.phi, r=row.r, roll=row.roll, pitch=row.pitch,
                        yaw=row.yaw)
            p = point_or_none(lattice, pose)
            if p is not None:
                out[p] = sample
    return out


def stored_by_key(session: Session, exploration_id: int, keys: Sequence[str]
                  ) -> dict[str, StoredPose]:
    """The stored poses among `keys` (the draws of a race: off the lattice), by key."""
    out: dict[str, StoredPose] = {}
    ordered = sorted(set(keys))
    for chunk in (ordered[i : i + _KEY_CHUNK] for i in range(0, len(ordered), _KEY_CHUNK)):
        for row in session.scalars(select(PoseRow).where(
                PoseRow.exploration_id == exploration_id, PoseRow.pose_key.in_(chunk))):
            out[row.pose_key] = StoredPose.from_row(row)
    return out
