"""Database fixtures of the whole suite, on the real backends: SQLite and the PostgreSQL server.

Every schema is made by `alembic upgrade head` (never create_all). `db_url` is one migrated
database per backend for the whole session (tables emptied around each test through
`sessions`); `any_url` / `sqlite_url` are a fresh database per test for suites that need one
of their own (dispatch, restart). PostgreSQL schemas are private (search_path in the URL), so
parallel runs and other suites sharing the `test` database do not collide.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest
from graspscape.services.coordinator import db
from sqlalchemy import Engine, text
from sqlalchemy.orm import Session, sessionmaker

PG_URL = os.environ.get(
    "GRASPSCAPE_TEST_PG_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
)
TABLES = ("poses", "manifolds", "tiles", "explorations", "objects", "workers")


def _pg_conninfo() -> str:
    return PG_URL.replace("postgresql+psycopg://", "postgresql://")


def _sqlite(directory: Path) -> Iterator[str]:
    url = f"sqlite:///{directory / 'coordinator.db'}"
    db.upgrade(url)
    yield url


def _postgres() -> Iterator[str]:
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


@pytest.fixture(scope="session", params=["sqlite", "postgresql"])
def db_url(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[str]:
    if request.param == "sqlite":
        yield from _sqlite(tmp_path_factory.mktemp("sqlite"))
    else:
        yield from _postgres()


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
def sqlite_url(tmp_path: Path) -> Iterator[str]:
    yield from _sqlite(tmp_path)


@pytest.fixture(params=["sqlite", "postgresql"])
def any_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    yield from (_sqlite(tmp_path) if request.param == "sqlite" else _postgres())


def _sessions(url: str) -> Iterator[sessionmaker[Session]]:
    engine = db.make_engine(url)
    yield db.make_sessionmaker(engine)
    engine.dispose()


@pytest.fixture
def sqlite_sessions(sqlite_url: str) -> Iterator[sessionmaker[Session]]:
    yield from _sessions(sqlite_url)


@pytest.fixture
def any_sessions(any_url: str) -> Iterator[sessionmaker[Session]]:
    yield from _sessions(any_url)
