"""The soak: one long exploration of many small tiles through `graspscape serve` and an
`--instant` worker whose simulation processes are killed -9 one after another, with the
memory of every process sampled all along. Used by `benchmarks/bench_soak.py` (20,000 tiles)
and the slow test (a few hundred).

"Every few simulated minutes": a kill every `kill_every_tiles` tiles stored, which stands for
the time those tiles would take with physics (`simulated_minutes`: tile poses / 3.7 pose
evaluations per second per core, eval_pose.json's rate on this VM, over the processes).

Process 0 of the worker is never killed, so its memory over the whole run tells whether a
worker process leaks; the others are killed in turn and come back under new ids. Leaks are
read from outside: RSS (first vs last quartile of the samples), open file descriptors and
threads of the coordinator, and its established zenoh connections at the end (one per live
worker process: a killed process's session must not linger).
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from graspscape.services.coordinator import db
from graspscape.services.coordinator.exploration.tiling import coarse_tiles
from graspscape.services.coordinator.store.models import ExplorationRow, TileRow
from graspscape.shared.specs.exploration import PoseGridSpec
from sqlalchemy import func, select

from tests.faults.scenarios import free_port, submit
from tests.faults.support import (
    REPO,
    Child,
    children_of,
    coordinator_args,
    fd_kinds,
    in_use,
    open_fds,
    rss_mb,
    tally,
    threads,
    wait_for,
    worker_args,
    zenoh_shm_segments,
)

EVALS_PER_S_PER_CORE = 3.7  # eval_pose.json, this VM: what a tile would take with physics
TILE_POSES = 3  # one cell × three r levels: the smallest tile, the most tiles per pose
GROWTH_LIMIT = 1.10  # "flat": the last quartile's mean RSS within 10 % of the first's
# Samples before this share of the tiles is stored are start-up (imports, caches, the first
# SQLite pages), not growth: left out of the quartiles.
WARMUP_SHARE = 0.1


def dtheta_for(tiles: int) -> float:
    """The grid step (degrees) whose coarse pass has about `tiles` tiles of TILE_POSES."""
    dtheta = math.degrees(math.sqrt(4 * math.pi / tiles))
    for _ in range(4):
        grid = PoseGridSpec(dtheta=math.radians(dtheta), r_min=0.01, r_max=0.03, dr=0.01)
        n = len(coarse_tiles(grid, target_poses=TILE_POSES))
        dtheta *= math.sqrt(n / tiles)
    return dtheta


def _quartiles(samples: list[float]) -> dict[str, float]:
    q = max(1, len(samples) // 4)
    first, last = statistics.fmean(samples[:q]), statistics.fmean(samples[-q:])
    return {"first_quartile_mb": round(first, 1), "last_quartile_mb": round(last, 1),
            "growth_ratio": round(last / first, 3), "max_mb": round(max(samples), 1),
            "flat": last <= first * GROWTH_LIMIT}


def _established(port: int) -> int:
    out = subprocess.run(["ss", "-Htn", "state", "established", f"( sport = :{port} )"],
                         capture_output=True, text=True).stdout
    return len([line for line in out.splitlines() if line.strip()])


def _process_ids(log: str) -> dict[int, int]:
    """Index → pid of the worker's live-or-last processes, from its 'connected' lines."""
    return {int(i): int(pid) for i, pid in re.findall(r"-p(\d+)-(\d+) connected", log)}


