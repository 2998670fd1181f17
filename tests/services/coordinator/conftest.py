"""Fixtures of the coordinator tests: its settings on each database backend, the app under a
test client, and objects to explore. The coordinator sees objects through the workers'
preparation, as every `graspscape` command composes it (graspscape.services.local)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.objects.service import create_named
from graspscape.services.coordinator.settings import Settings
from sqlalchemy.orm import Session, sessionmaker


@pytest.fixture(autouse=True, scope="session")
def _composed() -> None:
    from graspscape.services.local.compose import wire

    wire()


@pytest.fixture
def settings(db_url: str, tmp_path: Path) -> Settings:
    return Settings(
        database={"url": db_url, "data_dir": tmp_path},
        api={"token": None, "max_upload_bytes": 64 * 1024,
             "shared_objects_dir": tmp_path / "shared"},
        queue={"requeue_interval_s": 3600, "max_poses_per_exploration": 100_000},
    )


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
