"""The viewer's routes without a browser: the page and its vendored assets, the server-sent
progress events following stored results, the 3D view's directions, the workers page's
numbers, and the grasp picture's refusal where no renderer is wired."""

from __future__ import annotations

import json
from typing import Any

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.services.coordinator.web import grasp
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import oracle_result


def _events(client: TestClient, n: int = 1) -> list[dict[str, Any]]:
    with client.stream("GET", f"/events/explorations?max_events={n}&interval_s=0.2") as r:
        assert r.status_code == 200
        assert r.headers["content-type"].startswith("text/event-stream")
        text = "".join(r.iter_text())
    events = [block for block in text.split("\n\n") if block.startswith("event: progress")]
    assert len(events) == n
    return [json.loads(e.split("data: ", 1)[1]) for e in events]


def _submit(client: TestClient, object_id: int) -> int:
    body = {"object_id": object_id, "grid": {"dtheta": 0.8, "r_min": 0.0, "r_max": 0.01,
                                              "dr": 0.01}, "label": "viewer"}
    response = client.post("/explorations", json=body)
    assert response.status_code == 201, response.text
    return response.json()["id"]


def _work(sessions: sessionmaker[Session], n_tiles: int) -> int:
    stored = 0
    with sessions() as s:
        for t in lease_tiles(s, worker_id="w1", n=n_tiles, lease_seconds=60, host="box",
                             capacity=3):
            results = [oracle_result(p) for p in t.poses()]
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w1",
                           results=results)
            stored += len(results)
    return stored


SQLITE_ONLY = pytest.mark.parametrize("db_url", ["sqlite"], indirect=True)


@SQLITE_ONLY  # no query of its own: one backend is enough
def test_page_and_vendored_three_js(client: TestClient) -> None:
    page = client.get("/")
    assert page.status_code == 200 and "text/html" in page.headers["content-type"]
    assert '"three": "/static/vendor/three.module.min.js"' in page.text
    three = client.get("/static/vendor/three.module.min.js")
    assert three.status_code == 200 and "javascript" in three.headers["content-type"]
    assert "REVISION" in three.text  # the real library, not a placeholder
    assert client.get("/static/app.js").status_code == 200
    # The viewer's routes stay out of the API document (an endless stream would hang fuzzers).
    paths = client.app.openapi()["paths"]
    assert "/explorations" in paths
    assert not [p for p in paths
                if p == "/" or p.startswith(("/events", "/web", "/static"))
                or p.endswith("grasp.png")]


def test_events_follow_stored_results(client: TestClient, object_id: int,
                                      sessions: sessionmaker[Session]) -> None:
    eid = _submit(client, object_id)
    first = _events(client)[0]
    row = next(e for e in first["explorations"] if e["id"] == eid)
    assert row["poses_done"] == 0 and row["poses_total"] > 0 and row["status"] == "queued"
    assert first["workers_connected"] == 0
    stored = _work(sessions, 2)
    second = _events(client)[0]
    row = next(e for e in second["explorations"] if e["id"] == eid)
    assert row["poses_done"] == stored > 0
    assert row["fraction_done"] == pytest.approx(stored / row["poses_total"])
    assert row["throughput_poses_per_s"] > 0  # stored within the throughput window
    assert second["workers_connected"] == 1 and second["processes_connected"] == 3


def test_directions_workers_and_pose(client: TestClient, object_id: int,
                                     sessions: sessionmaker[Session]) -> None:
    eid = _submit(client, object_id)
    _work(sessions, 100)
    assert client.get(f"/explorations/{eid}/manifolds").status_code == 200
    d = client.get(f"/web/explorations/{eid}/directions").json()
    n = len(d["pose_id"])
    assert n == d["total_viable"] > 0
    assert all(len(d[k]) == n for k in ("theta", "phi", "r", "mu_s", "label"))
    # oracle_result holds only above θ = 2.2 rad, and every held pose is in a manifold.
    assert max(d["theta"]) < 2.2 and min(d["label"]) >= 0
    thinned = client.get(f"/web/explorations/{eid}/directions?limit=5").json()
    assert 0 < len(thinned["pose_id"]) <= 5
    pose = client.get(f"/web/explorations/{eid}/poses/{d['pose_id'][0]}").json()
    assert pose["viable"] is True and pose["id"] == d["pose_id"][0]
    assert client.get(f"/web/explorations/{eid + 1}/poses/{d['pose_id'][0]}").status_code == 404
    (worker,) = client.get("/web/workers").json()
    assert worker["id"] == "w1" and worker["processes"] == 3 and worker["connected"]
    assert worker["poses_last_window"] > 0


@SQLITE_ONLY
def test_grasp_picture_needs_a_renderer(client: TestClient, object_id: int,
                                        sessions: sessionmaker[Session]) -> None:
    eid = _submit(client, object_id)
    _work(sessions, 1)
    pose_id = client.get(f"/explorations/{eid}/poses?limit=1").json()["items"][0]["id"]
    saved = grasp._painter
    grasp.use_grasp_painter(None)
    try:
        assert client.get("/web/choices").json()["grasp_pictures"] is False
        response = client.get(f"/explorations/{eid}/poses/{pose_id}/grasp.png")
        assert response.status_code == 409 and "renderer" in response.json()["detail"]
    finally:
        grasp.use_grasp_painter(saved)
    assert client.get(f"/explorations/{eid}/poses/99999/grasp.png").status_code == 404
