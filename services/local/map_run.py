"""`graspscape map run`: explore an object in this process (pybullet, SQLite) and map it.

The same store code and composition as `explore` (`compose`), driven by the in-process run
(`run.run_local`) instead of worker processes over zenoh.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from graspscape.shared import cli_args

# `map run`'s grid: coarser than explore's, for a quick map (degrees; r_min, r_max, dr in m).
RUN_DTHETA_DEG = 30.0
RUN_R = (0.0, 0.02, 0.01)


def register_run(map_actions: Any) -> None:
    from graspscape.services.coordinator.maps.cli import picture_args

    run = map_actions.add_parser("run", help="explore an object here (pybullet, SQLite) and "
                                 "map it")
    cli_args.add_object(run)
    cli_args.add_gripper(run)
    cli_args.add_grid(run, dtheta=RUN_DTHETA_DEG, r=RUN_R, levels=1)
    run.add_argument("--normal-reuse", action="store_true",
                     help="shortcut 1: reuse a normal's results across its start gaps")
    cli_args.add_support(run)
    cli_args.add_procs(run, "simulation processes (default 1)")
    cli_args.add_hidden_alias(run, "--processes", "procs", type=int)
    cli_args.add_store(run, data_dir_default="a new temporary folder", url=False)
    cli_args.add_hidden_alias(run, "--db", "db", type=Path)
    run.add_argument("-o", "--out", type=Path, default=Path("map.png"),
                     help="map picture, PNG or SVG by suffix (default map.png)")
    run.add_argument("--table", type=Path, default=None,
                     help="also write the manifold table here (JSON)")
    picture_args(run)
    run.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator.exploration.service import create_explorations
    from graspscape.services.local.compose import open_store, store_object
    from graspscape.services.local.run import pybullet_evaluator, run_local
    from graspscape.shared.specs.exploration import ExplorationSpec
    from graspscape.shared.specs.objects import ObjectSpec
    from graspscape.shared.specs.sim import SimSettings

    if args.db is not None:  # the earlier --db FILE
        path = args.db
    else:
        path = (args.data_dir or Path(tempfile.mkdtemp())) / "coordinator.db"
        path.parent.mkdir(parents=True, exist_ok=True)
    given = {"dtheta": args.dtheta, "r_min": args.r_min, "r_max": args.r_max, "dr": args.dr}
    defaults = dict(zip(("dtheta", "r_min", "r_max", "dr"), (RUN_DTHETA_DEG, *RUN_R),
                        strict=True))
    grid = {k: defaults[k] if v is None else v for k, v in given.items()}
    gripper = args.gripper or "robotiq_3f"
    engine, sessions = open_store(f"sqlite:///{path}")
    with sessions() as session:
        spec = ExplorationSpec(
            object_id=store_object(session, args.object), gripper=gripper,
            label=args.object,
            grid={**grid, "dtheta": math.radians(grid["dtheta"]),
                  "attitudes": {"rolls": args.rolls or 1}},
            refinement={"levels": 1 if args.levels is None else args.levels},
            shortcuts={"normal_reuse": args.normal_reuse},
            support={"kind": args.support or "none",
                     **({} if args.support_friction is None
                        else {"friction": args.support_friction})},
        )
        rows = create_explorations(session, spec=spec, tile_target_poses=50, max_poses=10**7)
        tables = {row.id: ExplorationSpec.model_validate(row.spec).settings.table
                  for row in rows}
    procs = args.procs or 1
    pool = ProcessPoolExecutor(procs) if procs > 1 else None
    obj = ObjectSpec(name=args.object)
    try:
        # On a table each exploration simulates its own resting pose.
        evaluators = {i: pybullet_evaluator(obj, gripper, SimSettings(table=table), pool=pool)
                      for i, table in tables.items() if table is not None}
        stats = run_local(sessions, pybullet_evaluator(obj, gripper, pool=pool),
                          evaluators=evaluators)
    finally:
        if pool is not None:
            pool.shutdown()
    print(f"{stats.evaluated} poses evaluated in {stats.wall_s:.0f} s ({path})", file=sys.stderr)
    for k, exploration_id in enumerate(tables):
        write_outputs(sessions, exploration_id, args, f"-rest{k}" if len(tables) > 1 else "")
    engine.dispose()
    return 0


def write_outputs(sessions, exploration_id: int, args: argparse.Namespace, tag: str) -> None:
    """The map picture (and the manifold table where asked) of one exploration; `tag` goes
    before the suffix of each file name (one exploration per resting pose on a table)."""
    from graspscape.services.coordinator.manifolds.service import stored_manifolds
    from graspscape.services.coordinator.manifolds.summary import table_rows_of
    from graspscape.services.coordinator.maps.cli import write_picture

    def tagged(path: Path) -> Path:
        return path.with_name(f"{path.stem}{tag}{path.suffix}")

    write_picture(sessions, exploration_id, argparse.Namespace(**{**vars(args),
                                                                  "out": tagged(args.out)}))
    if args.table is not None:
        with sessions() as session:
            items = stored_manifolds(session, exploration_id)
        tagged(args.table).write_text(json.dumps(table_rows_of(items), indent=2))
