"""The `graspscape worker` subcommand (registered from graspscape.workers.cli)."""

from __future__ import annotations

import argparse
from pathlib import Path


def _worker(args: argparse.Namespace) -> int:
    from graspscape.workers.runtime.config import WorkerConfig
    from graspscape.workers.runtime.supervisor import run_worker

    options = {
        "connect": args.connect or None,
        "procs": args.procs,
        "name": args.name,
        "cache_dir": args.cache_dir,
        "instant": args.instant or None,
        "tiles_per_request": args.tiles_per_request,
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
    worker.add_argument("--procs", type=int, help="simulation processes (default: cores)")
    worker.add_argument("--name", help="worker name; process ids are <name>-p<i>-<pid>")
    worker.add_argument("--cache-dir", type=Path,
                        help="object cache (default: GRASPSCAPE_CACHE_DIR or ~/.cache/graspscape)")
    worker.add_argument("--instant", action="store_true",
                        help="benchmarks only: answer every pose at once without physics")
    worker.add_argument("--tiles-per-request", type=int,
                        help="tiles a process asks for at once (default 1; more only for "
                        "very short tiles, as with --instant)")
    worker.add_argument("--log-level", default="info",
                        choices=["critical", "error", "warning", "info", "debug"])
    worker.set_defaults(handler=_worker)
