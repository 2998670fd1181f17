"""`graspscape serve`, `explore` and `db upgrade|current`: the coordinator's subcommands.

Imports of FastAPI, uvicorn and Alembic stay inside the handlers so `graspscape --help` is
instant.
"""

from __future__ import annotations

import argparse
from pathlib import Path


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


def _explore(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator.dispatch.explore import ExploreOptions, run_explore

    options = {
        "object": args.object,
        "gripper": args.gripper,
        "dtheta_deg": args.dtheta,
        "r_min": args.r_min,
        "r_max": args.r_max,
        "dr": args.dr,
        "rolls": args.rolls,
        "levels": args.levels,
        "procs": args.procs,
        "data_dir": args.data_dir,
        "mass_kg": args.mass,
        "friction": args.friction,
        "robustness": None if args.robustness is None else tuple(
            t.strip() for t in args.robustness.split(",") if t.strip() and t.strip() != "none"),
        "quiet": args.quiet,
    }
    return run_explore(ExploreOptions(**{k: v for k, v in options.items() if v is not None}))


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

    from graspscape.services.coordinator.dispatch.explore_defaults import (
        DEFAULT_DTHETA_DEG,
        DEFAULT_R,
    )

    explore = subparsers.add_parser(
        "explore",
        help="explore an object on this machine: coordinator (SQLite) + local workers",
        epilog="The last line says how the exploration ended; exit status 0 done (every pose "
        "stored), 2 incomplete (tiles failed, some poses stored), 1 failed (no pose stored) or "
        "cancelled, 130 interrupted. The same command again resumes an unfinished exploration "
        "and queues its failed tiles again.",
    )
    explore.add_argument(
        "object", help="built-in name (sphere, cube, mug, ...), pb:<name>, ycb:<Folder> or a "
        "mesh file"
    )
    explore.add_argument("--gripper", help="gripper spec name (default robotiq_3f)")
    explore.add_argument(
        "--dtheta",
        type=float,
        help=f"angle between approach directions, degrees (default {DEFAULT_DTHETA_DEG:g})",
    )
    explore.add_argument("--r-min", type=float, help=f"smallest start gap, m ({DEFAULT_R[0]})")
    explore.add_argument("--r-max", type=float, help=f"largest start gap, m ({DEFAULT_R[1]})")
    explore.add_argument("--dr", type=float, help=f"start gap step, m ({DEFAULT_R[2]})")
    explore.add_argument("--rolls", type=int, choices=[1, 2, 4, 8], help="rolls per point (1)")
    explore.add_argument("--levels", type=int, choices=range(7), metavar="{0..6}",
                         help="border refinement levels (1): halvings of the grid where "
                         "neighbouring poses differ")
    explore.add_argument("--procs", type=int, help="worker processes (default: cores)")
    explore.add_argument(
        "--data-dir", type=Path, help="folder of the database and results (default data)"
    )
    explore.add_argument("--mass", type=float, help="object mass, kg")
    explore.add_argument("--friction", type=float, help="object friction coefficient")
    explore.add_argument(
        "--robustness", metavar="TESTS",
        help="robustness tests run on every held pose, comma-separated "
        "(torque_margin, friction_margin, gravity, force, tug, shake), or 'none'; "
        "default: the exploration spec's")
    explore.add_argument("--quiet", action="store_true", help="no progress bar")
    explore.set_defaults(handler=_explore)

    database = subparsers.add_parser("db", help="coordinator database schema")
    actions = database.add_subparsers(dest="db_command", required=True, metavar="ACTION")
    upgrade = actions.add_parser("upgrade", help="apply migrations (alembic upgrade)")
    upgrade.add_argument("revision", nargs="?", default="head")
    _database_options(upgrade)
    upgrade.set_defaults(handler=_db_upgrade)
    current = actions.add_parser("current", help="show the schema revision")
    _database_options(current)
    current.set_defaults(handler=_db_current)
