"""Fixtures: every store and API test runs on SQLite and on the real PostgreSQL.

Each backend's schema is made once per session by `alembic upgrade head` (never create_all):
SQLite in a temp file, PostgreSQL in a fresh schema of its own (search_path in the URL), so
parallel runs and other suites sharing the `test` database do not collide. Tables are
emptied after each test.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest
import trimesh
from fastapi.testclient import TestClient
from graspscape.services.coordinator import db
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.settings import Settings
from sqlalchemy import Engine, text
from sqlalchemy.orm import Session, sessionmaker

PG_URL = os.environ.get(
    "GRASPSCAPE_TEST_PG_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
)
TABLES = ("poses", "manifolds", "tiles", "explorations", "objects", "workers")


def _pg_conninfo() -> str:
    return PG_URL.replace("postgresql+psycopg://", "postgresql://")


@pytest.fixture(scope="session", params=["sqlite", "postgresql"])
def db_url(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[str]:
    if request.param == "sqlite":
        path = tmp_path_factory.mktemp("sqlite") / "coordinator.db"
        url = f"sqlite:///{path}"
        db.upgrade(url)
        yield url
        return
    schema = f"gs_test_{uuid.uuid4().hex[:12]}"
    with psycopg.connect(_pg_conninfo(), autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    url = f"{PG_URL}?options=-csearch_path%3D{schema}"
    try:
        db.upgrade(url)
        yield url
    finally:
        with psycopg.connect(_pg_conninfo(), autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


@pytest.fixture(scope="session")
def engine(db_url: str) -> Iterator[Engine]:
    eng = db.make_engine(db_url)
    yield eng
    eng.dispose()


def _empty(engine: Engine) -> None:
    with engine.begin() as conn:
        if engine.dialect.name == "postgresql":
            conn.execute(text(f"TRUNCATE {', '.join(TABLES)} RESTART IDENTITY CASCADE"))
        else:
            for table in TABLES:
                conn.execute(text(f"DELETE FROM {table}"))


@pytest.fixture
def sessions(engine: Engine) -> Iterator[sessionmaker[Session]]:
    _empty(engine)
    yield db.make_sessionmaker(engine)
    _empty(engine)


@pytest.fixture
def session(sessions: sessionmaker[Session]) -> Iterator[Session]:
    with sessions() as s:
        yield s


@pytest.fixture
def settings(db_url: str, tmp_path: Path) -> Settings:
    return Settings(
        database_url=db_url,
        data_dir=tmp_path,
        api_token=None,
        max_upload_bytes=64 * 1024,
        shared_objects_dir=tmp_path / "shared",
        requeue_interval_s=3600,
        max_poses_per_exploration=100_000,
    )


@pytest.fixture
def client(settings: Settings, sessions: sessionmaker[Session]) -> Iterator[TestClient]:
    with TestClient(create_app(settings)) as c:
        yield c


def box_stl(extents: tuple[float, float, float] = (0.05, 0.05, 0.1)) -> bytes:
    return trimesh.creation.box(extents=extents).export(file_type="stl")


@pytest.fixture
def object_id(client: TestClient) -> int:
    response = client.post("/objects", data={"name": "sphere", "mass_kg": "0.2"})
    assert response.status_code == 201, response.text
    return response.json()["id"]
