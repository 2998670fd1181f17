"""Leases are served apart from ingest: a lease query is answered while every ingest thread
waits on a batch's commit (real Dispatcher, real zenoh on loopback, real PostgreSQL).

The ingest is held deterministically: another connection holds the exploration's row lock,
which ingest takes for the exploration's counters, so the batch's thread waits in PostgreSQL
until the test lets it go. On SQLite the handler threads take turns at the single writer by
design (the store turn), so there a lease may wait for one commit, never for a queue of them:
this test is PostgreSQL's.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator

import psycopg
import pytest
import zenoh
from graspscape.services.coordinator.dispatch.service import Dispatcher
from graspscape.services.coordinator.settings import Settings, ZenohSettings
from graspscape.services.coordinator.store.models import PoseRow
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode, encode
from graspscape.shared.wire.messages import Ack, LeaseRequest, ResultBatch, TileLease
from graspscape.shared.wire.session import zenoh_config
from prometheus_client import CollectorRegistry
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from tests.conftest import _postgres, _sessions
from tests.services.coordinator.dispatch.support import SESSION_KEY, free_port, submit, wait_for
from tests.services.coordinator.dispatch.test_protocol import lease, made_up


@pytest.fixture
def pg_url() -> Iterator[str]:
    yield from _postgres()


@pytest.fixture
def pg_sessions(pg_url: str) -> Iterator[sessionmaker[Session]]:
    yield from _sessions(pg_url)


@pytest.fixture
def dispatcher(pg_url: str, pg_sessions: sessionmaker[Session]) -> Iterator[Dispatcher]:
    # One thread for each kind: with a shared pool of one, the lease below would queue
    # behind the held batch and time out.
    settings = Settings(
        database={"url": pg_url},
        zenoh=ZenohSettings(enabled=True, listen=[f"tcp/127.0.0.1:{free_port()}"],
                            orphan_grace_s=3600, handler_threads=1, lease_threads=1),
    )
    d = Dispatcher(settings, pg_sessions, CollectorRegistry())
    d.start()
    yield d
    d.stop()


@pytest.fixture
def client(dispatcher: Dispatcher) -> Iterator[zenoh.Session]:
    session = zenoh.open(zenoh_config(mode="client", connect=dispatcher.zenoh_settings.listen))
    yield session
    session.close()


def _conninfo(url: str) -> tuple[str, str]:
    """(libpq conninfo, schema) of a test URL with its private search_path."""
    base, options = url.replace("postgresql+psycopg://", "postgresql://").split("?options=")
    return base, options.split("%3D", 1)[1]


def _waiting_on_a_lock(admin: psycopg.Connection) -> bool:
    row = admin.execute("SELECT count(*) FROM pg_stat_activity WHERE wait_event_type = 'Lock' "
                        "AND datname = current_database()").fetchone()
    return bool(row and row[0])


def test_a_lease_is_answered_while_every_ingest_thread_waits_on_a_commit(
    pg_url: str, pg_sessions: sessionmaker[Session], client: zenoh.Session
) -> None:
    eid = submit(pg_sessions, dtheta_deg=90.0, tile_poses=3)
    (held,) = lease(client, "w1")
    batch = ResultBatch(session_key=SESSION_KEY,
                        worker_id="w1", tile_id=held.tile_id, lease_epoch=held.lease_epoch,
                        results=made_up(held), final=True)
    conninfo, schema = _conninfo(pg_url)
    acks: list[object] = []
    with psycopg.connect(conninfo) as blocker, psycopg.connect(conninfo, autocommit=True) as admin:
        blocker.execute(f'SET search_path TO "{schema}"')
        blocker.execute("SELECT id FROM explorations WHERE id = %s FOR UPDATE", (eid,))

        def send() -> None:
            for reply in client.get(keys.results_key(held.tile_id, held.lease_epoch),
                                    payload=encode(batch), timeout=30,
                                    consolidation=zenoh.ConsolidationMode.NONE):
                if reply.ok is not None:
                    acks.append(decode(reply.ok.payload.to_bytes()))

        sender = threading.Thread(target=send)
        sender.start()
        # The only ingest thread is now inside the batch's transaction, waiting for the lock.
        wait_for(lambda: _waiting_on_a_lock(admin), 10, "the batch to wait on the row lock")
        start = time.monotonic()
        replies = list(client.get(keys.LEASE_QUERY,
                                  payload=encode(LeaseRequest(session_key=SESSION_KEY,
                                                              worker_id="w2", capacity=1)),
                                  timeout=5, consolidation=zenoh.ConsolidationMode.NONE))
        waited = time.monotonic() - start
        leased = [decode(r.ok.payload.to_bytes()) for r in replies if r.ok is not None]
        assert len(leased) == 1 and isinstance(leased[0], TileLease), replies
        assert leased[0].tile_id != held.tile_id
        assert waited < 4.0
        assert not acks  # the batch is still waiting: the lease did not go through its thread
        blocker.rollback()  # let the batch commit
    sender.join(30)
    assert len(acks) == 1 and isinstance(acks[0], Ack) and acks[0].inserted == len(batch.results)
    with pg_sessions() as session:
        stored = session.scalars(select(PoseRow.pose_key).where(PoseRow.exploration_id == eid))
        assert sorted(stored) == sorted(r.pose_key for r in batch.results)
