"""Faults beyond one process, each run end to end and measured: a worker's network link cut
and restored mid-tile (network namespaces), the zenoh router killed and restarted mid-run,
PostgreSQL stopped and started mid-run. Each returns what it measured and the tally of the
stored poses against the plan; the slow tests assert on it, `benchmarks/bench_faults.py`
records it.

Instant workers (`--instant --instant-pose-s`: a sleep per pose, no physics) keep the CPU
free on the shared machine; the faults hit the network, the router and the database, where
physics plays no part.
"""

from __future__ import annotations

import math
import os
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import httpx
from graspscape.services.coordinator import db
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.objects.service import create_named
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec, RefinementSpec
from sqlalchemy import Engine
from sqlalchemy.orm import Session, sessionmaker

from tests.faults.support import (
    Child,
    Tally,
    coordinator_args,
    exploration_status,
    leased_to,
    namespaces,
    pg_cluster,
    router_args,
    stored,
    stored_by,
    stored_in,
    tally,
    wait_for,
    worker_args,
)

# Only the workers' and coordinator's own sessions: the password of the namespace run's
# zenoh login (it listens beyond loopback, so `serve` demands one).
PASSWORD = "faults-" + os.urandom(6).hex()
# Starting the coordinator and the workers (Python imports) took up to ~2 minutes on the
# shared 2-core VM at a load average of 30: the first progress is waited for this long.
STARTUP_S = 400


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def submit(sessions: sessionmaker[Session], dtheta_deg: float, tile_poses: int) -> int:
    with sessions() as session:
        obj, _ = create_named(session, name="sphere", properties={}, shared_dir=None)
        spec = ExplorationSpec(
            object_id=obj.id,
            grid=PoseGridSpec(dtheta=math.radians(dtheta_deg), r_min=0.01, r_max=0.03,
                              dr=0.01),
            refinement=RefinementSpec(levels=0),
        )
        return create_exploration(session, spec=spec, tile_target_poses=tile_poses,
                                  max_poses=5_000_000).id


@dataclass
class _Run:
    """One scenario's exploration, the processes working on it and what it measured."""

    engine: Engine
    sessions: sessionmaker[Session]
    exploration_id: int
    figures: dict[str, Any]
    children: list[Child] = field(default_factory=list)
    result: Tally | None = None

    def report(self) -> dict[str, Any]:
        assert self.result is not None  # set by _scenario's teardown
        return {"figures": self.figures, "tally": asdict(self.result),
                "complete": self.result.complete}


@contextmanager
def _scenario(url: str, dtheta_deg: float, tile_poses: int,
              **figures: Any) -> Iterator[_Run]:
    """Migrates the database and submits the exploration; however the scenario ends, stops
    its processes (the last started first), tallies the stored poses against the plan and
    closes the engine. Enter it inside what the processes need (namespaces, a cluster), so
    they are stopped before that goes."""
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    run = _Run(engine, sessions, submit(sessions, dtheta_deg, tile_poses), dict(figures))
    try:
        yield run
    finally:
        for child in reversed(run.children):
            child.stop(30)
        run.result = tally(sessions, run.exploration_id)
        engine.dispose()


def _finish(sessions: sessionmaker[Session], exploration_id: int, timeout: float,
            children: list[Child]) -> float:
    start = time.monotonic()
    try:
        wait_for(lambda: exploration_status(sessions, exploration_id) not in
                 ("queued", "running"), timeout, "the exploration to finish", every=0.25)
    except AssertionError:
        for child in children:
            print(f"--- {child.log_path.name}\n{child.output()[-4000:]}")
        raise
    return time.monotonic() - start


def _progress(sessions: sessionmaker[Session], exploration_id: int, base: int, since: float,
              timeout: float, prefix: str = "") -> float:
    """Seconds from `since` until more than `base` poses (of workers `prefix`) are stored."""
    wait_for(lambda: stored_by(sessions, exploration_id, prefix) > base, timeout,
             f"progress of {prefix or 'any worker'}", every=0.05)
    return time.monotonic() - since


def link_cut(work: Path, cut_s: float, *, dtheta_deg: float = 20.0, tile_poses: int = 12,
             pose_s: float = 0.2) -> dict[str, Any]:
    """The coordinator in a namespace of its own, two workers in one each, a veth pair per
    worker. Worker 0's link is cut while it holds a tile none of whose poses is stored yet
    (mid-tile), for `cut_s`, then restored. zenoh's transport lease is 10 s: a shorter cut
    is ridden out by the open transport, a longer one closes it (the coordinator sees the
    worker's liveliness token go, re-queues its tile, worker 1 takes it)."""
    url = f"sqlite:///{work / 'coordinator.db'}"
    with namespaces(2) as ns, _scenario(url, dtheta_deg, tile_poses, cut_s=cut_s) as run:
        sessions, exploration_id, figures = run.sessions, run.exploration_id, run.figures
        port = free_port()
        env = {"GRASPSCAPE_ZENOH__PASSWORD": PASSWORD}
        run.children.append(Child(ns.exec(ns.coordinator, coordinator_args(
            url, 8000, listen=[f"tcp/0.0.0.0:{port}"])), work / "coordinator.log", env))
        for i, link in enumerate(ns.links):
            run.children.append(Child(ns.exec(link.namespace, worker_args(
                f"tcp/{link.coordinator_ip}:{port}", f"w{i}", work / "cache",
                pose_s=pose_s)), work / f"worker{i}.log", env))
        # Worker 0 at work: one tile of its stored, then a tile of its none of whose poses is
        # stored yet.
        wait_for(lambda: stored_by(sessions, exploration_id, "w0-") > 0, STARTUP_S,
                 "worker 0's first tile")

        def fresh_tile() -> list:
            return [t for t in leased_to(sessions, "w0-") if stored_in(sessions, t[0]) == 0]
        tile_id = wait_for(fresh_tile, 60, "a fresh tile of worker 0", every=0.02)[0][0]
        ns.cut(0)
        cut_at = time.monotonic()
        figures["cut_tile"] = tile_id
        released_after = None
        while time.monotonic() - cut_at < cut_s:
            if released_after is None and not [
                    t for t in leased_to(sessions, "w0-") if t[0] == tile_id]:
                released_after = time.monotonic() - cut_at
            time.sleep(0.1)
        # Whether the coordinator gave the cut worker's tile up during the cut, and when.
        figures["tile_released_after_s"] = (None if released_after is None
                                            else round(released_after, 3))
        base = stored_by(sessions, exploration_id, "w0-")
        others_during = stored_by(sessions, exploration_id, "w1-")
        ns.restore(0)
        restored_at = time.monotonic()
        figures["cut_worker_progress_after_restore_s"] = round(_progress(
            sessions, exploration_id, base, restored_at, 120, "w0-"), 3)
        figures["other_worker_poses_stored_by_restore"] = others_during
        _finish(sessions, exploration_id, 300, run.children)
        figures["finish_after_restore_s"] = round(time.monotonic() - restored_at, 3)
        figures["refused_stale_batches"] = run.children[1].output().count("the lease is gone")
    return run.report()


