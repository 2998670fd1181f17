"""Chaos in one exploration: the coordinator (`graspscape serve`) and the workers
(`graspscape worker --instant`: the real worker loop, paced evaluations, no physics) killed
-9 in turn, several times each, while the exploration runs; each comes back (the coordinator
on the same database and zenoh endpoint, a simulation process by its supervisor, a killed
supervisor started again). Used by test_chaos.py on SQLite and PostgreSQL.

Kills are spread over the run: the next one once `every_poses` more poses are stored than at
the last, in the order of `plan` ("coordinator", "process": one simulation process,
"worker": the whole supervisor, whose processes stop with it).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path
from typing import Any

from graspscape.services.coordinator.store.models import ExplorationRow
from sqlalchemy.orm import Session, sessionmaker

from tests.faults.support import children_of, tally
from tests.services.coordinator.dispatch.support import Coordinator, Worker, free_port, submit

PLAN = ("coordinator", "process", "worker", "coordinator", "process", "worker",
        "coordinator", "process")


def _progress(sessions: sessionmaker[Session], exploration_id: int) -> tuple[str, int]:
    with sessions() as session:
        row = session.get(ExplorationRow, exploration_id)
        return row.status, row.poses_done


def _simulation_processes(worker: Worker) -> list[int]:
    return [pid for pid in children_of(worker.process.pid)
            if b"resource_tracker" not in Path(f"/proc/{pid}/cmdline").read_bytes()]


def chaos(db_url: str, sessions: sessionmaker[Session], work: Path, *,
          plan: tuple[str, ...] = PLAN, every_poses: int = 30, procs: int = 2,
          timeout_s: float = 500) -> dict[str, Any]:
    exploration_id = submit(sessions, dtheta_deg=20.0, tile_poses=3)
    # A tile killed with its process three times must not fail the run: the cap is not
    # what is tested here.
    coordinator = Coordinator(db_url, work, free_port(), GRASPSCAPE_QUEUE__MAX_ATTEMPTS="20",
                              GRASPSCAPE_ZENOH__ORPHAN_GRACE_S="3")
    cache = work / "cache"
    workers = [Worker(coordinator.endpoint, procs, "chaos0", cache, instant=True,
                      pose_s=0.1)]
    kills: list[dict[str, Any]] = []
    started = time.monotonic()
    next_at = every_poses
    try:
        while True:
            status, done = _progress(sessions, exploration_id)
            if status not in ("queued", "running"):
                break
            assert time.monotonic() - started < timeout_s, (status, done, kills)
            if len(kills) < len(plan) and done >= next_at:
                what = plan[len(kills)]
                worker = workers[-1]
                if what == "coordinator":
                    coordinator.kill()
                    coordinator.start()  # same database, same zenoh endpoint
                elif what == "process":
                    pids = _simulation_processes(worker)
                    if not pids:  # none up yet: try again on the next round
                        time.sleep(0.2)
                        continue
                    os.kill(pids[0], signal.SIGKILL)
                else:
                    worker.process.kill()
                    worker.process.wait(10)
                    worker.log.close()
                    workers.append(Worker(coordinator.endpoint, procs,
                                          f"chaos{len(workers)}", cache, instant=True,
                                          pose_s=0.1))
                kills.append({"what": what, "poses_done": done,
                              "at_s": round(time.monotonic() - started, 1)})
                next_at = done + every_poses
            time.sleep(0.2)
        elapsed = time.monotonic() - started
    finally:
        codes = [w.stop(60) for w in workers[-1:]]
        coordinator.stop()
    result_tally = tally(sessions, exploration_id)
    return {"status": status, "elapsed_s": round(elapsed, 1), "kills": kills,
            "tally": result_tally.__dict__, "complete": result_tally.complete,
            "last_worker_exit": codes[0]}

