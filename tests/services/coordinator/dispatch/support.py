"""Real processes for the dispatch tests: `graspscape serve` with its zenoh peer on a free
loopback port, `graspscape worker` processes, and store helpers to set up and check."""

from __future__ import annotations

import math
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import httpx
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.objects.service import create_named
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    PoseRow,
    TileRow,
)
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec, RefinementSpec
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

REPO = Path(__file__).resolve().parents[4]
# The session key of the made-up workers of these tests (a real process makes a random one).
SESSION_KEY = "5e55" * 8


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(check: Callable[[], object], timeout: float, what: str, every: float = 0.1):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(every)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


class Coordinator:
    """`graspscape serve` (REST + zenoh dispatch) as a child process."""

    def __init__(self, db_url: str, data_dir: Path, zenoh_port: int, **env: str) -> None:
        self.db_url, self.data_dir, self.zenoh_port = db_url, data_dir, zenoh_port
        self.endpoint = f"tcp/127.0.0.1:{zenoh_port}"
        self.extra_env = env
        self.process: subprocess.Popen | None = None
        self.start()

    def start(self) -> None:
        self.port = free_port()
        env = {**os.environ, "GRASPSCAPE_DATABASE__DATA_DIR": str(self.data_dir),
               **self.extra_env}
        env.pop("GRASPSCAPE_API__TOKEN", None)
        self.log = open(self.data_dir / f"coordinator-{self.port}.log", "wb")  # noqa: SIM115
        self.process = subprocess.Popen(
            [sys.executable, "-m", "graspscape.services.local.cli", "serve", "--database-url",
             self.db_url, "--port", str(self.port), "--no-migrate", "--log-level", "warning",
             "--zenoh-listen", self.endpoint],
            cwd=REPO, env=env, stdout=self.log, stderr=subprocess.STDOUT,
        )
        base = f"http://127.0.0.1:{self.port}"

        def healthy() -> bool:
            assert self.process is not None and self.process.poll() is None, self.output()
            try:
                return httpx.get(f"{base}/healthz", timeout=1).status_code == 200
            except httpx.HTTPError:
                return False

        wait_for(healthy, 30, "the coordinator to become healthy")

    def output(self) -> str:
        return (self.data_dir / f"coordinator-{self.port}.log").read_text(errors="replace")

    def kill(self) -> None:
        assert self.process is not None
        self.process.kill()
        self.process.wait(10)
        self.log.close()

    def stop(self) -> None:
        if self.process is None or self.process.poll() is not None:
            return
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(15)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(5)
        self.log.close()


class Worker:
    """`graspscape worker` (a supervisor with N simulation processes) as a child process."""

    def __init__(self, endpoint: str, procs: int, name: str, cache_dir: Path,
                 instant: bool = False, tiles_per_request: int = 1,
                 log_level: str = "info", pose_s: float = 0.0, cwd: Path = REPO,
                 env: dict[str, str] | None = None) -> None:
        self.log_path = cache_dir.parent / f"worker-{name}.log"
        self.log = open(self.log_path, "wb")  # noqa: SIM115
        args = [sys.executable, "-m", "graspscape.services.local.cli", "worker", "--connect",
                endpoint,
                "--procs", str(procs), "--name", name, "--cache-dir", str(cache_dir),
                "--log-level", log_level]
        if instant:
            args.append("--instant")
        if pose_s:
            args += ["--instant-pose-s", str(pose_s)]
        if tiles_per_request != 1:
            args += ["--tiles-per-request", str(tiles_per_request)]
        self.process = subprocess.Popen(args, cwd=cwd, stdout=self.log,
                                        stderr=subprocess.STDOUT,
                                        env=None if env is None else {**os.environ, **env})

    def output(self) -> str:
        return self.log_path.read_text(errors="replace")

    def stop(self, timeout: float = 60) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            code = self.process.wait(5)
        self.log.close()
        return code


def submit(sessions: sessionmaker[Session], *, dtheta_deg: float = 90.0,
           tile_poses: int = 3, object_name: str = "sphere", r_max: float = 0.03) -> int:
    """A tiny exploration of the cheap built-in sphere; returns its id."""
    with sessions() as session:
        obj, _ = create_named(session, name=object_name, properties={}, shared_dir=None)
        spec = ExplorationSpec(
            object_id=obj.id,
            grid=PoseGridSpec(dtheta=math.radians(dtheta_deg), r_min=0.01, r_max=r_max, dr=0.01),
            refinement=RefinementSpec(levels=0),
        )
        return create_exploration(session, spec=spec, tile_target_poses=tile_poses,
                                  max_poses=100_000).id


def status(sessions: sessionmaker[Session], exploration_id: int) -> str:
    with sessions() as session:
        return session.scalar(
            select(ExplorationRow.status).where(ExplorationRow.id == exploration_id))


def assert_complete(sessions: sessionmaker[Session], exploration_id: int) -> None:
    """Every pose key of every tile stored exactly once, and the counters agree."""
    with sessions() as session:
        row = session.get(ExplorationRow, exploration_id)
        assert row is not None and row.status == "done", row and row.status
        expected: set[str] = set()
        for cells, r_levels, attitudes in session.execute(
            select(TileRow.cells, TileRow.r_levels, TileRow.attitudes)
            .where(TileRow.exploration_id == exploration_id)
        ):
            from graspscape.shared.specs.pose import tile_poses

            expected |= {p.key() for p in tile_poses(cells, r_levels, attitudes)}
        counts = dict(session.execute(
            select(PoseRow.pose_key, func.count())
            .where(PoseRow.exploration_id == exploration_id)
            .group_by(PoseRow.pose_key)
        ).all())
        assert set(counts) == expected
        assert set(counts.values()) == {1}
        assert row.poses_done == row.poses_total == len(expected)
        states = set(session.scalars(
            select(TileRow.state).where(TileRow.exploration_id == exploration_id)))
        assert states == {"done"}
