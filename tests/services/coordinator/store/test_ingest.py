"""Result ingest on both databases: idempotent, only from the lease holder, only the tile's
poses, final only when complete, counted once, nothing lost."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from datetime import timedelta

import graspscape.services.coordinator.exploration.scheduler as scheduler_module
import graspscape.services.coordinator.store.ingest as ingest_module
import pytest
from graspscape.services.coordinator.errors import InvalidInput, NotFound, NotLeaseHolder
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import cancel_exploration
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow, TileRow
from graspscape.services.coordinator.store.pose_rows import _PER_POSE, _values
from graspscape.services.coordinator.store.queue import (
    LeasedTile,
    fail_tile,
    lease_tiles,
    requeue_expired,
)
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.results import ContactPoint, GraspSignature
from sqlalchemy import func, select, text
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import fake_results, make_exploration


def pose_count(session: Session, exploration_id: int) -> int:
    return (
        session.scalar(
            select(func.count())
            .select_from(PoseRow)
            .where(PoseRow.exploration_id == exploration_id)
        )
        or 0
    )


def exploration(session: Session, eid: int) -> ExplorationRow:
    session.expire_all()
    row = session.get(ExplorationRow, eid)
    assert row is not None
    return row


def test_a_tile_batch_is_stored_and_finishes_the_tile(session: Session) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w1", n=1, lease_seconds=60)
    results = fake_results(t.poses(), seed=1)
    report = ingest_results(
        session, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w1", results=results
    )
    assert (report.inserted, report.duplicates, report.tile_moved) == (len(results), 0, True)
    assert report.tile_state == "done"
    assert pose_count(session, eid) == len(results)
    row = exploration(session, eid)
    assert row.poses_done == len(results)
    assert row.viable_count == sum(r.viable for r in results)
    stored = session.scalars(select(PoseRow).where(PoseRow.exploration_id == eid)).all()
    by_key = {p.pose_key: p for p in stored}
    for result in results:
        p = by_key[result.pose_key]
        assert (p.theta, p.phi, p.r, p.viable, p.mu_s, p.outcome, p.worker_id) == (
            result.pose.theta,
            result.pose.phi,
            result.pose.r,
            result.viable,
            result.mu_s,
            result.outcome.value,
            "w1",
        )
        if result.signature is not None:
            assert p.signature == result.signature.model_dump(mode="json")
        if result.grasp is not None:
            assert p.grasp == result.grasp.model_dump(mode="json")


def test_the_same_batch_twice_leaves_one_row_per_pose(session: Session) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w1", n=1, lease_seconds=60)
    results = fake_results(t.poses())
    ingest_results(session, tile_id=t.tile_id, lease_epoch=1, worker_id="w1", results=results)
    again = ingest_results(
        session, tile_id=t.tile_id, lease_epoch=1, worker_id="w1", results=results + results[:3]
    )
    assert (again.inserted, again.duplicates, again.tile_moved) == (0, len(results) + 3, False)
    assert pose_count(session, eid) == len(results)
    assert exploration(session, eid).poses_done == len(results)


def test_a_report_under_an_older_epoch_is_refused_and_stores_nothing(session: Session) -> None:
    """The slow worker's lease ran out and the tile went to another worker: its late report
    cannot be told from a forged one (the row names only the current holder), so it is
    refused whole; the new holder stores every pose. Until 2026-12 it was stored."""
    eid = make_exploration(session)
    past = utcnow() - timedelta(hours=1)
    (old,) = lease_tiles(session, worker_id="slow", n=1, lease_seconds=60, now=past)
    requeue_expired(session, max_attempts=5)
    (new,) = lease_tiles(session, worker_id="fast", n=1, lease_seconds=60)
    assert (new.tile_id, new.lease_epoch) == (old.tile_id, 2)
    results = fake_results(old.poses())
    half = len(results) // 2

    with pytest.raises(NotLeaseHolder, match="latest lease is epoch 2, state leased"):
        ingest_results(session, tile_id=old.tile_id, lease_epoch=1, worker_id="slow",
                       results=results[:half])
    assert pose_count(session, eid) == 0
    current = ingest_results(
        session, tile_id=new.tile_id, lease_epoch=2, worker_id="fast", results=results
    )
    assert (current.inserted, current.duplicates, current.tile_moved) == (len(results), 0, True)
    with pytest.raises(NotLeaseHolder, match="latest lease is epoch 2, state done"):
        ingest_results(session, tile_id=old.tile_id, lease_epoch=1, worker_id="slow",
                       results=results)
    row = exploration(session, eid)
    assert row.poses_done == len(results) == pose_count(session, eid)


def test_a_worker_that_does_not_hold_the_lease_cannot_store_or_finish_the_tile(
    session: Session,
) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w1", n=1, lease_seconds=60)
    results = fake_results(t.poses())
    for epoch, match in ((t.lease_epoch, "leased to w1 under epoch 1, not to intruder"),
                         (t.lease_epoch + 1, "no lease of epoch 2")):
        with pytest.raises(NotLeaseHolder, match=match):
            ingest_results(session, tile_id=t.tile_id, lease_epoch=epoch,
                           worker_id="intruder", results=results)
    assert pose_count(session, eid) == 0
    row = session.get(TileRow, t.tile_id)
    assert row is not None and (row.state, row.lease_owner) == ("leased", "w1")
    assert exploration(session, eid).poses_done == 0
    # The holder's own report goes through.
    report = ingest_results(session, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                            worker_id="w1", results=results)
    assert (report.inserted, report.tile_moved) == (len(results), True)


def test_a_tile_never_leased_takes_no_report(session: Session) -> None:
    eid = make_exploration(session)
    tile_id = session.scalar(select(TileRow.id).where(TileRow.exploration_id == eid))
    assert tile_id is not None
    with pytest.raises(NotLeaseHolder, match="it was never leased"):
        ingest_results(session, tile_id=tile_id, lease_epoch=0, worker_id="w", results=[])
    assert session.get(TileRow, tile_id).state == "queued"  # type: ignore[union-attr]


def test_a_batch_with_a_pose_of_another_tile_is_refused_whole(session: Session) -> None:
    eid = make_exploration(session)
    mine, other = lease_tiles(session, worker_id="w", n=2, lease_seconds=60)
    results = fake_results(mine.poses())
    stranger = fake_results(other.poses())[0]
    made_up = fake_results([Pose(theta=1.234, phi=0.5, r=0.015)])[0]
    with pytest.raises(InvalidInput, match=r"2 pose\(s\) of the batch are not poses of") as refused:
        ingest_results(session, tile_id=mine.tile_id, lease_epoch=mine.lease_epoch,
                       worker_id="w", results=[*results, stranger, made_up])
    assert stranger.pose_key in refused.value.message
    assert made_up.pose_key in refused.value.message
    # Another tile's poses, all of them, under this tile: refused too.
    with pytest.raises(InvalidInput, match="not poses of tile"):
        ingest_results(session, tile_id=mine.tile_id, lease_epoch=mine.lease_epoch,
                       worker_id="w", results=fake_results(other.poses()))
    assert pose_count(session, eid) == 0
    assert session.get(TileRow, mine.tile_id).state == "leased"  # type: ignore[union-attr]
    assert exploration(session, eid).poses_done == 0


def test_final_finishes_the_tile_only_once_every_pose_is_stored(session: Session) -> None:
    eid = make_exploration(session)
    t = max(lease_tiles(session, worker_id="w", n=3, lease_seconds=60),
            key=lambda tile: len(tile.poses()))
    results = fake_results(t.poses())
    half = len(results) // 2
    assert half >= 2
    everything = sorted(r.pose_key for r in results)

    empty = ingest_results(session, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                           worker_id="w", results=[], final=True)
    assert (empty.tile_moved, empty.tile_state, empty.missing) == (False, "leased", everything)
    first = ingest_results(session, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                           worker_id="w", results=results[:half], final=True)
    assert (first.inserted, first.tile_moved, first.tile_state) == (half, False, "leased")
    assert first.missing == sorted(r.pose_key for r in results[half:])
    assert exploration(session, eid).poses_done == half
    # The rest alone completes it: the stored half is read back from the store.
    rest = ingest_results(session, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                          worker_id="w", results=results[half:], final=True)
    assert (rest.inserted, rest.tile_moved, rest.tile_state, rest.missing) == (
        len(results) - half, True, "done", [])
    assert pose_count(session, eid) == len(results)


def test_partial_batches_do_not_finish_the_tile(session: Session) -> None:
    make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=60)
    results = fake_results(t.poses())
    first = ingest_results(
        session, tile_id=t.tile_id, lease_epoch=1, worker_id="w", results=results[:2], final=False
    )
    assert (first.inserted, first.tile_state, first.tile_moved) == (2, "leased", False)
    last = ingest_results(
        session, tile_id=t.tile_id, lease_epoch=1, worker_id="w", results=results[2:]
    )
    assert (last.inserted, last.tile_state) == (len(results) - 2, "done")


def test_the_last_tile_finishes_the_exploration(session: Session) -> None:
    eid = make_exploration(session, dtheta=1.5, target=10_000)
    leased = lease_tiles(session, worker_id="w", n=100, lease_seconds=60)
    now = utcnow().replace(microsecond=0)
    for t in leased:
        assert exploration(session, eid).status == "running"
        ingest_results(
            session,
            tile_id=t.tile_id,
            lease_epoch=t.lease_epoch,
            worker_id="w",
            results=fake_results(t.poses(), seed=t.tile_id),
            now=now,
        )
    row = exploration(session, eid)
    assert row.status == "done" and row.finished_at == now
    assert row.poses_done == row.poses_total


def test_results_for_a_cancelled_exploration_are_kept(session: Session) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=60)
    cancel_exploration(session, exploration_id=eid)
    results = fake_results(t.poses())
    report = ingest_results(
        session, tile_id=t.tile_id, lease_epoch=1, worker_id="w", results=results
    )
    assert (report.inserted, report.tile_state, report.tile_moved) == (
        len(results),
        "cancelled",
        False,
    )
    assert pose_count(session, eid) == len(results)


def test_a_pose_key_that_does_not_match_its_pose_is_refused_whole(session: Session) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=60)
    results = fake_results(t.poses())
    results[-1] = results[-1].model_copy(update={"pose_key": "0.1/0.2/0.3/0/0/0"})
    with pytest.raises(InvalidInput, match="does not match its pose"):
        ingest_results(session, tile_id=t.tile_id, lease_epoch=1, worker_id="w", results=results)
    assert pose_count(session, eid) == 0
    assert session.get(TileRow, t.tile_id).state == "leased"  # type: ignore[union-attr]


def test_rows_read_back_as_the_orm_would_have_written_them(session: Session) -> None:
    """The ingest writes at the driver level: every column must still come back as written
    through the ORM (timestamps in the store's text form on SQLite, so that they compare and
    sort with the others; JSON columns as JSON)."""
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=60)
    now = (utcnow() - timedelta(minutes=5)).replace(microsecond=0)
    results = fake_results(t.poses(), seed=3)
    ingest_results(session, tile_id=t.tile_id, lease_epoch=1, worker_id="w", results=results,
                   now=now)
    session.expire_all()
    stored = {p.pose_key: p for p in session.scalars(
        select(PoseRow).where(PoseRow.exploration_id == eid))}
    for result in results:
        p = stored[result.pose_key]
        assert (p.tile_id, p.worker_id, p.created_at) == (t.tile_id, "w", now)
        assert (p.roll, p.pitch, p.yaw, p.effective_r, p.effort_max_nm, p.eval_time_s) == (
            result.pose.roll, result.pose.pitch, result.pose.yaw, result.effective_r,
            result.effort_max_nm, result.eval_time_s)
        assert p.contacts_per_link == (result.contacts_per_link or None)
        assert p.signature == (result.signature.model_dump(mode="json")
                               if result.signature else None)
        assert p.grasp == (result.grasp.model_dump(mode="json") if result.grasp else None)
    # In the database itself: the same value as the tile's done_at, written through Core.
    assert session.execute(text(
        "SELECT count(*) FROM poses JOIN tiles ON tiles.id = poses.tile_id "
        "WHERE poses.exploration_id = :eid AND poses.created_at = tiles.done_at"),
        {"eid": eid}).scalar() == len(results)
    since = now - timedelta(seconds=1)
    assert session.scalar(select(func.count()).select_from(PoseRow).where(
        PoseRow.exploration_id == eid, PoseRow.created_at > since)) == len(results)
    assert session.scalar(select(func.count()).select_from(PoseRow).where(
        PoseRow.exploration_id == eid, PoseRow.created_at > now)) == 0


def test_a_batch_over_several_statements_is_stored_and_counted_once(
    session: Session, monkeypatch: pytest.MonkeyPatch
) -> None:
    # SQLite takes a batch in statements of as many rows as it takes parameters: 2 rows here.
    monkeypatch.setattr(session.get_bind().dialect, "insertmanyvalues_max_parameters", 41)
    eid = make_exploration(session)
    t = max(lease_tiles(session, worker_id="w", n=3, lease_seconds=60),
            key=lambda tile: len(tile.poses()))
    results = fake_results(t.poses(), seed=5)
    assert len(results) > 4
    first = ingest_results(session, tile_id=t.tile_id, lease_epoch=1, worker_id="w",
                           results=results[:3], final=False)
    report = ingest_results(session, tile_id=t.tile_id, lease_epoch=1, worker_id="w",
                            results=results)
    assert (first.inserted, report.inserted, report.duplicates) == (3, len(results) - 3, 3)
    row = exploration(session, eid)
    assert row.poses_done == len(results) == pose_count(session, eid)
    assert row.viable_count == sum(r.viable for r in results)


def test_a_non_finite_value_in_a_json_column_is_kept_as_json_dumps_writes_it() -> None:
    # The models refuse NaN and ∞ (a worker sends such a pose as an error); built without
    # validation, the row's JSON still says what dumps writes.
    result = fake_results([Pose(theta=1.0, phi=0.5, r=0.01)], seed=1)[0]
    contact = ContactPoint.model_construct(link="palm", normal_force_n=float("inf"),
                                           position_object=(0.0, 0.1, 0.2))
    signature = GraspSignature.model_construct(links_in_contact=("palm",),
                                               joint_angles={"j": float("nan")},
                                               contacts=(contact,))
    values = dict(zip((name for name, _ in _PER_POSE),
                      _values(result.model_copy(update={"signature": signature})), strict=True))
    assert values["signature"] == json.dumps(signature.model_dump(mode="json"))
    assert "NaN" in values["signature"] and "Infinity" in values["signature"]
    assert json.loads(values["grasp"]) == result.grasp.model_dump(mode="json")


def test_an_unknown_tile_is_refused(session: Session) -> None:
    with pytest.raises(NotFound, match="tile 424242"):
        ingest_results(session, tile_id=424242, lease_epoch=1, worker_id="w", results=[])


def test_a_batch_with_every_optional_field_empty(session: Session) -> None:
    eid = make_exploration(session)
    (t,) = lease_tiles(session, worker_id="w", n=1, lease_seconds=60)
    bare = [
        r.model_copy(
            update={"effective_r": None, "signature": None, "grasp": None, "contacts_per_link": {}}
        )
        for r in fake_results(t.poses())
    ]
    report = ingest_results(session, tile_id=t.tile_id, lease_epoch=1, worker_id="w", results=bare)
    assert report.inserted == len(bare)
    stored = session.scalars(select(PoseRow).where(PoseRow.exploration_id == eid)).all()
    assert all(p.signature is None and p.grasp is None and p.effective_r is None for p in stored)


def test_a_late_report_before_anyone_re_leases_still_finishes_the_tile(session: Session) -> None:
    eid = make_exploration(session)
    past = utcnow() - timedelta(hours=1)
    (t,) = lease_tiles(session, worker_id="slow", n=1, lease_seconds=60, now=past)
    requeue_expired(session, max_attempts=5)
    assert session.get(TileRow, t.tile_id).state == "queued"  # type: ignore[union-attr]
    report = ingest_results(
        session,
        tile_id=t.tile_id,
        lease_epoch=t.lease_epoch,
        worker_id="slow",
        results=fake_results(t.poses()),
    )
    assert (report.tile_moved, report.tile_state) == (True, "done")
    again = lease_tiles(session, worker_id="w", n=100, lease_seconds=60)
    assert t.tile_id not in {x.tile_id for x in again}
    assert exploration(session, eid).poses_done == len(t.poses())


def ingest_concurrently(sessions: sessionmaker[Session], orders: list[list]) -> list[int]:
    """One thread per order of (tile, results) batches, each on its own session, all at once;
    the tiles whose batch moved them, in the order they moved. Fails on any thread's error."""
    errors: list[BaseException] = []
    moved: list[int] = []

    def report(order: list) -> None:
        try:
            with sessions() as s:
                for t, results in order:
                    r = ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                                       worker_id="w", results=results)
                    if r.tile_moved:
                        moved.append(t.tile_id)
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=report, args=(order,)) for order in orders]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert not errors
    return moved


