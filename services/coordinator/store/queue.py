"""The tile queue's transactions: lease, renew, fail, put expired leases back, retry.

Each function is one transaction and commits it; the tile changes themselves are
store/tiles.py's (the one module that writes tile state), the explorations' status changes
store/explorations.py's (the one module that writes exploration rows). Leasing is a single
`UPDATE … WHERE id IN (SELECT … LIMIT n) RETURNING …`: on PostgreSQL the inner SELECT takes
`FOR UPDATE SKIP LOCKED`, so concurrent leasers never get the same tile nor wait on each
other; on SQLite the statement runs under the single write lock, which gives the same.
Every lease bumps the tile's `lease_epoch`; ingest refuses a report made under an older
epoch (store/ingest.py), so it never moves the tile again.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from datetime import datetime, timedelta

from graspscape.services.coordinator.errors import Conflict, NotFound, WorkerIdTaken
from graspscape.services.coordinator.store import explorations, tiles
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.dialect import is_postgres
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    ExplorationStatus,
    TileRow,
    TileState,
)
from graspscape.services.coordinator.store.workers import touch_worker
from graspscape.shared.wire.messages import LeasedTile
from pydantic import BaseModel
from sqlalchemy import ColumnElement, String, cast, literal, select
from sqlalchemy.orm import Session


class RequeueReport(BaseModel):
    requeued: int
    failed: int


def lease_tiles(
    session: Session,
    *,
    worker_id: str,
    n: int,
    lease_seconds: float,
    host: str = "",
    capacity: int = 1,
    now: datetime | None = None,
    session_hash: str | None = None,
    engines: Sequence[str] = ("pybullet",),
) -> list[LeasedTile]:
    """Lease up to n queued tiles to a worker, oldest exploration first, of explorations
    whose physics engine the worker runs (`engines`). With `session_hash` the worker id is
    bound to that session if it is not bound yet, and WorkerIdTaken is raised (nothing
    leased) if it is bound to another."""
    if n < 1:
        return []
    now = now or utcnow()
    session.flush()  # what the session holds goes first, as autoflush would do it
    leased = tiles.lease(session, worker_id=worker_id, n=n,
                         expires=now + timedelta(seconds=lease_seconds), now=now,
                         skip_locked=is_postgres(session), engines=engines)
    exploration_ids = sorted({t.exploration_id for t in leased})
    if exploration_ids:
        explorations.start(session, exploration_ids, now)
    bound = touch_worker(session, worker_id=worker_id, host=host, capacity=capacity, now=now,
                         session_hash=session_hash)
    if session_hash is not None and bound != session_hash:
        # Another session registered the id between the caller's check and this lease.
        session.rollback()
        raise WorkerIdTaken(f"worker id {worker_id} belongs to another session")
    session.commit()
    return leased


def renew_lease(
    session: Session,
    *,
    tile_id: int,
    lease_epoch: int,
    lease_seconds: float,
    now: datetime | None = None,
) -> bool:
    """Extend a lease that is still current; False if it was lost (expired and re-leased)."""
    now = now or utcnow()
    renewed = tiles.renew(session, tile_id=tile_id, lease_epoch=lease_epoch,
                          expires=now + timedelta(seconds=lease_seconds), now=now)
    session.commit()
    return renewed


def fail_tile(
    session: Session,
    *,
    tile_id: int,
    lease_epoch: int,
    error: str,
    max_attempts: int,
    now: datetime | None = None,
) -> str:
    """A worker could not evaluate its tile: queue it again, or fail it after max_attempts.

    Returns the tile's state afterwards. A report under a stale epoch changes nothing.
    """
    now = now or utcnow()
    exploration_id = session.scalar(select(TileRow.exploration_id).where(TileRow.id == tile_id))
    if exploration_id is None:
        raise NotFound(f"tile {tile_id} does not exist")
    lock_explorations(session, [exploration_id])
    # One conditional UPDATE: atomic against the sweeper and a re-lease on both databases.
    row = tiles.fail_or_requeue(session, tile_id=tile_id, lease_epoch=lease_epoch, error=error,
                                max_attempts=max_attempts, now=now)
    if row is None:  # unknown tile, or a stale epoch: nothing changes
        session.rollback()
        state = session.scalar(select(TileRow.state).where(TileRow.id == tile_id))
        if state is None:
            raise NotFound(f"tile {tile_id} does not exist")
        return state
    if row.state == TileState.FAILED:
        explorations.finish_complete(session, [row.exploration_id], now=now)
    session.commit()
    return row.state


def requeue_where(
    session: Session,
    conditions: Sequence[ColumnElement[bool]],
    *,
    max_attempts: int,
    now: datetime,
    failed_error: ColumnElement[str],
    requeued_error: ColumnElement[str],
) -> tuple[int, int]:
    """Leased tiles matching `conditions` back to the queue, or failed once their attempts
    reached the cap; one transaction. Returns (requeued, failed).

    The one mechanism behind lease expiry and lost workers, so both count attempts alike.
    """
    leased = (TileRow.state == TileState.LEASED, *conditions)
    exploration_ids = session.scalars(select(TileRow.exploration_id).where(*leased)
                                      .distinct()).all()
    if not exploration_ids:
        session.commit()
        return 0, 0
    lock_explorations(session, exploration_ids)
    # Tiles that came to match since are left to the next call: their explorations are not
    # locked here.
    requeued, failed = tiles.requeue_leased(
        session, (*conditions, TileRow.exploration_id.in_(exploration_ids)),
        max_attempts=max_attempts, now=now, failed_error=failed_error,
        requeued_error=requeued_error)
    explorations.finish_complete(session, failed, now=now)
    session.commit()
    return requeued, len(failed)


def requeue_expired(
    session: Session, *, max_attempts: int, now: datetime | None = None
) -> RequeueReport:
    """Put leased tiles whose lease ran out back in the queue (or fail them at the cap)."""
    now = now or utcnow()
    requeued, failed = requeue_where(
        session,
        [TileRow.lease_expires_at < now],
        max_attempts=max_attempts,
        now=now,
        failed_error=literal("lease expired on attempt ")
        + cast(TileRow.attempts, String)
        + literal(f" of {max_attempts}"),
        requeued_error=literal("lease of ") + TileRow.lease_owner + literal(" expired"),
    )
    return RequeueReport(requeued=requeued, failed=failed)


def lock_explorations(session: Session, exploration_ids: Iterable[int]) -> None:
    """Row locks on explorations (in id order), held to the commit, before any tile of theirs
    changes state. Failure and requeue take them first; ingest takes a key-share lock on the
    row first (store/ingest.py) and the exclusive one last, with its counter update, so none of
    them waits on another in the opposite order, and the finish check that follows reads the
    others' tiles as committed (on PostgreSQL each statement reads what was committed when it
    started; a statement that waited on the row lock would still read the tiles from before).
    FOR UPDATE, not FOR NO KEY UPDATE: the latter would not wait for the ingests' key share,
    and a requeue of a tile an open ingest has moved would deadlock with that ingest's counter
    update (test_queue_locks.py). SQLite's write lock serializes these transactions anyway; it
    renders no FOR UPDATE."""
    ids = sorted(set(exploration_ids))
    if ids:
        session.execute(select(ExplorationRow.id).where(ExplorationRow.id.in_(ids))
                        .order_by(ExplorationRow.id).with_for_update()).all()


def retry_failed_tiles(
    session: Session, *, exploration_id: int, now: datetime | None = None
) -> int:
    """Queue the failed tiles of an exploration again, with their attempts back to zero, and
    set it running; one transaction. Returns how many tiles were queued. A cancelled
    exploration, or one without failed tiles, is a Conflict (nothing changes). Each tile keeps
    its last_error until it is done or fails again."""
    now = now or utcnow()
    lock_explorations(session, [exploration_id])
    status = session.scalar(select(ExplorationRow.status)
                            .where(ExplorationRow.id == exploration_id))
    if status is None:
        session.rollback()
        raise NotFound(f"exploration {exploration_id} does not exist")
    if status == ExplorationStatus.CANCELLED:
        session.rollback()
        raise Conflict(f"exploration {exploration_id} is cancelled; submit it again instead")
    requeued = tiles.retry_failed(session, exploration_id=exploration_id, now=now)
    if not requeued:
        session.rollback()
        raise Conflict(f"exploration {exploration_id} has no failed tiles to retry")
    explorations.reopen(session, exploration_id, status, now)
    session.commit()
    return requeued
