"""The grasp dataset exports (GraspGen JSON, ACRONYM-style HDF5) read back with json and h5py,
every transform checked against the stored pose it came from, on both databases."""

from __future__ import annotations

import io
import json
import math
import random
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.datasets import rows as dataset_rows
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.objects.geometry import object_mesh, use_mesh_source
from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.services.local.cli import main
from graspscape.services.local.compose import wire
from graspscape.shared.specs.results import PoseResult
from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from tests.factories import fake_results
from tests.services.coordinator.conftest import own_app

GRID = {"dtheta": 0.6, "r_min": 0.0, "r_max": 0.02, "dr": 0.01}
ATTITUDES = {"rolls": 2, "tilts": [0.3]}


def _turned(results: list[PoseResult], rng: random.Random) -> list[PoseResult]:
    """The factory's grasps all face one way; turn each by a random rotation, so that the
    quaternion → matrix check means something. Half the poses without a grasp backed off
    4 mm from interpenetration (their stored effective_r)."""
    out = []
    for r in results:
        if r.grasp is None and rng.random() < 0.5:
            r = r.model_copy(update={"effective_r": r.pose.r + 0.004})
        elif r.grasp is not None:
            q = np.array([rng.gauss(0, 1) for _ in range(4)])
            q /= np.linalg.norm(q)
            r = r.model_copy(update={"grasp": r.grasp.model_copy(
                update={"base_orientation": tuple(q.tolist())})})
        out.append(r)
    return out


@dataclass(frozen=True)
class Explored:
    """An app on a database of its own holding one stored exploration."""

    client: TestClient
    id: int

    @property
    def sessions(self) -> sessionmaker[Session]:
        return self.client.app.state.sessionmaker  # type: ignore[attr-defined]

    @property
    def url(self) -> str:
        return self.client.app.state.settings.database.resolved_url  # type: ignore[attr-defined]


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def explored(request: pytest.FixtureRequest,
             tmp_path_factory: pytest.TempPathFactory) -> Iterator[Explored]:
    """Stored once per backend for the module (1.6 s a time): every test here only reads it."""
    directory = tmp_path_factory.mktemp("exports")
    template = request.getfixturevalue("sqlite_template")
    with own_app(request.param, directory, template) as client:
        response = client.post("/objects", data={"name": "sphere", "mass_kg": "0.2"})
        assert response.status_code == 201, response.text
        body = {"object_id": response.json()["id"], "gripper": "robotiq_3f",
                "grid": {**GRID, "attitudes": ATTITUDES}}
        response = client.post("/explorations", json=body)
        assert response.status_code == 201, response.text
        rng = random.Random(7)
        with client.app.state.sessionmaker() as s:  # type: ignore[attr-defined]
            for t in lease_tiles(s, worker_id="w1", n=10_000, lease_seconds=60):
                ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch,
                               worker_id="w1",
                               results=_turned(fake_results(t.poses(), seed=t.tile_id), rng))
        yield Explored(client, response.json()["id"])


def _stored(sessions: sessionmaker[Session], eid: int) -> list[PoseRow]:
    with sessions() as s:
        rows = list(s.scalars(select(PoseRow).where(PoseRow.exploration_id == eid)
                              .order_by(PoseRow.pose_key)))
        s.expunge_all()
    return rows