def test_concurrent_reports_of_the_same_tiles_count_each_pose_once(
    sessions: sessionmaker[Session],
) -> None:
    with sessions() as s:
        eid = make_exploration(s)
        leased = lease_tiles(s, worker_id="w", n=6, lease_seconds=600)
    batches = [(t, fake_results(t.poses(), seed=t.tile_id)) for t in leased]
    # Every thread sends every tile (the holder's retries and duplicates), in a different order.
    moved = ingest_concurrently(sessions, [batches[i:] + batches[:i] for i in range(4)])
    assert sorted(moved) == sorted(t.tile_id for t in leased)  # each tile moved exactly once
    total = sum(len(results) for _, results in batches)
    row = exploration_row(sessions, eid)
    assert row.poses_done == total
    assert row.viable_count == sum(r.viable for _, results in batches for r in results)
    with sessions() as s:
        assert pose_count(s, eid) == total


def all_but_two_reported(
    sessions: sessionmaker[Session],
) -> tuple[int, tuple[LeasedTile, LeasedTile]]:
    """An exploration with every tile leased and all but the last two reported."""
    with sessions() as s:
        eid = make_exploration(s, dtheta=1.5, target=10_000)
        leased = lease_tiles(s, worker_id="w", n=100, lease_seconds=600)
        assert len(leased) >= 2
        for t in leased[:-2]:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=fake_results(t.poses(), seed=t.tile_id))
    return eid, (leased[-2], leased[-1])


