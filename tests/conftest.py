"""Database fixtures of the whole suite, on the real backends: SQLite and the PostgreSQL server.

Every schema is made by `alembic upgrade head` (never create_all). `db_url` is one migrated
database per backend for the whole session (tables emptied around each test through
`sessions`); `any_url` / `sqlite_url` are a database per test that no other test uses, for
suites that need one of their own (dispatch, restart). PostgreSQL schemas are private
(search_path in the URL), so parallel runs and other suites sharing the `test` database do not
collide.

What keeps this cheap (the default suite's budget): migrating costs 0.4-1.2 s a database and
PostgreSQL's TRUNCATE 0.1-0.4 s (it swaps every table's and index's files), against ~1 ms for
DELETE of a test's few rows. So SQLite is migrated once per session into a template file that
each test copies, PostgreSQL's `any_url` is one migrated schema per session handed to one test
at a time and emptied before each (DELETE in foreign-key order, sequences restarted: the state
a fresh `upgrade head` leaves), and `sessions` empties by DELETE as well.
"""

from __future__ import annotations

import os
import sqlite3
import uuid
import weakref
from collections.abc import Iterator
from pathlib import Path

import psycopg
import pytest
from graspscape.services.coordinator import db
from graspscape.services.coordinator.store.models import Base
from sqlalchemy import Engine, inspect, text
from sqlalchemy.orm import Session, sessionmaker

PG_URL = os.environ.get(
    "GRASPSCAPE_TEST_PG_URL", "postgresql+psycopg://postgres@127.0.0.1:5432/test"
)
# Children before parents, so that DELETE never trips a foreign key.
_MODEL_TABLES = [t.name for t in reversed(Base.metadata.sorted_tables)]
# PostgreSQL's TRUNCATE … RESTART IDENTITY, for the sequences: the next id is the first again.
_RESTART_SEQUENCES = text(
    "SELECT setval(format('%I.%I', schemaname, sequencename), start_value, false) "
    "FROM pg_sequences WHERE schemaname = current_schema()"
)


def _pg_conninfo() -> str:
    return PG_URL.replace("postgresql+psycopg://", "postgresql://")


def _migrated_sqlite(path: Path) -> None:
    db.upgrade(f"sqlite:///{path}")


def _sqlite(directory: Path, template: Path | None = None) -> Iterator[str]:
    """A migrated SQLite file in `directory`: a copy of `template` (a migrated file) where
    given, else made by `upgrade head`."""
    path = directory / "coordinator.db"
    if template is None:
        _migrated_sqlite(path)
    else:
        # The backup API copies a consistent database whatever its journal (WAL) holds.
        with sqlite3.connect(template) as source, sqlite3.connect(path) as target:
            source.backup(target)
        source.close()
        target.close()
    yield f"sqlite:///{path}"


def _postgres() -> Iterator[str]:
    """A private schema migrated to head, dropped afterwards."""
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


def _tables(engine: Engine) -> list[str]:
    """The database's tables, dependents first: the models' order, then any table a migration
    made that no model names (emptied first, since nothing is known of its keys)."""
    present = set(inspect(engine).get_table_names()) - {"alembic_version"}
    return sorted(present - set(_MODEL_TABLES)) + [t for t in _MODEL_TABLES if t in present]


_TABLES_OF: weakref.WeakKeyDictionary[Engine, list[str]] = weakref.WeakKeyDictionary()


def _empty(engine: Engine) -> None:
    tables = _TABLES_OF.get(engine)
    if tables is None:
        tables = _TABLES_OF[engine] = _tables(engine)
    with engine.begin() as conn:
        for table in tables:
            conn.execute(text(f'DELETE FROM "{table}"'))
        if engine.dialect.name == "postgresql":
            conn.execute(_RESTART_SEQUENCES)


@pytest.fixture(scope="session")
def sqlite_template(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One SQLite file migrated to head for the session; tests get copies."""
    path = tmp_path_factory.mktemp("sqlite-template") / "template.db"
    _migrated_sqlite(path)
    return path


@pytest.fixture(scope="session", params=["sqlite", "postgresql"])
def db_url(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[str]:
    if request.param == "sqlite":
        template = request.getfixturevalue("sqlite_template")
        yield from _sqlite(tmp_path_factory.mktemp("sqlite"), template)
    else:
        yield from _postgres()


@pytest.fixture(scope="session")
def engine(db_url: str) -> Iterator[Engine]:
    eng = db.make_engine(db_url)
    yield eng
    eng.dispose()


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
def sqlite_url(tmp_path: Path, sqlite_template: Path) -> Iterator[str]:
    yield from _sqlite(tmp_path, sqlite_template)


@pytest.fixture(scope="session")
def _own_postgres() -> Iterator[tuple[str, Engine]]:
    """The schema behind `any_url[postgresql]`: migrated once, lent to one test at a time."""
    for url in _postgres():
        engine = db.make_engine(url)
        try:
            yield url, engine
        finally:
            engine.dispose()


@pytest.fixture(params=["sqlite", "postgresql"])
def any_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    if request.param == "sqlite":
        yield from _sqlite(tmp_path, request.getfixturevalue("sqlite_template"))
        return
    url, engine = request.getfixturevalue("_own_postgres")
    _empty(engine)  # as `upgrade head` leaves it, whatever the previous borrower stored
    yield url
    _empty(engine)


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
