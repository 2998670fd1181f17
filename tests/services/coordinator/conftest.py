"""Fixtures of the coordinator tests: its settings on each database backend, the app under a
test client, and objects to explore. The coordinator sees objects through the workers'
preparation, as every `graspscape` command composes it (graspscape.services.local)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.objects.service import create_named
from graspscape.services.coordinator.settings import Settings
from sqlalchemy.orm import Session, sessionmaker

from tests.conftest import _postgres, _sqlite


@pytest.fixture(autouse=True, scope="session")
def _composed() -> None:
    from graspscape.services.local.compose import wire

    wire()


def _settings(url: str, directory: Path) -> Settings:
    return Settings(
        database={"url": url, "data_dir": directory},
        api={"token": None, "max_upload_bytes": 64 * 1024,
             "shared_objects_dir": directory / "shared"},
        queue={"requeue_interval_s": 3600, "max_poses_per_exploration": 100_000},
    )


@pytest.fixture
def settings(db_url: str, tmp_path: Path) -> Settings:
    return _settings(db_url, tmp_path)


@pytest.fixture
def client(settings: Settings, sessions: sessionmaker[Session]) -> Iterator[TestClient]:
    with TestClient(create_app(settings)) as c:
        yield c


@pytest.fixture
def object_id(client: TestClient) -> int:
    response = client.post("/objects", data={"name": "sphere", "mass_kg": "0.2"})
    assert response.status_code == 201, response.text
    return response.json()["id"]


@pytest.fixture
def named_object(sessions: sessionmaker[Session]):
    def make(name: str) -> int:
        with sessions() as s:
            row, _ = create_named(s, name=name, properties={}, shared_dir=None)
            return row.id

    return make


@contextlib.contextmanager
def own_app(backend: str, directory: Path, sqlite_template: Path) -> Iterator[TestClient]:
    """The app on a database of its own ("sqlite": a copy of the session's migrated template
    in `directory`; "postgresql": a private schema migrated to head, dropped at the end), for
    module-scoped fixtures whose tests share what they only read."""
    urls = _sqlite(directory, sqlite_template) if backend == "sqlite" else _postgres()
    url = next(urls)
    try:
        with TestClient(create_app(_settings(url, directory))) as client:
            yield client
    finally:
        urls.close()


@dataclass(frozen=True)
class RefusalApi:
    """One app for a module's refusal tests, with an object and an exploration in place."""

    client: TestClient
    object_id: int
    exploration_id: int

    def explorations(self) -> int:
        return self.client.get("/explorations").json()["total"]


@pytest.fixture(scope="module", params=["sqlite", "postgresql"])
def refusals(request: pytest.FixtureRequest,
             tmp_path_factory: pytest.TempPathFactory) -> Iterator[RefusalApi]:
    """The app on a database of its own per backend, shared by a module's tests of requests
    that must be refused (422, 405): a refusal stores nothing, so they need no fresh tables,
    and one app for dozens of cases keeps the default suite short. Both backends still run,
    since a value the API let through could fail in one database only."""
    directory = tmp_path_factory.mktemp("refusals")
    template = request.getfixturevalue("sqlite_template")
    with own_app(request.param, directory, template) as client:
        response = client.post("/objects", data={"name": "sphere", "mass_kg": "0.2"})
        assert response.status_code == 201, response.text
        object_id = response.json()["id"]
        response = client.post("/explorations", json={
            "object_id": object_id, "gripper": "robotiq_3f",
            "grid": {"dtheta": 0.6, "r_min": 0.0, "r_max": 0.02, "dr": 0.01}})
        assert response.status_code == 201, response.text
        yield RefusalApi(client, object_id, response.json()["id"])