def never_quiet(monkeypatch: pytest.MonkeyPatch) -> None:
    """The store never commits with the counters (a strategy that reacts), so that after_batch
    runs inside the transaction and a test can hold it open there."""
    store_batch = scheduler_module.store_batch

    def loud(*args: object, **kwargs: object) -> object:
        return store_batch(*args, **{**kwargs, "quiet": None})  # type: ignore[arg-type]

    monkeypatch.setattr(scheduler_module, "store_batch", loud)


def run_overlapped(first: Callable[[], None], second: Callable[[], None],
                   inside: threading.Event, go_on: threading.Event) -> list[BaseException]:
    """Runs `first` (in a thread named "first") until it sets `inside` with its transaction
    open, then `second`, which must wait for `first` to commit; then lets `first` go on.
    Returns what either raised."""
    errors: list[BaseException] = []

    def guarded(work: Callable[[], None]) -> Callable[[], None]:
        def run() -> None:
            try:
                work()
            except BaseException as exc:
                errors.append(exc)
        return run

    one = threading.Thread(target=guarded(first), name="first")
    one.start()
    assert inside.wait(30)
    two = threading.Thread(target=guarded(second), name="second")
    two.start()
    two.join(1.0)  # it waits for the first to commit (row lock, or SQLite's write lock)
    go_on.set()
    one.join(60)
    two.join(60)
    return errors


