"""An exploration on a table, as submitted: one spec per chosen resting pose of the object
(shared/specs/resting.py), each naming its pose in `support.resting` and `settings.table`.
The resting poses come from the object's mesh as the workers simulate it
(objects/geometry.object_mesh), so a coordinator without the workers' object preparation
refuses a plane rather than guess."""

from __future__ import annotations

from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.exploration.object_symmetry import resolve_grid
from graspscape.services.coordinator.objects.geometry import MESH_QUERIES, object_mesh
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.placement import place_gripper
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.resting import chosen_resting_poses
from sqlalchemy import select
from sqlalchemy.orm import Session


def resting_specs(session: Session, spec: ExplorationSpec) -> list[ExplorationSpec]:
    """`[spec]`, or on a plane with no resting pose chosen yet, the spec at each resting pose
    the support chooses (most probable first)."""
    support = spec.support
    if support.kind != "plane" or support.resting is not None:
        return [spec]
    mesh = object_mesh(session, spec.object_id)
    if mesh is None:
        raise InvalidInput(
            f"object {spec.object_id}: its mesh is not available here, so its resting poses "
            "on a plane cannot be found; submit support.kind 'none', or run the coordinator "
            "with the workers' object preparation (graspscape serve)",
            loc=("body", "support"))
    with MESH_QUERIES:
        poses = chosen_resting_poses(mesh, min_probability=support.min_probability,
                                     max_poses=support.max_poses)
    if not poses:
        raise InvalidInput(f"object {spec.object_id}: no stable resting pose found on a plane",
                           loc=("body", "support"))
    return [spec.at_rest(pose) for pose in poses]


def group_rows(session: Session, exploration_id: int) -> list[ExplorationRow]:
    """The explorations of the group `exploration_id` belongs to, by resting pose (most
    probable first); a free object's exploration alone."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    if row.support_group is None:
        return [row]
    return list(session.scalars(select(ExplorationRow)
                                .where(ExplorationRow.support_group == row.support_group)
                                .order_by(ExplorationRow.resting_index, ExplorationRow.id)))


def at_resting_pose(session: Session, exploration_id: int, resting: int) -> int:
    """The id of the exploration of `exploration_id`'s group at resting pose `resting`."""
    for row in group_rows(session, exploration_id):
        if row.resting_index == resting:
            return row.id
    raise NotFound(f"exploration {exploration_id} has no resting pose {resting} in its group "
                   "(GET /explorations/{id}/group lists them)")


def seed_poses(session: Session, spec: ExplorationSpec) -> list[Pose]:
    """The viable poses of `spec.support.seed_exploration` that the table at `spec`'s resting
    pose leaves: those whose palm centre is not under the table (module doc of
    strategies/seeded.py). Refused (InvalidInput) where the seed is not a free-object map of
    the same object, gripper, grid and lattice depth."""
    seed_id, resting = spec.support.seed_exploration, spec.support.resting
    assert seed_id is not None and resting is not None
    seed = session.get(ExplorationRow, seed_id)
    if seed is None:
        raise InvalidInput(f"seed exploration {seed_id} does not exist",
                           loc=("body", "support", "seed_exploration"))
    seed_spec = resolve_grid(session, ExplorationSpec.model_validate(seed.spec))
    mine = resolve_grid(session, spec)
    same = (seed_spec.object_id == mine.object_id and seed_spec.gripper == mine.gripper
            and seed_spec.grid == mine.grid
            and seed_spec.refinement.levels == mine.refinement.levels
            and seed_spec.support.kind == "none")
    if not same:
        raise InvalidInput(
            f"seed exploration {seed_id} is not a free-object map of this object with the same "
            "gripper, grid and refinement levels", loc=("body", "support", "seed_exploration"))
    rows = session.execute(select(PoseRow.theta, PoseRow.phi, PoseRow.r, PoseRow.roll,
                                  PoseRow.pitch, PoseRow.yaw)
                           .where(PoseRow.exploration_id == seed_id, PoseRow.viable)).all()
    poses = {p.key(): p for p in (Pose(theta=t, phi=f, r=r, roll=a, pitch=b, yaw=c)
                                  for t, f, r, a, b, c in rows)}
    mesh = object_mesh(session, spec.object_id)
    if mesh is None:
        return sorted(poses.values(), key=lambda p: p.key())
    up, height = resting.up(), resting.position[2]
    with MESH_QUERIES:
        return [p for _, p in sorted(poses.items())
                if float(up @ place_gripper(mesh, p).position) > -height]
