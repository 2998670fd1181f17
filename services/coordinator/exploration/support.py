"""An exploration on a table, as submitted: one spec per chosen resting pose of the object
(shared/specs/resting.py), each naming its pose in `support.resting` and `settings.table`.
The resting poses come from the object's mesh as the workers simulate it
(objects/geometry.object_mesh), so a coordinator without the workers' object preparation
refuses a plane rather than guess."""

from __future__ import annotations

from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.objects.geometry import MESH_QUERIES, object_mesh
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.shared.specs.exploration import ExplorationSpec
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
