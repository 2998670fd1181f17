"""A manifold refresh's cost against the map's size, grouping full vs incremental (issue 21
item 2).

Maps: every finest point of a real lattice (Δθ 10° refined once, r 0–5 cm by 1 cm, 1/2/4
rolls) with a synthetic behaviour field (regions cut by planes through the direction sphere,
joint angles that drift across a region with noise, 15 % failures), sampled as refinement
leaves it: the whole coarse pass and half of the finer points. For each map: the full
recompute `grouping.components` (what each refresh ran before), and the incremental state
fed the whole map in shuffled tiles of TILE poses, then timed on the last few tiles:
`add(tile)` + `components()` (what a refresh runs now). `build_map` with the grouping given
is timed too: fine labels, volumes, robust scores and summaries still look at every pose.

`--store` measures `refresh_manifolds` itself on SQLite: an exploration of the grid strategy
(Δθ 10°, r 0–5 cm, 4 rolls, no refinement; `tests.factories.oracle_result`'s results, 3
contacts and 9 joints each) stored tile by tile through the real ingest (`lease_tiles` +
`ingest_results`); at each checkpoint the refresh after one more tile is timed with the
grouping state kept since the tile before (now) and again with it dropped (the full grouping,
as before), over the same stored poses.

Run: python -m benchmarks.bench_incremental_manifolds [--rolls 1,2,4] [--tiles 5] [--store]
"""

from __future__ import annotations

import argparse
import math
import os
import random
import statistics
import time

from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import components
from graspscape.services.coordinator.manifolds.incremental import IncrementalGrouping
from graspscape.services.coordinator.manifolds.service import radius_function
from graspscape.services.coordinator.manifolds.summary import build_map
from graspscape.shared.specs.exploration import AttitudeSpec, PoseGridSpec

try:
    from benchmarks._results import write_results
except ModuleNotFoundError:  # run as a script: benchmarks/ itself is on sys.path
    from _results import write_results  # type: ignore[no-redef]

TILE = 64
KINDS = (frozenset({"A", "B"}), frozenset({"A", "B", "C"}), frozenset({"A", "B", "palm"}))


def synthetic_map(lattice: Lattice, rng: random.Random) -> dict[Point, StoredPose]:
    planes = [tuple(rng.gauss(0, 1) for _ in range(3)) for _ in range(2)]
    n_i = (lattice.n_r << lattice.depth) + 1
    out = {}
    for K, J in lattice.cells(lattice.depth):
        for i in range(n_i):
            for a in range(len(lattice.attitudes)):
                p = Point(K, J, i, a)
                if lattice.birth(p) > 0 and rng.random() < 0.5:
                    continue
                x = lattice.pose(p)
                d = lattice.direction(p)
                side = [sum(u * v for u, v in zip(n, d, strict=True)) > 0 for n in planes]
                kind = KINDS[(side[0] + 2 * side[1] + a) % len(KINDS)]
                viable = rng.random() > 0.15
                drift = 0.6 * d[2] + 0.02 * i + rng.gauss(0, 0.08)
                out[p] = StoredPose(
                    key=f"{K}.{J}.{i}.{a}", theta=x.theta, phi=x.phi, r=x.r, roll=x.roll,
                    pitch=x.pitch, yaw=x.yaw, viable=viable,
                    outcome="held" if viable else "dropped",
                    mu_s=rng.random() if viable else 0.0,
                    digits=kind if viable else frozenset(),
                    joints={f"{g}_1": drift + 0.1 * k for k, g in enumerate(sorted(kind))}
                    if viable else {},
                )
    return out


def measure(rolls: int, tiles: int) -> dict[str, float]:
    grid = PoseGridSpec(dtheta=math.radians(10), r_min=0.0, r_max=0.05, dr=0.01,
                        attitudes=AttitudeSpec(rolls=rolls))  # type: ignore[arg-type]
    lattice = Lattice(grid, 1)
    rng = random.Random(rolls)
    samples = synthetic_map(lattice, rng)
    order = sorted(samples)
    rng.shuffle(order)
    t = time.process_time()
    full = components(lattice, samples)
    full_s = time.process_time() - t

    state = IncrementalGrouping(lattice)
    head = len(order) - tiles * TILE
    t = time.process_time()
    for i in range(0, head, TILE):
        state.add((p, samples[p]) for p in order[i : min(i + TILE, head)])
    state.components()
    feed_s = time.process_time() - t
    per_tile = []
    for i in range(head, len(order), TILE):
        t = time.process_time()
        state.add((p, samples[p]) for p in order[i : i + TILE])
        comps = state.components()
        per_tile.append(time.process_time() - t)
    assert comps == full, "incremental grouping differs from the full recompute"

    t = time.process_time()
    build_map(lattice, samples, radius_function(None), comps=comps)
    rest_s = time.process_time() - t
    return {
        f"poses_{rolls}roll": len(samples),
        f"grouping_full_cpu_s_{rolls}roll": round(full_s, 4),
        f"grouping_incremental_per_tile_cpu_s_{rolls}roll": round(statistics.median(per_tile), 4),
        f"grouping_incremental_feed_whole_map_cpu_s_{rolls}roll": round(feed_s, 3),
        f"build_map_without_grouping_cpu_s_{rolls}roll": round(rest_s, 3),
    }


