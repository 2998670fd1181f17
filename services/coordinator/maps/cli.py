"""`graspscape map`: pictures, exports and local runs of behavioral maps from the command line.

  graspscape map show ID [-o map.png|map.svg] [--cut vertical --phi0 90] [--attitude 0]
  graspscape map export ID --what poses.csv|poses.parquet|manifolds.json -o FILE
  graspscape map run --object mug [--dtheta 30 --levels 2 …] -o map.png [--db run.db]

`show` and `export` read the coordinator's database (--database-url, default: the
coordinator's settings); `run` (graspscape.services.local.map_run, which needs the workers)
explores an object in this process (pybullet, SQLite) with the same store code as the
coordinator and writes the map and the manifold table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any


def register(subparsers: Any) -> Any:
    """Adds `map show|export`; returns the map's actions, where `run` is added by the
    composing package (it needs the workers)."""
    parser = subparsers.add_parser("map", help="behavioral map pictures, exports, local runs")
    sub = parser.add_subparsers(dest="map_command", required=True, metavar="ACTION")

    show = sub.add_parser("show", help="write the map picture of an exploration")
    show.add_argument("exploration_id", type=int)
    show.add_argument("-o", "--out", type=Path, default=Path("map.png"),
                      help="PNG or SVG by suffix (default map.png)")
    picture_args(show)
    show.add_argument("--database-url", default=None)
    show.set_defaults(handler=_show)

    exp = sub.add_parser("export", help="export poses (CSV, Parquet) or the manifold table")
    exp.add_argument("exploration_id", type=int)
    exp.add_argument("--what", choices=["poses.csv", "poses.parquet", "manifolds.json"],
                     default="poses.csv")
    exp.add_argument("-o", "--out", type=Path, required=True)
    exp.add_argument("--database-url", default=None)
    exp.set_defaults(handler=_export)

    return sub


def picture_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cut", choices=["horizontal", "vertical"], default="horizontal")
    parser.add_argument("--phi0", type=float, default=0.0, help="vertical cut azimuth, degrees")
    parser.add_argument("--attitude", type=int, default=0, help="attitude index of the cut")


def _sessions(url: str | None) -> Any:
    from graspscape.services.coordinator import db

    if url is None:
        from graspscape.services.coordinator.settings import get_settings

        url = get_settings().database.resolved_url
    return db.make_sessionmaker(db.make_engine(url))


def write_picture(sessions: Any, exploration_id: int, args: argparse.Namespace) -> None:
    from graspscape.services.coordinator.maps.picture import write_map_files

    with sessions() as session:
        manifolds, poses = write_map_files(session, exploration_id, args.out, cut=args.cut,
                                           phi0_deg=args.phi0, attitude=args.attitude)
    print(f"{args.out}: {manifolds} manifolds, {poses} poses")


def _show(args: argparse.Namespace) -> int:
    write_picture(_sessions(args.database_url), args.exploration_id, args)
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
            with args.out.open("wb") as out:  # streamed in chunks, as the REST export
                export.write_poses(session, args.exploration_id,
                                   "csv" if args.what == "poses.csv" else "parquet", out)
    print(args.out)
    return 0
