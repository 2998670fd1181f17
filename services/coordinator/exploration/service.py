"""Explorations: submit (with its coarse-pass tiles), list, progress, cancel, delete, poses."""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

from graspscape.services.coordinator.errors import Conflict, InvalidInput, NotFound
from graspscape.services.coordinator.exploration.object_symmetry import resolve_grid
from graspscape.services.coordinator.exploration.scheduler import initial_tiles
from graspscape.services.coordinator.exploration.schemas import (
    FailureReason,
    FailureSummary,
    PoseFilter,
    PoseOut,
    Progress,
)
from graspscape.services.coordinator.exploration.support import resting_specs
from graspscape.services.coordinator.manifolds import snapshot
from graspscape.services.coordinator.objects.grippers import gripper_hash_for
from graspscape.services.coordinator.store import explorations, queue, tiles
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    ExplorationRow,
    ExplorationStatus,
    ManifoldRow,
    MapPictureRow,
    ObjectRow,
    PosePlanRow,
    PoseRow,
    TileRow,
    TileState,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.results import Outcome
from sqlalchemy import bindparam, delete, func, select
from sqlalchemy.orm import Session


def create_exploration(
    session: Session, *, spec: ExplorationSpec, tile_target_poses: int, max_poses: int
) -> ExplorationRow:
    """Submits `spec`; on a plane, one exploration per chosen resting pose (the first is
    returned, the others share its `support_group`)."""
    return create_explorations(session, spec=spec, tile_target_poses=tile_target_poses,
                               max_poses=max_poses)[0]


def create_explorations(
    session: Session, *, spec: ExplorationSpec, tile_target_poses: int, max_poses: int
) -> list[ExplorationRow]:
    """Submits `spec` as one exploration, or on a plane (support 'plane' without a resting
    pose) as one per chosen resting pose of the object, grouped (support.py); one commit."""
    if session.get(ObjectRow, spec.object_id) is None:
        raise InvalidInput(
            f"object_id {spec.object_id} does not exist; upload it to /objects",
            loc=("body", "object_id"),
        )
    specs = resting_specs(session, spec)
    rows = [_add_exploration(session, one, tile_target_poses, max_poses) for one in specs]
    if spec.support.kind == "plane":
        explorations.group(rows)
    session.commit()
    return rows


def _add_exploration(session: Session, spec: ExplorationSpec, tile_target_poses: int,
                     max_poses: int) -> ExplorationRow:
    spec = resolve_grid(session, spec)
    gripper_hash = gripper_hash_for(session, spec.gripper)  # workers fetch it by this hash
    poses_total, first_tiles = initial_tiles(session, spec, target_poses=tile_target_poses)
    if poses_total > max_poses:
        raise InvalidInput(
            f"the exploration plans {poses_total} poses, more than the limit of {max_poses}; "
            "raise grid.dtheta or grid.dr, use fewer attitudes or a smaller pose budget",
            loc=("body", "grid"),
        )
    now = utcnow()
    resting = spec.support.resting
    row = explorations.create(
        session, object_id=spec.object_id, spec=spec.model_dump(mode="json"),
        tiles_total=len(first_tiles), poses_total=poses_total, now=now,
        resting_index=None if resting is None else resting.index,
        resting_probability=None if resting is None else resting.probability,
        gripper_hash=gripper_hash,
    )
    tiles.add_tiles(session, exploration_id=row.id, level=0, tiles=first_tiles, now=now)
    return row


def get_exploration(session: Session, *, exploration_id: int) -> ExplorationRow:
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    return row


def list_explorations(
    session: Session, *, status: str | None, object_id: int | None, limit: int, offset: int
) -> tuple[list[ExplorationRow], int]:
    query = select(ExplorationRow)
    if status is not None:
        query = query.where(ExplorationRow.status == status)
    if object_id is not None:
        query = query.where(ExplorationRow.object_id == object_id)
    total = session.scalar(select(func.count()).select_from(query.subquery())) or 0
    rows = session.scalars(query.order_by(ExplorationRow.id).limit(limit).offset(offset)).all()
    return list(rows), total


