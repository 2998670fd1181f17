"""The one `graspscape` command. Each side registers its own subcommands.

Subcommand modules expose `register(subparsers)`; they keep heavy imports (pybullet, FastAPI)
inside their handlers so that `graspscape --help` stays instant.
"""

from __future__ import annotations

import argparse
import importlib
import sys

SUBCOMMAND_MODULES = (
    "graspscape.workers.cli",
    "graspscape.services.coordinator.cli",
    "graspscape.services.coordinator.maps.cli",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="graspscape",
        description="Map the behavioral manifolds of an object for a gripper.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name != name:
                raise
            continue  # that side is not built yet
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # one clear line for users instead of a traceback
        if getattr(args, "debug", False):
            raise
        print(f"graspscape {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
