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


def register_run(map_actions: Any) -> None:
    from graspscape.services.coordinator.maps.cli import picture_args

    run = map_actions.add_parser("run", help="explore an object here (pybullet, SQLite) and "
                                 "map it")
    run.add_argument("--object", required=True, help="object name (sphere, cube, mug, …)")
    run.add_argument("--gripper", default="robotiq_3f")
    run.add_argument("--dtheta", type=float, default=30.0, help="coarse step, degrees")
    run.add_argument("--r-min", type=float, default=0.0)
    run.add_argument("--r-max", type=float, default=0.02)
    run.add_argument("--dr", type=float, default=0.01)
    run.add_argument("--rolls", type=int, choices=[1, 2, 4, 8], default=1)
    run.add_argument("--levels", type=int, default=1, help="refinement depth")
    run.add_argument("--normal-reuse", action="store_true", help="shortcut 1")
    run.add_argument("--processes", type=int, default=1)
    run.add_argument("--db", type=Path, default=None, help="SQLite file (default: a temp file)")
    run.add_argument("-o", "--out", type=Path, default=Path("map.png"))
    run.add_argument("--table", type=Path, default=None, help="write the manifold table (JSON)")
    picture_args(run)
    run.set_defaults(handler=_run)


def _run(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.manifolds.service import stored_manifolds
    from graspscape.services.coordinator.manifolds.summary import table_rows_of
    from graspscape.services.coordinator.maps.cli import write_picture
    from graspscape.services.local.compose import open_store, store_object
    from graspscape.services.local.run import pybullet_evaluator, run_local
    from graspscape.shared.specs.exploration import ExplorationSpec
    from graspscape.shared.specs.objects import ObjectSpec

    path = args.db or Path(tempfile.mkdtemp()) / "map.db"
    engine, sessions = open_store(f"sqlite:///{path}")
    with sessions() as session:
        spec = ExplorationSpec(
            object_id=store_object(session, args.object), gripper=args.gripper,
            label=args.object,
            grid={"dtheta": math.radians(args.dtheta), "r_min": args.r_min, "r_max": args.r_max,
                  "dr": args.dr, "attitudes": {"rolls": args.rolls}},
            refinement={"levels": args.levels},
            shortcuts={"normal_reuse": args.normal_reuse},
        )
        exploration_id = create_exploration(session, spec=spec, tile_target_poses=50,
                                            max_poses=10**7).id
    pool = ProcessPoolExecutor(args.processes) if args.processes > 1 else None
    try:
        stats = run_local(sessions, pybullet_evaluator(ObjectSpec(name=args.object),
                                                       args.gripper, pool=pool))
    finally:
        if pool is not None:
            pool.shutdown()
    print(f"{stats.evaluated} poses evaluated in {stats.wall_s:.0f} s ({path})", file=sys.stderr)
    write_picture(sessions, exploration_id, args)
    if args.table is not None:
        with sessions() as session:
            items = stored_manifolds(session, exploration_id)
        args.table.write_text(json.dumps(table_rows_of(items), indent=2))
    engine.dispose()
    return 0
