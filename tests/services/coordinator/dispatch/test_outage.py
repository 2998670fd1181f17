"""A store outage is logged once per episode, with its reason, not once per refused query."""

from __future__ import annotations

import logging

import psycopg
import pytest
from graspscape.services.coordinator import db
from graspscape.services.coordinator.dispatch.outage import StoreOutage, is_store_outage
from sqlalchemy import create_engine, text
from sqlalchemy.exc import IntegrityError, OperationalError

from tests.conftest import PG_URL


def _refused() -> OperationalError:
    """The error a query gets while PostgreSQL is down: a real connection refused (port 1)."""
    engine = create_engine("postgresql+psycopg://postgres@127.0.0.1:1/test",
                           connect_args={"connect_timeout": 2})
    try:
        with engine.connect() as conn:
            conn.execute(text("SELECT 1"))
    except OperationalError as exc:
        return exc
    finally:
        engine.dispose()
    pytest.fail("a connection to port 1 succeeded")


def test_one_warning_per_episode_with_reason_and_reminders(caplog):
    exc = _refused()
    assert is_store_outage(exc) and not is_store_outage(ValueError("a bug"))
    assert not is_store_outage(IntegrityError("INSERT …", {}, ValueError("duplicate key")))
    now = [0.0]
    outage = StoreOutage(remind_s=60.0, clock=lambda: now[0])
    caplog.set_level(logging.WARNING, logger="graspscape.dispatch")
    outage.succeeded()  # no outage: nothing to say
    for i in range(500):
        now[0] = i * 0.1  # 50 s of refused queries
        outage.failed("lease", exc)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "store unavailable" in lines[0]
    assert "OperationalError" in lines[0] and "a lease query" in lines[0]
    assert outage.ongoing
    now[0] = 61.0
    outage.failed("results", exc)
    outage.failed("results", exc)
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 2 and "still unavailable after 61 s" in lines[1]
    assert "500 queries refused" in lines[1]  # 499 after the first line, and this one
    now[0] = 70.0
    outage.succeeded()
    outage.succeeded()
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 3 and "available again after 70.0 s; 502 queries" in lines[2]
    assert not outage.ongoing
    outage.failed("lease", exc)  # a new episode gets its own first line
    assert len(caplog.records) == 4 and "store unavailable" in caplog.records[3].getMessage()


def test_a_dropped_connection_costs_one_unavailable_answer_then_the_pool_reconnects() -> None:
    """Without pool_pre_ping (a round trip per transaction): PostgreSQL ends every backend of
    the pool (a restart); the next query fails as a store outage, which the dispatcher answers
    `unavailable`, and every later checkout gets a fresh connection, including those pooled
    before the failure."""
    engine = db.make_engine(PG_URL)
    try:
        with engine.connect() as first, engine.connect() as second:  # two pooled connections
            pids = {c.execute(text("SELECT pg_backend_pid()")).scalar() for c in (first, second)}
        assert len(pids) == 2
        with psycopg.connect(PG_URL.replace("postgresql+psycopg://", "postgresql://"),
                             autocommit=True) as admin:
            for pid in pids:
                admin.execute("SELECT pg_terminate_backend(%s)", (pid,))
        with pytest.raises(OperationalError) as failed, engine.connect() as conn:
            conn.execute(text("SELECT 1"))
        assert is_store_outage(failed.value) and failed.value.connection_invalidated
        for _ in range(3):  # the other dead connection is not handed out again
            with engine.connect() as conn:
                assert conn.execute(text("SELECT pg_backend_pid()")).scalar() not in pids
    finally:
        engine.dispose()
