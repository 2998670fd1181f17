"""The one owner of tile state: every change of a tile's state and lease columns is made here.

queued → leased (lease) → done (finish), or back to queued (a lost or expired lease, a
failure under the attempt cap, a hand-back), or failed (at the cap), or cancelled (with its
exploration); failed → queued again on a retry. Each function is one statement (or one batch
of statements) inside the caller's transaction: the callers (store/queue.py, store/ingest.py,
dispatch/leases.py, the exploration service and scheduler) decide when to commit and which
exploration rows to lock first (store/queue.lock_explorations). Nothing else in the
coordinator writes `TileRow.state`, `lease_owner`, `lease_holder`, `lease_expires_at`,
`lease_epoch` or `attempts`, so the rules of the queue can be read in one module.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from datetime import datetime
from typing import Any, Protocol

from graspscape.services.coordinator.store.models import ExplorationRow, TileRow, TileState
from graspscape.services.coordinator.store.pipeline import Piped, Step
from graspscape.shared.wire.messages import LeasedTile
from sqlalchemy import ColumnElement, bindparam, case, func, insert, select, update
from sqlalchemy.orm import Session

_INSERT_CHUNK = 2000


class TileShape(Protocol):
    """A planned tile (exploration/tiling.TilePlan): the store needs only its shape."""

    index: int
    cells: Sequence[Sequence[float]]
    r_levels: list[float]
    attitudes: Sequence[Sequence[float]]

    @property
    def n_poses(self) -> int: ...


def engine_set(engines: Collection[str]) -> str:
    """A set of engines as `tiles.needs_engines` stores it: sorted, comma-joined."""
    return ",".join(sorted(set(engines)))


def engine_sets(engines: Collection[str]) -> list[str]:
    """Every non-empty subset of a worker's engines as `engine_set` writes it: the tiles of
    draws it can run are those whose `needs_engines` is one of these."""
    names = sorted(set(engines))
    return [engine_set(n for i, n in enumerate(names) if mask >> i & 1)
            for mask in range(1, 1 << len(names))]


def add_tiles(session: Session, *, exploration_id: int, level: int, tiles: Sequence[TileShape],
              now: datetime, round: int = 0) -> int:
    """Queue new tiles of one exploration in one round at one level; returns how many."""
    values = []
    for t in tiles:
        sample = _sample_of(t)
        values.append({
            "exploration_id": exploration_id, "round": round, "level": level, "index": t.index,
            "cells": [list(c) for c in t.cells], "r_levels": t.r_levels,
            "attitudes": [list(a) for a in t.attitudes], "n_poses": t.n_poses,
            "state": TileState.QUEUED, "lease_epoch": 0, "attempts": 0, "updated_at": now,
            "sample": sample,
            "needs_engines": None if sample is None else engine_set(sample["engines"]),
        })
    for start in range(0, len(values), _INSERT_CHUNK):
        session.execute(insert(TileRow), values[start : start + _INSERT_CHUNK])
    return len(values)


def _sample_of(tile: TileShape) -> dict[str, Any] | None:
    """A tile of draws' wire TileSample as JSON (exploration/tiling.TilePlan.sample)."""
    sample = getattr(tile, "sample", None)
    return None if sample is None else sample.model_dump(mode="json")


# --- leasing ---------------------------------------------------------------------------------
def _engine_of_exploration() -> ColumnElement[str]:
    """The exploration's physics engine (its spec's settings.engine; pybullet where a spec
    stored before engines existed has none)."""
    return func.coalesce(ExplorationRow.spec["settings"]["engine"].as_string(), "pybullet")


def _lease_statement(*, skip_locked: bool) -> Any:
    runnable = select(ExplorationRow.id).where(
        _engine_of_exploration().in_(bindparam("engines", expanding=True)))
    candidates = (
        select(TileRow.id)
        .where(TileRow.state == TileState.QUEUED,
               TileRow.exploration_id.in_(runnable.scalar_subquery()),
               # a tile of draws runs in each of its engines: the worker must run them all
               TileRow.needs_engines.is_(None)
               | TileRow.needs_engines.in_(bindparam("engine_sets", expanding=True)))
        .order_by(TileRow.exploration_id, TileRow.round, TileRow.level, TileRow.id)
        .limit(bindparam("n"))
    )
    if skip_locked:
        candidates = candidates.with_for_update(skip_locked=True)
    return (
        update(TileRow)
        .where(TileRow.id.in_(candidates.scalar_subquery()))
        .values(
            state=TileState.LEASED,
            lease_owner=bindparam("owner"),
            lease_holder=bindparam("owner"),  # kept when the lease ends (lease_owner is not)
            lease_expires_at=bindparam("expires"),
            lease_epoch=TileRow.lease_epoch + 1,
            attempts=TileRow.attempts + 1,
            updated_at=bindparam("now"),
        )
        .returning(
            TileRow.id.label("tile_id"),
            TileRow.exploration_id,
            TileRow.level,
            TileRow.index,
            TileRow.lease_epoch,
            TileRow.lease_expires_at,
            TileRow.cells,
            TileRow.r_levels,
            TileRow.attitudes,
            TileRow.sample,
        )
    )


