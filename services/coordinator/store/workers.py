"""The worker registry: who has been seen, from where, with how many cores."""

from __future__ import annotations

from datetime import datetime

from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.dialect import insert_for
from graspscape.services.coordinator.store.models import WorkerRow
from sqlalchemy import func, select
from sqlalchemy.orm import Session


def touch_worker(
    session: Session, *, worker_id: str, host: str, capacity: int, now: datetime
) -> None:
    """Upsert a worker's last-seen time without committing (part of the caller's transaction)."""
    stmt = insert_for(session, WorkerRow.__table__).values(
        id=worker_id, host=host, capacity=capacity, first_seen=now, last_seen=now
    )
    session.execute(
        stmt.on_conflict_do_update(
            index_elements=[WorkerRow.id],
            set_={
                "host": stmt.excluded.host,
                "capacity": stmt.excluded.capacity,
                "last_seen": stmt.excluded.last_seen,
            },
        )
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