def _matrix_of(q: tuple[float, float, float, float]) -> np.ndarray:
    """The rotation of a unit quaternion (x, y, z, w), written out (not scipy's)."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _check_transforms(transforms: np.ndarray, rows: list[PoseRow], mesh: Any) -> None:
    import trimesh

    assert transforms.shape == (len(rows), 4, 4)
    for t, row in zip(transforms, rows, strict=True):
        rot = t[:3, :3]
        assert np.allclose(rot @ rot.T, np.eye(3), atol=1e-9)
        assert np.linalg.det(rot) == pytest.approx(1.0)
        assert t[3].tolist() == [0.0, 0.0, 0.0, 1.0]
        if row.grasp is not None:
            assert t[:3, 3].tolist() == list(row.grasp["base_position"])
            assert np.allclose(rot, _matrix_of(row.grasp["base_orientation"]), atol=1e-9)
        else:
            # The start pose: the palm centre at the stored gap from the surface, its normal
            # (z) pointing at the nearest surface point.
            nearest, distance, _ = trimesh.proximity.closest_point(mesh, t[None, :3, 3])
            assert distance[0] == pytest.approx(row.effective_r, abs=2e-5)
            if row.effective_r > 1e-3:
                toward = (nearest[0] - t[:3, 3]) / distance[0]
                assert toward @ rot[:, 2] == pytest.approx(
                    math.cos(row.pitch) * math.cos(row.yaw), abs=1e-3)


def _mesh(sessions: sessionmaker[Session], eid: int) -> Any:
    with sessions() as s:
        return object_mesh(s, s.get(ExplorationRow, eid).object_id)


def test_graspgen_round_trip(explored: Explored) -> None:
    client, sessions = explored.client, explored.sessions
    response = client.get(f"/explorations/{explored.id}/export/graspgen.json")
    assert response.status_code == 200, response.text
    assert response.headers["content-type"].startswith("application/json")
    data = json.loads(response.content)
    rows = _stored(sessions, explored.id)
    assert data["object"] == {"file": f"exploration-{explored.id}-object.obj", "scale": 1.0,
                              "source": "sphere", "source_scale": 1.0, "mass": 0.2}
    assert data["gripper"] == {"name": "robotiq_3f"}
    # GraspGen's own reading: positives and negatives by the boolean mask.
    grasps = np.array(data["grasps"]["transforms"])
    mask = np.array(data["grasps"]["object_in_gripper"])
    assert mask.dtype == bool and len(mask) == len(grasps) == len(rows) > 50
    assert mask.tolist() == [bool(r.viable) for r in rows]
    assert 0 < len(grasps[mask]) < len(rows)
    assert data["graspscape"]["transform_from_grasp"] == [r.grasp is not None for r in rows]
    _check_transforms(grasps, rows, _mesh(sessions, explored.id))


def test_acronym_round_trip(explored: Explored) -> None:
    client, sessions = explored.client, explored.sessions
    response = client.get(f"/explorations/{explored.id}/export/acronym.h5")
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "application/x-hdf5"
    rows = _stored(sessions, explored.id)
    mesh = _mesh(sessions, explored.id)
    with h5py.File(io.BytesIO(response.content), "r") as f:
        # ACRONYM's own reading (acronym_tools.load_grasps, load_mesh).
        transforms = np.array(f["grasps/transforms"])
        success = np.array(f["grasps/qualities/flex/object_in_gripper"])
        assert f["object/file"][()].decode() == f"exploration-{explored.id}-object.obj"
        assert f["object/scale"][()] == 1.0 and f["object/mass"][()] == 0.2
        assert f["gripper/type"][()].decode() == f["gripper/name"][()].decode() == "robotiq_3f"
        assert success.tolist() == [int(r.viable) for r in rows]
        assert [k.decode() for k in f["grasps/pose_key"]] == [r.pose_key for r in rows]
        assert [o.decode() for o in f["grasps/outcome"]] == [r.outcome for r in rows]
        assert np.array(f["grasps/from_grasp"]).tolist() == [int(r.grasp is not None)
                                                            for r in rows]
        assert np.array(f["grasps/qualities/mu_s"]).tolist() == [r.mu_s for r in rows]
        assert np.isnan(np.array(f["grasps/qualities/torque_margin_ratio"])).all()
        for q in ("robust_s", "robust_q"):  # the robust map's, NaN where not computed
            np.testing.assert_array_equal(f[f"grasps/qualities/{q}"], [
                np.nan if getattr(r, q) is None else getattr(r, q) for r in rows])
        assert np.array(f["grasps/pose"]).tolist() == [
            [r.theta, r.phi, r.r, r.roll, r.pitch, r.yaw] for r in rows]
        assert np.array_equal(f["object/mesh/vertices"], mesh.vertices)
        _check_transforms(transforms, rows, mesh)


def test_chunks_do_not_change_the_exports(explored: Explored,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    client = explored.client
    whole = client.get(f"/explorations/{explored.id}/export/graspgen.json").content
    monkeypatch.setattr(dataset_rows, "CHUNK_ROWS", 7)
    assert client.get(f"/explorations/{explored.id}/export/graspgen.json").content == whole


@pytest.mark.slow  # the command end to end, three formats, both databases
def test_cli_writes_what_the_route_serves(explored: Explored, tmp_path: Path) -> None:
    for what in ("graspgen.json", "acronym.h5", "object.obj"):
        out = tmp_path / what
        assert main(["map", "export", str(explored.id), "--what", what, "-o", str(out),
                     "--database-url", explored.url]) == 0
        served = explored.client.get(f"/explorations/{explored.id}/export/{what}").content
        if what == "acronym.h5":
            with h5py.File(out, "r") as a, h5py.File(io.BytesIO(served), "r") as b:
                assert np.array_equal(a["grasps/transforms"], b["grasps/transforms"])
        else:
            assert out.read_bytes() == served
    assert not list(tmp_path.glob("*.part"))


@pytest.mark.parametrize("what", ["graspgen.json", "acronym.h5"])
def test_a_cli_export_loads_with_the_mesh_it_names(explored: Explored, tmp_path: Path,
                                                   what: str) -> None:
    """The round trip a user of the dataset makes: read the file, open the mesh its
    object.file names beside it, and find the object the transforms are about."""
    import trimesh

    out = tmp_path / "out" / what
    out.parent.mkdir()
    assert main(["map", "export", str(explored.id), "--what", what, "-o", str(out),
                 "--database-url", explored.url]) == 0
    if what == "graspgen.json":
        data = json.loads(out.read_text())
        named, scale = data["object"]["file"], data["object"]["scale"]
        n = len(data["grasps"]["transforms"])
    else:
        with h5py.File(out, "r") as f:
            named, scale = f["object/file"][()].decode(), float(f["object/scale"][()])
            n = len(f["grasps/transforms"])
            stored = np.asarray(f["object/mesh/vertices"])
    mesh = trimesh.load(out.parent / named, force="mesh")
    with explored.sessions() as s:
        expected = object_mesh(s, s.get(ExplorationRow, explored.id).object_id)
        poses = s.get(ExplorationRow, explored.id).poses_done
    assert n == poses and scale == 1.0
    assert np.allclose(np.sort(mesh.vertices, axis=0), np.sort(expected.vertices, axis=0),
                       atol=1e-6)
    if what == "acronym.h5":
        assert np.allclose(np.sort(stored, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-6)
    assert sorted(p.name for p in out.parent.iterdir()) == sorted([what, named])


def test_refusals(explored: Explored) -> None:
    client = explored.client
    for what in ("graspgen.json", "acronym.h5", "object.obj"):
        assert client.get(f"/explorations/999999/export/{what}").status_code == 404
    use_mesh_source(None)  # a coordinator without the workers' object preparation
    try:
        response = client.get(f"/explorations/{explored.id}/export/acronym.h5")
        assert response.status_code == 409 and "formed no grasp" in response.json()["detail"]
    finally:
        wire()
