"""Result ingest: one batch of pose results (one tile) in one transaction, idempotently.

`INSERT … ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING viable` stores each pose
once and tells exactly which rows are new, so the exploration's counters only count those: a
batch sent twice (a retry, or a late report from an expired lease) leaves the same rows and
the same counts. The tile moves to done only under its current lease epoch (leased, or
queued again after expiry but not yet re-leased). Results are stored even when they cannot
move the tile (stale epoch, cancelled exploration): computed poses are never thrown away.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.exploration.adaptive import after_ingest
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.dialect import insert_for, is_postgres
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
        "worker_id": worker_id,
        "eval_time_s": result.eval_time_s,
        "created_at": now,
    }


_PER_POSE = (
    ("pose_key", "varchar"),
    ("theta", "float8"),
    ("phi", "float8"),
    ("r", "float8"),
    ("roll", "float8"),
    ("pitch", "float8"),
    ("yaw", "float8"),
    ("outcome", "varchar"),
    ("viable", "boolean"),
    ("mu_s", "float8"),
    ("effective_r", "float8"),
    ("effort_max_nm", "float8"),
    ("contacts_per_link", "text"),
    ("signature", "text"),
    ("grasp", "text"),
    ("eval_time_s", "float8"),
)
_JSON_COLUMNS = ("contacts_per_link", "signature", "grasp")
_PER_BATCH = ("exploration_id", "tile_id", "worker_id", "created_at")
_PG_INSERT = (
    "INSERT INTO poses ({columns}) SELECT {batch}, {select} FROM unnest({arrays}) AS u({names}) "
    "ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING viable"
).format(
    columns=", ".join(_PER_BATCH + tuple(name for name, _ in _PER_POSE)),
    batch=", ".join(f"%({name})s" for name in _PER_BATCH),
    select=", ".join(
        f"u.{name}::json" if name in _JSON_COLUMNS else f"u.{name}" for name, _ in _PER_POSE
    ),
    # %(...)b: binary parameters, which psycopg dumps without escaping each array element.
    arrays=", ".join(f"%({name})b::{sql_type}[]" for name, sql_type in _PER_POSE),
    names=", ".join(name for name, _ in _PER_POSE),
)


def _insert_new(session: Session, rows: list[dict[str, Any]]) -> list[bool]:
    """Insert the rows not stored yet; return the `viable` flag of each row inserted."""
    if is_postgres(session):
        # One short statement with a column array each: psycopg parses and prepares it once.
        # A multi-row VALUES statement has thousands of placeholders that psycopg re-parses
        # on every batch, which took half of the ingest time.
        first = rows[0]
        params: dict[str, Any] = {name: first[name] for name in _PER_BATCH}
        for name, _ in _PER_POSE:
            column = [row[name] for row in rows]
            if name in _JSON_COLUMNS:
                column = [None if v is None else json.dumps(v) for v in column]
            params[name] = column
        result = session.connection().exec_driver_sql(_PG_INSERT, params)
        return [bool(v) for (v,) in result]
    table = PoseRow.__table__
    stmt = (
        insert_for(session, table)
        .on_conflict_do_nothing(index_elements=[table.c.exploration_id, table.c.pose_key])
        .returning(table.c.viable)
    )
    return [bool(v) for (v,) in session.connection().execute(stmt, rows)]


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
        returned = _insert_new(session, list(rows.values()))
        inserted = len(returned)
        viable = sum(1 for v in returned if v)
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
    # The lease under which the results were computed is the tile's current one when the
    # epochs match. Its tile may be `queued` if the lease ran out but nobody re-leased it
    # yet: the complete result then still finishes it, sparing a second evaluation.
    movable = (TileState.LEASED, TileState.QUEUED)
    if final and tile.state in movable and tile.lease_epoch == lease_epoch:
        moved = (
            session.execute(
                update(TileRow)
                .where(
                    TileRow.id == tile_id,
                    TileRow.state.in_(movable),
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
            ).rowcount  # type: ignore[attr-defined]
            == 1
        )
        if moved:
            state = TileState.DONE
            finish_complete_explorations(session, [tile.exploration_id], now=now)
    if inserted or moved:
        # Adaptive exploration (exploration/adaptive.py): border refinement, shortcuts, local
        # search and manifolds, decided from what is stored now. In this transaction, after the
        # counter update whose row lock makes ingests of one exploration take turns.
        after_ingest(
            session, exploration_id=tile.exploration_id, results=results, tile_moved=moved, now=now
        )
    session.commit()
    return IngestReport(
        inserted=inserted, duplicates=len(results) - inserted, tile_state=state, tile_moved=moved
    )
