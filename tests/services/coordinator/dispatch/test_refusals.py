"""Refused batches and borrowed worker ids, against a real Dispatcher and zenoh sessions on
loopback, on SQLite and PostgreSQL: a refused batch is never answered with a code workers
retry, never echoes internals, logs one line and counts as an attempt of its tile (so a tile
refused max_attempts times fails and its exploration ends `incomplete`); a worker id belongs
to the session that registered it; late results are taken only from the lease's holder."""

from __future__ import annotations

import json
import logging

import pytest
import zenoh
from graspscape.services.coordinator.dispatch.leases import requeue_lost
from graspscape.services.coordinator.dispatch.service import Dispatcher
from graspscape.services.coordinator.exploration.service import failure_summary
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow, TileRow
from graspscape.shared.specs.results import Outcome
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import encode
from graspscape.shared.wire.messages import (
    Ack,
    ErrorCode,
    ErrorReply,
    LeaseRequest,
    ResultBatch,
    TileLease,
)
from graspscape.shared.wire.session import zenoh_config
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.support import SESSION_KEY, submit
from tests.services.coordinator.dispatch.test_protocol import (  # noqa: F401 (fixtures)
    ask,
    client,
    dispatcher,
    lease,
    made_up,
    registry,
)

OTHER_KEY = "07e5" * 8  # another session's key
# What a reply must never carry: exception text, SQL, driver names.
INTERNALS = ("Traceback", "INSERT", "SELECT", "UPDATE", "psycopg", "sqlite3", "Error:")


def _batch(tile: TileLease, worker_id: str = "w-1", key: str = SESSION_KEY,
           **fields: object) -> ResultBatch:
    return ResultBatch(session_key=key, worker_id=worker_id, tile_id=tile.tile_id,
                       lease_epoch=tile.lease_epoch, **{"results": made_up(tile), **fields})


def _with_nan(tile: TileLease) -> bytes:
    """A batch whose one result has a NaN effort, as a worker without the finite check sent
    it: pydantic writes NaN as `null` (model_copy skips validation)."""
    results = made_up(tile)
    results[0] = results[0].model_copy(update={"effort_max_nm": float("nan")})
    data = encode(ResultBatch.model_construct(**{**dict(_batch(tile)), "results": results}))
    assert b'"effort_max_nm":null' in data
    return data


def _dispatch_lines(caplog: pytest.LogCaptureFixture) -> list[logging.LogRecord]:
    return [r for r in caplog.records if r.name == "graspscape.dispatch"
            and r.levelno >= logging.INFO]


def _refused(reply: tuple[str, object], code: ErrorCode) -> ErrorReply:
    where, message = reply
    assert where == "error" and isinstance(message, ErrorReply), reply
    assert message.code == code and not message.code.retryable, message
    assert not any(word in message.message for word in INTERNALS), message.message
    return message


def test_a_non_finite_result_refused_max_attempts_times_fails_its_tile_and_the_exploration_ends(
    client: zenoh.Session, dispatcher: Dispatcher, any_sessions: sessionmaker[Session],  # noqa: F811
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="graspscape.dispatch")
    exploration_id = submit(any_sessions, tile_poses=3)
    max_attempts = dispatcher.settings.queue.max_attempts
    refused_tile = None
    for attempt in range(1, max_attempts + 1):
        (tile,) = lease(client, "w-1")  # holding nothing: the worker dropped the batch
        refused_tile = refused_tile or tile.tile_id
        assert (tile.tile_id, tile.lease_epoch) == (refused_tile, attempt)
        caplog.clear()
        (reply,) = ask(client, keys.results_key(tile.tile_id, tile.lease_epoch), _with_nan(tile))
        message = _refused(reply, ErrorCode.MALFORMED)
        assert "effort_max_nm" in message.message
        assert "counted as a failed attempt" in message.message
        lines = _dispatch_lines(caplog)
        assert len(lines) == 1 and lines[0].exc_info is None, [r.getMessage() for r in lines]
        with any_sessions() as session:
            row = session.get(TileRow, tile.tile_id)
            assert row.attempts == attempt
            assert row.state == ("failed" if attempt == max_attempts else "queued")
    # The other tiles are leased and stored; the exploration ends, with the reason.
    while tiles := lease(client, "w-1"):
        (tile,) = tiles
        assert tile.tile_id != refused_tile
        (reply,) = ask(client, keys.results_key(tile.tile_id, tile.lease_epoch),
                       encode(_batch(tile)))
        assert isinstance(reply[1], Ack), reply
    with any_sessions() as session:
        assert session.get(ExplorationRow, exploration_id).status == "incomplete"
        failures = failure_summary(session, exploration_id=exploration_id)
        assert failures.tiles == 1 and "effort_max_nm" in failures.reasons[0].reason
        assert not session.scalar(select(func.count()).select_from(PoseRow)
                                  .where(PoseRow.tile_id == refused_tile))


def test_a_nan_coordinate_at_the_pole_is_refused_and_not_stored(
    client: zenoh.Session, any_sessions: sessionmaker[Session],  # noqa: F811
) -> None:
    submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")
    assert tile.cells[0][0] == 0.0  # the first tile holds the pole, where φ is not in the key
    raw = json.loads(encode(_batch(tile)))
    raw["results"][0]["pose"]["phi"] = float("nan")
    (reply,) = ask(client, keys.results_key(tile.tile_id, tile.lease_epoch),
                   json.dumps(raw).encode())  # JSON's NaN token, as json.dumps writes it
    message = _refused(reply, ErrorCode.MALFORMED)
    assert "pose.phi: Input should be a finite number" in message.message
    with any_sessions() as session:
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0


