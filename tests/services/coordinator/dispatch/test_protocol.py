"""The protocol against a real Dispatcher (in this process) over a real zenoh session on
loopback: duplicate batches, malformed messages, object fetch, lost lease replies. No physics:
results are made up here, the store and the wire are real. Runs on SQLite and PostgreSQL."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator
from pathlib import Path

import pytest
import trimesh
import zenoh
from graspscape.services.coordinator.dispatch.service import Dispatcher
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.objects.service import create_uploaded
from graspscape.services.coordinator.settings import Settings, ZenohSettings
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow, TileRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.results import Outcome, PoseResult
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode, encode
from graspscape.shared.wire.messages import (
    Ack,
    ErrorCode,
    ErrorReply,
    LeaseRequest,
    ResultBatch,
    TileLease,
)
from graspscape.shared.wire.session import zenoh_config
from graspscape.workers.runtime.objects import ObjectCache
from prometheus_client import CollectorRegistry
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.support import SESSION_KEY, free_port, submit, wait_for


@pytest.fixture
def registry() -> CollectorRegistry:
    return CollectorRegistry()


@pytest.fixture
def dispatcher(
    any_url: str, any_sessions: sessionmaker[Session], registry: CollectorRegistry
) -> Iterator[Dispatcher]:
    port = free_port()
    settings = Settings(
        database={"url": any_url},
        zenoh=ZenohSettings(enabled=True, listen=[f"tcp/127.0.0.1:{port}"], orphan_grace_s=3600),
    )
    d = Dispatcher(settings, any_sessions, registry)
    d.start()
    assert d.ready
    yield d
    d.stop()


@pytest.fixture
def client(dispatcher: Dispatcher) -> Iterator[zenoh.Session]:
    endpoint = dispatcher.zenoh_settings.listen[0]
    session = zenoh.open(zenoh_config(mode="client", connect=[endpoint]))
    yield session
    session.close()


def ask(session: zenoh.Session, key: str, payload: bytes) -> list[tuple[str, object]]:
    """(reply key or 'error', decoded message) for every reply of one query."""
    out = []
    for reply in session.get(key, payload=payload, consolidation=zenoh.ConsolidationMode.NONE,
                             timeout=10):
        if reply.ok is not None:
            out.append((str(reply.ok.key_expr), decode(reply.ok.payload.to_bytes())))
        else:
            out.append(("error", decode(reply.err.payload.to_bytes())))
    return out


def lease(session: zenoh.Session, worker_id: str, capacity: int = 1) -> list[TileLease]:
    replies = ask(session, keys.LEASE_QUERY,
                  encode(LeaseRequest(session_key=SESSION_KEY,
                                      worker_id=worker_id, capacity=capacity)))
    tiles = [m for _, m in replies if isinstance(m, TileLease)]
    assert len(tiles) == len(replies), replies
    return tiles


def made_up(tile: TileLease) -> list[PoseResult]:
    return [PoseResult(pose=p, pose_key=p.key(), outcome=Outcome.HELD, viable=True, mu_s=0.5)
            for p in tile.poses()]


def counter(registry: CollectorRegistry, name: str, **labels: str) -> float:
    return registry.get_sample_value(name, labels) or 0.0


def test_one_reply_per_tile_on_distinct_keys(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    submit(any_sessions, tile_poses=3)
    replies = ask(client, keys.LEASE_QUERY, encode(LeaseRequest(session_key=SESSION_KEY,
                                                                worker_id="w-1", capacity=4)))
    assert len(replies) == 4
    assert {k for k, _ in replies} == {keys.lease_reply_key(m.tile_id) for _, m in replies}
    tile = replies[0][1]
    assert tile.gripper == "robotiq_3f" and tile.object.name == "sphere"
    assert len(tile.poses()) == 3


def test_same_batch_twice_leaves_one_row_each(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    exploration_id = submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")
    batch = encode(ResultBatch(session_key=SESSION_KEY, worker_id="w-1", tile_id=tile.tile_id,
                               lease_epoch=tile.lease_epoch, results=made_up(tile)))
    key = keys.results_key(tile.tile_id, tile.lease_epoch)
    (first,) = ask(client, key, batch)
    (second,) = ask(client, key, batch)
    assert first == (key, Ack(tile_id=tile.tile_id, lease_epoch=tile.lease_epoch, inserted=3,
                              duplicates=0, tile_state="done"))
    assert isinstance(second[1], Ack) and second[1].inserted == 0
    assert second[1].duplicates == 3
    with any_sessions() as session:
        rows = session.scalar(select(func.count()).select_from(PoseRow)
                              .where(PoseRow.tile_id == tile.tile_id))
        done = session.scalar(select(ExplorationRow.poses_done)
                              .where(ExplorationRow.id == exploration_id))
    assert rows == 3 and done == 3


@pytest.mark.parametrize(
    ("key", "payload", "code"),
    [
        (keys.LEASE_QUERY, b"\xff\x00 not json", ErrorCode.MALFORMED),
        (keys.LEASE_QUERY, b"[1, 2]", ErrorCode.MALFORMED),
        (keys.LEASE_QUERY, b'{"v": 9, "kind": "lease_request"}', ErrorCode.UNSUPPORTED_VERSION),
        (keys.LEASE_QUERY, b'{"v": 1, "kind": "gimme"}', ErrorCode.UNKNOWN_KIND),
        (keys.LEASE_QUERY, b'{"v": 1, "kind": "lease_request", "worker_id": "a/b*",'
                           b' "capacity": 1}', ErrorCode.MALFORMED),
        (keys.LEASE_QUERY, b'{"v": 1, "kind": "object_request", "content_hash": "' + b"0" * 64
         + b'"}', ErrorCode.UNEXPECTED_KIND),
        ("gs/results/1/1", b"", ErrorCode.MALFORMED),
        ("gs/results/1/1", b'{"v": 1, "kind": "result_batch", "worker_id": "w", "tile_id": 1,'
                           b' "lease_epoch": 1, "results": [{"pose": 3}]}', ErrorCode.MALFORMED),
        ("gs/object/x", b'{"v": 1, "kind": "object_request", "content_hash": "zz"}',
         ErrorCode.MALFORMED),
        ("gs/object/" + "0" * 64, json.dumps({"v": 1, "kind": "object_request",
                                             "content_hash": "0" * 64}).encode(),
         ErrorCode.NOT_FOUND),
    ],
)
def test_malformed_messages_get_error_replies(
    client: zenoh.Session, any_sessions: sessionmaker[Session], registry: CollectorRegistry,
    key: str, payload: bytes, code: ErrorCode,
) -> None:
    (reply,) = ask(client, key, payload)
    assert reply[0] == "error"
    assert isinstance(reply[1], ErrorReply) and reply[1].code == code, reply
    kind = key.split("/")[1]  # lease, results, object
    assert counter(registry, "graspscape_dispatch_errors_total", where=kind,
                   code=code.value) == 1
    # Nothing crashed: the dispatcher still serves a valid request.
    submit(any_sessions, tile_poses=3)
    assert len(lease(client, "w-ok")) == 1


def test_result_with_wrong_pose_key_is_refused_and_nothing_stored(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")
    results = made_up(tile)
    results[1] = results[1].model_copy(update={"pose_key": "0/0/0/0/0/0"})
    batch = ResultBatch(session_key=SESSION_KEY,
                        worker_id="w-1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                        results=results)
    ((where, message),) = ask(client, keys.results_key(tile.tile_id, tile.lease_epoch),
                              encode(batch))
    assert where == "error" and message.code == ErrorCode.INVALID
    assert not message.code.retryable
    with any_sessions() as session:
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0


def test_lost_lease_reply_is_released_by_the_next_request(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    submit(any_sessions, tile_poses=3)
    (lost,) = lease(client, "w-1")  # pretend this reply never reached the worker
    (again,) = lease(client, "w-1")  # holding nothing: the first goes back first
    assert again.tile_id == lost.tile_id and again.lease_epoch == lost.lease_epoch + 1
    with any_sessions() as session:
        assert session.get(TileRow, lost.tile_id).attempts == 1  # not counted


def test_partial_batch_with_release_requeues_uncounted(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")
    batch = ResultBatch(session_key=SESSION_KEY,
                        worker_id="w-1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                        results=made_up(tile)[:1], final=False, release=True)
    ((_, ack),) = ask(client, keys.results_key(tile.tile_id, tile.lease_epoch), encode(batch))
    assert isinstance(ack, Ack) and ack.inserted == 1 and ack.tile_state == "queued"
    with any_sessions() as session:
        row = session.get(TileRow, tile.tile_id)
        assert (row.state, row.attempts, row.lease_owner) == ("queued", 0, None)


def test_error_report_counts_an_attempt(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")
    batch = ResultBatch(session_key=SESSION_KEY,
                        worker_id="w-1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                        results=[], final=False, error="pybullet exploded")
    ((_, ack),) = ask(client, keys.results_key(tile.tile_id, tile.lease_epoch), encode(batch))
    assert isinstance(ack, Ack) and ack.tile_state == "queued"
    with any_sessions() as session:
        row = session.get(TileRow, tile.tile_id)
        assert row.attempts == 1 and "pybullet exploded" in row.last_error


def test_lost_worker_token_requeues_its_tiles_at_once(
    client: zenoh.Session, dispatcher: Dispatcher, any_sessions: sessionmaker[Session]
) -> None:
    submit(any_sessions, tile_poses=3)
    worker = zenoh.open(zenoh_config(mode="client", connect=dispatcher.zenoh_settings.listen))
    token = worker.liveliness().declare_token(keys.alive_key("w-gone"))
    (tile,) = lease(worker, "w-gone")
    worker.close()  # the token vanishes with the session, as with kill -9

    def queued() -> bool:
        with any_sessions() as session:
            return session.get(TileRow, tile.tile_id).state == "queued"

    wait_for(queued, 5, "the lost worker's tile to be queued again", every=0.05)
    del token


def test_mesh_is_fetched_once_and_checked(
    client: zenoh.Session, any_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    data = trimesh.creation.box(extents=(0.05, 0.05, 0.1)).export(file_type="stl")
    with any_sessions() as session:
        row, _ = create_uploaded(session, filename="box.stl", data=data,
                                 properties={"mass_kg": 0.2})
        exploration = create_exploration(
            session, spec=ExplorationSpec(object_id=row.id), tile_target_poses=100,
            max_poses=100_000)
    (tile,) = lease(client, "w-1")
    assert tile.exploration_id == exploration.id
    ref = tile.object
    assert ref.content_hash == hashlib.sha256(data).hexdigest() and ref.name is None
    # Two processes of one worker share the cache folder: one fetch between them.
    first = ObjectCache(client, tmp_path, timeout_s=10)
    second = ObjectCache(client, tmp_path, timeout_s=10)
    spec = first.spec(ref)
    assert Path(spec.mesh_path).read_bytes() == data
    assert second.spec(ref).mesh_path == spec.mesh_path
    assert (first.fetched, second.fetched) == (1, 0)


def test_lease_context_follows_a_reused_exploration_id(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    from graspscape.services.coordinator.exploration.service import delete_exploration

    first = submit(any_sessions, tile_poses=3, object_name="sphere")
    (tile,) = lease(client, "w-1")
    assert tile.object.name == "sphere"
    with any_sessions() as session:
        delete_exploration(session, exploration_id=first)
    submit(any_sessions, tile_poses=3, object_name="cube")  # SQLite reused ids before 0006
    (tile,) = lease(client, "w-1")
    assert tile.object.name == "cube"


@pytest.mark.parametrize(
    ("key", "message", "reason"),
    [
        ("gs/results/1/1", {"kind": "result_batch", "worker_id": "w", "session_key": SESSION_KEY,
                            "tile_id": 2**70,
                            "lease_epoch": 1, "results": []},
         "result_batch.tile_id: Input should be less than or equal to 2147483647"),
        ("gs/results/1/1", {"kind": "result_batch", "worker_id": "w", "session_key": SESSION_KEY,
                            "tile_id": 1,
                            "lease_epoch": -(2**64), "results": []},
         "result_batch.lease_epoch: Input should be greater than or equal to 0"),
        (keys.LEASE_QUERY, {"kind": "lease_request", "worker_id": "w", "session_key": SESSION_KEY,
                            "capacity": 1,
                            "holding": [2**70]},
         "lease_request.holding.0: Input should be less than or equal to 2147483647"),
    ],
)
def test_out_of_range_integers_are_malformed_not_a_store_failure(
    client: zenoh.Session, any_sessions: sessionmaker[Session], registry: CollectorRegistry,
    key: str, message: dict[str, object], reason: str,
) -> None:
    # A tile id of 2^70 used to reach the database driver (OverflowError on SQLite, out of
    # range on PostgreSQL): a traceback and an `unavailable` reply the worker retried forever.
    submit(any_sessions, tile_poses=3)
    (reply,) = ask(client, key, json.dumps({"v": 1, **message}).encode())
    assert reply[0] == "error"
    error = reply[1]
    assert isinstance(error, ErrorReply) and error.code == ErrorCode.MALFORMED, error
    assert error.message == reason
    kind = key.split("/")[1]
    assert counter(registry, "graspscape_dispatch_errors_total", where=kind,
                   code="unavailable") == 0
    with any_sessions() as session:
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0
        assert set(session.scalars(select(TileRow.state))) == {"queued"}


@pytest.mark.slow  # waits past query timeouts on purpose
def test_a_timed_out_batch_is_sent_again_until_acknowledged_stored_and_evaluated_once(
    dispatcher: Dispatcher, any_sessions: sessionmaker[Session], registry: CollectorRegistry,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The coordinator holds the batch past the worker's query timeout (another transaction
    holds the database's write lock on SQLite, the exploration's row lock on PostgreSQL):
    zenoh answers the worker with its `Timeout` error reply, which is no refusal. The worker
    sends the batch again with backoff until the ack comes; the batch is stored once and the
    tile evaluated once."""
    import threading

    from graspscape.services.coordinator.store.base import utcnow
    from graspscape.workers.runtime.config import WorkerConfig
    from graspscape.workers.runtime.process import WorkerProcess
    from sqlalchemy import update

    exploration_id = submit(any_sessions, tile_poses=3)
    timeout_s = 0.4
    config = WorkerConfig(connect=dispatcher.zenoh_settings.listen,
                          procs=1, name="slow", instant=True,
                          query_timeout_s=timeout_s, backoff_min_s=0.05, backoff_max_s=0.2)
    worker = WorkerProcess(config, 0)
    worker.session = zenoh.open(
        zenoh_config(mode="client", connect=dispatcher.zenoh_settings.listen))
    evaluated: list[str] = []
    evaluate = worker._evaluate

    def counted(tile, obj, pose, donors=None):  # type: ignore[no-untyped-def]
        evaluated.append(pose.key())
        return evaluate(tile, obj, pose, donors)

    worker._evaluate = counted  # type: ignore[method-assign]
    acks: list[Ack | None] = []
    lock = any_sessions()
    try:
        (tile,) = worker._lease()
        lock.execute(update(ExplorationRow).where(ExplorationRow.id == exploration_id)
                     .values(updated_at=utcnow()))  # held until the rollback below
        caplog.set_level("WARNING", logger="graspscape.worker")

        def work() -> None:
            worker._work(tile)  # evaluates, sends, goes on
            acks.append(worker._settle())  # reads the ack, sending again until it comes

        thread = threading.Thread(target=work, daemon=True)
        thread.start()
        thread.join(5 * timeout_s)
        # The old worker took zenoh's Timeout for a malformed refusal and gave up here.
        assert thread.is_alive() and not acks, acks
        lock.rollback()
        thread.join(30)
        assert not thread.is_alive()
    finally:
        lock.rollback()
        lock.close()
        worker.stop.set()
        worker.stop_deadline = 0.0  # a worker still sending gives up at once
        worker.session.close()
    (ack,) = acks
    assert isinstance(ack, Ack) and ack.tile_id == tile.tile_id and ack.tile_state == "done"
    assert ack.inserted + ack.duplicates == 3
    assert "Timeout" in caplog.text and "refused for good" not in caplog.text
    assert counter(registry, "graspscape_dispatch_queries_total", kind="results",
                   outcome="ok") >= 2  # it was sent again
    assert sorted(evaluated) == sorted(p.key() for p in tile.poses())  # evaluated once
    with any_sessions() as session:
        keys_stored = session.scalars(select(PoseRow.pose_key)
                                      .where(PoseRow.exploration_id == exploration_id)).all()
        row = session.get(TileRow, tile.tile_id)
        exploration = session.get(ExplorationRow, exploration_id)
        assert sorted(keys_stored) == sorted(evaluated)  # stored once
        assert (row.state, row.attempts, row.lease_epoch) == ("done", 1, tile.lease_epoch)
        assert exploration.poses_done == 3


