"""A restart of the real coordinator process (`graspscape serve`) keeps every exploration and
puts the tiles whose leases ran out while it was down back in the queue; live leases stay."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from datetime import timedelta
from pathlib import Path

import httpx
import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.queue import lease_tiles
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import fake_results

REPO = Path(__file__).resolve().parents[3]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Coordinator:
    """`graspscape serve` as a child process on a given database."""

    def __init__(self, db_url: str, data_dir: Path) -> None:
        self.port = _free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        env = {**os.environ, "GRASPSCAPE_DATABASE__DATA_DIR": str(data_dir)}
        env.pop("GRASPSCAPE_API__TOKEN", None)
        self.process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "graspscape.services.local.cli",
                "serve",
                "--database-url",
                db_url,
                "--port",
                str(self.port),
                "--no-migrate",
                "--log-level",
                "warning",
            ],
            cwd=REPO,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
        )
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                out = self.process.stdout.read().decode() if self.process.stdout else ""
                raise RuntimeError(f"coordinator exited early:\n{out}")
            try:
                if httpx.get(f"{self.base}/healthz", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.1)
        self.stop()
        raise RuntimeError("coordinator did not become healthy in 30 s")

    def stop(self) -> None:
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(15)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(5)


@pytest.mark.slow
@pytest.mark.timeout(90)
def test_restart_keeps_explorations_and_requeues_expired_leases(
    db_url: str, sessions: sessionmaker[Session], tmp_path: Path
) -> None:
    first = Coordinator(db_url, tmp_path)
    try:
        object_id = httpx.post(f"{first.base}/objects", data={"name": "cube"}).json()["id"]
        ids = []
        for dtheta in (0.6, 0.8):
            response = httpx.post(
                f"{first.base}/explorations",
                json={"object_id": object_id, "gripper": "robotiq_3f", "grid": {"dtheta": dtheta}},
            )
            assert response.status_code == 201, response.text
            ids.append(response.json()["id"])
        before = {i: httpx.get(f"{first.base}/explorations/{i}").json() for i in ids}
    finally:
        first.stop()

    # While the coordinator is down: a worker finishes one tile, one holds two live leases,
    # and one dies holding three leases that have run out.
    with sessions() as s:
        (done,) = lease_tiles(s, worker_id="ok", n=1, lease_seconds=600)
        report = ingest_results(
            s,
            tile_id=done.tile_id,
            lease_epoch=done.lease_epoch,
            worker_id="ok",
            results=fake_results(done.poses()),
        )
        live = lease_tiles(s, worker_id="alive", n=2, lease_seconds=600)
        dead = lease_tiles(
            s, worker_id="dead", n=3, lease_seconds=60, now=utcnow() - timedelta(hours=1)
        )
    assert {t.exploration_id for t in [done, *live, *dead]} == {ids[0]}

    second = Coordinator(db_url, tmp_path)
    try:
        listing = httpx.get(f"{second.base}/explorations").json()
        assert [e["id"] for e in listing["items"]] == ids
        after = {i: httpx.get(f"{second.base}/explorations/{i}").json() for i in ids}
    finally:
        second.stop()
    for i in ids:
        assert after[i]["spec"] == before[i]["spec"]
        assert after[i]["created_at"] == before[i]["created_at"]
    tiles = after[ids[0]]["progress"]["tiles"]
    total = after[ids[0]]["tiles_total"]
    assert (tiles["done"], tiles["leased"], tiles["queued"]) == (1, 2, total - 3)
    assert after[ids[0]]["poses_done"] == report.inserted > 0
    assert after[ids[1]]["progress"]["tiles"]["queued"] == after[ids[1]]["tiles_total"]


def test_the_running_app_sweeps_expired_leases(
    settings,
    sessions: sessionmaker[Session],  # type: ignore[no-untyped-def]
) -> None:

    fast = settings.model_copy(
        update={"queue": settings.queue.model_copy(update={"requeue_interval_s": 0.1})})
    with TestClient(create_app(fast)) as client:
        object_id = client.post("/objects", data={"name": "cube"}).json()["id"]
        eid = client.post(
            "/explorations",
            json={"object_id": object_id, "gripper": "robotiq_3f", "grid": {"dtheta": 1.0}},
        ).json()["id"]
        with sessions() as s:
            lease_tiles(s, worker_id="w", n=2, lease_seconds=0.3)
        assert client.get(f"/explorations/{eid}").json()["progress"]["tiles"]["leased"] == 2
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            tiles = client.get(f"/explorations/{eid}").json()["progress"]["tiles"]
            if tiles["leased"] == 0:
                break
            time.sleep(0.1)
        total = client.get(f"/explorations/{eid}").json()["tiles_total"]
        assert (tiles["leased"], tiles["queued"]) == (0, total)