def router_restart(work: Path, down_s: float, *, dtheta_deg: float = 30.0,
                   tile_poses: int = 12, pose_s: float = 0.05) -> dict[str, Any]:
    """The deployment of docker-compose.yml: a zenoh router, the coordinator a client of it,
    two workers clients of it. The router is killed (-9) mid-run and started again on the same
    port after `down_s`."""
    url = f"sqlite:///{work / 'coordinator.db'}"
    router_endpoint = f"tcp/127.0.0.1:{free_port()}"
    with _scenario(url, dtheta_deg, tile_poses, down_s=down_s) as run:
        sessions, exploration_id, figures = run.sessions, run.exploration_id, run.figures
        router = Child(router_args(router_endpoint), work / "router.log")
        run.children.append(router)
        run.children.append(Child(coordinator_args(url, free_port(), mode="client",
                                                   connect=[router_endpoint]),
                                  work / "coordinator.log"))
        for i in range(2):
            run.children.append(Child(worker_args(router_endpoint, f"w{i}", work / "cache",
                                                  pose_s=pose_s), work / f"worker{i}.log"))
        total = tally(sessions, exploration_id).planned
        wait_for(lambda: stored(sessions, exploration_id) >= total // 4, STARTUP_S,
                 "a quarter of the poses")
        router.kill()
        killed_at = time.monotonic()
        time.sleep(down_s)
        figures["stored_at_kill"] = stored(sessions, exploration_id)
        base = stored(sessions, exploration_id)
        router.start()
        restarted_at = time.monotonic()
        figures["progress_after_restart_s"] = round(_progress(
            sessions, exploration_id, base, restarted_at, 180), 3)
        _finish(sessions, exploration_id, 300, run.children)
        figures["finish_after_restart_s"] = round(time.monotonic() - restarted_at, 3)
        figures["outage_s"] = round(restarted_at - killed_at, 3)
    return run.report()


def postgres_restart(work: Path, down_s: float, *, dtheta_deg: float = 30.0,
                     tile_poses: int = 12, pose_s: float = 0.05) -> dict[str, Any]:
    """The coordinator on a PostgreSQL cluster of this run's own (another port; the shared
    server is never touched), two workers on loopback. The cluster is stopped (`pg_ctl -m
    fast`: every connection closed) mid-run and started again after `down_s`."""
    with (pg_cluster(free_port()) as cluster,
          _scenario(cluster.url, dtheta_deg, tile_poses, down_s=down_s) as run):
        sessions, exploration_id, figures = run.sessions, run.exploration_id, run.figures
        api = free_port()
        zenoh_endpoint = f"tcp/127.0.0.1:{free_port()}"
        run.children.append(Child(coordinator_args(cluster.url, api, listen=[zenoh_endpoint]),
                                  work / "coordinator.log"))
        for i in range(2):
            run.children.append(Child(worker_args(zenoh_endpoint, f"w{i}", work / "cache",
                                                  pose_s=pose_s), work / f"worker{i}.log"))
        total = tally(sessions, exploration_id).planned
        wait_for(lambda: stored(sessions, exploration_id) >= total // 4, STARTUP_S,
                 "a quarter of the poses")
        base = stored(sessions, exploration_id)
        run.engine.dispose()
        cluster.stop("fast")
        stopped_at = time.monotonic()
        figures["healthz_while_down"] = _healthz(api)
        time.sleep(down_s)
        cluster.start()
        started_at = time.monotonic()
        figures["outage_s"] = round(started_at - stopped_at, 3)
        wait_for(lambda: _healthz(api) == 200, 60, "the coordinator's /healthz")
        figures["healthz_ok_after_start_s"] = round(time.monotonic() - started_at, 3)
        figures["progress_after_start_s"] = round(_progress(
            sessions, exploration_id, base, started_at, 180), 3)
        _finish(sessions, exploration_id, 300, run.children)
        figures["finish_after_start_s"] = round(time.monotonic() - started_at, 3)
        figures["coordinator_alive"] = run.children[0].alive()
    return run.report()


def _healthz(port: int) -> int | None:
    try:
        return httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=2).status_code
    except httpx.HTTPError:
        return None