def test_the_last_two_tiles_reported_at_once_finish_the_exploration(
    sessions: sessionmaker[Session], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two ingests finish the last two tiles at the same time: whichever commits last must
    see the other's tile done and finish the exploration (on PostgreSQL each statement reads
    what was committed when it started, so the check must come after the row lock)."""
    eid, (first, second) = all_but_two_reported(sessions)
    inside, go_on = threading.Event(), threading.Event()
    hook = scheduler_module.after_batch

    def held_open(session: Session, *args: object) -> None:
        hook(session, *args)  # type: ignore[arg-type]
        if threading.current_thread().name == "first":  # keep its transaction open
            inside.set()
            go_on.wait(30)

    monkeypatch.setattr(scheduler_module, "after_batch", held_open)
    never_quiet(monkeypatch)

    def report(t: LeasedTile) -> None:
        with sessions() as s:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=fake_results(t.poses(), seed=t.tile_id))

    errors = run_overlapped(lambda: report(first), lambda: report(second), inside, go_on)
    assert not errors
    row = exploration_row(sessions, eid)
    assert (row.status, row.poses_done) == ("done", row.poses_total)


def exploration_row(sessions: sessionmaker[Session], eid: int) -> ExplorationRow:
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert row is not None
        return row


def test_a_failure_and_an_ingest_on_the_last_two_tiles_finish_the_exploration(
    sessions: sessionmaker[Session], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A worker's failure report and another worker's results end the last two tiles at the
    same time: the exploration must still finish (failure and requeue take the exploration's
    lock before touching a tile, as ingest does)."""
    eid, (reported, failing) = all_but_two_reported(sessions)
    inside, go_on = threading.Event(), threading.Event()
    hook = scheduler_module.after_batch

    def held_open(session: Session, *args: object) -> None:
        hook(session, *args)  # type: ignore[arg-type]
        inside.set()
        go_on.wait(30)

    monkeypatch.setattr(scheduler_module, "after_batch", held_open)
    never_quiet(monkeypatch)

    def report() -> None:
        with sessions() as s:
            ingest_results(s, tile_id=reported.tile_id, lease_epoch=reported.lease_epoch,
                           worker_id="w", results=fake_results(reported.poses(), seed=1))

    def fail() -> None:
        with sessions() as s:
            fail_tile(s, tile_id=failing.tile_id, lease_epoch=failing.lease_epoch,
                      error="boom", max_attempts=1)

    errors = run_overlapped(report, fail, inside, go_on)
    assert not errors
    # Finished, and not "done": the failed tile's poses are missing.
    assert exploration_row(sessions, eid).status == "incomplete"


