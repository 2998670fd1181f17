"""Sustained pose-result ingest through the coordinator store, on SQLite and on PostgreSQL.

Does what the workers' reports will do: lease tiles, then write each tile's results as one
batch in one transaction (`store.ingest.ingest_results`). Only the ingest calls are timed;
making the synthetic results (the workers' side) is not. Each backend gets a fresh database
migrated to head. Writes benchmarks/results/ingest.json.

    .venv/bin/python benchmarks/bench_ingest.py [--seconds 10] [--batch 100]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import uuid
from pathlib import Path

import psycopg

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # for tests.factories: the same results the tests use

from graspscape.services.coordinator import db  # noqa: E402
from graspscape.services.coordinator.exploration.scheduler import ingest_results  # noqa: E402
from graspscape.services.coordinator.exploration.service import create_exploration  # noqa: E402
from graspscape.services.coordinator.store.models import ObjectRow  # noqa: E402
from graspscape.services.coordinator.store.queue import lease_tiles  # noqa: E402
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec  # noqa: E402

from benchmarks._results import write_results  # noqa: E402
from tests.factories import fake_results  # noqa: E402

PG_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"
LEASE_CHUNK = 16  # tiles a worker asks for at once


def run(url: str, *, seconds: float, batch: int) -> dict[str, float]:
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    # ~190k poses: more than any run of `seconds` at the target rate can use up.
    grid = PoseGridSpec(dtheta=0.04, r_min=0.0, r_max=0.05, dr=0.01, attitudes={"rolls": 4})
    with sessions() as s:
        obj = ObjectRow(kind="named", name="sphere", properties={})
        s.add(obj)
        s.commit()
        spec = ExplorationSpec(object_id=obj.id, gripper="robotiq_3f", grid=grid)
        create_exploration(s, spec=spec, tile_target_poses=batch, max_poses=10**7)
    poses = batches = 0
    busy = 0.0
    with sessions() as s:
        while busy < seconds:
            tiles = lease_tiles(s, worker_id="bench", n=LEASE_CHUNK, lease_seconds=600)
            if not tiles:
                break
            for tile in tiles:
                results = fake_results(tile.poses(), seed=tile.tile_id)
                start = time.perf_counter()
                report = ingest_results(
                    s,
                    tile_id=tile.tile_id,
                    lease_epoch=tile.lease_epoch,
                    worker_id="bench",
                    results=results,
                )
                busy += time.perf_counter() - start
                assert report.inserted == len(results) and report.tile_moved
                poses += report.inserted
                batches += 1
    engine.dispose()
    return {"poses": poses, "batches": batches, "seconds": busy, "poses_per_s": poses / busy}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="ingest time per backend")
    parser.add_argument("--batch", type=int, default=100, help="target poses per tile")
    parser.add_argument("--pg-url", default=PG_URL)
    args = parser.parse_args()

    figures: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp:
        sqlite = run(f"sqlite:///{tmp}/bench.db", seconds=args.seconds, batch=args.batch)
    print(f"sqlite:     {sqlite}")
    figures["ingest_poses_per_s_sqlite"] = round(sqlite["poses_per_s"])

    schema = f"bench_ingest_{uuid.uuid4().hex[:8]}"
    conninfo = args.pg_url.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    try:
        pg = run(
            f"{args.pg_url}?options=-csearch_path%3D{schema}",
            seconds=args.seconds,
            batch=args.batch,
        )
    finally:
        with psycopg.connect(conninfo, autocommit=True) as conn:
            conn.execute(f'DROP SCHEMA "{schema}" CASCADE')
    print(f"postgresql: {pg}")
    figures["ingest_poses_per_s_postgres"] = round(pg["poses_per_s"])

    write_results("ingest", figures)
    return 0


if __name__ == "__main__":
    sys.exit(main())
