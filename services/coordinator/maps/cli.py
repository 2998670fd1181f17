"""`graspscape map`: pictures, exports and local runs of behavioral maps from the command line.

  graspscape map show ID [-o map.png|map.svg] [--cut vertical --phi0 90] [--attitude 0]
  graspscape map export ID --what poses.csv|poses.parquet|manifolds.json -o FILE
  graspscape map run --object mug [--dtheta 30 --levels 2 …] -o map.png [--db run.db]

`show` and `export` read the coordinator's database (--database-url, default: the
coordinator's settings); `run` explores an object in this process (pybullet, SQLite) with the
same store code as the coordinator and writes the map and the manifold table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("map", help="behavioral map pictures, exports, local runs")
    sub = parser.add_subparsers(dest="map_command", required=True, metavar="ACTION")

    show = sub.add_parser("show", help="write the map picture of an exploration")
    show.add_argument("exploration_id", type=int)
    show.add_argument("-o", "--out", type=Path, default=Path("map.png"),
                      help="PNG or SVG by suffix (default map.png)")
    _picture_args(show)
    show.add_argument("--database-url", default=None)
    show.set_defaults(handler=_show)

    exp = sub.add_parser("export", help="export poses (CSV, Parquet) or the manifold table")
    exp.add_argument("exploration_id", type=int)
    exp.add_argument("--what", choices=["poses.csv", "poses.parquet", "manifolds.json"],
                     default="poses.csv")
    exp.add_argument("-o", "--out", type=Path, required=True)
    exp.add_argument("--database-url", default=None)
    exp.set_defaults(handler=_export)

    run = sub.add_parser("run", help="explore an object here (pybullet, SQLite) and map it")
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
    _picture_args(run)
    run.set_defaults(handler=_run)


def _picture_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cut", choices=["horizontal", "vertical"], default="horizontal")
    parser.add_argument("--phi0", type=float, default=0.0, help="vertical cut azimuth, degrees")
    parser.add_argument("--attitude", type=int, default=0, help="attitude index of the cut")


def _sessions(url: str | None) -> Any:
    from graspscape.services.coordinator import db

    if url is None:
        from graspscape.services.coordinator.settings import get_settings

        url = get_settings().resolved_database_url
    return db.make_sessionmaker(db.make_engine(url))


def _write_picture(sessions: Any, exploration_id: int, args: argparse.Namespace) -> None:
    from graspscape.services.coordinator.maps.picture import write_map_files

    with sessions() as session:
        manifolds, poses = write_map_files(session, exploration_id, args.out, cut=args.cut,
                                           phi0_deg=args.phi0, attitude=args.attitude)
    print(f"{args.out}: {manifolds} manifolds, {poses} poses")


def _show(args: argparse.Namespace) -> int:
    _write_picture(_sessions(args.database_url), args.exploration_id, args)
    return 0


def _export(args: argparse.Namespace) -> int:
    from graspscape.services.coordinator.manifolds import export
    from graspscape.services.coordinator.manifolds.service import (
        ensure_manifolds,
        stored_manifolds,
    )

    sessions = _sessions(args.database_url)
    with sessions() as session:
        ensure_manifolds(session, args.exploration_id)
        if args.what == "manifolds.json":
            items = stored_manifolds(session, args.exploration_id)
            args.out.write_text(json.dumps([m.model_dump(mode="json") for m in items], indent=2))
        else:
            records = export.pose_records(session, args.exploration_id)
            data = export.poses_csv(records) if args.what == "poses.csv" else export.poses_parquet(
                records)
            args.out.write_bytes(data)
    print(args.out)
    return 0


def _run(args: argparse.Namespace) -> int:
    import tempfile
    from concurrent.futures import ProcessPoolExecutor

    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.exploration.local_run import (
        pybullet_evaluator,
        run_local,
    )
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.manifolds.service import stored_manifolds
    from graspscape.services.coordinator.manifolds.summary import table_rows_of
    from graspscape.services.coordinator.objects.service import create_named
    from graspscape.shared.specs.exploration import ExplorationSpec
    from graspscape.shared.specs.objects import ObjectSpec

    path = args.db or Path(tempfile.mkdtemp()) / "map.db"
    url = f"sqlite:///{path}"
    db.upgrade(url)
    sessions = db.make_sessionmaker(db.make_engine(url))
    with sessions() as session:
        obj, _ = create_named(session, name=args.object, properties={}, shared_dir=None)
        spec = ExplorationSpec(
            object_id=obj.id, gripper=args.gripper, label=args.object,
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
    _write_picture(sessions, exploration_id, args)
    if args.table is not None:
        with sessions() as session:
            items = stored_manifolds(session, exploration_id)
        args.table.write_text(json.dumps(table_rows_of(items), indent=2))
    return 0
