"""`graspscape map`: pictures, exports and local runs of behavioral maps from the command line.

  graspscape map show ID [-o map.png|map.svg] [--cut vertical --phi0 90] [--attitude 0] [--r-mm 10]
  graspscape map export ID --what poses.csv|poses.parquet|manifolds.json -o FILE
  graspscape map export ID --what graspgen.json|acronym.h5|object.obj -o FILE
  graspscape map run --object mug [--dtheta 30 --levels 2 …] -o map.png [--db run.db]

`show` and `export` read the coordinator's database (--database-url, default: the
coordinator's settings); the grasp datasets (graspgen.json, acronym.h5 and the object mesh
they name) are services/coordinator/datasets' (docs/reference/formats.md). `run`
(graspscape.services.local.map_run, which needs the workers) explores an object in this
process (pybullet, SQLite) with the same store code as the coordinator and writes the map and
the manifold table.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from graspscape.shared import cli_args

# The grasp datasets' names (services/coordinator/datasets/formats.py, which imports h5py:
# loaded only when one is written).
DATASETS = ("graspgen.json", "acronym.h5", "object.obj")


def register(subparsers: Any) -> Any:
    """Adds `map show|export`; returns the map's actions, where `run` is added by the
    composing package (it needs the workers)."""
    parser = subparsers.add_parser("map", help="behavioral map pictures, exports, local runs")
    sub = parser.add_subparsers(dest="map_command", required=True, metavar="ACTION")

    show = sub.add_parser("show", help="write the map picture of an exploration")
    cli_args.add_exploration_id(show)
    show.add_argument("-o", "--out", type=Path, default=Path("map.png"),
                      help="PNG or SVG by suffix (default map.png)")
    picture_args(show)
    cli_args.add_store(show)
    show.set_defaults(handler=_show)

    exp = sub.add_parser("export", help="export poses (CSV, Parquet), the manifold table or a "
                         "grasp dataset (GraspGen JSON, ACRONYM-style HDF5)")
    cli_args.add_exploration_id(exp)
    exp.add_argument("--what", choices=["poses.csv", "poses.parquet", "manifolds.json",
                                        *DATASETS], default="poses.csv",
                     help="which export (default poses.csv); a dataset (graspgen.json, "
                     "acronym.h5) is written with the mesh it names beside it")
    exp.add_argument("-o", "--out", type=Path, required=True, help="file to write")
    cli_args.add_store(exp)
    exp.set_defaults(handler=_export)

    return sub


def picture_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cut", choices=["horizontal", "vertical"], default="horizontal",
                        help="plane of the map's cut (default horizontal)")
    parser.add_argument("--phi0", type=cli_args.degrees(-360, 360), default=0.0, metavar="DEG",
                        help="azimuth of a vertical cut, degrees (default 0)")
    parser.add_argument("--attitude", type=cli_args.bounded("(attitude index)", 0, 1000,
                                                            integer=True), default=0,
                        help="attitude index of the cut (default 0)")
    parser.add_argument("--r-mm", type=float, default=None,
                        help="draw only the cut's band at this r, mm (default: every r)")


def _sessions(args: argparse.Namespace) -> Any:
    """The coordinator's database as --database-url, --data-dir or the settings name it; one
    that does not exist is refused (a read creates nothing), naming what makes one."""
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.settings import DatabaseSettings, get_settings

    url = args.database_url
    if url is None and args.data_dir is not None:
        url = DatabaseSettings(data_dir=args.data_dir).resolved_url
    if url is None:
        url = get_settings().database.resolved_url
    return db.make_sessionmaker(db.open_existing(url))


def write_picture(sessions: Any, exploration_id: int, args: argparse.Namespace) -> None:
    """Writes the picture, then prints the manifold table: a line per large manifold (volume,
    robust core, robust best), the dust as one line."""
    from graspscape.services.coordinator.manifolds.service import stored_manifolds
    from graspscape.services.coordinator.manifolds.summary import table_text
    from graspscape.services.coordinator.maps.picture import write_map_files

    with sessions() as session:
        manifolds, poses = write_map_files(session, exploration_id, args.out, cut=args.cut,
                                           phi0_deg=args.phi0, attitude=args.attitude,
                                           r_mm=getattr(args, "r_mm", None))
        table = table_text(stored_manifolds(session, exploration_id))
    print(f"{args.out}: {manifolds} manifolds, {poses} poses")
    if table:
        print(table)


def _show(args: argparse.Namespace) -> int:
    write_picture(_sessions(args), args.exploration_id, args)
    return 0


def _write_atomically(path: Path, write: Any) -> int:
    """`write(file)` into PATH.part, renamed at the end: a refusal halfway leaves no torn
    file."""
    part = path.with_name(path.name + ".part")
    try:
        with part.open("w+b") as out:  # h5py reads back
            rows = write(out)
    except BaseException:
        part.unlink(missing_ok=True)
        raise
    part.replace(path)
    return int(rows)


def _export_dataset(args: argparse.Namespace) -> int:
    """A dataset and, beside it, the object's mesh under the name its `object.file` gives
    (the download name of the REST export), so that it loads unchanged."""
    from graspscape.services.coordinator.datasets.formats import FORMATS
    from graspscape.services.coordinator.datasets.rows import object_file_name

    eid = args.exploration_id
    mesh_name = object_file_name(eid)
    with _sessions(args)() as session:
        rows = _write_atomically(args.out, lambda out: FORMATS[args.what].write(
            session, eid, out, object_file=mesh_name))
        if args.what != "object.obj":
            mesh = args.out.with_name(mesh_name)
            faces = _write_atomically(mesh, lambda out: FORMATS["object.obj"].write(
                session, eid, out))
            print(f"{mesh}: {faces} faces")
    print(f"{args.out}: {rows} {'faces' if args.what == 'object.obj' else 'poses'}")
    return 0


def _export(args: argparse.Namespace) -> int:
    if args.what in DATASETS:
        return _export_dataset(args)
    from graspscape.services.coordinator.manifolds import export
    from graspscape.services.coordinator.manifolds.service import (
        ensure_manifolds,
    )

    sessions = _sessions(args)
    with sessions() as session:
        ensure_manifolds(session, args.exploration_id)
        if args.what == "manifolds.json":  # as GET …/export/manifolds.json
            from graspscape.services.coordinator.manifolds.table import table_document

            args.out.write_text(json.dumps(table_document(session, args.exploration_id),
                                           indent=2))
        else:
            with args.out.open("wb") as out:  # streamed in chunks, as the REST export
                export.write_poses(session, args.exploration_id,
                                   "csv" if args.what == "poses.csv" else "parquet", out)
    print(args.out)
    return 0
