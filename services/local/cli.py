"""The one `graspscape` command: composes the subcommands of both sides.

Each side registers its own (`register(subparsers)`): the workers' (`worker`, `eval-pose`, …),
the coordinator's (`serve`, `db`, `map show|export`); this composing package adds those that
run both on one machine (`explore`, `map run`). Every command runs with the coordinator wired to
the workers' object preparation (`compose.wire`). Heavy imports (pybullet, FastAPI) stay inside
the handlers so that `graspscape --help` stays instant.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from graspscape.services.local.defaults import DEFAULT_DTHETA_DEG, DEFAULT_LEVELS, DEFAULT_R
from graspscape.shared import cli_args


def _explore(args: argparse.Namespace) -> int:
    from graspscape.services.local.explore import ExploreOptions, run_explore
    from graspscape.shared.specs.gripper import engine_problem

    # An MJCF gripper loads in MuJoCo only: refused here, not pose by pose in the workers.
    problem = engine_problem(args.gripper or "robotiq_3f", {args.engine or "pybullet"})
    if problem is not None:
        print(f"graspscape explore: error: {problem} (--engine mujoco)", file=sys.stderr)
        return 2

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
        "scale": args.scale,
        "units": args.units,
        "engine": args.engine,
        "robustness": None if args.robustness is None else tuple(
            t.strip() for t in args.robustness.split(",") if t.strip() and t.strip() != "none"),
        "quiet": args.quiet,
        "new": args.new,
        "uncertainty": args.uncertainty,
        "support": args.support,
        "support_friction": args.support_friction,
        "draw_engines": args.draw_engines,
    }
    return run_explore(ExploreOptions(**{k: v for k, v in options.items() if v is not None}))


def _register_explore(subparsers: argparse._SubParsersAction) -> None:
    explore = subparsers.add_parser(
        "explore",
        help="explore an object on this machine: coordinator (SQLite) + local workers",
        epilog="The last line says how the exploration ended; exit status 0 done (every pose "
        "stored), 2 incomplete (tiles failed, some poses stored), 1 failed (no pose stored) or "
        "cancelled, 130 interrupted. The same command again resumes an unfinished exploration "
        "and queues its failed tiles again.",
    )
    cli_args.add_object(explore)
    cli_args.add_gripper(explore)
    cli_args.add_grid(explore, dtheta=DEFAULT_DTHETA_DEG, r=DEFAULT_R, levels=DEFAULT_LEVELS)
    cli_args.add_procs(explore)
    cli_args.add_store(explore, data_dir_default="data", url=False)
    cli_args.add_object_properties(explore)
    cli_args.add_support(explore)
    explore.add_argument(
        "--robustness", metavar="TESTS",
        help="robustness tests run on every held pose, comma-separated "
        "(torque_margin, friction_margin, gravity, force, tug, shake), or 'none'; "
        "default: the exploration spec's")
    explore.add_argument("--engine", choices=["pybullet", "mujoco"],
                         help="physics engine (default pybullet; docs/design/simulation.md)")
    explore.add_argument(
        "--uncertainty", choices=["none", "lab", "field"],
        help="the errors P(success) is stated and certified under: lab (default; 2 mm / 2° "
        "start pose error), field (5 mm / 5°, friction ×0.5–1, mass ×0.8–1.2) or none")
    cli_args.add_draw_engines(explore)
    explore.add_argument("--quiet", action="store_true", help="no progress bar")
    explore.add_argument("--new", action="store_true",
                         help="explore again even where this very exploration is done (by "
                         "default its stored results are printed)")
    explore.set_defaults(handler=_explore)


def _atlas(args: argparse.Namespace) -> int:
    from graspscape.services.local.atlas import AtlasOptions, run_atlas

    given = {"setting": args.setting, "objects_dir": args.objects_dir,
             "only": tuple(args.only or ()),
             "data_dir": args.data_dir, "out": args.out, "database_url": args.database_url,
             "procs": args.procs, "pictures": not args.no_pictures, "quiet": args.quiet,
             "support": args.support, "support_friction": args.support_friction}
    return run_atlas(AtlasOptions(**{k: v for k, v in given.items() if v is not None}))


def _register_atlas(subparsers: argparse._SubParsersAction) -> None:
    atlas = subparsers.add_parser(
        "atlas", help="explore every object in ../shared/objects and the built-ins with one "
        "setting and write a static site (docs/howto/atlas.md)",
        epilog="Resumable: objects already explored with the setting are skipped. Exit status "
        "0 when every exploration is done, 2 when some ended otherwise.")
    atlas.add_argument("--setting", choices=["reduced", "full"],
                       help="reduced (default: 30° grid, no refinement, no robustness tests; "
                       "under an hour on 2 cores) or full (explore's defaults)")
    atlas.add_argument("--objects-dir", type=Path, help="objects folder: "
                       "ycb/<Folder>/model.urdf and mesh files (default ../shared/objects "
                       "beside the checkout)")
    cli_args.add_hidden_alias(atlas, "--objects", "objects_dir", type=Path)
    atlas.add_argument("--only", action="append", metavar="NAME",
                       help="only this object (repeatable), e.g. mug or ycb:YcbBanana")
    atlas.add_argument("--out", type=Path, help="site folder (default atlas)")
    cli_args.add_support(atlas)
    cli_args.add_store(atlas, data_dir_default="atlas-data")
    cli_args.add_procs(atlas, "local worker processes (default: cores; 0: none, the workers "
                       "of the coordinator whose --database-url is given)", low=0)
    atlas.add_argument("--no-pictures", action="store_true",
                       help="no best-grasp pictures in the site (each is a simulation)")
    atlas.add_argument("--quiet", action="store_true", help="no progress lines")
    atlas.set_defaults(handler=_atlas)


def build_parser() -> argparse.ArgumentParser:
    from graspscape.services.client import cli as client_cli
    from graspscape.services.coordinator import cli as coordinator_cli
    from graspscape.services.coordinator.maps import cli as maps_cli
    from graspscape.services.local.gripper_cli import register as register_gripper
    from graspscape.services.local.map_run import register_run
    from graspscape.workers import cli as workers_cli

    parser = argparse.ArgumentParser(
        prog="graspscape",
        description="Map the behavioral manifolds of an object for a gripper.",
    )
    subparsers = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    workers_cli.register(subparsers)
    coordinator_cli.register(subparsers)
    _register_explore(subparsers)
    _register_atlas(subparsers)
    register_run(maps_cli.register(subparsers))
    register_gripper(subparsers)
    client_cli.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    cli_args.resolve_object(parser, args)
    try:
        from graspscape.services.local.compose import wire

        wire()
        return int(args.handler(args) or 0)
    except KeyboardInterrupt:
        return 130
    except Exception as exc:  # one clear line for users instead of a traceback
        if getattr(args, "debug", False):
            raise
        print(f"graspscape {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return 1


def one_line(exc: Exception) -> str:
    """An error as one line: pydantic's multi-line dump as `field: why` per error (a
    validator's own message without pydantic's "Value error, "), anything else joined."""
    from pydantic import ValidationError

    if not isinstance(exc, ValidationError):
        return " ".join(str(exc).split())
    parts = []
    for e in exc.errors(include_url=False):
        where = ".".join(str(part) for part in e["loc"])
        why = str(e["msg"]).removeprefix("Value error, ")
        shown = f" (got {e['input']!r})" if not isinstance(e.get("input"), dict | list) else ""
        parts.append(f"{where}: {why}{shown}" if where else why)
    return "; ".join(" ".join(part.split()) for part in parts)


if __name__ == "__main__":
    sys.exit(main())