# Poses within the throughput window before an ETA is given: fewer measure start-up, not a rate.
MIN_POSES_FOR_ETA = 10


def progress(
    session: Session, *, row: ExplorationRow, window_s: float, now: datetime | None = None
) -> Progress:
    now = now or utcnow()
    tiles = {state.value: 0 for state in TileState}
    for state, count in session.execute(
        select(TileRow.state, func.count())
        .where(TileRow.exploration_id == row.id)
        .group_by(TileRow.state)
    ):
        tiles[state] = count
    recent, first = session.execute(
        select(func.count(), func.min(PoseRow.created_at)).where(
            PoseRow.exploration_id == row.id,
            PoseRow.created_at >= now - timedelta(seconds=window_s),
        )
    ).one()
    # The rate over the part of the window that saw poses: a run younger than the window,
    # divided by the whole of it, read many times too slow (21 min for a 17 s run).
    span = window_s if first is None else min(window_s, max(1.0, (now - first).total_seconds()))
    throughput = recent / span
    remaining = max(0, row.poses_total - row.poses_done)
    # No ETA for a finished run (nothing is left to wait for), nor for a running one with
    # all its planned poses stored (refinement decides what comes next), nor before enough
    # poses came in to measure a rate.
    eta: float | None = None
    if (row.status not in FINISHED_STATUSES and remaining > 0
            and recent >= MIN_POSES_FOR_ETA and throughput > 0):
        eta = remaining / throughput
    return Progress(
        tiles=tiles,
        poses_done=row.poses_done,
        poses_total=row.poses_total,
        fraction_done=min(1.0, row.poses_done / row.poses_total) if row.poses_total else 1.0,
        viable_share=row.viable_count / row.poses_done if row.poses_done else None,
        throughput_poses_per_s=throughput,
        eta_s=eta,
        manifolds_poses_done=row.manifolds_poses_done or 0,
        manifolds_lag_poses=max(0, row.poses_done - (row.manifolds_poses_done or 0)),
    )


def cancel_exploration(session: Session, *, exploration_id: int) -> ExplorationRow:
    """Stop handing out its tiles. Results of tiles already out are still stored on arrival."""
    row = get_exploration(session, exploration_id=exploration_id)
    if row.status == ExplorationStatus.CANCELLED:
        return row
    if row.status in FINISHED_STATUSES:
        raise Conflict(f"exploration {exploration_id} is already {row.status}; nothing to cancel")
    now = utcnow()
    tiles.cancel_open(session, exploration_id=exploration_id, now=now)
    explorations.cancel(row, now)
    session.commit()
    # The table of what was stored, final: the keeper's, as after a finishing batch.
    from graspscape.services.coordinator.manifolds.keeper import current_keeper

    current_keeper().keep(session, exploration_id)
    return row


_MAX_REASONS = 20


def failure_summary(session: Session, *, exploration_id: int) -> FailureSummary:
    """How many tiles failed, and why: their distinct last errors, most frequent first."""
    counts = session.execute(
        select(TileRow.last_error, func.count())
        .where(TileRow.exploration_id == exploration_id, TileRow.state == TileState.FAILED)
        .group_by(TileRow.last_error)
        .order_by(func.count().desc(), TileRow.last_error)
    ).all()
    errors = session.scalar(
        select(func.count()).select_from(PoseRow)
        .where(PoseRow.exploration_id == exploration_id, PoseRow.outcome == Outcome.ERROR.value)
    )
    return FailureSummary(
        tiles=sum(n for _, n in counts),
        reasons=[FailureReason(reason=reason, tiles=n) for reason, n in counts[:_MAX_REASONS]],
        poses_with_errors=errors or 0,
    )


