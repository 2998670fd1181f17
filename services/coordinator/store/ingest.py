"""Result ingest: one batch of pose results (one tile) in one transaction, idempotently.

`INSERT … ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING viable` stores each pose
once and tells exactly which rows are new, so the exploration's counters only count those: a
batch sent twice (a retry, or a late report from an expired lease) leaves the same rows and
the same counts. The tile moves to done only under the lease epoch it is currently leased
with. Results are stored even when they cannot move the tile (stale epoch, cancelled
exploration): computed poses are never thrown away.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.dialect import insert_for
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    PoseRow,
    TileRow,
    TileState,
)
from graspscape.services.coordinator.store.queue import finish_complete_explorations
from graspscape.shared.specs.results import PoseResult
from pydantic import BaseModel
from sqlalchemy import select, update
from sqlalchemy.orm import Session


class IngestReport(BaseModel):
    inserted: int
    duplicates: int
    tile_state: str
    tile_moved: bool  # this batch moved the tile leased → done


def _row(
    result: PoseResult, *, exploration_id: int, tile_id: int, worker_id: str, now: datetime
) -> dict[str, Any]:
    pose = result.pose
    return {
        "exploration_id": exploration_id,
        "tile_id": tile_id,
        "pose_key": result.pose_key,
        "theta": pose.theta,
        "phi": pose.phi,
        "r": pose.r,
        "roll": pose.roll,
        "pitch": pose.pitch,
        "yaw": pose.yaw,
        "outcome": result.outcome.value,
        "viable": result.viable,
        "mu_s": result.mu_s,
        "effective_r": result.effective_r,
        "effort_max_nm": result.effort_max_nm,
        "contacts_per_link": result.contacts_per_link or None,
        "signature": result.signature.model_dump(mode="json") if result.signature else None,
        "grasp": result.grasp.model_dump(mode="json") if result.grasp else None,
        "manifold_id": None,
        "worker_id": worker_id,
        "eval_time_s": result.eval_time_s,
        "created_at": now,
    }


def ingest_results(
    session: Session,
    *,
    tile_id: int,
    lease_epoch: int,
    worker_id: str,
    results: Sequence[PoseResult],
    final: bool = True,
    now: datetime | None = None,
) -> IngestReport:
    """Store a batch of results of one tile; with `final`, the tile is finished by it."""
    now = now or utcnow()
    tile = session.execute(
        select(TileRow.exploration_id, TileRow.state, TileRow.lease_epoch).where(
            TileRow.id == tile_id
        )
    ).one_or_none()
    if tile is None:
        session.rollback()
        raise NotFound(f"tile {tile_id} does not exist (was its exploration deleted?)")
    rows: dict[str, dict[str, Any]] = {}
    for result in results:
        key = result.pose.key()
        if result.pose_key != key:
            session.rollback()
            raise InvalidInput(
                f"result pose_key {result.pose_key!r} does not match its pose (key {key!r})"
            )
        rows[key] = _row(
            result,
            exploration_id=tile.exploration_id,
            tile_id=tile_id,
            worker_id=worker_id,
            now=now,
        )

    inserted = viable = 0
    if rows:
        table = PoseRow.__table__
        stmt = (
            insert_for(session, table)
            .on_conflict_do_nothing(index_elements=[table.c.exploration_id, table.c.pose_key])
            .returning(table.c.viable)
        )
        returned = session.connection().execute(stmt, list(rows.values())).all()
        inserted = len(returned)
        viable = sum(1 for (v,) in returned if v)
        if inserted:
            session.execute(
                update(ExplorationRow)
                .where(ExplorationRow.id == tile.exploration_id)
                .values(
                    poses_done=ExplorationRow.poses_done + inserted,
                    viable_count=ExplorationRow.viable_count + viable,
                    updated_at=now,
                )
                .execution_options(synchronize_session=False)
            )

    moved = False
    state = tile.state
    if final and tile.state == TileState.LEASED and tile.lease_epoch == lease_epoch:
        moved = (
            session.execute(
                update(TileRow)
                .where(
                    TileRow.id == tile_id,
                    TileRow.state == TileState.LEASED,
                    TileRow.lease_epoch == lease_epoch,
                )
                .values(
                    state=TileState.DONE,
                    done_at=now,
                    updated_at=now,
                    lease_owner=None,
                    lease_expires_at=None,
                )
                .execution_options(synchronize_session=False)
            ).rowcount
            == 1
        )  # type: ignore[attr-defined]
        if moved:
            state = TileState.DONE
            finish_complete_explorations(session, [tile.exploration_id], now=now)
    session.commit()
    return IngestReport(
        inserted=inserted, duplicates=len(results) - inserted, tile_state=state, tile_moved=moved
    )
