"""Fixtures of the dispatch tests: a migrated database per test (SQLite file, or a fresh
PostgreSQL schema) and its sessions."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest
from graspscape.services.coordinator import db
from sqlalchemy.orm import Session, sessionmaker

PG_URL = os.environ.get(
    "GRASPSCAPE_TEST_PG_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
)


def _sqlite(tmp_path: Path) -> Iterator[str]:
    url = f"sqlite:///{tmp_path / 'coordinator.db'}"
    db.upgrade(url)
    yield url


def _postgres() -> Iterator[str]:
    schema = f"gs_dispatch_{uuid.uuid4().hex[:12]}"
    conninfo = PG_URL.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    url = f"{PG_URL}?options=-csearch_path%3D{schema}"
    try:
        db.upgrade(url)
        yield url
    finally:
        with psycopg.connect(conninfo, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


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
