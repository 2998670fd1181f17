"""Reads of large explorations: the map picture and the pose exports at ~100k and ~1M poses.

Builds each exploration through the real ingest path (`lease_tiles` + `ingest_results`, the
grid strategy on a real lattice, results from `tests.factories.oracle_result`: two grasp types
split at φ = π, a non-viable cap and side), on SQLite (and PostgreSQL, `--pg-sizes`, in a
schema of its own). The manifold table is then stored
directly (viable poses with φ < π are manifold A, the others B: the oracle's own split) —
grouping a million poses is issue 21's incremental-manifold work, not a read. Each measurement
runs in a fresh subprocess, so its peak RSS (`ru_maxrss`) is its own: `map.png` as the route
makes it (`maps.picture.picture_bytes`), CSV and Parquet as the routes stream them
(`manifolds.export.pose_pieces`, the pieces counted and dropped). Writes
benchmarks/results/reads.json.

    .venv/bin/python benchmarks/bench_reads.py [--sizes 100k,1m] [--pg-sizes 100k] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import psycopg

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # for tests.factories: the same results the tests use

from benchmarks._explorations import store_only  # noqa: E402
from benchmarks._results import write_results  # noqa: E402

# Coarse Δθ giving about this many poses with 6 r levels and 4 rolls.
SIZES = {"100k": 0.056, "1m": 0.017}
TILE_POSES = 2000
MEASUREMENTS = ("map_png", "csv", "parquet")
PG_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def create_grid_exploration(session, dtheta: float) -> int:  # type: ignore[no-untyped-def]
    """A dense-grid exploration of the sphere (r 0–5 cm by 1 cm, 4 rolls) in `session`'s
    database; its id. The map the read and query benchmarks fill through the real ingest."""
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.store.models import ObjectRow
    from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec

    grid = PoseGridSpec(dtheta=dtheta, r_min=0.0, r_max=0.05, dr=0.01, attitudes={"rolls": 4})
    obj = ObjectRow(kind="named", name="sphere", properties={})
    session.add(obj)
    session.commit()
    spec = ExplorationSpec(object_id=obj.id, gripper="robotiq_3f", grid=grid,
                           strategy={"name": "grid"}, refinement={"levels": 0})
    return create_exploration(session, spec=spec, tile_target_poses=TILE_POSES,
                              max_poses=10**7).id


def build(url: str, dtheta: float) -> tuple[int, int, float]:
    """An exploration of the grid made through the real ingest; (id, poses, seconds)."""
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.exploration.scheduler import ingest_results
    from graspscape.services.coordinator.store.queue import lease_tiles

    from tests.factories import oracle_result

    db.upgrade(url)
    sessions = db.make_sessionmaker(db.make_engine(url))
    with sessions() as s:
        eid = create_grid_exploration(s, dtheta)
    poses = 0
    start = time.perf_counter()
    with sessions() as s:
        while tiles := lease_tiles(s, worker_id="bench", n=8, lease_seconds=3600):
            for tile in tiles:
                results = [oracle_result(p) for p in tile.poses()]
                poses += ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                                        worker_id="bench", results=results,
                                        **store_only(ingest_results)).inserted
        seconds = time.perf_counter() - start
        store_manifolds(s, eid)
    return eid, poses, seconds


def store_manifolds(session, eid: int) -> None:  # type: ignore[no-untyped-def]
    """The oracle's two grasp types as the stored manifold table (rows, poses' column)."""
    from graspscape.services.coordinator.manifolds.summary import ManifoldSummary, PoseBrief
    from graspscape.services.coordinator.store.models import ExplorationRow, ManifoldRow, PoseRow
    from sqlalchemy import func, select, update

    sides = {0: PoseRow.phi < math.pi, 1: PoseRow.phi >= math.pi}
    for label, side in sides.items():
        where = (PoseRow.exploration_id == eid, PoseRow.viable, side)
        count, lo, mean, hi = session.execute(select(
            func.count(), func.min(PoseRow.mu_s), func.avg(PoseRow.mu_s),
            func.max(PoseRow.mu_s)).where(*where)).one()
        best = session.scalars(select(PoseRow).where(*where).order_by(
            PoseRow.mu_s.desc(), PoseRow.pose_key).limit(1)).one()
        brief = PoseBrief(key=best.pose_key, theta=best.theta, phi=best.phi, r=best.r,
                          roll=best.roll, pitch=best.pitch, yaw=best.yaw, mu_s=best.mu_s,
                          effort_max_nm=best.effort_max_nm)
        summary = ManifoldSummary(
            label=label, name="AB"[label], description="A, B, C touch the object",
            digits=["A", "B", "C"], pose_count=count, evaluated_count=count, volume_cm3=0.0,
            mu_s_min=lo, mu_s_mean=mean, mu_s_max=hi, mu_s_std=0.0, best=brief,
            local_maxima=[brief])
        row = ManifoldRow(exploration_id=eid, label=label, signature=best.signature,
                          size=count, best_pose_key=best.pose_key, best_mu_s=best.mu_s,
                          summary=summary.model_dump(mode="json"))
        session.add(row)
        session.flush()
        session.execute(update(PoseRow).where(*where).values(manifold_id=row.id)
                        .execution_options(synchronize_session=False))
    exploration = session.get(ExplorationRow, eid)
    exploration.manifolds_poses_done = exploration.poses_done
    exploration.manifolds_final = True
    session.commit()


def measure(url: str, eid: int, what: str) -> dict[str, float]:
    """One read, in this (fresh) process: seconds, peak RSS, rows where it counts them."""
    from graspscape.services.coordinator import (
        app,  # noqa: F401
        db,
    )
    from graspscape.services.coordinator.manifolds import export
    from graspscape.services.coordinator.manifolds.service import ensure_manifolds
    from graspscape.services.coordinator.maps import render  # noqa: F401
    from graspscape.services.coordinator.maps.picture import picture_bytes

    sessions = db.make_sessionmaker(db.make_engine(url))
    # Imports (matplotlib: ~1 s) are not timed: a running coordinator has them loaded.
    before = _rss_mb()
    start, cpu = time.perf_counter(), time.process_time()
    out: dict[str, float] = {}
    with sessions() as s:
        ensure_manifolds(s, eid)
        if what == "map_png":
            out["bytes"] = len(picture_bytes(s, eid, "png")[0])
        else:
            size = 0
            for piece in export.pose_pieces(s, eid, "csv" if what == "csv" else "parquet"):
                size += len(piece)
            out["bytes"] = size
    out["seconds"] = time.perf_counter() - start
    # CPU time too: on a shared machine the wall time also counts other processes' turns.
    out["cpu_s"] = time.process_time() - cpu
    out["rss_before_mb"] = before
    out["peak_rss_mb"] = _rss_mb()
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="100k,1m")
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep the SQLite databases here (and reuse them)")
    parser.add_argument("--pg-sizes", default="100k", help="the same on PostgreSQL")
    parser.add_argument("--pg-url", default=PG_URL)
    parser.add_argument("--measure", nargs=3, metavar=("URL", "ID", "WHAT"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.measure:
        url, eid, what = args.measure
        print(json.dumps(measure(url, int(eid), what)))
        return 0

    figures: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        where = args.keep or Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        for size in args.sizes.split(","):
            path = where / f"reads_{size}.db"
            url = f"sqlite:///{path}"
            if path.exists():
                eid, poses = 1, _poses(url)
            else:
                eid, poses, seconds = build(url, SIZES[size])
                print(f"{size}: {poses} poses ingested in {seconds:.0f} s")
            measure_all(url, eid, poses, size, figures)
    for size in filter(None, args.pg_sizes.split(",")):
        schema = f"bench_reads_{uuid.uuid4().hex[:8]}"
        conninfo = args.pg_url.replace("postgresql+psycopg://", "postgresql://")
        with psycopg.connect(conninfo, autocommit=True) as conn:
            conn.execute(f'CREATE SCHEMA "{schema}"')
        try:
            url = f"{args.pg_url}?options=-csearch_path%3D{schema}"
            eid, poses, seconds = build(url, SIZES[size])
            print(f"{size} postgresql: {poses} poses ingested in {seconds:.0f} s")
            measure_all(url, eid, poses, f"{size}_pg", figures)
        finally:
            with psycopg.connect(conninfo, autocommit=True) as conn:
                conn.execute(f'DROP SCHEMA "{schema}" CASCADE')
    write_results("reads", figures)
    return 0


def measure_all(url: str, eid: int, poses: int, tag: str, figures: dict[str, float]) -> None:
    """Every measurement of one exploration, each in a fresh process, into `figures`."""
    figures[f"poses_{tag}"] = poses
    for what in MEASUREMENTS:
        done = subprocess.run([sys.executable, __file__, "--measure", url, str(eid), what],
                              check=True, capture_output=True, text=True, cwd=REPO)
        m = json.loads(done.stdout.strip().splitlines()[-1])
        print(f"{tag} {what}: {m}")
        figures[f"{what}_s_{tag}"] = round(m["seconds"], 2)
        figures[f"{what}_cpu_s_{tag}"] = round(m["cpu_s"], 2)
        figures[f"{what}_peak_rss_mb_{tag}"] = round(m["peak_rss_mb"])
        if what != "map_png":
            figures[f"{what}_rows_per_s_{tag}"] = round(poses / m["seconds"])
            figures[f"{what}_rows_per_cpu_s_{tag}"] = round(poses / m["cpu_s"])
            figures[f"{what}_mb_{tag}"] = round(m["bytes"] / 2**20, 1)


def _poses(url: str) -> int:
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.store.models import PoseRow
    from sqlalchemy import func, select

    with db.make_sessionmaker(db.make_engine(url))() as s:
        return s.scalar(select(func.count()).select_from(PoseRow)) or 0


if __name__ == "__main__":
    sys.exit(main())