def measure_store(figures: dict[str, float], checkpoints: int = 4) -> None:
    import sys
    import tempfile
    from pathlib import Path

    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.exploration.scheduler import ingest_results
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.manifolds import service
    from graspscape.services.coordinator.store.models import ObjectRow
    from graspscape.services.coordinator.store.queue import lease_tiles
    from graspscape.shared.specs.exploration import ExplorationSpec

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.factories import oracle_result

    url = f"sqlite:///{tempfile.mkdtemp(prefix='gs-incr-')}/bench.db"
    db.upgrade(url, "head")
    sessions = db.make_sessionmaker(db.make_engine(url))
    grid = PoseGridSpec(dtheta=math.radians(10), r_min=0.0, r_max=0.05, dr=0.01,
                        attitudes=AttitudeSpec(rolls=4))
    with sessions() as s:
        obj = ObjectRow(kind="named", name="sphere", properties={})
        s.add(obj)
        s.commit()
        spec = ExplorationSpec(object_id=obj.id, gripper="robotiq_3f", grid=grid,
                               strategy={"name": "grid"}, refinement={"levels": 0})
        eid = create_exploration(s, spec=spec, tile_target_poses=TILE, max_poses=10**7).id
        tiles = []
        while leased := lease_tiles(s, worker_id="bench", n=64, lease_seconds=3600):
            tiles += leased
        marks = {round(len(tiles) * (k + 1) / (checkpoints + 1)) for k in range(checkpoints)}
        poses = 0
        for n, tile in enumerate(tiles):
            poses += ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                                    worker_id="bench",
                                    results=[oracle_result(p) for p in tile.poses()]).inserted
            s.commit()
            if n + 1 not in marks:
                continue
            service.refresh_manifolds(s, eid)  # the state current at the tile before
            s.commit()
            nxt = tiles[n + 1] if n + 1 < len(tiles) else None
            if nxt is not None:
                poses += ingest_results(s, tile_id=nxt.tile_id, lease_epoch=nxt.lease_epoch,
                                        worker_id="bench", results=[
                                            oracle_result(p) for p in nxt.poses()]).inserted
                s.commit()
            timed = {}
            for mode in ("incremental", "full"):
                if mode == "full":
                    service.GROUPINGS._states.clear()
                t = time.process_time()  # SQLite runs in this process: its work counts
                service.refresh_manifolds(s, eid)
                s.commit()
                timed[mode] = time.process_time() - t
            figures[f"store_refresh_cpu_s_incremental_{poses}poses"] = round(
                timed["incremental"], 3)
            figures[f"store_refresh_cpu_s_full_{poses}poses"] = round(timed["full"], 3)
            print(figures, flush=True)
            if nxt is not None:
                tiles.remove(nxt)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rolls", default="1,2,4")
    parser.add_argument("--tiles", type=int, default=5, help="tiles timed at the end")
    parser.add_argument("--store", action="store_true", help="time refresh_manifolds too")
    args = parser.parse_args()
    figures: dict[str, float] = {"tile_poses": TILE,
                                 "load_avg_1min_start": round(os.getloadavg()[0], 2)}
    for rolls in (int(x) for x in args.rolls.split(",") if x):
        figures.update(measure(rolls, args.tiles))
        print(figures, flush=True)
    if args.store:
        measure_store(figures)
    figures["load_avg_1min_end"] = round(os.getloadavg()[0], 2)
    write_results("incremental_manifolds", figures, {"note": (
        "CPU seconds (process_time) on a shared 2-core machine; per tile: the median over the "
        "last --tiles tiles of a shuffled arrival. build_map_without_grouping: the rest of a "
        "refresh's computation (fine labels, volumes, robust scores, summaries), given the "
        "grouping; the store's read of every pose and write of every assignment come on top. "
        "store_refresh_cpu_s_*: one refresh_manifolds on SQLite (CPU s of this process, "
        "SQLite included) after one more tile, with the grouping state kept (incremental) "
        "and dropped (full).")})


if __name__ == "__main__":
    main()
