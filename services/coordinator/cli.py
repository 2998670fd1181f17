"""`graspscape serve` and `db upgrade|current`: the coordinator's subcommands.

Imports of FastAPI, uvicorn and Alembic stay inside the handlers so `graspscape --help` is
instant.
"""

from __future__ import annotations

import argparse


def _settings(args: argparse.Namespace):  # -> Settings
    from graspscape.services.coordinator.settings import Settings

    overrides = {
        k: v
        for k, v in {
            "database_url": getattr(args, "database_url", None),
            "data_dir": getattr(args, "data_dir", None),
            "host": getattr(args, "host", None),
            "port": getattr(args, "port", None),
        }.items()
        if v is not None
    }
    zenoh = {
        k: v
        for k, v in {
            "enabled": getattr(args, "dispatch", None),
            "mode": getattr(args, "zenoh_mode", None),
            "listen": getattr(args, "zenoh_listen", None),
            "connect": getattr(args, "zenoh_connect", None),
            "users_file": getattr(args, "zenoh_users_file", None),
            "allow_unauthenticated": getattr(args, "zenoh_allow_unauthenticated", None),
        }.items()
        if v is not None
    }
    if zenoh:
        # Nested values merge with the config file's [zenoh] section key by key.
        overrides["zenoh"] = zenoh
    return Settings(**overrides)


def _serve(args: argparse.Namespace) -> int:
    import uvicorn
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.app import create_app
    from sqlalchemy.engine import make_url

    settings = _settings(args)
    url = settings.resolved_database_url
    # The embedded SQLite file belongs to this process alone, so bringing its schema up to
    # date here is safe; a shared PostgreSQL is migrated by its own step (`db upgrade`).
    if args.migrate or (args.migrate is None and make_url(url).get_backend_name() == "sqlite"):
        db.upgrade(url)
    uvicorn.run(
        create_app(settings), host=settings.host, port=settings.port, log_level=args.log_level
    )
    return 0


def _db_upgrade(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator import db

    db.upgrade(_settings(args).resolved_database_url, args.revision)
    return 0


def _db_current(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator import db

    engine = db.make_engine(_settings(args).resolved_database_url)
    try:
        print(f"current: {db.current_revision(engine)}  head: {db.head_revision()}")
    finally:
        engine.dispose()
    return 0


def _database_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--database-url", help="SQLAlchemy URL (default: settings)")
    parser.add_argument("--data-dir", help="folder of the embedded SQLite database")


def register(subparsers: argparse._SubParsersAction) -> None:
    serve = subparsers.add_parser("serve", help="run the coordinator (REST API)")
    serve.add_argument("--host", help="bind address (default: settings, 127.0.0.1)")
    serve.add_argument("--port", type=int, help="port (default: settings, 8000)")
    _database_options(serve)
    serve.add_argument(
        "--migrate",
        dest="migrate",
        action="store_true",
        default=None,
        help="run 'db upgrade' first (default: only for SQLite)",
    )
    serve.add_argument("--no-migrate", dest="migrate", action="store_false")
    serve.add_argument(
        "--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"]
    )
    serve.add_argument(
        "--no-dispatch",
        dest="dispatch",
        action="store_false",
        default=True,
        help="REST API only: no zenoh dispatch to workers",
    )
    serve.add_argument(
        "--zenoh-mode", choices=["peer", "client"], help="peer (embedded, default) or client"
    )
    serve.add_argument(
        "--zenoh-listen",
        action="append",
        metavar="ENDPOINT",
        help="endpoint the embedded peer listens on (repeatable; default tcp/127.0.0.1:7447)",
    )
    serve.add_argument(
        "--zenoh-connect",
        action="append",
        metavar="ENDPOINT",
        help="zenoh router to connect to, e.g. tcp/router:7447 (repeatable)",
    )
    serve.add_argument(
        "--zenoh-users-file",
        metavar="FILE",
        help="zenoh dictionary (user:password lines) of the workers the peer accepts; or set "
        "GRASPSCAPE_ZENOH__PASSWORD (and __USER, default graspscape) for one shared login",
    )
    serve.add_argument(
        "--zenoh-allow-unauthenticated",
        action="store_true",
        default=None,
        help="listen beyond loopback without authentication (refused otherwise)",
    )
    serve.set_defaults(handler=_serve)

    database = subparsers.add_parser("db", help="coordinator database schema")
    actions = database.add_subparsers(dest="db_command", required=True, metavar="ACTION")
    upgrade = actions.add_parser("upgrade", help="apply migrations (alembic upgrade)")
    upgrade.add_argument("revision", nargs="?", default="head")
    _database_options(upgrade)
    upgrade.set_defaults(handler=_db_upgrade)
    current = actions.add_parser("current", help="show the schema revision")
    _database_options(current)
    current.set_defaults(handler=_db_current)
