"""The worker registry: who has been seen, from where, with how many cores."""

from __future__ import annotations

import functools
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.dialect import insert_for_dialect
from graspscape.services.coordinator.store.models import WorkerRow
from sqlalchemy import bindparam, func, select
from sqlalchemy.orm import Session


@functools.cache
def _touch_statement(dialect: str) -> Any:
    stmt = insert_for_dialect(dialect, WorkerRow.__table__).values(
        id=bindparam("worker_id"), host=bindparam("worker_host"),
        capacity=bindparam("worker_capacity"),
        first_seen=bindparam("now"), last_seen=bindparam("now"),
    )
    return stmt.on_conflict_do_update(
        index_elements=[WorkerRow.id],
        set_={
            "host": stmt.excluded.host,
            "capacity": stmt.excluded.capacity,
            "last_seen": stmt.excluded.last_seen,
        },
    )


def touch_worker(
    session: Session, *, worker_id: str, host: str, capacity: int, now: datetime
) -> None:
    """Upsert a worker's last-seen time without committing (part of the caller's transaction)."""
    session.flush()
    session.connection().execute(
        _touch_statement(session.get_bind().dialect.name),
        {"worker_id": worker_id, "worker_host": host, "worker_capacity": capacity, "now": now},
    )


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
