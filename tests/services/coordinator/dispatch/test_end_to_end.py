"""Real processes on loopback: `graspscape serve` with its embedded zenoh peer, `graspscape
worker` processes with the real simulation on the cheap built-in sphere. Machines die (kill
-9 of a simulation process, kill -9 of the coordinator) and nothing is lost or doubled."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest
from graspscape.services.coordinator.store.models import PoseRow, TileRow
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.support import (
    Coordinator,
    Worker,
    assert_complete,
    free_port,
    status,
    submit,
    wait_for,
)

pytestmark = pytest.mark.slow


@pytest.fixture
def coordinator(sqlite_url: str, tmp_path: Path):
    c = Coordinator(sqlite_url, tmp_path, free_port())
    yield c
    c.stop()


def _finish(sessions: sessionmaker[Session], exploration_id: int, timeout: float,
            *workers: Worker) -> None:
    try:
        wait_for(lambda: status(sessions, exploration_id) == "done", timeout,
                 "the exploration to finish", every=0.25)
    except AssertionError:
        for w in workers:
            print(w.output()[-3000:])
        raise


def test_two_workers_with_two_processes_each_finish(
    any_url: str, any_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    # On both databases: leasing (SKIP LOCKED) and ingest (unnest arrays) differ on PostgreSQL.
    coordinator = Coordinator(any_url, tmp_path, free_port())
    exploration_id = submit(any_sessions, tile_poses=3)
    workers = [Worker(coordinator.endpoint, 2, f"w{i}", tmp_path / "cache") for i in range(2)]
    try:
        _finish(any_sessions, exploration_id, 120, *workers)
    finally:
        codes = [w.stop() for w in workers]
        coordinator.stop()
    assert codes == [0, 0]
    assert_complete(any_sessions, exploration_id)
    with any_sessions() as session:
        owners = set(session.scalars(select(PoseRow.worker_id)))
    # Work was spread over processes of both workers.
    assert {o.split("-")[0] for o in owners} == {"w0", "w1"}


def test_instant_workers_lease_each_tile_once_while_batches_are_in_flight(
    any_url: str, any_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    # A process sends a batch and evaluates its next tile before reading the ack, and asks
    # for more tiles with that batch still in flight: the tile it names as held must stay
    # leased to it (not be handed back as a lost lease reply and leased again).
    coordinator = Coordinator(any_url, tmp_path, free_port())
    exploration_id = submit(any_sessions, dtheta_deg=15.0, tile_poses=6)
    worker = Worker(coordinator.endpoint, 2, "quick", tmp_path / "cache", instant=True,
                    tiles_per_request=3)
    try:
        _finish(any_sessions, exploration_id, 120, worker)
    finally:
        code = worker.stop()
        coordinator.stop()
    assert code == 0
    assert_complete(any_sessions, exploration_id)
    with any_sessions() as session:
        tiles = session.execute(select(TileRow.lease_epoch, TileRow.attempts)).all()
    assert len(tiles) > 20
    assert set(tiles) == {(1, 1)}


def _leased(sessions: sessionmaker[Session]) -> list[tuple[int, str, int]]:
    with sessions() as session:
        return [tuple(r) for r in session.execute(
            select(TileRow.id, TileRow.lease_owner, TileRow.lease_epoch)
            .where(TileRow.state == "leased"))]


def test_kill_9_of_a_worker_process_releases_its_tile_by_liveliness(
    coordinator: Coordinator, sqlite_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    # Lease expiry is the default 300 s: only liveliness can bring the tile back in time.
    exploration_id = submit(sqlite_sessions, tile_poses=6)
    worker = Worker(coordinator.endpoint, 2, "victim", tmp_path / "cache")
    try:
        tile_id, owner, epoch = wait_for(lambda: _leased(sqlite_sessions), 60,
                                         "a leased tile")[0]
        with sqlite_sessions() as session:  # mid-tile: leased, not all poses stored
            stored = session.scalar(select(func.count()).select_from(PoseRow)
                                    .where(PoseRow.tile_id == tile_id))
        assert stored == 0
        pid = int(owner.rsplit("-", 1)[1])  # worker ids end with the process id
        os.kill(pid, signal.SIGKILL)

        def moved_on() -> bool:
            with sqlite_sessions() as session:
                tile = session.get(TileRow, tile_id)
                return tile.lease_owner != owner or tile.lease_epoch > epoch
        wait_for(moved_on, 5, "the killed process's tile to be released")
        # The supervisor starts a new process; the exploration finishes.
        _finish(sqlite_sessions, exploration_id, 120, worker)
    finally:
        assert worker.stop() == 0
    assert_complete(sqlite_sessions, exploration_id)
    with sqlite_sessions() as session:
        tile = session.get(TileRow, tile_id)
        assert tile.attempts >= 2 and "lost" in (tile.last_error or "")


def test_coordinator_restart_mid_exploration(
    sqlite_url: str, sqlite_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    exploration_id = submit(sqlite_sessions, tile_poses=3)
    coordinator = Coordinator(sqlite_url, tmp_path, free_port())
    worker = Worker(coordinator.endpoint, 2, "steady", tmp_path / "cache")
    try:
        def some_done() -> bool:
            with sqlite_sessions() as session:
                return (session.scalar(select(func.count()).select_from(PoseRow)) or 0) >= 3
        wait_for(some_done, 60, "the first results")
        coordinator.kill()  # kill -9: replies in flight are lost, batches not acknowledged
        with sqlite_sessions() as session:
            stored_before = session.scalar(select(func.count()).select_from(PoseRow))
        coordinator.start()  # same database, same zenoh endpoint
        _finish(sqlite_sessions, exploration_id, 120, worker)
    finally:
        code = worker.stop()
        coordinator.stop()
    assert code == 0
    assert_complete(sqlite_sessions, exploration_id)
    with sqlite_sessions() as session:
        assert session.scalar(select(func.count()).select_from(PoseRow)) > stored_before


def test_sigterm_finishes_the_pose_sends_it_and_releases_the_rest(
    coordinator: Coordinator, sqlite_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    # The first tile: 12 poses at a pole, a second or more of work after its first pose.
    submit(sqlite_sessions, tile_poses=12, r_max=0.12)
    worker = Worker(coordinator.endpoint, 1, "leaving", tmp_path / "cache", log_level="debug")
    tile_id, _, _ = wait_for(lambda: _leased(sqlite_sessions), 60, "a leased tile")[0]
    # Into the tile: its first pose is done (the worker logs each pose at debug level).
    wait_for(lambda: f"tile {tile_id}: pose 1 of 12 evaluated" in worker.output(), 60,
             "the first pose of the tile", every=0.02)
    assert worker.stop() == 0
    with sqlite_sessions() as session:
        tile = session.get(TileRow, tile_id)
        stored = session.scalar(select(func.count()).select_from(PoseRow)
                                .where(PoseRow.tile_id == tile_id))
        # Handed back without counting an attempt; the pose in progress was finished and sent.
        assert (tile.state, tile.lease_owner, tile.attempts) == ("queued", None, 0)
        assert 1 <= stored < tile.n_poses == 12
