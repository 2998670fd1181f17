"""Result ingest: store one batch of pose results (one tile), idempotently.

The batch is stored in the caller's transaction, which exploration/scheduler.py commits once
the exploration's strategy has decided what comes next.

`INSERT … ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING viable` stores each pose
once and tells exactly which rows are new, so the exploration's counters only count those: a
batch sent twice (a retry after a lost ack) leaves the same rows and the same counts.

A batch is taken only from the holder of the tile's latest lease: its epoch must be the tile's
current `lease_epoch`, and its worker the one that lease went to (`lease_holder`, stored with
the lease). Anything else (another worker's id, an older epoch: the tile was leased again
since) is refused whole with NotLeaseHolder and stores nothing. Once the latest lease ended
without a new one (expired or lost and queued again, cancelled, failed), its holder's late
report under that epoch is still taken, since its poses can only be the tile's own (below)
and storing them loses nothing. Every result must be a pose of the tile (its cells × r levels ×
attitudes): one foreign pose refuses the whole batch. `final` finishes the tile (leased, or
queued under the same epoch) only when every pose of the tile is stored after the batch;
otherwise the batch is stored and the report lists the poses still missing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from datetime import datetime
from typing import Any, NamedTuple

from graspscape.services.coordinator.errors import InvalidInput, NotFound, NotLeaseHolder
from graspscape.services.coordinator.store import explorations, pipeline, tiles
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.dialect import is_postgres
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow, TileRow, TileState
from graspscape.services.coordinator.store.pipeline import Piped
from graspscape.services.coordinator.store.pose_rows import (
    _values,
    bound_batch,
    insert_new,
    pg_insert,
)
from graspscape.shared.specs.pose import tile_pose_keys
from graspscape.shared.specs.results import PoseResult
from pydantic import BaseModel
from sqlalchemy import Connection, bindparam, select
from sqlalchemy.orm import Session


class StoredBatch(NamedTuple):
    """What storing a batch did, for the scheduler that decides what comes next: the report
    for the worker, and the exploration's status and creation time when the batch changed
    anything (None otherwise: nothing to react to)."""

    report: IngestReport
    exploration_id: int
    exploration_status: str | None
    exploration_created_at: datetime | None
    committed: bool = False  # `quiet` said nothing follows: committed with the counters


class IngestReport(BaseModel):
    inserted: int
    duplicates: int
    tile_state: str
    tile_moved: bool  # this batch moved the tile leased → done
    # With `final`: the tile's poses that are not stored even after this batch (sorted), so
    # the tile did not move; empty when it moved or could not move anyway.
    missing: list[str] = []


# The statements of every batch, built once (building them took longer than running them).
_TILE = select(
    TileRow.exploration_id, TileRow.state, TileRow.lease_epoch, TileRow.lease_holder,
    TileRow.cells, TileRow.r_levels, TileRow.attitudes, ExplorationRow.created_at,
).join(ExplorationRow, ExplorationRow.id == TileRow.exploration_id).where(
    TileRow.id == bindparam("tile_id"))
# Which of some pose keys an exploration has stored (the unique index's own columns).
_STORED = select(PoseRow.pose_key).where(
    PoseRow.exploration_id == bindparam("exploration_id"),
    PoseRow.pose_key.in_(bindparam("keys", expanding=True)),
)
_KEY_CHUNK = 500
_SHOWN_KEYS = 10
_KEY_SHARE = (select(ExplorationRow.id).where(ExplorationRow.id == bindparam("exploration_id"))
              .with_for_update(read=True, key_share=True))
# The same, for PostgreSQL pipelines (store/pipeline.py).
_KEY_SHARE_PIPED = Piped(_KEY_SHARE, {"exploration_id": 0})


def _not_holder(tile: Any, tile_id: int, lease_epoch: int, worker_id: str) -> str | None:
    """Why a report under (worker_id, lease_epoch) is not from the holder of the tile's latest
    lease, or None when it is. The holder is stored with the lease (`lease_holder`) and kept
    when the lease ends, so late results are taken from that worker alone."""
    if tile.lease_epoch < 1 or lease_epoch != tile.lease_epoch:
        latest = (f"its latest lease is epoch {tile.lease_epoch}" if tile.lease_epoch >= 1
                  else "it was never leased")
        return (f"tile {tile_id} has no lease of epoch {lease_epoch} to report for ({latest}, "
                f"state {tile.state}): a late or forged report, nothing of it stored")
    if tile.lease_holder != worker_id:
        holder = tile.lease_holder or "a worker not recorded"
        verb = "is leased" if tile.state == TileState.LEASED else "was leased"
        return (f"tile {tile_id} {verb} to {holder} under epoch {lease_epoch}, not to "
                f"{worker_id}: nothing of the report stored")
    return None


def _shown(keys: Sequence[str]) -> str:
    more = len(keys) - _SHOWN_KEYS
    return ", ".join(keys[:_SHOWN_KEYS]) + (f" and {more} more" if more > 0 else "")


def _stored_keys(connection: Any, exploration_id: int, keys: Sequence[str]) -> set[str]:
    stored: set[str] = set()
    for start in range(0, len(keys), _KEY_CHUNK):
        stored.update(connection.execute(
            _STORED,
            {"exploration_id": exploration_id, "keys": list(keys[start : start + _KEY_CHUNK])},
        ).scalars())
    return stored


def store_batch(
    session: Session,
    *,
    tile_id: int,
    lease_epoch: int,
    worker_id: str,
    results: Sequence[PoseResult],
    final: bool = True,
    now: datetime | None = None,
    quiet: Callable[[int, datetime], bool] | None = None,
) -> StoredBatch:
    """Store a batch of results of one tile; with `final`, the tile is finished by it once
    every pose of the tile is stored. The caller commits (exploration/scheduler.py, after
    asking the exploration's strategy what comes next in the same transaction), unless
    `quiet(exploration_id, created_at)` says nothing follows the batch in its transaction:
    then on PostgreSQL the COMMIT goes in the counter update's round trip (`committed`), so
    the exploration's row lock is held for one round trip and the commit's flush.

    Raises NotFound (no such tile), NotLeaseHolder (not from the holder of the tile's latest
    lease) or InvalidInput (a result whose key does not match its pose, or a pose not of this
    tile); a refused batch stores nothing."""
    now = now or utcnow()
    session.flush()  # what the session holds goes first, as autoflush would do it
    tile = _reported_tile(session, tile_id, lease_epoch, worker_id)
    # The tile's pose keys (its cells × r levels × attitudes, as the worker expands them;
    # refinement and search tiles are such products too, exploration/tiling.group_tiles).
    tile_keys = (frozenset(tile_pose_keys(tile.cells, tile.r_levels, tile.attitudes))
                 if results or final else frozenset())
    rows, robustness = _batch_rows(session, tile_id, results, tile_keys)
    eid = tile.exploration_id
    # The epochs match (checked above).
    movable = final and tiles.finishable(tile.state)
    returned, moved, missing = _insert(session, (eid, tile_id, worker_id, now), rows,
                                       robustness, tile_keys, movable, lease_epoch)
    inserted = len(returned)
    report = _report(results, inserted, TileState.DONE if moved else tile.state, moved,
                     missing)
    if not (inserted or moved):  # nothing to count, nothing that could end the exploration
        return StoredBatch(report, eid, None, None)
    # Last, the exploration's counters: their row lock, held to the commit, makes the batches
    # of one exploration take turns only from here on (the strategy reacts under it too);
    # validation, insert and tile run concurrently. A batch moves its tile before it takes the
    # lock (fail_tile and the requeue lock, then move theirs), so whichever takes it last
    # reads every other tile as committed in the finish check after it (a statement of its
    # own: one that waited on the lock would still read the tiles from before; on PostgreSQL
    # the two go in one round trip, still two statements).
    commit = quiet is not None and is_postgres(session) and quiet(eid, tile.created_at)
    status, created_at = _count(session, {"exploration_id": eid, "inserted": inserted,
                                          "viable": sum(1 for v in returned if v),
                                          "now": now},
                                finish=moved, commit=commit)
    return StoredBatch(report, eid, status, created_at, commit)


def _reported_tile(session: Session, tile_id: int, lease_epoch: int, worker_id: str) -> Any:
    """The tile a batch reports for, once its sender is known to hold the latest lease."""
    tile = session.connection().execute(_TILE, {"tile_id": tile_id}).one_or_none()
    if tile is None:
        session.rollback()
        raise NotFound(f"tile {tile_id} does not exist (was its exploration deleted?)")
    refusal = _not_holder(tile, tile_id, lease_epoch, worker_id)
    if refusal is not None:
        session.rollback()
        raise NotLeaseHolder(refusal)
    return tile


def _batch_rows(session: Session, tile_id: int, results: Sequence[PoseResult],
                tile_keys: frozenset[str]) -> tuple[dict[str, tuple[Any, ...]], bool]:
    """The rows to insert by pose key, and whether any has robustness columns; every result
    must be a pose of the tile under its own key, or the whole batch is refused."""
    rows: dict[str, tuple[Any, ...]] = {}
    foreign: list[str] = []
    robustness = any(result.robustness is not None for result in results)
    for result in results:
        key = result.pose.key()
        if result.pose_key != key:
            session.rollback()
            raise InvalidInput(
                f"result pose_key {result.pose_key!r} does not match its pose (key {key!r})"
            )
        if key not in tile_keys:
            foreign.append(key)
        rows[key] = _values(result, robustness)
    if foreign:
        session.rollback()
        foreign = sorted(set(foreign))
        raise InvalidInput(
            f"{len(foreign)} pose(s) of the batch are not poses of tile {tile_id}: "
            f"{_shown(foreign)}; the whole batch is refused, nothing of it stored"
        )
    return rows, robustness


def _insert(session: Session, batch: tuple[Any, ...], rows: dict[str, tuple[Any, ...]],
            robustness: bool, tile_keys: frozenset[str], movable: bool, lease_epoch: int
            ) -> tuple[list[bool], bool, list[str]]:
    """Insert the new rows and, with `movable`, finish the tile if every pose of it is stored:
    the new rows' `viable` flags, whether the tile moved, and the poses still missing."""
    connection = session.connection()
    eid, tile_id, _, now = batch
    if movable and len(rows) == len(tile_keys) and is_postgres(session):
        # A complete batch on PostgreSQL: the insert, the key-share lock and the tile's move,
        # as below, in one round trip (none of them waits for another's answer).
        returned, moved = _insert_and_finish(connection, batch, list(rows.values()),
                                             robustness, lease_epoch)
        return returned, moved, []
    returned = insert_new(session, batch, list(rows.values()), robustness) if rows else []
    if not (returned or movable):
        return returned, False, []
    # A shared (key) lock on the exploration's row before the tile's, as fail_tile and the
    # requeue take their exclusive one (queue.lock_explorations): no crosswise waits. The
    # insert's foreign key check took it already.
    if not returned:
        connection.execute(_KEY_SHARE, {"exploration_id": eid}).all()
    missing: list[str] = []
    if movable and len(rows) < len(tile_keys):
        # Not every pose of the tile is in the batch (rows ⊆ tile_keys): the tile is done
        # only if the rest is stored already. Under the tile's row lock, so this reads the
        # batches of this tile committed before and two such batches take turns.
        tiles.lock(session, tile_id)
        absent = sorted(tile_keys.difference(rows))
        missing = sorted(set(absent) - _stored_keys(connection, eid, absent))
        movable = not missing
    moved = movable and tiles.finish(session, tile_id=tile_id, lease_epoch=lease_epoch,
                                     now=now)
    return returned, moved, missing


def _count(session: Session, counted: dict[str, Any], *, finish: bool, commit: bool = False
           ) -> tuple[str, datetime]:
    """The counter update, then with `finish` the exploration's finish check, and with
    `commit` (PostgreSQL only) the COMMIT; returns the exploration's status and creation
    time."""
    connection = session.connection()
    eid, now = counted["exploration_id"], counted["now"]
    if (finish or commit) and is_postgres(session):
        finishing = [explorations.finish_step(eid, now)] if finish else []
        count, *_ = pipeline.run(connection, [explorations.count_stored_step(**counted),
                                              *finishing], commit=commit)
        row = count.fetchone()
        assert row is not None  # the poses' foreign key: the row exists
        return row[0], row[1]
    exploration = explorations.count_stored(connection, counted)
    if finish:
        explorations.finish_complete(session, [eid], now=now)
    return exploration.status, exploration.created_at


def _insert_and_finish(connection: Connection, batch: tuple[Any, ...],
                       rows: list[tuple[Any, ...]], robustness: bool, lease_epoch: int
                       ) -> tuple[list[bool], bool]:
    """PostgreSQL, a complete batch: the new rows' `viable` flags and whether the tile moved.
    The key-share lock as in store_batch (the insert's foreign key check took it already
    when it inserted anything)."""
    eid, tile_id, _, now = batch
    insert, _, finish = pipeline.run(connection, [
        pg_insert(bound_batch(connection, batch), rows, robustness),
        _KEY_SHARE_PIPED.step(exploration_id=eid),
        tiles.finish_step(tile_id=tile_id, lease_epoch=lease_epoch, now=now)])
    return [bool(v) for (v,) in insert.fetchall()], finish.rowcount == 1


def _report(results: Sequence[PoseResult], inserted: int, state: str, moved: bool,
            missing: list[str]) -> IngestReport:
    return IngestReport(inserted=inserted, duplicates=len(results) - inserted, tile_state=state,
                        tile_moved=moved, missing=missing)