def soak(work: Path, *, tiles: int, procs: int = 3, kill_every_tiles: int | None = None,
         simulated_minutes: float = 3.0, sample_every_s: float = 1.0,
         timeout_s: float = 3600, pose_s: float = 0.0) -> dict[str, Any]:
    url = f"sqlite:///{work / 'coordinator.db'}"
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    dtheta = dtheta_for(tiles)
    exploration_id = submit(sessions, dtheta, TILE_POSES)
    with sessions() as session:
        tiles_total = session.get(ExplorationRow, exploration_id).tiles_total
    sim_tile_s = TILE_POSES / EVALS_PER_S_PER_CORE / procs  # physics time per tile, all procs
    if kill_every_tiles is None:
        kill_every_tiles = max(1, round(simulated_minutes * 60 / sim_tile_s))
    shm_before = set(zenoh_shm_segments())
    zenoh_port = free_port()
    endpoint = f"tcp/127.0.0.1:{zenoh_port}"
    coordinator = Child(coordinator_args(url, free_port(), listen=[endpoint]),
                        work / "coordinator.log")
    worker = Child(worker_args(endpoint, "soak", work / "cache", procs=procs, pose_s=pose_s),
                   work / "worker.log")
    samples: dict[str, list[float]] = {"coordinator": [], "supervisor": [], "process_0": []}
    fds: list[int] = []
    thread_counts: list[int] = []
    kills: list[dict[str, Any]] = []
    loop_s: list[float] = []
    next_kill, victim = kill_every_tiles, 1
    try:
        wait_for(lambda: 0 in _process_ids(worker.output()), 400, "the worker's processes")
        started = time.monotonic()  # the processes are up: the time of the tiles alone
        while True:
            loop_at = time.monotonic()
            with sessions() as session:
                done = session.scalar(select(func.count()).select_from(TileRow).where(
                    TileRow.exploration_id == exploration_id,
                    TileRow.state.in_(("done", "failed")))) or 0
            if done >= WARMUP_SHARE * tiles_total:
                for name, pid in (("coordinator", coordinator.pid),
                                  ("supervisor", worker.pid),
                                  ("process_0", _process_ids(worker.output()).get(0))):
                    value = rss_mb(pid) if pid else None
                    if value is not None:
                        samples[name].append(value)
                if not fds:
                    fd_kinds_first = fd_kinds(coordinator.pid)
                fds.append(open_fds(coordinator.pid) or 0)
                thread_counts.append(threads(coordinator.pid) or 0)
            if done >= tiles_total:
                break
            if done >= next_kill and procs > 1:
                # The next live process in turn (never process 0); one killed earlier may not
                # be back yet, and then the kill waits for a live one rather than lapsing.
                ids, live = _process_ids(worker.output()), set(children_of(worker.pid))
                for _ in range(procs - 1):
                    pid = ids.get(victim)
                    if pid is not None and pid in live:
                        os.kill(pid, signal.SIGKILL)
                        kills.append({"tiles_done": done, "process": victim,
                                      "at_s": round(time.monotonic() - started, 1)})
                        next_kill += kill_every_tiles
                        victim = victim % (procs - 1) + 1
                        break
                    victim = victim % (procs - 1) + 1
            assert coordinator.alive(), coordinator.output()[-3000:]
            if time.monotonic() - started > timeout_s:
                raise AssertionError(f"soak not finished after {timeout_s} s: {done} of "
                                     f"{tiles_total} tiles")
            loop_s.append(time.monotonic() - loop_at)
            time.sleep(sample_every_s)
        elapsed = time.monotonic() - started
        # The last kill's replacement: the supervisor polls every 0.5 s, and on a loaded
        # 2-core machine its log line and the new connection can take seconds to appear.
        deadline = time.monotonic() + 30
        while (worker.output().count("starting it again") < len(kills)
               and time.monotonic() < deadline):
            time.sleep(0.2)
        # Then each live process's zenoh session, established (a replacement's can follow its
        # log line by seconds under load) and the killed ones' closed: waited for, not slept
        # on. A session that stays open past the deadline is what the caller's check catches.
        deadline = time.monotonic() + 30
        while True:
            live = len([pid for pid in children_of(worker.pid) if "resource_tracker" not in
                        Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")])
            connections = _established(zenoh_port)
            if connections == live or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        fd_kinds_last = fd_kinds(coordinator.pid)
        with sessions() as session:
            status = session.get(ExplorationRow, exploration_id).status
        result_tally = tally(sessions, exploration_id)
    finally:
        worker.stop(60)
        coordinator.stop(30)
        engine.dispose()
    # zenoh's shared-memory segments made during the run that no process holds any more
    # (a killed process cannot remove its own; in soak_isolated, /dev/shm is this run's).
    left = {path: size for path, size in zenoh_shm_segments().items()
            if path not in shm_before and not in_use(path)}
    return {
        "zenoh_shm_segments_left": len(left),
        "zenoh_shm_bytes_left": sum(left.values()),
        "tiles": tiles_total,
        "poses": result_tally.planned,
        "status": status,
        "complete": result_tally.complete,
        "tally": result_tally.__dict__,
        "elapsed_s": round(elapsed, 1),
        "tiles_per_s": round(tiles_total / elapsed, 1),
        "procs": procs,
        "pose_s": pose_s,
        "kill_every_tiles": kill_every_tiles,
        "kill_every_simulated_min": round(kill_every_tiles * sim_tile_s / 60, 2),
        "simulated_hours": round(tiles_total * sim_tile_s / 3600, 2),
        "kills": len(kills),
        "kill_log": kills,
        "rss": {name: _quartiles(values) for name, values in samples.items() if values},
        "samples_after_warmup": len(fds),
        "sample_loop_s_max": round(max(loop_s, default=0.0), 2),
        "coordinator_fds_first_last": [fds[0], fds[-1]],
        "coordinator_fd_kinds_first_last": [fd_kinds_first, fd_kinds_last],
        "coordinator_fds_max": max(fds),
        "coordinator_threads_first_last": [thread_counts[0], thread_counts[-1]],
        "worker_processes_alive_at_end": live,
        "coordinator_zenoh_connections_at_end": connections,
        "worker_restarts_logged": worker.output().count("starting it again"),
    }


def soak_isolated(work: Path, **options: Any) -> dict[str, Any]:
    """`soak` in a mount namespace of its own with a private /dev/shm (tmpfs), so the zenoh
    shared-memory segments counted at the end are this run's alone (other suites on the
    machine open and kill zenoh sessions of their own). The segments are read before the
    namespace goes."""
    out = work / "soak.json"
    args = [sys.executable, "-m", "tests.faults.soak", str(work), str(out),
            json.dumps(options)]
    script = 'mount -t tmpfs -o size=2g gs-soak-shm /dev/shm && exec "$@"'
    done = subprocess.run(["unshare", "--mount", "--propagation", "private", "--", "sh",
                           "-c", script, "sh", *args], cwd=REPO)
    if done.returncode != 0:
        raise AssertionError(f"the soak exited with {done.returncode}")
    return json.loads(out.read_text())


if __name__ == "__main__":
    result = soak(Path(sys.argv[1]), **json.loads(sys.argv[3]))
    Path(sys.argv[2]).write_text(json.dumps(result, indent=1))
