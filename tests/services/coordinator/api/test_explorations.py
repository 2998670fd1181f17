"""Explorations, poses, workers, health and metrics through the real app on both databases."""

from __future__ import annotations

import math
from typing import Any

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.tiling import count_poses
from graspscape.services.coordinator.store.models import ManifoldRow, PoseRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.services.coordinator.store.workers import heartbeat
from graspscape.shared.specs.exploration import PoseGridSpec
from graspscape.shared.specs.results import Outcome, PoseResult
from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import fake_results
from tests.services.coordinator.conftest import RefusalApi

SMALL_GRID = {"dtheta": 0.6, "r_min": 0.0, "r_max": 0.02, "dr": 0.01}


def submit(client: TestClient, object_id: int, **extra: Any) -> dict[str, Any]:
    body = {"object_id": object_id, "gripper": "robotiq_3f", "grid": SMALL_GRID, **extra}
    response = client.post("/explorations", json=body)
    assert response.status_code == 201, response.text
    return response.json()


def work(sessions: sessionmaker[Session], n_tiles: int, worker: str = "w1") -> list[Any]:
    """Do what a worker would: lease tiles and report one batch of results per tile."""
    done = []
    with sessions() as s:
        for t in lease_tiles(s, worker_id=worker, n=n_tiles, lease_seconds=60):
            results = fake_results(t.poses(), seed=t.tile_id)
            ingest_results(
                s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id=worker, results=results
            )
            done.extend(results)
    return done


