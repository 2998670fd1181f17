"""Real processes on loopback: an exploration submitted over REST with a gripper of one's own
(a file only the coordinator's machine has) completes with a worker that cannot find it: the
worker is started in another folder, with an empty GRASPSCAPE_GRIPPER_PATH and its own cache,
and fetches the gripper's archive from the coordinator."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow
from graspscape.shared.specs.gripper import GRIPPER_PATH_ENV
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.dispatch.support import (
    Coordinator,
    Worker,
    assert_complete,
    free_port,
    status,
    wait_for,
)
from tests.services.coordinator.dispatch.test_gripper_shipping import own_gripper

pytestmark = pytest.mark.slow


def test_a_rest_exploration_with_its_own_gripper_completes_on_a_worker_without_it(
    sqlite_url: str, sqlite_sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    coordinator = Coordinator(sqlite_url, tmp_path, free_port())
    gripper = own_gripper(tmp_path / "coordinator-side")
    elsewhere = tmp_path / "worker-machine"
    elsewhere.mkdir()
    worker = None
    try:
        api = f"http://127.0.0.1:{coordinator.port}"
        obj = httpx.post(f"{api}/objects", data={"name": "sphere"}, timeout=30)
        assert obj.status_code == 201, obj.text
        run = httpx.post(f"{api}/explorations", timeout=30, json={
            "object_id": obj.json()["id"], "gripper": str(gripper),
            "grid": {"dtheta": 1.5707963, "r_min": 0.01, "r_max": 0.02, "dr": 0.01},
            "refinement": {"levels": 0}})
        assert run.status_code == 201, run.text
        exploration_id = run.json()["id"]
        worker = Worker(coordinator.endpoint, 1, "far", elsewhere / "cache", cwd=elsewhere,
                        env={GRIPPER_PATH_ENV: ""})
        try:
            wait_for(lambda: status(sqlite_sessions, exploration_id) == "done", 180,
                     "the exploration to finish", every=0.25)
        except AssertionError:
            print(worker.output()[-3000:])
            raise
    finally:
        code = worker.stop() if worker is not None else 0
        coordinator.stop()
    assert code == 0
    assert_complete(sqlite_sessions, exploration_id)
    with sqlite_sessions() as session:
        stored = session.get(ExplorationRow, exploration_id).gripper_hash
        errors = session.scalar(select(func.count()).select_from(PoseRow).where(
            PoseRow.exploration_id == exploration_id, PoseRow.error.is_not(None)))
    assert errors == 0
    unpacked = elsewhere / "cache" / "grippers" / stored / "spec.toml"
    assert unpacked.read_text() == gripper.read_text()
