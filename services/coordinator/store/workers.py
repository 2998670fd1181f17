"""The worker registry: who has been seen, from where, with how many cores, and which
session a worker id belongs to (the hash of the session key of the process that registered
it: the first lease request under the id binds it, for good)."""

from __future__ import annotations

import functools
import hashlib
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.dialect import insert_for_dialect
from graspscape.services.coordinator.store.models import WorkerRow
from sqlalchemy import bindparam, func, select
from sqlalchemy.orm import Session


def session_hash(session_key: str) -> str:
    """What is stored of a worker's session key: its SHA-256 (the key itself never is)."""
    return hashlib.sha256(session_key.encode()).hexdigest()


_BOUND = select(WorkerRow.session_hash).where(WorkerRow.id == bindparam("worker_id"))


def bound_session(session: Session, worker_id: str) -> str | None:
    """The session hash a worker id is bound to; None for an id not registered (or
    registered before bindings, by no session yet)."""
    return session.connection().execute(_BOUND, {"worker_id": worker_id}).scalar()


@functools.cache
def _touch_statement(dialect: str) -> Any:
    stmt = insert_for_dialect(dialect, WorkerRow.__table__).values(
        id=bindparam("worker_id"), host=bindparam("worker_host"),
        capacity=bindparam("worker_capacity"), session_hash=bindparam("session_hash"),
        first_seen=bindparam("now"), last_seen=bindparam("now"),
    )
    return stmt.on_conflict_do_update(
        index_elements=[WorkerRow.id],
        set_={
            "host": stmt.excluded.host,
            "capacity": stmt.excluded.capacity,
            "last_seen": stmt.excluded.last_seen,
            # The first session binds the id; a later one never rebinds it.
            "session_hash": func.coalesce(WorkerRow.session_hash, stmt.excluded.session_hash),
        },
    ).returning(WorkerRow.session_hash)


def touch_worker(
    session: Session, *, worker_id: str, host: str, capacity: int, now: datetime,
    session_hash: str | None = None,
) -> str | None:
    """Upsert a worker's last-seen time without committing (part of the caller's
    transaction); returns the session hash the id is bound to after it (`session_hash` binds
    an id not bound yet)."""
    session.flush()
    return session.connection().execute(
        _touch_statement(session.get_bind().dialect.name),
        {"worker_id": worker_id, "worker_host": host, "worker_capacity": capacity, "now": now,
         "session_hash": session_hash},
    ).scalar()


def heartbeat(
    session: Session, *, worker_id: str, host: str, capacity: int, now: datetime | None = None
) -> None:
    touch_worker(session, worker_id=worker_id, host=host, capacity=capacity, now=now or utcnow())
    session.commit()


def list_workers(session: Session, *, limit: int, offset: int) -> tuple[list[WorkerRow], int]:
    total = session.scalar(select(func.count()).select_from(WorkerRow)) or 0
    rows = session.scalars(
        select(WorkerRow)
        .order_by(WorkerRow.last_seen.desc(), WorkerRow.id)
        .limit(limit)
        .offset(offset)
    ).all()
    return list(rows), total