# Built once: a lease is several statements, and building them took longer than running them.
_LEASE = {False: _lease_statement(skip_locked=False), True: _lease_statement(skip_locked=True)}


def lease(session: Session, *, worker_id: str, n: int, expires: datetime, now: datetime,
          skip_locked: bool, engines: Sequence[str] = ("pybullet",)) -> list[LeasedTile]:
    """Up to n queued tiles leased to a worker (oldest exploration, then earliest round,
    then lowest level first), by tile id, of explorations whose engine is among `engines`
    (those the worker runs). Every lease bumps the epoch: ingest refuses reports made under
    an older one."""
    rows = session.connection().execute(
        _LEASE[skip_locked], {"n": n, "owner": worker_id, "expires": expires, "now": now,
                              "engines": list(engines), "engine_sets": engine_sets(engines)}
    ).all()
    return sorted((LeasedTile.model_validate(row._mapping) for row in rows),
                  key=lambda t: t.tile_id)


def held_under(tile_id: int, lease_epoch: int) -> tuple[ColumnElement[bool], ...]:
    """The tile is leased, under the lease a worker reports for: the one condition every
    worker report must meet before it may move a tile."""
    return (
        TileRow.id == tile_id,
        TileRow.state == TileState.LEASED,
        TileRow.lease_epoch == lease_epoch,
    )


def renew(session: Session, *, tile_id: int, lease_epoch: int, expires: datetime,
          now: datetime) -> bool:
    """Extend a lease that is still current; False if it was lost."""
    result = session.execute(
        update(TileRow)
        .where(*held_under(tile_id, lease_epoch))
        .values(lease_expires_at=expires, updated_at=now)
        .execution_options(synchronize_session=False)
    )
    return result.rowcount == 1  # type: ignore[attr-defined]


# --- ending a lease --------------------------------------------------------------------------
_MOVABLE = (TileState.LEASED, TileState.QUEUED)
_FINISH = (
    update(TileRow)
    .where(
        TileRow.id == bindparam("tile_id"),
        TileRow.state.in_(_MOVABLE),
        TileRow.lease_epoch == bindparam("epoch"),
    )
    .values(
        state=TileState.DONE,
        done_at=bindparam("now"),
        updated_at=bindparam("now"),
        lease_owner=None,
        lease_expires_at=None,
    )
)


def finishable(state: str) -> bool:
    """Whether a complete batch may finish a tile in this state: leased, or queued again under
    the same epoch (the lease ran out but nobody re-leased it yet: the complete result still
    finishes it, sparing a second evaluation)."""
    return state in _MOVABLE


# FOR NO KEY UPDATE: what the tile's own UPDATEs take, so it does not block inserts of poses
# that reference the tile.
_LOCK = (select(TileRow.id).where(TileRow.id == bindparam("tile_id"))
         .with_for_update(key_share=True, read=False))


def lock(session: Session, tile_id: int) -> None:
    """The tile's row lock, held to the commit (no state changes): the ingest of a partial
    batch takes it before it asks which of the tile's poses are stored, so that two such
    batches of one tile take turns. No FOR UPDATE on SQLite, whose write lock does it."""
    session.connection().execute(_LOCK, {"tile_id": tile_id}).all()


def finish(session: Session, *, tile_id: int, lease_epoch: int, now: datetime) -> bool:
    """Done, every pose of it stored (the caller checked); False if the epoch moved on."""
    done = session.connection().execute(
        _FINISH, {"tile_id": tile_id, "epoch": lease_epoch, "now": now})
    return done.rowcount == 1


_FINISH_PIPED = Piped(_FINISH, {"tile_id": 0, "epoch": 0, "now": None})


def finish_step(*, tile_id: int, lease_epoch: int, now: datetime) -> Step:
    """finish() as a step of a PostgreSQL pipeline (store/pipeline.py): moved when its
    cursor's rowcount is 1."""
    return _FINISH_PIPED.step(tile_id=tile_id, epoch=lease_epoch, now=now)


