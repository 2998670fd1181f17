"""The `graspscape worker` subcommand (registered from graspscape.workers.cli)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from graspscape.shared import cli_args


def _password(args: argparse.Namespace) -> str | None:
    """--zenoh-password-file (its first line), else GRASPSCAPE_ZENOH__PASSWORD; empty: none."""
    if args.zenoh_password_file is not None:
        lines = args.zenoh_password_file.read_text().splitlines()
        return (lines[0].strip() if lines else "") or None
    return os.environ.get("GRASPSCAPE_ZENOH__PASSWORD") or None


def _worker(args: argparse.Namespace) -> int:
    from graspscape.workers.runtime.config import WorkerConfig
    from graspscape.workers.runtime.supervisor import run_worker

    options = {
        "zenoh_user": args.zenoh_user or os.environ.get("GRASPSCAPE_ZENOH__USER") or None,
        "zenoh_password": _password(args),
        "connect": args.connect or None,
        "procs": args.procs,
        "name": args.name,
        "cache_dir": args.cache_dir,
        "instant": args.instant or None,
        "instant_pose_s": args.instant_pose_s,
        "tiles_per_request": args.tiles_per_request,
        "engines": tuple(args.engine.split(",")) if args.engine else None,
    }
    config = WorkerConfig(**{k: v for k, v in options.items() if v is not None})
    return run_worker(config, args.log_level)


def register_worker(subparsers: argparse._SubParsersAction) -> None:
    worker = subparsers.add_parser(
        "worker", help="evaluate tiles of poses for a coordinator (pulls work over zenoh)"
    )
    worker.add_argument(
        "--connect",
        action="append",
        metavar="ENDPOINT",
        help="coordinator or zenoh router endpoint, e.g. tcp/10.0.0.5:7447 (repeatable; "
        "default tcp/127.0.0.1:7447)",
    )
    cli_args.add_procs(worker, "simulation processes (default: cores)")
    worker.add_argument("--name", help="worker name; process ids are <name>-p<i>-<pid>")
    worker.add_argument("--cache-dir", type=Path,
                        help="object cache (default: GRASPSCAPE_CACHE_DIR or ~/.cache/graspscape)")
    worker.add_argument("--instant", action="store_true",
                        help="benchmarks only: answer every pose at once without physics")
    worker.add_argument("--instant-pose-s", type=float, metavar="SECONDS",
                        help="with --instant: seconds each pose takes (a sleep; fault tests)")
    worker.add_argument("--tiles-per-request", type=int,
                        help="tiles a process asks for at once (default 1; more only for "
                        "very short tiles, as with --instant)")
    worker.add_argument("--engine", metavar="ENGINES",
                        help="physics engines this worker runs, comma-separated (pybullet, "
                        "mujoco; default: every one installed); it is leased tiles of those")
    worker.add_argument("--zenoh-user",
                        help="zenoh login where the coordinator or router asks for one "
                        "(default: GRASPSCAPE_ZENOH__USER, else graspscape)")
    worker.add_argument("--zenoh-password-file", type=Path, metavar="FILE",
                        help="file whose first line is the zenoh password (default: "
                        "GRASPSCAPE_ZENOH__PASSWORD; none: no login)")
    worker.add_argument("--log-level", default="info",
                        choices=["critical", "error", "warning", "info", "debug"],
                        help="log messages from this level up (default info)")
    worker.set_defaults(handler=_worker)
