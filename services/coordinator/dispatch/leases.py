"""Queue transactions the dispatch needs beyond store/queue.py: give back a worker's leases
(the tile changes themselves are store/tiles.py's).

Three cases, each one conditional UPDATE (atomic against the sweeper and a re-lease):
- a worker hands a tile back on shutdown, or a lease reply never reached it: not the tile's
  fault, so the attempt is not counted;
- a worker's liveliness token vanished (crash, kill -9, lost host): counted like an expired
  lease, so a tile that crashes every worker ends `failed` after max_attempts.
"""

from __future__ import annotations

from collections.abc import Collection
from datetime import datetime

from graspscape.services.coordinator.store import tiles
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import TileRow, TileState
from graspscape.services.coordinator.store.queue import requeue_where
from sqlalchemy import ColumnElement, bindparam, literal, select
from sqlalchemy.orm import Session


def release_tile(
    session: Session, *, tile_id: int, lease_epoch: int, now: datetime | None = None
) -> bool:
    """Put a tile back in the queue under its current lease, uncounted; False if not held."""
    now = now or utcnow()
    released = tiles.release(session, tile_id=tile_id, lease_epoch=lease_epoch, now=now)
    session.commit()
    return released


_HELD = select(TileRow.id).where(
    TileRow.state == TileState.LEASED, TileRow.lease_owner == bindparam("owner")
)


def release_unheld(
    session: Session, *, worker_id: str, holding: Collection[int], now: datetime | None = None
) -> int:
    """Tiles leased to a worker that says it does not hold them: their lease reply was lost.

    Commits what it releases; when there is nothing to release, it writes nothing and leaves
    the transaction to the caller (the lease that follows goes on in it)."""
    now = now or utcnow()
    # Almost always nothing to release: a read first keeps the common case free of a write
    # (SQLite has a single writer).
    held = set(session.scalars(_HELD, {"owner": worker_id}))
    if not held - set(holding):
        return 0
    released = tiles.release_all_but(
        session, worker_id=worker_id, holding=holding, now=now,
        error=literal("lease reply lost on the way to ") + TileRow.lease_owner)
    session.commit()
    return released


def requeue_lost(
    session: Session,
    *,
    worker_ids: Collection[str] | None = None,
    alive: Collection[str] | None = None,
    max_attempts: int,
    now: datetime | None = None,
) -> tuple[int, int]:
    """Leases of lost workers back to the queue (failed at the cap): (requeued, failed).

    Lost means `worker_ids` (their tokens vanished), or every owner not in `alive` (the sweep
    after a coordinator start).
    """
    now = now or utcnow()
    owned: list[ColumnElement[bool]] = []
    if worker_ids is not None:
        owned.append(TileRow.lease_owner.in_(list(worker_ids)))
    if alive is not None:
        owned.append(TileRow.lease_owner.not_in(list(alive)) if alive else literal(True))
    return requeue_where(
        session,
        owned,
        max_attempts=max_attempts,
        now=now,
        failed_error=literal("worker ") + TileRow.lease_owner + literal(" lost on last attempt"),
        requeued_error=literal("worker ") + TileRow.lease_owner + literal(" lost"),
    )


def lease_owners(session: Session) -> set[str]:
    rows = session.scalars(
        select(TileRow.lease_owner).where(TileRow.state == TileState.LEASED).distinct()
    )
    return {owner for owner in rows if owner}