def test_submit_get_and_progress(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    created = submit(client, object_id, label="first try")
    assert created["status"] == "queued"
    assert created["poses_total"] == count_poses(PoseGridSpec(**SMALL_GRID))
    eid = created["id"]
    detail = client.get(f"/explorations/{eid}").json()
    assert detail["spec"]["gripper"] == "robotiq_3f" and detail["spec"]["label"] == "first try"
    assert detail["spec"]["grid"]["attitudes"] == {"rolls": 1, "tilts": []}
    assert detail["progress"]["tiles"]["queued"] == created["tiles_total"]
    assert detail["progress"]["viable_share"] is None and detail["progress"]["eta_s"] is None

    results = work(sessions, 2)
    while len(results) < 10:  # enough to estimate
        results += work(sessions, 1)
    detail = client.get(f"/explorations/{eid}").json()
    progress = detail["progress"]
    assert detail["status"] == "running"
    tiles_done = progress["tiles"]["done"]
    assert tiles_done >= 2
    assert progress["tiles"]["queued"] == created["tiles_total"] - tiles_done
    assert progress["poses_done"] == len(results) == detail["poses_done"]
    assert progress["viable_share"] == pytest.approx(sum(r.viable for r in results) / len(results))
    # Stored within the last second: the rate over that second, not diluted over the whole
    # 60 s window.
    assert progress["throughput_poses_per_s"] == pytest.approx(len(results), rel=0.5)
    remaining = created["poses_total"] - len(results)
    assert progress["eta_s"] == pytest.approx(remaining / progress["throughput_poses_per_s"])
    assert progress["fraction_done"] == pytest.approx(len(results) / created["poses_total"])

    work(sessions, 10_000)
    detail = client.get(f"/explorations/{eid}").json()
    assert detail["status"] == "done" and detail["finished_at"] is not None
    assert detail["progress"]["fraction_done"] == 1.0 and detail["progress"]["eta_s"] is None


def test_list_filters_and_pagination(client: TestClient, object_id: int) -> None:
    ids = [submit(client, object_id)["id"] for _ in range(5)]
    assert client.post(f"/explorations/{ids[1]}/cancel").status_code == 200
    page = client.get("/explorations", params={"limit": 2, "offset": 2}).json()
    assert page["total"] == 5 and [e["id"] for e in page["items"]] == ids[2:4]
    cancelled = client.get("/explorations", params={"status": "cancelled"}).json()
    assert [e["id"] for e in cancelled["items"]] == [ids[1]]
    queued = client.get("/explorations", params={"status": "queued", "object_id": object_id})
    assert queued.json()["total"] == 4
    assert client.get("/explorations", params={"object_id": 999}).json()["total"] == 0
    assert client.get("/explorations", params={"status": "bogus"}).status_code == 422
    assert client.get("/explorations", params={"limit": 0}).status_code == 422


def _spec(**changes: Any) -> dict[str, Any]:
    spec: dict[str, Any] = {"object_id": 1, "gripper": "robotiq_3f", "grid": dict(SMALL_GRID)}
    for path, value in changes.items():
        target = spec
        *parents, leaf = path.split("__")
        for p in parents:
            target = target.setdefault(p, {})
        target[leaf] = value
    return spec


@pytest.mark.parametrize(
    ("spec", "fragment"),
    [
        (_spec(object_id=999), "object_id 999 does not exist"),
        (_spec(object_id=0), "object_id"),
        (_spec(gripper="bad name!"), "gripper"),
        (_spec(settings__policy_name="nope"), "unknown policy 'nope'"),
        (_spec(gripper="no_such_gripper"), "unknown gripper"),
        (_spec(grid__dtheta=0.001), "dtheta"),
        (_spec(grid__dtheta=2.0), "dtheta"),
        (_spec(grid__r_min=0.05, grid__r_max=0.01), "r_max (0.01) must not be below r_min"),
        (_spec(grid__dr=0), "dr"),
        (_spec(grid__r_max=0.6), "r_max"),
        (_spec(grid__attitudes__rolls=3), "rolls"),
        (_spec(grid__attitudes__tilts=[1.0]), "tilt 1.0 must be in"),
        (_spec(grid__attitudes__tilts=[0.1, 0.1]), "distinct"),
        (_spec(settings__trajectory__spin=1), "spin"),
        (_spec(settings__trajectory__duration_s=0), "duration_s"),
        (_spec(settings__physics__solver_iterations=0), "solver_iterations"),
        (_spec(refinement__levels=9), "levels"),
        (_spec(colour="red"), "colour"),
        (_spec(grid__dtheta=0.05, grid__attitudes__rolls=8), "more than the limit"),
        (_spec(label="x" * 201), "label"),
    ],
)
def test_exploration_validation_errors(
    refusals: RefusalApi, spec: dict[str, Any], fragment: str
) -> None:
    before = refusals.explorations()
    if spec.get("object_id") == 1:  # _spec's placeholder: the module's object
        spec = {**spec, "object_id": refusals.object_id}
    response = refusals.client.post("/explorations", json=spec)
    assert response.status_code == 422, response.text
    assert fragment in str(response.json()["detail"])
    assert refusals.explorations() == before


def test_malformed_body_is_422(client: TestClient) -> None:
    response = client.post(
        "/explorations", content=b"{not json", headers={"content-type": "application/json"}
    )
    assert response.status_code == 422


def test_cancel_and_delete(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    eid = submit(client, object_id)["id"]
    results = work(sessions, 1)
    with sessions() as s:
        (out,) = lease_tiles(s, worker_id="w2", n=1, lease_seconds=60)
    cancelled = client.post(f"/explorations/{eid}/cancel")
    assert cancelled.status_code == 200 and cancelled.json()["status"] == "cancelled"
    assert client.post(f"/explorations/{eid}/cancel").status_code == 200  # idempotent
    tiles = client.get(f"/explorations/{eid}").json()["progress"]["tiles"]
    assert tiles["done"] == 1 and tiles["queued"] == tiles["leased"] == 0
    with sessions() as s:
        assert lease_tiles(s, worker_id="w3", n=5, lease_seconds=60) == []
        # The tile that was out when the exploration was cancelled still delivers its results.
        late = ingest_results(
            s,
            tile_id=out.tile_id,
            lease_epoch=out.lease_epoch,
            worker_id="w2",
            results=fake_results(out.poses()),
        )
    assert late.inserted == len(out.poses())
    poses = client.get(f"/explorations/{eid}/poses", params={"limit": 1000}).json()["items"]
    assert len(poses) == len(results) + late.inserted

    assert client.delete(f"/explorations/{eid}").status_code == 204
    assert client.get(f"/explorations/{eid}").status_code == 404
    assert client.get(f"/explorations/{eid}/poses").status_code == 404
    assert client.delete(f"/explorations/{eid}").status_code == 404
    assert client.post(f"/explorations/{eid}/cancel").status_code == 404


def test_cancelling_a_done_exploration_is_409(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    eid = submit(client, object_id, grid={**SMALL_GRID, "dtheta": 1.5})["id"]
    work(sessions, 1000)
    response = client.post(f"/explorations/{eid}/cancel")
    assert response.status_code == 409 and "already done" in response.json()["detail"]


def test_poses_pagination_and_filters(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    eid = submit(client, object_id)["id"]
    results = work(sessions, 4)
    seen: list[dict[str, Any]] = []
    cursor = None
    while True:
        params: dict[str, Any] = {"limit": 7}
        if cursor is not None:
            params["cursor"] = cursor
        page = client.get(f"/explorations/{eid}/poses", params=params).json()
        assert len(page["items"]) <= 7
        seen.extend(page["items"])
        cursor = page["next_cursor"]
        if cursor is None:
            break
    assert len(seen) == len({p["pose_key"] for p in seen}) == len(results)
    by_key = {r.pose_key: r for r in results}
    assert all(p["mu_s"] == by_key[p["pose_key"]].mu_s for p in seen)

    def query(**params: Any) -> list[dict[str, Any]]:
        response = client.get(f"/explorations/{eid}/poses", params={"limit": 1000, **params})
        assert response.status_code == 200, response.text
        return response.json()["items"]

    viable = query(viable="true")
    assert len(viable) == sum(r.viable for r in results) > 0
    assert all(p["viable"] for p in viable)
    mid = query(mu_min=0.25, mu_max=0.75)
    assert {p["pose_key"] for p in mid} == {r.pose_key for r in results if 0.25 <= r.mu_s <= 0.75}
    box = query(theta_min=0.5, theta_max=1.3, phi_min=0.0, phi_max=math.pi, r_min=0.01, r_max=0.02)
    assert {p["pose_key"] for p in box} == {
        r.pose_key
        for r in results
        if 0.5 <= r.pose.theta <= 1.3 and 0 <= r.pose.phi <= math.pi and r.pose.r >= 0.01
    }

    with sessions() as s:
        manifold = ManifoldRow(exploration_id=eid, label=0, size=3)
        s.add(manifold)
        s.flush()
        keys = [p["pose_key"] for p in viable[:3]]
        s.execute(update(PoseRow).where(PoseRow.pose_key.in_(keys)).values(manifold_id=manifold.id))
        s.commit()
        manifold_id = manifold.id
    assert sorted(p["pose_key"] for p in query(manifold_id=manifold_id)) == sorted(keys)


@pytest.mark.parametrize(
    ("params", "fragment"),
    [
        ({"mu_min": 0.9, "mu_max": 0.1}, "mu_min (0.9) is greater than mu_max (0.1)"),
        ({"theta_min": 2, "theta_max": 1}, "theta_min"),
        ({"r_min": 0.5, "r_max": 0.1}, "r_min"),
        ({"phi_min": 3, "phi_max": 1}, "phi_min"),
        ({"mu_min": "nan"}, "finite"),
        ({"theta_max": "inf"}, "finite"),
        ({"limit": 0}, "limit"),
        ({"limit": 5000}, "limit"),
        ({"cursor": -1}, "cursor"),
        ({"viable": "maybe"}, "viable"),
    ],
)
def test_pose_query_validation_errors(
    refusals: RefusalApi, params: dict[str, Any], fragment: str
) -> None:
    eid = refusals.exploration_id
    response = refusals.client.get(f"/explorations/{eid}/poses", params=params)
    assert response.status_code == 422, response.text
    assert fragment in str(response.json()["detail"])


def test_workers_are_listed(client: TestClient, sessions: sessionmaker[Session]) -> None:
    with sessions() as s:
        heartbeat(s, worker_id="box-1", host="box", capacity=16)
        heartbeat(s, worker_id="box-2", host="box", capacity=8)
        heartbeat(s, worker_id="box-1", host="box", capacity=12)
    body = client.get("/workers").json()
    assert body["total"] == 2
    assert {w["id"]: w["capacity"] for w in body["items"]} == {"box-1": 12, "box-2": 8}
    assert body["items"][0]["id"] == "box-1"  # most recently seen first


def test_healthz_and_metrics(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    health = client.get("/healthz")
    assert health.status_code == 200
    assert health.json()["status"] == "ok" and health.json()["schema_revision"] is not None
    eid = submit(client, object_id)["id"]
    results = work(sessions, 1)
    client.get(f"/explorations/{eid}")
    metrics = client.get("/metrics")
    assert metrics.status_code == 200
    assert metrics.headers["content-type"].startswith("text/plain")
    text = metrics.text
    assert 'graspscape_tiles{state="done"} 1.0' in text
    assert 'graspscape_explorations{status="running"} 1.0' in text
    assert f"graspscape_poses_stored {float(len(results))}" in text
    assert "graspscape_workers_active 1.0" in text
    assert (
        'graspscape_http_requests_total{method="GET",'
        'route="/explorations/{exploration_id}",status="200"} 1.0'
    ) in text


def test_service_refusals_use_the_validation_error_shape(client: TestClient) -> None:
    response = client.post("/explorations", json={"object_id": 77, "gripper": "robotiq_3f"})
    assert response.status_code == 422
    (error,) = response.json()["detail"]
    assert error["loc"] == ["body", "object_id"] and error["type"] == "value_error"
    assert error["msg"] == "object_id 77 does not exist; upload it to /objects"


@pytest.mark.parametrize(
    ("body", "loc"),
    [
        (b'{"object_id": OBJ, "grid": {"dtheta": NaN}}', ["body", "grid", "dtheta"]),
        (b'{"object_id": OBJ, "grid": {"r_max": Infinity}}', ["body", "grid", "r_max"]),
        (b'{"object_id": OBJ, "grid": {"dr": -Infinity}}', ["body", "grid", "dr"]),
        (b'{"object_id": OBJ, "grid": {"r_min": 1e999}}', ["body", "grid", "r_min"]),
        (b'{"object_id": NaN}', ["body", "object_id"]),
        (b'{"object_id": OBJ, "grid": {"attitudes": {"tilts": [0.1, NaN]}}}',
         ["body", "grid", "attitudes", "tilts", 1]),
        (b'{"object_id": OBJ, "settings": {"trajectory": {"duration_s": NaN}}}',
         ["body", "settings", "trajectory", "duration_s"]),
    ],
)
def test_non_finite_numbers_in_a_body_are_422(
    refusals: RefusalApi, body: bytes, loc: list[Any]
) -> None:
    # Python's JSON parser takes NaN and Infinity; the 422 handler could not write them back
    # (a 500), and a number without bounds would have been stored.
    before = refusals.explorations()
    response = refusals.client.post(
        "/explorations", content=body.replace(b"OBJ", str(refusals.object_id).encode()),
        headers={"content-type": "application/json"})
    assert response.status_code == 422, response.text
    (error,) = response.json()["detail"]
    assert error["loc"] == loc and error["msg"] == "Input should be a finite number"
    assert refusals.explorations() == before


@pytest.mark.parametrize(("field", "value"), [("mass_kg", "nan"), ("friction", "inf"),
                                              ("scale", "-inf"), ("mass_kg", "1e999")])
def test_non_finite_form_numbers_are_422(refusals: RefusalApi, field: str, value: str) -> None:
    response = refusals.client.post("/objects", data={"name": "sphere", field: value})
    assert response.status_code == 422, response.text
    (error,) = response.json()["detail"]
    assert error["loc"] == ["body", field] and "finite" in error["msg"]


@pytest.mark.parametrize(("field", "value"), [("friction", "1e-400"), ("mass_kg", "-1e-400"),
                                              ("scale", "0.0000000001e-320")])
def test_form_numbers_that_underflow_to_zero_are_422(refusals: RefusalApi, field: str,
                                                     value: str) -> None:
    # float("1e-400") is 0.0, which friction ≥ 0 would take (a 201 before).
    response = refusals.client.post("/objects", data={"name": "sphere", field: value})
    assert response.status_code == 422, response.text
    (error,) = response.json()["detail"]
    assert error["loc"] == ["body", field] and "too small for a float" in error["msg"]
    zero = refusals.client.post("/objects", data={"name": "sphere", "friction": "0e-400"})
    assert zero.status_code in (200, 201), zero.text  # a zero written so is zero


def test_a_number_that_underflows_in_a_body_is_422(refusals: RefusalApi) -> None:
    before = refusals.explorations()
    body = b'{"object_id": OBJ, "grid": {"r_min": 1e-400}}'
    response = refusals.client.post(
        "/explorations", content=body.replace(b"OBJ", str(refusals.object_id).encode()),
        headers={"content-type": "application/json"})
    assert response.status_code == 422, response.text
    (error,) = response.json()["detail"]
    assert error["loc"] == ["body", "grid", "r_min"] and error["type"] == "float_underflow"
    assert error["input"] == "1e-400" and refusals.explorations() == before


@pytest.mark.parametrize(
    ("path", "params"),
    [
        ("/explorations/{eid}/poses", {"r_min": "nan"}),
        ("/explorations/{eid}/best", {"max_effort_nm": "inf"}),
        ("/explorations/{eid}/best", {"cone_x": 0, "cone_y": 0, "cone_z": 1,
                                      "cone_half_angle_deg": "nan"}),
        ("/explorations/{eid}/map.svg", {"phi0_deg": "-inf"}),
    ],
)
def test_non_finite_query_numbers_are_422(
    refusals: RefusalApi, path: str, params: dict[str, Any]
) -> None:
    response = refusals.client.get(path.format(eid=refusals.exploration_id), params=params)
    assert response.status_code == 422, response.text
    assert "finite" in str(response.json()["detail"])


def test_the_422_handler_writes_non_finite_inputs() -> None:
    import asyncio

    from fastapi.exceptions import RequestValidationError
    from graspscape.services.coordinator.api.finite import validation_error_handler

    exc = RequestValidationError([{"type": "greater_than_equal", "loc": ("body", "x"),
                                   "msg": "bad", "input": [math.nan, math.inf, -math.inf]}])
    response = asyncio.run(validation_error_handler(None, exc))  # type: ignore[arg-type]
    assert response.status_code == 422
    assert b'"input":["NaN","Infinity","-Infinity"]' in response.body


def _fail(sessions: sessionmaker[Session], n_tiles: int, error: str = "pybullet exploded",
          worker: str = "w9") -> list[int]:
    """Lease tiles and have each fail for good (max_attempts 1), as a worker's error report."""
    from graspscape.services.coordinator.store.queue import fail_tile

    failed = []
    with sessions() as s:
        for t in lease_tiles(s, worker_id=worker, n=n_tiles, lease_seconds=60):
            assert fail_tile(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                             error=f"{worker}: {error}", max_attempts=1) == "failed"
            failed.append(t.tile_id)
    return failed


def test_failed_tiles_leave_an_exploration_incomplete_with_reasons_until_retried(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    created = submit(client, object_id)
    eid, n_tiles = created["id"], created["tiles_total"]
    assert n_tiles >= 3
    results = work(sessions, n_tiles - 2)
    failed = _fail(sessions, 1, "RuntimeError: pybullet exploded")
    failed += _fail(sessions, 1, "lease expired on attempt 3 of 3", worker="w8")

    detail = client.get(f"/explorations/{eid}").json()
    # Two tiles' poses were never stored: this used to read "done".
    assert detail["status"] == "incomplete" and detail["finished_at"] is not None
    assert detail["poses_done"] == len(results) < detail["poses_total"]
    assert detail["progress"]["tiles"]["failed"] == 2 and detail["progress"]["eta_s"] is None
    assert detail["failures"] == {"tiles": 2, "poses_with_errors": 0, "reasons": [
        {"reason": "w8: lease expired on attempt 3 of 3", "tiles": 1},
        {"reason": "w9: RuntimeError: pybullet exploded", "tiles": 1},
    ]}
    listed = client.get("/explorations", params={"status": "incomplete"}).json()
    assert [e["id"] for e in listed["items"]] == [eid]

    page = client.get(f"/explorations/{eid}/failures", params={"limit": 1}).json()
    assert page["total"] == 2 and page["limit"] == 1 and len(page["items"]) == 1
    (first,) = page["items"]
    assert first["tile_id"] == min(failed) and first["level"] == 0 and first["attempts"] == 1
    assert first["last_error"] == "w9: RuntimeError: pybullet exploded"
    second = client.get(f"/explorations/{eid}/failures", params={"offset": 1}).json()["items"]
    assert [t["tile_id"] for t in second] == [max(failed)]
    assert client.get("/explorations/999999/failures").status_code == 404

    cancel = client.post(f"/explorations/{eid}/cancel")
    assert cancel.status_code == 409 and "already incomplete" in cancel.json()["detail"]

    retried = client.post(f"/explorations/{eid}/retry")
    assert retried.status_code == 200, retried.text
    assert retried.json() == {"id": eid, "status": "running", "tiles_requeued": 2}
    detail = client.get(f"/explorations/{eid}").json()
    assert detail["status"] == "running" and detail["finished_at"] is None
    assert detail["failures"] == {"tiles": 0, "poses_with_errors": 0, "reasons": []}
    assert detail["progress"]["tiles"]["queued"] == 2
    assert client.get(f"/explorations/{eid}/failures").json()["total"] == 0
    again = client.post(f"/explorations/{eid}/retry")
    assert again.status_code == 409 and "no failed tiles" in again.json()["detail"]

    with sessions() as s:  # attempts start from zero: the first failure requeues
        (t,) = lease_tiles(s, worker_id="w7", n=1, lease_seconds=60)
        from graspscape.services.coordinator.store.queue import fail_tile

        assert fail_tile(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, error="once",
                         max_attempts=2) == "queued"
    work(sessions, 2)
    detail = client.get(f"/explorations/{eid}").json()
    assert detail["status"] == "done" and detail["poses_done"] == detail["poses_total"]
    assert detail["failures"]["tiles"] == 0
    assert client.post(f"/explorations/{eid}/retry").status_code == 409


def test_an_exploration_whose_tiles_all_failed_without_a_pose_is_failed(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    created = submit(client, object_id, grid={**SMALL_GRID, "dtheta": 1.5})
    eid = created["id"]
    _fail(sessions, created["tiles_total"], "ObjectFetchError: mesh is not watertight")
    detail = client.get(f"/explorations/{eid}").json()
    assert detail["status"] == "failed" and detail["poses_done"] == 0
    reason = "w9: ObjectFetchError: mesh is not watertight"
    assert detail["failures"] == {"tiles": created["tiles_total"], "poses_with_errors": 0,
                                  "reasons": [{"reason": reason, "tiles": created["tiles_total"]}]}
    assert client.get("/explorations", params={"status": "failed"}).json()["total"] == 1
    assert 'graspscape_explorations{status="failed"} 1.0' in client.get("/metrics").text
    assert client.post(f"/explorations/{eid}/retry").json()["status"] == "running"


def test_retry_refuses_cancelled_and_unknown_explorations(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    eid = submit(client, object_id)["id"]
    _fail(sessions, 1)
    assert client.post(f"/explorations/{eid}/cancel").status_code == 200
    response = client.post(f"/explorations/{eid}/retry")
    assert response.status_code == 409 and "cancelled" in response.json()["detail"]
    assert client.get(f"/explorations/{eid}").json()["status"] == "cancelled"
    assert client.post("/explorations/999999/retry").status_code == 404


def test_exploration_and_tile_ids_are_never_reused_after_delete(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    from graspscape.services.coordinator.store.models import TileRow
    from sqlalchemy import func

    submit(client, object_id)
    newest = submit(client, object_id)["id"]
    with sessions() as s:
        top_tile = s.scalar(select(func.max(TileRow.id)))
    assert client.delete(f"/explorations/{newest}").status_code == 204
    again = submit(client, object_id)["id"]
    # SQLite gave the deleted exploration's id (and its tiles' ids) to the next one: a late
    # batch for a deleted tile could have landed on another exploration's tile.
    assert again > newest
    with sessions() as s:
        first_tile = s.scalar(select(func.min(TileRow.id)).where(TileRow.exploration_id == again))
    assert first_tile > top_tile


@pytest.mark.parametrize(
    ("method", "path"),
    [("PUT", "/explorations"), ("PATCH", "/explorations/1"), ("GET", "/explorations/1/retry"),
     ("DELETE", "/objects"), ("POST", "/explorations/1/poses"), ("PUT", "/healthz")],
)
def test_405_allow_header_lists_the_documented_methods(
    refusals: RefusalApi, method: str, path: str
) -> None:
    client = refusals.client
    from starlette.routing import compile_path

    documented = {
        m.upper()
        for template, operations in client.get("/openapi.json").json()["paths"].items()
        if compile_path(template)[0].match(path)
        for m in operations
    }
    response = client.request(method, path)
    assert response.status_code == 405
    assert response.headers["allow"] == ", ".join(sorted(documented))


def test_a_pose_that_raised_is_stored_with_its_message_and_counted(
    client: TestClient, object_id: int, sessions: sessionmaker[Session]
) -> None:
    """A worker isolates a pose whose evaluation raised (outcome `error`, the message): it is
    stored like any pose, so the tile and the exploration finish, and it is shown."""
    created = submit(client, object_id)
    eid = created["id"]
    message = "FloatingPointError: solver diverged"
    stored = []
    with sessions() as s:
        while tiles := lease_tiles(s, worker_id="w1", n=4, lease_seconds=60):
            for t in tiles:
                results = fake_results(t.poses(), seed=t.tile_id)
                first = results[0]
                results[0] = PoseResult(pose=first.pose, pose_key=first.pose_key,
                                        outcome=Outcome.ERROR, viable=False, mu_s=0.0,
                                        error=message)
                ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                               worker_id="w1", results=results)
                stored.append(first.pose_key)
    detail = client.get(f"/explorations/{eid}").json()
    assert detail["status"] == "done" and detail["poses_done"] == detail["poses_total"]
    assert detail["failures"]["poses_with_errors"] == len(stored) == created["tiles_total"]
    errors = client.get(f"/explorations/{eid}/poses",
                        params={"outcome": "error", "limit": 1000}).json()["items"]
    assert sorted(p["pose_key"] for p in errors) == sorted(stored)
    assert all(p["error"] == message and not p["viable"] for p in errors)
    held = client.get(f"/explorations/{eid}/poses", params={"outcome": "held"}).json()["items"]
    assert held and all(p["outcome"] == "held" and p["error"] is None for p in held)
    csv_text = client.get(f"/explorations/{eid}/export/poses.csv").text
    assert csv_text.splitlines()[0].endswith(",error") and csv_text.count(message) == len(stored)
    assert client.get(f"/explorations/{eid}/poses",
                      params={"outcome": "exploded"}).status_code == 422