def fail_or_requeue(session: Session, *, tile_id: int, lease_epoch: int, error: str,
                    max_attempts: int, now: datetime) -> Any:
    """A worker could not evaluate its tile: queued again, or failed at max_attempts. Returns
    the row's (state, exploration_id), or None if the lease is not current."""
    return session.execute(
        update(TileRow)
        .where(*held_under(tile_id, lease_epoch))
        .values(
            state=case(
                (TileRow.attempts >= max_attempts, TileState.FAILED.value),
                else_=TileState.QUEUED.value,
            ),
            last_error=error[:4000],
            lease_owner=None,
            lease_expires_at=None,
            updated_at=now,
        )
        .returning(TileRow.state, TileRow.exploration_id)
        .execution_options(synchronize_session=False)
    ).one_or_none()


def requeue_leased(session: Session, leased: Sequence[ColumnElement[bool]], *,
                   max_attempts: int, now: datetime, failed_error: ColumnElement[str],
                   requeued_error: ColumnElement[str]) -> tuple[int, set[int]]:
    """Leased tiles matching `leased` back to the queue, or failed once their attempts reached
    the cap. Returns (requeued, ids of the explorations with a newly failed tile)."""
    failed_rows = session.execute(
        update(TileRow)
        .where(TileRow.state == TileState.LEASED, *leased, TileRow.attempts >= max_attempts)
        .values(state=TileState.FAILED, last_error=failed_error, lease_owner=None,
                lease_expires_at=None, updated_at=now)
        .returning(TileRow.exploration_id)
        .execution_options(synchronize_session=False)
    ).all()
    requeued = session.execute(
        update(TileRow)
        .where(TileRow.state == TileState.LEASED, *leased)
        .values(state=TileState.QUEUED, last_error=requeued_error, lease_owner=None,
                lease_expires_at=None, updated_at=now)
        .execution_options(synchronize_session=False)
    )
    return requeued.rowcount, {row[0] for row in failed_rows}  # type: ignore[attr-defined]


def release(session: Session, *, tile_id: int, lease_epoch: int, now: datetime) -> bool:
    """Back to the queue under its current lease, the attempt not counted (a worker handed it
    back on shutdown); False if not held."""
    result = session.execute(
        update(TileRow)
        .where(*held_under(tile_id, lease_epoch))
        .values(state=TileState.QUEUED, attempts=TileRow.attempts - 1, lease_owner=None,
                lease_expires_at=None, updated_at=now)
        .execution_options(synchronize_session=False)
    )
    return result.rowcount == 1  # type: ignore[attr-defined]


def release_all_but(session: Session, *, worker_id: str, holding: Collection[int],
                    error: ColumnElement[str], now: datetime) -> int:
    """Tiles leased to a worker, except those it holds, back to the queue uncounted (their
    lease reply never reached it); returns how many."""
    stmt = update(TileRow).where(
        TileRow.state == TileState.LEASED, TileRow.lease_owner == worker_id
    )
    if holding:
        stmt = stmt.where(TileRow.id.not_in(list(holding)))
    result = session.execute(
        stmt.values(state=TileState.QUEUED, attempts=TileRow.attempts - 1, last_error=error,
                    lease_owner=None, lease_expires_at=None, updated_at=now)
        .execution_options(synchronize_session=False)
    )
    return result.rowcount  # type: ignore[attr-defined]


def cancel_open(session: Session, *, exploration_id: int, now: datetime) -> None:
    """Its exploration was cancelled: queued and leased tiles are not handed out any more."""
    session.execute(
        update(TileRow)
        .where(
            TileRow.exploration_id == exploration_id,
            TileRow.state.in_((TileState.QUEUED, TileState.LEASED)),
        )
        .values(state=TileState.CANCELLED, lease_owner=None, lease_expires_at=None, updated_at=now)
        .execution_options(synchronize_session=False)
    )


def retry_failed(session: Session, *, exploration_id: int, now: datetime) -> int:
    """The failed tiles of an exploration queued again, attempts from zero; returns how many.
    Each keeps its last_error until it is done or fails again."""
    return session.execute(
        update(TileRow)
        .where(TileRow.exploration_id == exploration_id, TileRow.state == TileState.FAILED)
        .values(state=TileState.QUEUED, attempts=0, lease_owner=None, lease_expires_at=None,
                updated_at=now)
        .execution_options(synchronize_session=False)
    ).rowcount  # type: ignore[attr-defined]
