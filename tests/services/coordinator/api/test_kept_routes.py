"""The kept read routes' fast path (api/answers.KeptRoutes, issue 21): a repeated request at a
settled map version is answered before FastAPI with the bytes, status and headers FastAPI
answered; a write that moves the version (an ingest, a refresh) sends the next request through
FastAPI again, which computes the new map's answer. On SQLite and PostgreSQL."""

from __future__ import annotations

import math
from typing import Any

from fastapi.testclient import TestClient
from graspscape.services.coordinator.api import answers
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.manifolds.service import refresh_manifolds
from graspscape.services.coordinator.state import of
from graspscape.services.coordinator.store.queue import lease_tiles
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import oracle_result

GRID = {"dtheta": math.radians(30), "r_min": 0.0, "r_max": 0.02, "dr": 0.01,
        "attitudes": {"rolls": 2}}


def _paths(eid: int) -> list[str]:
    return [f"/explorations/{eid}/best?limit=3&rank=mu_s", f"/explorations/{eid}/best?limit=3",
            f"/explorations/{eid}/manifolds", f"/explorations/{eid}/manifolds/A"]


def _read(client: TestClient, eid: int) -> list[tuple[int, dict[str, str], bytes]]:
    out = []
    for path in _paths(eid):
        response = client.get(path)
        assert response.status_code == 200, response.text
        out.append((response.status_code, dict(response.headers), response.content))
    return out


def _computed(client: TestClient, eid: int) -> list[tuple[int, dict[str, str], bytes]]:
    """The answers FastAPI's routes compute, nothing kept."""
    answers.clear(of(client.app))
    return _read(client, eid)


def _ingest(sessions: sessionmaker[Session], tiles: list[Any]) -> None:
    with sessions() as s:
        for t in tiles:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])


def _refresh(sessions: sessionmaker[Session], eid: int, *, final: bool) -> None:
    with sessions() as s:
        refresh_manifolds(s, eid, final=final)
        s.commit()


def test_kept_routes_answer_what_fastapi_answers_until_a_write(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    eid = client.post("/explorations", json={
        "object_id": object_id, "gripper": "robotiq_3f", "grid": GRID,
        "strategy": {"name": "grid"}, "refinement": {"levels": 0}}).json()["id"]
    with sessions() as s:
        tiles = lease_tiles(s, worker_id="w", n=1000, lease_seconds=60)
    assert len(tiles) >= 2
    half = len(tiles) // 2
    _ingest(sessions, tiles[:half])
    # Fewer poses than the keeper's REFRESH_MIN_POSES: refreshed by a writer here (reads
    # never refresh).
    _refresh(sessions, eid, final=False)

    # A running map whose table is not final: FastAPI answers every request (its own kept
    # answers), the fast path none.
    answers.clear(of(client.app))
    hits = of(client.app).route_hits
    running = _read(client, eid)
    assert _read(client, eid) == running and of(client.app).route_hits == hits

    # Settled (the table final at every stored pose): the second read is the fast path's, and
    # is what FastAPI computes, status and headers included.
    _refresh(sessions, eid, final=True)
    answers.clear(of(client.app))
    settled = _read(client, eid)
    assert _read(client, eid) == settled and of(client.app).route_hits == hits + 4
    assert _computed(client, eid) == settled
    assert _read(client, eid) == settled and of(client.app).route_hits == hits + 8
    metrics = client.get("/metrics").text
    assert 'route="/explorations/{exploration_id}/best",status="200"} 12.0' in metrics

    # A refresh that moves the mark (not final any more): through FastAPI again.
    _refresh(sessions, eid, final=False)
    assert _read(client, eid) == _computed(client, eid)
    assert of(client.app).route_hits == hits + 8

    # An ingest moves the version: the fast path does not answer the old map's bytes; the
    # keeper refreshed the table after the batch that finished the exploration, FastAPI
    # answers the new map's, which the fast path keeps (settled).
    _refresh(sessions, eid, final=True)
    before = _read(client, eid)
    assert _read(client, eid) == before and of(client.app).route_hits == hits + 12
    _ingest(sessions, tiles[half:])
    after = _read(client, eid)
    assert of(client.app).route_hits == hits + 12
    assert after != before and after[2][2] != before[2][2]  # /manifolds counts the new poses
    assert _computed(client, eid) == after
    assert _read(client, eid) == after and of(client.app).route_hits == hits + 16

    # A deleted exploration: its kept answers are not served (the version read finds no row).
    assert client.delete(f"/explorations/{eid}").status_code in (200, 204)
    assert client.get(_paths(eid)[2]).status_code == 404
    assert of(client.app).route_hits == hits + 16


def test_a_query_string_is_its_own_key(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    """The fast path keys on the raw query string: a different one (another limit, a refused
    value) is FastAPI's to answer, never a kept answer of another request."""
    eid = client.post("/explorations", json={
        "object_id": object_id, "gripper": "robotiq_3f", "grid": GRID,
        "strategy": {"name": "grid"}, "refinement": {"levels": 0}}).json()["id"]
    with sessions() as s:
        tiles = lease_tiles(s, worker_id="w", n=1000, lease_seconds=60)
    _ingest(sessions, tiles)
    answers.clear(of(client.app))
    base = f"/explorations/{eid}/best"
    one = client.get(f"{base}?limit=1")
    assert one.status_code == 200 and client.get(f"{base}?limit=1").content == one.content
    hits = of(client.app).route_hits
    two = client.get(f"{base}?limit=2")
    assert two.status_code == 200 and len(two.json()["poses"]) == 2
    assert client.get(f"{base}?limit=0").status_code == 422
    assert client.get(f"{base}?limit=0").status_code == 422  # a refusal is never kept
    assert client.get(f"/explorations/{eid}/manifolds/ZZ").status_code == 404
    assert client.get(f"/explorations/{eid}/manifolds/ZZ").status_code == 404
    assert of(client.app).route_hits == hits
