"""`graspscape serve` and `db upgrade|current`: the coordinator's subcommands.

Imports of FastAPI, uvicorn and Alembic stay inside the handlers so `graspscape --help` is
instant.
"""

from __future__ import annotations

import argparse

from graspscape.shared import cli_args


def _given(args: argparse.Namespace, names: dict[str, str]) -> dict[str, object]:
    """{setting: value} of the options given on the command line (option dest → setting)."""
    values = {key: getattr(args, dest, None) for dest, key in names.items()}
    return {key: value for key, value in values.items() if value is not None}


def _settings(args: argparse.Namespace):  # -> Settings
    from graspscape.services.coordinator.settings import Settings

    sections = {
        "database": _given(args, {"database_url": "url", "data_dir": "data_dir"}),
        "api": _given(args, {"host": "host", "port": "port"}),
        "zenoh": _given(args, {
            "dispatch": "enabled", "zenoh_mode": "mode", "zenoh_listen": "listen",
            "zenoh_connect": "connect", "zenoh_users_file": "users_file",
            "zenoh_allow_unauthenticated": "allow_unauthenticated"}),
    }
    # Each section merges with the environment's and the config file's key by key.
    return Settings(**{name: values for name, values in sections.items() if values})


def _serve(args: argparse.Namespace) -> int:
    import uvicorn
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.app import create_app
    from sqlalchemy.engine import make_url

    settings = _settings(args)
    url = settings.database.resolved_url
    # The embedded SQLite file belongs to this process alone, so bringing its schema up to
    # date here is safe; a shared PostgreSQL is migrated by its own step (`db upgrade`).
    if args.migrate or (args.migrate is None and make_url(url).get_backend_name() == "sqlite"):
        db.upgrade(url)
    uvicorn.run(
        create_app(settings), host=settings.api.host, port=settings.api.port,
        log_level=args.log_level,
    )
    return 0


def _db_upgrade(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator import db

    db.upgrade(_settings(args).database.resolved_url, args.revision)
    return 0


def _db_current(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator import db

    engine = db.make_engine(_settings(args).database.resolved_url)
    try:
        print(f"current: {db.current_revision(engine)}  head: {db.head_revision()}")
    finally:
        engine.dispose()
    return 0


def _database_options(parser: argparse.ArgumentParser) -> None:
    cli_args.add_store(parser)


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
    serve.add_argument("--no-migrate", dest="migrate", action="store_false",
                       help="do not run 'db upgrade' first, even for SQLite")
    serve.add_argument(
        "--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"],
        help="log messages from this level up (default info)"
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
    upgrade.add_argument("revision", nargs="?", default="head",
                         help="the schema revision to migrate to (default head)")
    _database_options(upgrade)
    upgrade.set_defaults(handler=_db_upgrade)
    current = actions.add_parser("current", help="show the schema revision")
    _database_options(current)
    current.set_defaults(handler=_db_current)
