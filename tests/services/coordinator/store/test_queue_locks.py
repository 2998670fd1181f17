"""The lock mode of failure and requeue on PostgreSQL (store/queue.lock_explorations).

They take the exploration's row `FOR UPDATE`, which waits for every open ingest of the
exploration (ingest holds a key-share lock on that row from its insert on). `FOR NO KEY
UPDATE` would not wait on the key-share lock, but then a requeue that touches the tile an open
ingest has already moved waits on that tile's row while the ingest waits on the requeue's row
lock for its counter update: PostgreSQL's deadlock detector aborts one of them
(docs/design/store.md, "Ingest"). The test plays that race with the real requeue.
"""

from __future__ import annotations

import threading
from datetime import timedelta

import pytest
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import TileRow
from graspscape.services.coordinator.store.queue import RequeueReport, lease_tiles, requeue_expired
from sqlalchemy import select, text
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import make_exploration

# What store/ingest.py's store_batch takes, in its order: the exploration's row key-share
# locked (the poses' foreign key check, or its explicit SELECT), the tile moved to done, and
# last the counter update, then the commit.
_KEY_SHARE = text("SELECT id FROM explorations WHERE id = :eid FOR KEY SHARE")
_MOVE_TILE = text("UPDATE tiles SET state = 'done' WHERE id = :tid AND state = 'leased'")
_COUNT = text("UPDATE explorations SET poses_done = poses_done + 1 WHERE id = :eid")


@pytest.fixture
def pg_sessions(sessions: sessionmaker[Session]) -> sessionmaker[Session]:
    if sessions.kw["bind"].dialect.name != "postgresql":
        pytest.skip("row lock modes: PostgreSQL (SQLite's write lock serializes these)")
    return sessions


def test_a_requeue_of_the_tile_an_open_ingest_moved_waits_for_it_without_a_deadlock(
    pg_sessions: sessionmaker[Session],
) -> None:
    """The sweeper requeues a tile whose lease ran out while the worker's late, complete
    report of it (latest epoch: it still finishes the tile) has moved it and not yet taken
    the counter lock."""
    with pg_sessions() as s:
        eid = make_exploration(s)
        (tile, *_) = lease_tiles(s, worker_id="w", n=1, lease_seconds=1)
    outcome: dict[str, RequeueReport | BaseException] = {}

    def sweep() -> None:
        try:
            with pg_sessions() as s:
                outcome["requeue"] = requeue_expired(
                    s, max_attempts=3, now=utcnow() + timedelta(seconds=60))
        except BaseException as exc:
            outcome["requeue"] = exc

    with pg_sessions() as ingest:
        ingest.execute(_KEY_SHARE, {"eid": eid})
        assert ingest.execute(_MOVE_TILE, {"tid": tile.tile_id}).rowcount == 1
        sweeper = threading.Thread(target=sweep)
        sweeper.start()
        sweeper.join(0.5)
        # It waits for the ingest's commit: its exclusive lock conflicts with the key share.
        assert sweeper.is_alive()
        ingest.execute(_COUNT, {"eid": eid})  # a deadlock here under FOR NO KEY UPDATE
        ingest.commit()
    sweeper.join(30)
    # Then it reads the tile as the ingest left it: done, nothing to requeue, and no error.
    assert outcome["requeue"] == RequeueReport(requeued=0, failed=0)
    with pg_sessions() as s:
        assert s.scalar(select(TileRow.state).where(TileRow.id == tile.tile_id)) == "done"
