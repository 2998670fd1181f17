"""The Python client against a live coordinator (uvicorn on loopback, SQLite and PostgreSQL):
submit, progress, best/manifolds/poses as typed objects with 4×4 transforms, exports that
name the mesh written beside them, failures and retry, and refusals as one clear error."""

from __future__ import annotations

import json
import math
import threading

import numpy as np
import pytest
import trimesh
from graspscape.services.client import ApiError, Client, Exploration
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.store.queue import fail_tile, lease_tiles

from tests.factories import oracle_result

SPEC = {"gripper": "robotiq_3f", "strategy": {"name": "grid"}, "refinement": {"levels": 0},
        "grid": {"dtheta": math.radians(40), "r_min": 0.0, "r_max": 0.01, "dr": 0.01}}


def _work(sessions, *, fail_one: bool = False) -> None:  # type: ignore[no-untyped-def]
    """What workers do: lease every tile and report oracle results (one tile failed for good
    when asked)."""
    with sessions() as s:
        failed = not fail_one
        while tiles := lease_tiles(s, worker_id="w", n=4, lease_seconds=3600):
            for tile in tiles:
                if not failed:
                    failed = True
                    fail_tile(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                              error="the worker fell over", max_attempts=1)
                    continue
                ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                               worker_id="w", results=[oracle_result(p) for p in tile.poses()])


def test_submit_wait_and_read_the_map(live_url, sessions, tmp_path) -> None:
    with Client(live_url) as api:
        obj = api.add_object("sphere", mass_kg=0.2)
        run = api.submit({**SPEC, "object_id": obj.id})
        assert api.status(run.id).status == "queued"
        seen: list[Exploration] = []
        worker = threading.Thread(target=_work, args=(sessions,))
        worker.start()
        final = api.wait(run.id, poll_s=0.05, timeout_s=60, progress=seen.append)
        worker.join()
        assert final.status == "done" and final.poses_done == run.poses_total > 0
        assert seen[-1] is final and all(s.id == run.id for s in seen)
        assert final.progress is not None and final.progress.fraction_done == 1.0

        best = api.best(run.id, limit=3)
        assert 1 <= len(best.poses) <= 3
        # What P(success) is stated under comes with the answer, typed.
        assert (best.rank, best.level, best.uncertainty["preset"]) == ("p_success", 0.9, "lab")
        assert all(p.success is None or 0 <= p.success.lower <= p.success.p <= 1
                   for p in best.poses)
        top = best.poses[0]
        assert top.viable and top.transform is not None and top.transform.shape == (4, 4)
        rotation = top.transform[:3, :3]
        assert np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
        assert np.allclose(top.transform[:3, 3], top.grasp["base_position"])

        maps = api.manifolds(run.id)
        assert maps.final and maps.large and all(m.large for m in maps.large)
        poses = list(api.poses(run.id, page_size=7))
        assert len(poses) == final.poses_done
        assert len({p.id for p in poses}) == len(poses)
        viable = list(api.poses(run.id, viable=True))
        assert viable and all(p.viable for p in viable) and len(viable) < len(poses)

        out = api.export(run.id, "graspgen.json", tmp_path / "grasps.json")
        data = json.loads(out.read_text())
        mesh = trimesh.load(tmp_path / data["object"]["file"], force="mesh")
        assert len(mesh.faces) > 0
        assert len(data["grasps"]["transforms"]) == final.poses_done
        csv = api.export(run.id, "poses.csv", tmp_path / "poses.csv")
        assert len(csv.read_text().splitlines()) == final.poses_done + 1


def test_failures_and_retry(live_url, sessions) -> None:
    with Client(live_url) as api:
        obj = api.add_object("sphere")
        run = api.submit({**SPEC, "object_id": obj.id})
        _work(sessions, fail_one=True)
        final = api.wait(run.id, poll_s=0.05, timeout_s=30)
        assert final.status == "incomplete"
        assert final.failures is not None and final.failures.tiles == 1
        tiles = api.failures(run.id)
        assert [t.last_error for t in tiles] == ["the worker fell over"]
        retried = api.retry(run.id)
        assert retried.tiles_requeued == 1 and api.status(run.id).status == "running"
        _work(sessions)
        assert api.wait(run.id, poll_s=0.05, timeout_s=30).status == "done"
        with pytest.raises(ApiError) as refused:
            api.retry(run.id)
        assert refused.value.status == 409


def test_refusals_name_what_is_wrong(live_url) -> None:
    with Client(live_url) as api:
        with pytest.raises(ApiError) as missing:
            api.status(999)
        assert missing.value.status == 404 and "999" in str(missing.value)
        with pytest.raises(ApiError) as invalid:
            api.submit({"object_id": 1, "grid": {"dtheta": -1}})
        assert invalid.value.status == 422 and "dtheta" in str(invalid.value)
        with pytest.raises(ValueError, match=r"poses\.csv"):
            api.export(1, "nothing.txt", "x")


def test_a_connection_refused_is_retried_then_raised(unused_port) -> None:
    import httpx

    attempts: list[httpx.Request] = []
    with Client(f"http://127.0.0.1:{unused_port}", retries=2, backoff_s=0.01) as api:
        api._http.event_hooks["request"].append(attempts.append)
        with pytest.raises(httpx.ConnectError):
            api.status(1)
    assert len(attempts) == 3


@pytest.fixture
def unused_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_docs_example_runs(live_url, sessions, tmp_path, monkeypatch, capsys) -> None:
    from pathlib import Path

    text = (Path(__file__).resolve().parents[3] / "docs" / "howto" / "client.md").read_text()
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.setenv("GRASPSCAPE_URL", live_url)
    monkeypatch.chdir(tmp_path)
    stop = threading.Event()

    def work() -> None:
        while not stop.is_set():
            _work(sessions)
            stop.wait(0.05)

    worker = threading.Thread(target=work)
    worker.start()
    try:
        exec(compile(code, "docs/howto/client.md", "exec"), {})
    finally:
        stop.set()
        worker.join()
    out = capsys.readouterr().out
    assert "done" in out.splitlines() and (tmp_path / "grasps.json").is_file()
    assert len(list(tmp_path.glob("exploration-*-object.obj"))) == 1