def test_threads_ingesting_halves_and_repeats_of_one_exploration_keep_counters_equal_to_rows(
    sessions: sessionmaker[Session],
) -> None:
    """Four threads store every tile of one exploration at once, each tile as two final
    halves and once whole, every thread in its own order: the tile's lock lets exactly one
    batch finish each tile, the counters (updated last, under the exploration's row lock)
    equal the stored rows, and whichever batch ends the last tile finishes the exploration."""
    with sessions() as s:
        eid = make_exploration(s, dtheta=1.2, target=12)
        leased = lease_tiles(s, worker_id="w", n=1000, lease_seconds=600)
        assert len(leased) >= 6 and not lease_tiles(s, worker_id="w", n=1, lease_seconds=600)
    batches = []
    for t in leased:
        results = fake_results(t.poses(), seed=t.tile_id)
        half = len(results) // 2
        batches += [(t, results[:half]), (t, results[half:]), (t, results)]
    moved = ingest_concurrently(sessions, [batches[k::4] + batches[:k:-1] + batches[k::-1]
                                           for k in range(4)])
    assert sorted(moved) == sorted(t.tile_id for t in leased)  # each tile moved exactly once
    with sessions() as s:
        rows = pose_count(s, eid)
        viable = s.scalar(select(func.count()).select_from(PoseRow).where(
            PoseRow.exploration_id == eid, PoseRow.viable.is_(True)))
        undone = s.scalar(select(func.count()).select_from(TileRow).where(
            TileRow.exploration_id == eid, TileRow.state != "done"))
    row = exploration_row(sessions, eid)
    assert rows == sum(len(t.poses()) for t in leased) == row.poses_done == row.poses_total
    assert row.viable_count == viable
    assert undone == 0 and row.status == "done"


