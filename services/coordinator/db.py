"""Engines, sessions and migrations: one code path for the SQLite file and PostgreSQL.

SQLite gets WAL (readers do not block the single writer), foreign keys (off by default there)
and a busy timeout so that a second connection waits for the writer instead of failing.
"""

from __future__ import annotations

from pathlib import Path

from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

REPO_ROOT = Path(__file__).resolve().parents[2]
MIGRATIONS_DIR = REPO_ROOT / "migrations"


def make_engine(url: str) -> Engine:
    parsed = make_url(url)
    if parsed.get_backend_name() != "sqlite":
        # No pool_pre_ping: it cost a round trip at every transaction's start (7 % of the
        # coordinator's samples with a thousand workers). A connection the server dropped
        # (PostgreSQL restarted) fails its next statement instead; SQLAlchemy sees the
        # disconnect, invalidates the whole pool (every connection older than the failure
        # reconnects at its next checkout) and raises an error with connection_invalidated,
        # which the dispatcher answers `unavailable` (the worker resends) and /healthz as 503:
        # one refused query per thread in flight, then the store answers again.
        return create_engine(url, pool_size=10, max_overflow=10)
    if parsed.database and parsed.database != ":memory:":
        Path(parsed.database).parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, connect_args={"timeout": 30})

    @event.listens_for(engine, "connect")
    def _sqlite_pragmas(dbapi_connection, _record) -> None:  # type: ignore[no-untyped-def]
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA journal_mode=WAL")
        # NORMAL is durable across application crashes in WAL mode; only an OS crash can lose
        # the last commits, which the queue recovers from by re-leasing their tiles.
        cursor.execute("PRAGMA synchronous=NORMAL")
        cursor.execute("PRAGMA foreign_keys=ON")
        cursor.execute("PRAGMA busy_timeout=30000")
        cursor.close()

    return engine


def make_sessionmaker(engine: Engine) -> sessionmaker[Session]:
    return sessionmaker(engine, expire_on_commit=False)


def alembic_config(url: str):  # -> alembic.config.Config; import kept lazy for the CLI
    from alembic.config import Config

    config = Config(str(REPO_ROOT / "alembic.ini"))
    config.set_main_option("script_location", str(MIGRATIONS_DIR))
    # Passed as an attribute, not a config option: configparser would choke on '%' in URLs.
    config.attributes["database_url"] = url
    return config


def upgrade(url: str, revision: str = "head") -> None:
    from alembic import command

    command.upgrade(alembic_config(url), revision)


def head_revision() -> str | None:
    from alembic.script import ScriptDirectory

    return ScriptDirectory(str(MIGRATIONS_DIR)).get_current_head()


def current_revision(engine: Engine) -> str | None:
    from alembic.runtime.migration import MigrationContext

    with engine.connect() as connection:
        return MigrationContext.configure(connection).get_current_revision()


def open_existing(url: str) -> Engine:
    """An engine on a database that exists and has the schema; a read must not create one
    (make_engine makes a SQLite file's folder, connecting makes the file). Refused with the
    commands that make one."""
    parsed = make_url(url)
    hint = ("`graspscape explore OBJECT --data-dir DIR` explores into a new one; "
            "`graspscape db upgrade --database-url URL` makes an empty one")
    file = parsed.database if parsed.get_backend_name() == "sqlite" else None
    if file not in (None, "", ":memory:") and not Path(str(file)).is_file():
        raise FileNotFoundError(f"no database at {parsed.database}: {hint}")
    engine = make_engine(url)
    try:
        revision = current_revision(engine)
    except Exception:
        engine.dispose()
        raise
    if revision is None:
        engine.dispose()
        raise FileNotFoundError(f"the database {parsed.render_as_string(hide_password=True)} "
                                f"has no graspscape schema: {hint}")
    return engine