def list_failures(
    session: Session, *, exploration_id: int, limit: int, offset: int
) -> tuple[list[TileRow], int]:
    """The failed tiles of an exploration, by tile id."""
    get_exploration(session, exploration_id=exploration_id)
    failed = (TileRow.exploration_id == exploration_id, TileRow.state == TileState.FAILED)
    total = session.scalar(select(func.count()).select_from(TileRow).where(*failed)) or 0
    rows = session.scalars(
        select(TileRow).where(*failed).order_by(TileRow.id).limit(limit).offset(offset)
    ).all()
    return list(rows), total


def retry_exploration(session: Session, *, exploration_id: int) -> tuple[ExplorationRow, int]:
    """Queue its failed tiles again (attempts from zero) and set it running."""
    get_exploration(session, exploration_id=exploration_id)
    requeued = queue.retry_failed_tiles(session, exploration_id=exploration_id)
    row = get_exploration(session, exploration_id=exploration_id)
    session.refresh(row)
    return row, requeued


def delete_exploration(session: Session, *, exploration_id: int) -> None:
    get_exploration(session, exploration_id=exploration_id)
    # Children first, explicitly: the FK cascades would do it too, but this does not depend
    # on SQLite's foreign_keys pragma being on for whoever opened the connection.
    created_at = session.get(ExplorationRow, exploration_id).created_at
    for model in (PoseRow, ManifoldRow, PosePlanRow, TileRow, MapPictureRow):
        session.execute(delete(model).where(model.exploration_id == exploration_id))
    explorations.delete_row(session, exploration_id)
    session.commit()
    # Its running map's file on disk too (after the commit: a failed delete keeps it).
    url = str(session.get_bind().url)
    snapshot.remove(snapshot.directory(url), (url, exploration_id, created_at))


def list_poses(
    session: Session,
    *,
    exploration_id: int,
    filters: PoseFilter,
    limit: int,
    cursor: int | None,
) -> tuple[list[dict[str, Any]], int | None]:
    """Keyset pagination by row id: stable while results keep arriving. Rows of only the
    columns PoseOut returns, read through Core on the session's connection: the ORM's identity
    map, instance state and the columns the page does not show cost most of a page's CPU
    (issue 21). Each as a dict of PoseOut's fields: pydantic validates a dict in half the
    time it reads a row's attributes. The exploration's existence is checked by its id alone
    (the ORM row decodes its spec)."""
    if session.connection().execute(_EXISTS, {"eid": exploration_id}).first() is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    problems = filters.inverted_ranges()
    if problems:
        raise InvalidInput("; ".join(problems), loc=("query",))
    query = select(*_POSE_OUT_COLUMNS).where(PoseRow.exploration_id == exploration_id)
    if cursor is not None:
        query = query.where(PoseRow.id > cursor)
    if filters.viable is not None:
        query = query.where(PoseRow.viable == filters.viable)
    if filters.outcome is not None:
        query = query.where(PoseRow.outcome == filters.outcome.value)
    if filters.manifold_id is not None:
        query = query.where(PoseRow.manifold_id == filters.manifold_id)
    for column, name in (
        (PoseRow.mu_s, "mu"),
        (PoseRow.theta, "theta"),
        (PoseRow.phi, "phi"),
        (PoseRow.r, "r"),
    ):
        lo, hi = getattr(filters, f"{name}_min"), getattr(filters, f"{name}_max")
        if lo is not None:
            query = query.where(column >= lo)
        if hi is not None:
            query = query.where(column <= hi)
    rows = list(session.connection().execute(query.order_by(PoseRow.id).limit(limit + 1)))
    next_cursor = rows[limit - 1].id if len(rows) > limit else None
    return [row._asdict() for row in rows[:limit]], next_cursor


_EXISTS = select(ExplorationRow.id).where(ExplorationRow.id == bindparam("eid"))
# PoseOut's fields are PoseRow's column names (a KeyError here at import otherwise).
_POSE_OUT_COLUMNS = [PoseRow.__table__.c[name] for name in PoseOut.model_fields]
