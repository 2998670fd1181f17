"""A non-finite number in one pose of a real worker loop, end to end: `graspscape serve`
(SQLite) with a short lease and one worker process (tests/faults/nan_worker.py) that returns
a NaN effort for one pose. Sampled every `every_s` until the exploration ends: its status,
poses stored, tiles failed; then the leases per tile (each lease bumps the tile's epoch), the
stored outcome of the poisoned pose and the coordinator's log lines per refused batch.

With the worker's check the pose is stored as `error` and the exploration ends `done`;
without it (`checked=False`, a worker of before the check) the coordinator refuses the batch,
counts each refusal as an attempt and fails the tile at max_attempts: `incomplete`.
A second exploration queued behind the first must be leased and finish as well.
`tests/faults/test_nan_result.py` asserts on it, `benchmarks/bench_nan_result.py` records it.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from graspscape.services.coordinator import db
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow, TileRow
from sqlalchemy import func, select

from tests.faults.scenarios import free_port, submit
from tests.faults.support import PYTHON, Child, coordinator_args, tally, wait_for

LEASE_S = 20.0
MAX_ATTEMPTS = 3


def _sample(sessions: Any, exploration_id: int, started: float) -> dict[str, Any]:
    with sessions() as session:
        row = session.get(ExplorationRow, exploration_id)
        failed = session.scalar(select(func.count()).select_from(TileRow).where(
            TileRow.exploration_id == exploration_id, TileRow.state == "failed")) or 0
        return {"t_s": round(time.monotonic() - started, 1), "status": row.status,
                "poses_done": row.poses_done, "poses_total": row.poses_total,
                "tiles_failed": failed}


def nan_run(work: Path, *, checked: bool = True, every_s: float = 1.0, pose_s: float = 0.15,
            timeout_s: float = 400) -> dict[str, Any]:
    url = f"sqlite:///{work / 'coordinator.db'}"
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    exploration_id = submit(sessions, 60.0, 3)
    second_id = submit(sessions, 60.0, 3)  # queued behind it: must be leased and finish too
    with sessions() as session:  # the poisoned pose: the first of the exploration's 3rd tile
        cells, r_levels, attitudes = session.execute(
            select(TileRow.cells, TileRow.r_levels, TileRow.attitudes)
            .where(TileRow.exploration_id == exploration_id).order_by(TileRow.id)
            .offset(2).limit(1)).one()
    from graspscape.shared.specs.pose import tile_poses

    poisoned = tile_poses(cells, r_levels, attitudes)[0].key()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    env = {"GRASPSCAPE_QUEUE__LEASE_SECONDS": str(LEASE_S),
           "GRASPSCAPE_QUEUE__MAX_ATTEMPTS": str(MAX_ATTEMPTS)}
    coordinator = Child(coordinator_args(url, free_port(), listen=[endpoint]),
                        work / "coordinator.log", env)
    worker = Child([PYTHON, "-m", "tests.faults.nan_worker", endpoint, "nan", str(work / "cache"),
                    str(pose_s), f"{exploration_id}:{poisoned}",
                    *([] if checked else ["--unchecked"])],
                   work / "worker.log")
    timeline: list[dict[str, Any]] = []
    try:
        def leased() -> bool:
            with sessions() as session:
                return bool(session.scalar(select(ExplorationRow.started_at)
                                           .where(ExplorationRow.id == exploration_id)))
        wait_for(leased, 300, "the first lease")
        started = time.monotonic()
        while True:
            timeline.append(_sample(sessions, exploration_id, started))
            timeline[-1]["second"] = _sample(sessions, second_id, started)["status"]
            if {timeline[-1]["status"], timeline[-1]["second"]}.isdisjoint(
                    ("queued", "running")):
                break
            assert time.monotonic() - started < timeout_s, timeline[-1]
            time.sleep(every_s)
        ended_s = next(s["t_s"] for s in timeline if s["status"] not in ("queued", "running"))
        with sessions() as session:
            leases = dict(session.execute(
                select(TileRow.index, TileRow.lease_epoch)
                .where(TileRow.exploration_id == exploration_id).order_by(TileRow.index)).all())
            pose = session.execute(select(PoseRow.outcome, PoseRow.error, PoseRow.effort_max_nm)
                                   .where(PoseRow.exploration_id == exploration_id,
                                          PoseRow.pose_key == poisoned)).one_or_none()
            failed = list(session.scalars(select(TileRow.last_error).where(
                TileRow.exploration_id == exploration_id, TileRow.state == "failed")))
        result_tally = tally(sessions, exploration_id)
        second = tally(sessions, second_id)
    finally:
        worker.stop(30)
        coordinator.stop(30)
        engine.dispose()
    log = coordinator.output()
    refused = [line for line in log.splitlines() if "results query refused" in line]
    return {
        "checked": checked, "lease_s": LEASE_S, "max_attempts": MAX_ATTEMPTS,
        "ended_s": round(ended_s, 1), "status": timeline[-1]["status"], "timeline": timeline,
        "leases_per_tile": leases, "poisoned_pose": poisoned,
        "poisoned_outcome": None if pose is None else {"outcome": pose[0], "error": pose[1],
                                                       "effort_max_nm": pose[2]},
        "failed_tiles_reasons": failed, "tally": result_tally.__dict__,
        "second_exploration": second.__dict__, "second_complete": second.complete,
        "refused_batches_in_log": len(refused),
        "coordinator_log_lines": len([line for line in log.splitlines() if line.strip()]),
        "coordinator_tracebacks": log.count("Traceback"),
        "refused_lines": refused,
        "worker_dropped_batches": worker.output().count("refused for good"),
    }