def test_a_batch_the_store_cannot_take_is_refused_for_good_without_its_sql(
    client: zenoh.Session, any_url: str, any_sessions: sessionmaker[Session],  # noqa: F811
    caplog: pytest.LogCaptureFixture,
) -> None:
    if not any_url.startswith("postgresql"):
        pytest.skip("a NUL byte in text is refused by PostgreSQL only (SQLite stores it)")
    caplog.set_level(logging.DEBUG, logger="graspscape.dispatch")
    submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")
    results = made_up(tile)
    results[0] = results[0].model_copy(update={"outcome": Outcome.ERROR, "viable": False,
                                               "error": "boom\x00"})
    caplog.clear()
    (reply,) = ask(client, keys.results_key(tile.tile_id, tile.lease_epoch),
                   encode(_batch(tile, results=results)))
    message = _refused(reply, ErrorCode.INVALID)  # not `unavailable`: sent again, it fails again
    assert "could not store this batch" in message.message and "0x00" not in message.message
    lines = _dispatch_lines(caplog)
    warnings = [r for r in lines if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and warnings[0].exc_info is None
    # The cause is in the log line, not the reply; no SQL in either.
    assert "0x00" in warnings[0].getMessage() and "UPDATE" not in warnings[0].getMessage()
    with any_sessions() as session:
        row = session.get(TileRow, tile.tile_id)
        assert (row.state, row.attempts) == ("queued", 1)
        assert "could not store" in row.last_error
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0


def test_a_worker_id_belongs_to_the_session_that_registered_it(
    client: zenoh.Session, dispatcher: Dispatcher, any_sessions: sessionmaker[Session],  # noqa: F811
) -> None:
    submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")  # the first session registers w-1
    borrower = zenoh.open(zenoh_config(mode="client", connect=dispatcher.zenoh_settings.listen))
    try:
        # A second session under the same id, holding nothing: neither the tile is released
        # nor another leased.
        (reply,) = ask(borrower, keys.LEASE_QUERY, encode(LeaseRequest(
            session_key=OTHER_KEY, worker_id="w-1", capacity=1)))
        assert "belongs to another session" in _refused(reply, ErrorCode.WORKER_ID_TAKEN).message
        # Its made-up results under the holder's id and epoch are refused too.
        key = keys.results_key(tile.tile_id, tile.lease_epoch)
        fake = [r.model_copy(update={"mu_s": 0.987}) for r in made_up(tile)]
        (reply,) = ask(borrower, key, encode(_batch(tile, key=OTHER_KEY, results=fake)))
        _refused(reply, ErrorCode.WORKER_ID_TAKEN)
        # A made-up id of its own holds no lease (refused, nothing released or counted).
        (reply,) = ask(borrower, key, encode(_batch(tile, worker_id="w-9", key=OTHER_KEY)))
        _refused(reply, ErrorCode.NOT_LEASE_HOLDER)
        with any_sessions() as session:
            row = session.get(TileRow, tile.tile_id)
            assert (row.state, row.lease_owner, row.lease_epoch, row.attempts) == (
                "leased", "w-1", 1, 1)
            assert session.scalar(select(func.count()).select_from(PoseRow)) == 0
            assert session.scalar(select(func.count()).select_from(TileRow)
                                  .where(TileRow.state == "leased")) == 1
    finally:
        borrower.close()
    # The real worker's batch is stored, its values and not the borrower's.
    (reply,) = ask(client, key, encode(_batch(tile)))
    assert isinstance(reply[1], Ack) and reply[1].tile_state == "done"
    with any_sessions() as session:
        assert set(session.scalars(select(PoseRow.mu_s))) == {0.5}


def test_late_results_are_taken_only_from_the_holder_of_that_lease(
    client: zenoh.Session, any_sessions: sessionmaker[Session],  # noqa: F811
) -> None:
    submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-a")
    (other,) = lease(client, "w-b")  # w-b is a registered worker, with a lease of its own
    with any_sessions() as session:  # w-a's lease ends: its tile is queued, nobody holds it
        assert requeue_lost(session, worker_ids=["w-a"], max_attempts=3) == (1, 0)
        row = session.get(TileRow, tile.tile_id)
        assert (row.state, row.lease_owner, row.lease_holder) == ("queued", None, "w-a")
    key = keys.results_key(tile.tile_id, tile.lease_epoch)
    # A complete batch under that epoch from a worker that never held the tile: refused.
    (reply,) = ask(client, key, encode(_batch(tile, worker_id="w-b")))
    assert "was leased to w-a" in _refused(reply, ErrorCode.NOT_LEASE_HOLDER).message
    with any_sessions() as session:
        assert session.get(TileRow, tile.tile_id).state == "queued"
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0
    # The holder's late batch is taken and finishes the tile.
    (reply,) = ask(client, key, encode(_batch(tile, worker_id="w-a")))
    assert isinstance(reply[1], Ack) and (reply[1].inserted, reply[1].tile_state) == (3, "done")
    assert other.tile_id != tile.tile_id