def test_a_coordinator_killed_before_the_counter_update_leaves_nothing_and_a_resend_counts_once(
    sessions: sessionmaker[Session], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Killed after the insert and the tile's move, before the counters (the statements that
    run outside the exploration's row lock): its connection goes without a commit, so
    nothing of the batch is left; the worker's resend is stored and counted once."""
    with sessions() as s:
        eid = make_exploration(s)
        (t,) = lease_tiles(s, worker_id="w", n=1, lease_seconds=600)
    results = fake_results(t.poses(), seed=t.tile_id)
    count = ingest_module._count

    def killed(session: Session, *args: object, **kwargs: object) -> object:
        session.connection().invalidate()  # the process is gone: its connection with it
        raise ConnectionError("killed")

    monkeypatch.setattr(ingest_module, "_count", killed)
    with sessions() as s, pytest.raises(ConnectionError):
        ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                       results=results)
    with sessions() as s:
        assert pose_count(s, eid) == 0 and exploration(s, eid).poses_done == 0
        assert s.get(TileRow, t.tile_id).state == "leased"  # type: ignore[union-attr]
    monkeypatch.setattr(ingest_module, "_count", count)
    with sessions() as s:
        report = ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                                worker_id="w", results=results)
        assert report.inserted == len(results) and report.tile_moved
        assert pose_count(s, eid) == exploration(s, eid).poses_done == len(results)


def test_a_quiet_batch_commits_with_its_counters_on_postgresql(
    sessions: sessionmaker[Session],
) -> None:
    """`quiet` (nothing follows in the transaction): PostgreSQL commits in the counter
    update's round trip, so another session sees the rows and counts before the caller's own
    commit; SQLite leaves the commit to the caller. Either way the caller's commit is safe."""
    with sessions() as s:
        eid = make_exploration(s)
        (t,) = lease_tiles(s, worker_id="w", n=1, lease_seconds=600)
    results = fake_results(t.poses(), seed=t.tile_id)
    asked: list[int] = []
    with sessions() as s:
        postgres = s.get_bind().dialect.name == "postgresql"
        stored = ingest_module.store_batch(
            s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w", results=results,
            quiet=lambda exploration_id, _: asked.append(exploration_id) or True)
        assert asked == ([eid] if postgres else []) and stored.committed == postgres
        assert stored.report.inserted == len(results) and stored.report.tile_moved
        with sessions() as other:
            seen = (pose_count(other, eid), exploration(other, eid).poses_done)
        assert seen == ((len(results), len(results)) if postgres else (0, 0))
        s.commit()
    with sessions() as s:
        assert pose_count(s, eid) == exploration(s, eid).poses_done == len(results)