# -- ingest trusts only the lease holder, only the tile's poses, final only when complete ----


def instant_worker(dispatcher: Dispatcher, name: str):  # -> WorkerProcess
    """A worker process without physics, on its own session to the dispatcher, driven by the
    test (its _lease, _work and _settle) instead of its loop."""
    from graspscape.workers.runtime.config import WorkerConfig
    from graspscape.workers.runtime.process import WorkerProcess

    config = WorkerConfig(connect=dispatcher.zenoh_settings.listen,
                          procs=1, name=name, instant=True,
                          query_timeout_s=5, backoff_min_s=0.05, backoff_max_s=0.2)
    worker = WorkerProcess(config, 0)
    worker.session = zenoh.open(
        zenoh_config(mode="client", connect=dispatcher.zenoh_settings.listen))
    return worker


def test_a_batch_from_a_worker_that_does_not_hold_the_lease_is_refused(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    """A worker id that does not hold the tile's lease could finish it (and fail it) until
    2026-12: now every report of it is refused before anything is stored or moved."""
    exploration_id = submit(any_sessions, tile_poses=3)
    (tile,) = lease(client, "w-1")
    key = keys.results_key(tile.tile_id, tile.lease_epoch)
    forged = [
        ResultBatch(session_key=SESSION_KEY,
                    worker_id="w-intruder", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                    results=made_up(tile)),
        ResultBatch(session_key=SESSION_KEY,
                    worker_id="w-intruder", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                    results=[], final=False, error="forged failure"),
        ResultBatch(session_key=SESSION_KEY,
                    worker_id="w-intruder", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                    results=[], final=False, release=True),
        ResultBatch(session_key=SESSION_KEY,
                    worker_id="w-1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch + 1,
                    results=made_up(tile)),
    ]
    refusals = []
    for batch in forged:
        ((where, message),) = ask(client, key, encode(batch))
        assert where == "error" and isinstance(message, ErrorReply), message
        assert message.code == ErrorCode.NOT_LEASE_HOLDER and not message.code.retryable
        refusals.append(message.message)
    assert "leased to w-1 under epoch 1, not to w-intruder" in refusals[0]
    assert "no lease of epoch 2" in refusals[-1]
    with any_sessions() as session:
        row = session.get(TileRow, tile.tile_id)
        assert (row.state, row.lease_owner, row.attempts, row.last_error) == (
            "leased", "w-1", 1, None)
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0
        assert session.get(ExplorationRow, exploration_id).status == "running"
    # The holder's batch is taken.
    (reply,) = ask(client, key, encode(ResultBatch(session_key=SESSION_KEY,
        worker_id="w-1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
        results=made_up(tile))))
    assert isinstance(reply[1], Ack) and reply[1].tile_state == "done"


def test_a_batch_with_a_pose_of_another_tile_is_refused_with_its_key(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    submit(any_sessions, tile_poses=3)
    mine, other = lease(client, "w-1", capacity=2)
    stranger = made_up(other)[1]
    batch = ResultBatch(session_key=SESSION_KEY,
                        worker_id="w-1", tile_id=mine.tile_id, lease_epoch=mine.lease_epoch,
                        results=[*made_up(mine), stranger])
    ((where, message),) = ask(client, keys.results_key(mine.tile_id, mine.lease_epoch),
                              encode(batch))
    assert where == "error" and message.code == ErrorCode.INVALID, message
    assert stranger.pose_key in message.message and f"tile {mine.tile_id}" in message.message
    with any_sessions() as session:
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0
        # The holder's refused batch is an attempt of the tile: queued again with the reason.
        row = session.get(TileRow, mine.tile_id)
        assert (row.state, row.attempts) == ("queued", 1)
        assert stranger.pose_key in row.last_error


def test_final_with_half_the_poses_leaves_the_tile_open_and_says_what_is_missing(
    client: zenoh.Session, any_sessions: sessionmaker[Session]
) -> None:
    exploration_id = submit(any_sessions, tile_poses=6, r_max=0.06)  # 6 r levels a cell
    (tile,) = lease(client, "w-1")
    results = made_up(tile)
    assert len(results) == 6
    key = keys.results_key(tile.tile_id, tile.lease_epoch)
    ((_, ack),) = ask(client, key, encode(ResultBatch(session_key=SESSION_KEY,
        worker_id="w-1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
        results=results[:3], final=True)))
    assert isinstance(ack, Ack), ack
    assert (ack.inserted, ack.tile_state) == (3, "leased")
    assert ack.missing == sorted(r.pose_key for r in results[3:])
    with any_sessions() as session:
        assert session.get(TileRow, tile.tile_id).state == "leased"
        exploration = session.get(ExplorationRow, exploration_id)
        assert (exploration.status, exploration.poses_done) == ("running", 3)
    ((_, ack),) = ask(client, key, encode(ResultBatch(session_key=SESSION_KEY,
        worker_id="w-1", tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
        results=results[3:], final=True)))
    assert isinstance(ack, Ack) and (ack.inserted, ack.tile_state, ack.missing) == (
        3, "done", [])


def test_the_worker_evaluates_and_sends_the_poses_the_coordinator_misses(
    dispatcher: Dispatcher, any_sessions: sessionmaker[Session],
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A final batch that lacks a pose (here the worker's batch loses its last result) no
    longer finishes the tile: the ack lists the pose, the worker evaluates it and sends it;
    then the tile is done with every pose stored."""
    exploration_id = submit(any_sessions, tile_poses=3)
    worker = instant_worker(dispatcher, "gappy")
    make_batch = worker._batch
    dropped: list[str] = []

    def lossy(tile, results, **kwargs):  # type: ignore[no-untyped-def]
        if kwargs.get("final") and not dropped and len(results) > 1:
            dropped.append(results[-1].pose_key)
            results = results[:-1]
        return make_batch(tile, results, **kwargs)

    worker._batch = lossy  # type: ignore[method-assign]
    caplog.set_level("WARNING", logger="graspscape.worker")
    try:
        (tile,) = worker._lease()
        worker._work(tile)
        ack = worker._settle()
    finally:
        worker.session.close()
    assert dropped and isinstance(ack, Ack)
    assert (ack.tile_state, ack.missing, ack.inserted) == ("done", [], 1)
    assert "misses 1 pose(s) of its final batch" in caplog.text
    with any_sessions() as session:
        stored = session.scalars(select(PoseRow.pose_key)
                                 .where(PoseRow.exploration_id == exploration_id)).all()
        assert sorted(stored) == sorted(p.key() for p in tile.poses())
        assert session.get(TileRow, tile.tile_id).state == "done"


def test_a_worker_whose_lease_went_elsewhere_drops_its_batch_for_good(
    dispatcher: Dispatcher, any_sessions: sessionmaker[Session],
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Its lease ran out and the tile was leased again meanwhile: the batch is refused as
    not the lease holder's, and the worker neither stores it nor resends it."""
    from sqlalchemy import update

    submit(any_sessions, tile_poses=3)
    worker = instant_worker(dispatcher, "late")
    caplog.set_level("WARNING", logger="graspscape.worker")
    try:
        (tile,) = worker._lease()
        with any_sessions() as session:  # expired and re-leased to another worker
            session.execute(update(TileRow).where(TileRow.id == tile.tile_id).values(
                lease_owner="w-next", lease_epoch=tile.lease_epoch + 1))
            session.commit()
        worker._work(tile)
        ack = worker._settle()
    finally:
        worker.session.close()
    assert ack is None
    assert "dropped, the lease is gone" in caplog.text and "sending it again" not in caplog.text
    with any_sessions() as session:
        assert session.scalar(select(func.count()).select_from(PoseRow)) == 0
        row = session.get(TileRow, tile.tile_id)
        assert (row.state, row.lease_owner) == ("leased", "w-next")
