"""The tile queue on both databases: leasing, concurrency, expiry, attempts, failures."""

from __future__ import annotations

import threading
from datetime import timedelta

import pytest
from graspscape.services.coordinator.errors import NotFound
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    TileRow,
    WorkerRow,
)
from graspscape.services.coordinator.store.queue import (
    fail_tile,
    lease_tiles,
    renew_lease,
    requeue_expired,
)
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import make_exploration


def tiles(session: Session, exploration_id: int) -> list[TileRow]:
    session.expire_all()
    return list(
        session.scalars(
            select(TileRow).where(TileRow.exploration_id == exploration_id).order_by(TileRow.id)
        )
    )


def test_lease_hands_out_distinct_tiles_and_starts_the_exploration(session: Session) -> None:
    eid = make_exploration(session)
    first = lease_tiles(session, worker_id="w1", n=3, lease_seconds=60, host="h1", capacity=4)
    second = lease_tiles(session, worker_id="w2", n=3, lease_seconds=60)
    assert len(first) == len(second) == 3
    assert not {t.tile_id for t in first} & {t.tile_id for t in second}
    assert all(t.lease_epoch == 1 for t in first + second)
    assert all(len(t.poses()) > 0 for t in first)
    rows = {t.id: t for t in tiles(session, eid)}
    assert {rows[t.tile_id].lease_owner for t in first} == {"w1"}
    assert all(rows[t.tile_id].state == "leased" and rows[t.tile_id].attempts == 1 for t in first)
    exploration = session.get(ExplorationRow, eid)
    assert exploration is not None and exploration.status == "running"
    assert exploration.started_at is not None
    worker = session.get(WorkerRow, "w1")
    assert worker is not None and (worker.host, worker.capacity) == ("h1", 4)


def test_lease_returns_only_what_is_queued(session: Session) -> None:
    eid = make_exploration(session)
    total = len(tiles(session, eid))
    got = lease_tiles(session, worker_id="w", n=total + 10, lease_seconds=60)
    assert len(got) == total
    assert lease_tiles(session, worker_id="w", n=5, lease_seconds=60) == []
    assert lease_tiles(session, worker_id="w", n=0, lease_seconds=60) == []


def test_concurrent_leasers_never_share_a_tile(sessions: sessionmaker[Session]) -> None:
    with sessions() as s:
        eid = make_exploration(s, dtheta=0.2, target=6)
        total = len(tiles(s, eid))
    assert total > 40
    leased: list[list[int]] = [[] for _ in range(4)]
    errors: list[BaseException] = []

    def worker(i: int) -> None:
        try:
            with sessions() as s:
                while got := lease_tiles(s, worker_id=f"w{i}", n=3, lease_seconds=60):
                    leased[i].extend(t.tile_id for t in got)
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors
    all_ids = [tid for ids in leased for tid in ids]
    assert len(all_ids) == len(set(all_ids)) == total


def test_expired_leases_go_back_to_the_queue_with_a_new_epoch(session: Session) -> None:
    eid = make_exploration(session)
    past = utcnow() - timedelta(hours=1)
    expired = lease_tiles(session, worker_id="dead", n=2, lease_seconds=60, now=past)
    live = lease_tiles(session, worker_id="alive", n=1, lease_seconds=3600)
    report = requeue_expired(session, max_attempts=3)
    assert (report.requeued, report.failed) == (2, 0)
    rows = {t.id: t for t in tiles(session, eid)}
    for t in expired:
        row = rows[t.tile_id]
        assert (row.state, row.lease_owner, row.lease_expires_at) == ("queued", None, None)
        assert "dead" in (row.last_error or "")
    assert rows[live[0].tile_id].state == "leased"
    again = lease_tiles(session, worker_id="w", n=2, lease_seconds=60)
    assert {t.tile_id for t in again} == {t.tile_id for t in expired}
    assert all(t.lease_epoch == 2 for t in again)


def test_attempts_are_capped_and_the_tile_fails_with_its_error(session: Session) -> None:
    eid = make_exploration(session, dtheta=1.5, target=10_000)  # one tile per ring
    n = len(tiles(session, eid))
    past = utcnow() - timedelta(hours=1)
    for _ in range(2):
        lease_tiles(session, worker_id="dead", n=n, lease_seconds=1, now=past)
        requeue_expired(session, max_attempts=2)
    rows = tiles(session, eid)
    assert {r.state for r in rows} == {"failed"}
    assert all("attempt 2 of 2" in (r.last_error or "") for r in rows)
    exploration = session.get(ExplorationRow, eid)
    session.refresh(exploration)
    # Every tile failed and no pose was stored: the exploration failed (it was "done").
    assert exploration is not None and exploration.status == "failed"
    assert exploration.finished_at is not None
    assert lease_tiles(session, worker_id="w", n=1, lease_seconds=60) == []


def test_fail_tile_requeues_then_fails_and_ignores_stale_epochs(session: Session) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=60)
    assert (
        fail_tile(
            session,
            tile_id=t.tile_id,
            lease_epoch=t.lease_epoch,
            error="pybullet crashed",
            max_attempts=2,
        )
        == "queued"
    )
    assert (
        fail_tile(
            session, tile_id=t.tile_id, lease_epoch=t.lease_epoch, error="again", max_attempts=2
        )
        == "queued"
    )  # stale: nothing moves
    (t2,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=60)
    assert (t2.tile_id, t2.lease_epoch) == (t.tile_id, 2)
    assert (
        fail_tile(session, tile_id=t2.tile_id, lease_epoch=2, error="mesh exploded", max_attempts=2)
        == "failed"
    )
    row = next(r for r in tiles(session, eid) if r.id == t.tile_id)
    assert (row.state, row.last_error, row.attempts) == ("failed", "mesh exploded", 2)
    with pytest.raises(NotFound, match="tile 999999"):
        fail_tile(session, tile_id=999999, lease_epoch=1, error="x", max_attempts=2)


def test_renew_lease_only_for_the_current_epoch(session: Session) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=10)
    assert renew_lease(session, tile_id=t.tile_id, lease_epoch=1, lease_seconds=600)
    row = next(r for r in tiles(session, eid) if r.id == t.tile_id)
    assert row.lease_expires_at is not None
    assert row.lease_expires_at > utcnow() + timedelta(seconds=500)
    assert not renew_lease(session, tile_id=t.tile_id, lease_epoch=0, lease_seconds=600)
