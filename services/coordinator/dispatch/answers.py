"""What the dispatcher answers a worker's lease request and result batch, from the store.

No zenoh here: each function is the store work of one query (its own transactions), and the
Dispatcher (dispatch/service.py) decodes the query, takes the store turn, calls it, and
replies with what it returns.
"""

from __future__ import annotations

from dataclasses import dataclass

from graspscape.services.coordinator.dispatch.catalog import WorkContext, WorkContexts
from graspscape.services.coordinator.dispatch.leases import release_tile, release_unheld
from graspscape.services.coordinator.dispatch.sessions import WorkerSessions
from graspscape.services.coordinator.errors import (
    InvalidInput,
    NotFound,
    NotLeaseHolder,
    WorkerIdTaken,
)
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.store.models import TileRow, TileState
from graspscape.services.coordinator.store.queue import fail_tile, lease_tiles
from graspscape.services.coordinator.store.workers import session_hash
from graspscape.shared.wire.codec import error
from graspscape.shared.wire.messages import (
    Ack,
    BatchHeader,
    ErrorCode,
    ErrorReply,
    LeasedTile,
    LeaseRequest,
    ResultBatch,
    TileLease,
)
from sqlalchemy import select
from sqlalchemy.orm import Session


@dataclass(frozen=True)
class Leased:
    tiles: list[LeasedTile]
    contexts: dict[int, WorkContext]
    lost: int  # tiles of the worker whose lease reply was lost, queued again

    def messages(self) -> list[TileLease]:
        """One lease message per tile (built after the store turn: it needs no database)."""
        out = []
        for tile in self.tiles:
            ctx = self.contexts[tile.exploration_id]
            out.append(TileLease.of(tile, object=ctx.object, gripper=ctx.gripper,
                                    settings=ctx.settings,
                                    configuration_match=ctx.configuration_match,
                                    gripper_ref=ctx.gripper_ref))
        return out


def lease_for(session: Session, request: LeaseRequest, *, n: int, lease_seconds: float,
              contexts: WorkContexts, sessions: WorkerSessions | None = None) -> Leased:
    """Release what the worker does not hold any more, then lease up to n tiles to it.
    Raises WorkerIdTaken, before either, when the id belongs to another session."""
    refusal = (sessions or WorkerSessions()).refusal(session, request.worker_id,
                                                    request.session_key)
    if refusal is not None:
        session.rollback()
        raise WorkerIdTaken(refusal)
    lost = release_unheld(session, worker_id=request.worker_id, holding=request.holding)
    tiles = lease_tiles(session, worker_id=request.worker_id, n=n, lease_seconds=lease_seconds,
                        host=request.host, capacity=request.capacity,
                        session_hash=session_hash(request.session_key),
                        engines=request.engines)
    if tiles and session.get_bind().dialect.name == "postgresql":
        # The lease is committed; the contexts are only read, outside a transaction: one
        # round trip where a transaction of their own took three (BEGIN, the read, and the
        # ROLLBACK when the session closes).
        session.connection(execution_options={"isolation_level": "AUTOCOMMIT"})
    return Leased(tiles, contexts.contexts(session, {t.exploration_id for t in tiles}), lost)


@dataclass(frozen=True)
class Reported:
    reply: Ack | ErrorReply
    released: bool = False  # the worker handed the rest of the tile back


def report_batch(session: Session, batch: ResultBatch, *, max_attempts: int,
                 sessions: WorkerSessions | None = None) -> Reported:
    """Store a result batch (the scheduler reacts in the same transaction), then fail or
    release the tile when the worker says so. A batch of the lease holder refused as invalid
    counts as a failed attempt of its tile (so a tile whose batches are always refused fails
    at max_attempts instead of going round for good)."""
    refusal = (sessions or WorkerSessions()).refusal(session, batch.worker_id,
                                                    batch.session_key)
    if refusal is not None:
        session.rollback()
        return Reported(error(ErrorCode.WORKER_ID_TAKEN, refusal))
    try:
        report = ingest_results(
            session,
            tile_id=batch.tile_id,
            lease_epoch=batch.lease_epoch,
            worker_id=batch.worker_id,
            results=batch.results,
            final=batch.final and batch.error is None,
        )
    except NotFound:
        # Its exploration was deleted: the results have no home, and a retry never will;
        # acknowledging ends the worker's retries.
        return Reported(Ack(tile_id=batch.tile_id, lease_epoch=batch.lease_epoch, inserted=0,
                            duplicates=0, tile_state="deleted"))
    except NotLeaseHolder as exc:
        # Not from the tile's latest lease (another worker's, or re-leased since): refused
        # before anything is stored, failed or released.
        return Reported(error(ErrorCode.NOT_LEASE_HOLDER, exc.message))
    except InvalidInput as exc:
        # Refused after the holder check: the sender holds the lease, so it is counted.
        counted = count_refusal(session, BatchHeader.of(batch), f"batch refused: {exc.message}",
                                max_attempts=max_attempts)
        return Reported(error(ErrorCode.INVALID, exc.message + counted))
    state = report.tile_state
    released = False
    if batch.error is not None:
        state = fail_tile(session, tile_id=batch.tile_id, lease_epoch=batch.lease_epoch,
                          error=f"{batch.worker_id}: {batch.error}", max_attempts=max_attempts)
    elif batch.release and not batch.final and release_tile(
        session, tile_id=batch.tile_id, lease_epoch=batch.lease_epoch
    ):
        released = True
        state = "queued"
    ack = Ack(tile_id=batch.tile_id, lease_epoch=batch.lease_epoch, inserted=report.inserted,
              duplicates=report.duplicates, tile_state=str(state), missing=report.missing)
    return Reported(ack, released)


def count_refusal(session: Session, header: BatchHeader, reason: str, *, max_attempts: int,
                  sessions: WorkerSessions | None = None) -> str:
    """A refused batch (malformed, invalid, or one the store could not take) counts as a
    failed attempt of its tile, with `reason` as the tile's last error (`/failures`), when
    its sender is the holder of the tile's current lease and the tile is still leased;
    anyone else's refused batch changes nothing. Returns what to add to the refusal's
    message."""
    if (sessions or WorkerSessions()).refusal(session, header.worker_id,
                                              header.session_key) is not None:
        session.rollback()
        return ""
    tile = session.execute(select(TileRow.state, TileRow.lease_epoch, TileRow.lease_owner)
                           .where(TileRow.id == header.tile_id)).one_or_none()
    if tile is None or (tile.state, tile.lease_epoch, tile.lease_owner) != (
            TileState.LEASED, header.lease_epoch, header.worker_id):
        session.rollback()
        return ""
    state = fail_tile(session, tile_id=header.tile_id, lease_epoch=header.lease_epoch,
                      error=f"{header.worker_id}: {reason}", max_attempts=max_attempts)
    return f"; counted as a failed attempt of tile {header.tile_id} (now {state})"
