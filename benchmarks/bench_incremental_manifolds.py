"""A manifold refresh's cost against the map's size: the full recompute against the running
map (manifolds/running.py), issue 21 item 2.

Maps: every finest point of a real lattice (Δθ 10° or 9° refined once, r 0–5 cm by 1 cm,
1/4/8 rolls: ~10k/41k/101k poses, `--maps`) with a synthetic behaviour field (regions cut by
planes through the direction sphere, joint angles that drift across a region with noise, 15
% failures, contact centroids), sampled as refinement leaves it: the whole coarse pass and
half of the finer points. For each map: the full recompute, `grouping.components` +
`summary.build_map` (before: a refresh grouped incrementally but ran build_map over every
pose), and the running map fed the map in shuffled order, then timed on the last TILES tiles
of TILE poses: `RunningMap.add(tile)` (after: what a refresh computes now). The running
table is checked against build_map's, field by field.

`--store` measures `refresh_manifolds` itself on SQLite: a grid exploration of the sphere
(Δθ 0.056 rad, r 0–5 cm, 4 rolls: ~100k poses; `tests.factories.oracle_result`'s results)
stored tile by tile through the real ingest (`lease_tiles` + `ingest_results`); at ~10k,
~50k and ~100k poses the refresh after one more tile is timed with the running map kept
since the tile before (after) and cold (the process's maps dropped: every row read, the map
computed and written whole, as every refresh did before; up to --store-cold-up-to poses).

`--baseline REF`: before each map, the same map measured in a fresh process with the manifolds
and exploration packages (the latter holds the lattice's Point) as they were at git REF (`git
archive`): its running-map figures as baseline_*, in incremental_manifolds_ab.json (or
`--results NAME`).

Run: python -m benchmarks.bench_incremental_manifolds [--maps 10:1,10:4,9:8] [--tiles 8] [--store]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

# before anything imports a module of the packages a baseline run swaps
try:
    from benchmarks._baseline import PACKAGES_AT, extract_packages
    from benchmarks._explorations import store_only
except ModuleNotFoundError:  # run as a script: benchmarks/ itself is on sys.path
    from _baseline import PACKAGES_AT, extract_packages  # type: ignore[no-redef]
    from _explorations import store_only  # type: ignore[no-redef]

from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds import snapshot
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import components
from graspscape.services.coordinator.manifolds.live import MapState
from graspscape.services.coordinator.manifolds.running import RunningMap
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
                    contacts={g: (0.03 * d[0] + rng.gauss(0, 0.005), 0.03 * d[1],
                                  0.03 * d[2] + 0.01 * k) for k, g in enumerate(sorted(kind))}
                    if viable else {},
                    joints={f"{g}_1": drift + 0.1 * k for k, g in enumerate(sorted(kind))}
                    if viable else {},
                )
    return out


def measure(dtheta_deg: float, rolls: int, tiles: int) -> dict[str, float]:
    grid = PoseGridSpec(dtheta=math.radians(dtheta_deg), r_min=0.0, r_max=0.05, dr=0.01,
                        attitudes=AttitudeSpec(rolls=rolls))  # type: ignore[arg-type]
    lattice = Lattice(grid, 1)
    rng = random.Random(rolls)
    samples = synthetic_map(lattice, rng)
    n = len(samples)
    radius = radius_function(None)
    t = time.process_time()
    comps = components(lattice, samples)
    grouping_s = time.process_time() - t
    t = time.process_time()
    full, _, _ = build_map(lattice, samples, radius, comps=comps)
    build_s = time.process_time() - t

    order = sorted(samples)
    rng.shuffle(order)
    head = n - tiles * TILE
    t = time.process_time()
    running = RunningMap(lattice, radius)
    running.add({p: samples[p] for p in order[:head]})
    feed_s = time.process_time() - t
    per_tile = []
    for i in range(head, n, TILE):
        t = time.process_time()
        running.add({p: samples[p] for p in order[i : i + TILE]})
        per_tile.append(time.process_time() - t)
    assert running.table.manifolds == full.manifolds, "the running table differs"
    # Cold start: the map saved to disk and read back (manifolds/snapshot.py), against
    # feeding it every pose again (running_feed_whole_map).
    folder = Path(tempfile.mkdtemp(prefix="gs-snap-"))
    state = MapState(running, last_id=n, rows=n)
    wall, t = time.perf_counter(), time.process_time()
    min_rows, snapshot.MIN_ROWS = snapshot.MIN_ROWS, 0  # saved whatever the map's size
    assert snapshot.maybe_save(folder, "bench", state, final=True)
    snapshot.MIN_ROWS = min_rows
    save_cpu, save_wall = time.process_time() - t, time.perf_counter() - wall
    size = sum(f.stat().st_size for f in folder.iterdir())
    wall, t = time.perf_counter(), time.process_time()
    loaded = snapshot.load(folder, "bench")
    load_cpu, load_wall = time.process_time() - t, time.perf_counter() - wall
    assert loaded is not None and loaded.running.table.manifolds == full.manifolds
    shutil.rmtree(folder)
    return {
        f"snapshot_save_cpu_s_{n}": round(save_cpu, 2),
        f"snapshot_save_wall_s_{n}": round(save_wall, 2),
        f"snapshot_load_cpu_s_{n}": round(load_cpu, 2),
        f"snapshot_load_wall_s_{n}": round(load_wall, 2),
        f"snapshot_mb_{n}": round(size / 1e6, 1),
        f"poses_{n}": n,
        f"manifolds_{n}": len(full.manifolds),
        f"full_grouping_cpu_s_{n}": round(grouping_s, 3),
        f"full_build_map_cpu_s_{n}": round(build_s, 3),
        f"running_per_tile_cpu_s_{n}": round(statistics.median(per_tile), 4),
        f"running_per_tile_max_cpu_s_{n}": round(max(per_tile), 4),
        f"running_feed_whole_map_cpu_s_{n}": round(feed_s, 2),
    }


def measure_store(figures: dict[str, float], dtheta: float = 0.056,
                  marks: tuple[int, ...] = (10_000, 50_000), cold_up_to: int = 20_000) -> None:
    import sys

    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.exploration.scheduler import ingest_results
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.manifolds import service
    from graspscape.services.coordinator.store.models import ObjectRow
    from graspscape.services.coordinator.store.queue import lease_tiles
    from graspscape.shared.specs.exploration import ExplorationSpec

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.factories import oracle_result

    folder = tempfile.mkdtemp(prefix="gs-incr-")
    url = f"sqlite:///{folder}/bench.db"
    os.environ[snapshot.ENV] = f"{folder}/maps"  # snapshots saved as a coordinator saves them
    load = snapshot.load
    load_cpu: list[float] = []

    def timed_load(*args):  # type: ignore[no-untyped-def]
        t = time.process_time()
        got = load(*args)
        load_cpu.append(time.process_time() - t)
        return got

    snapshot.load = timed_load
    save = snapshot.maybe_save
    db.upgrade(url, "head")
    sessions = db.make_sessionmaker(db.make_engine(url))
    grid = PoseGridSpec(dtheta=dtheta, r_min=0.0, r_max=0.05, dr=0.01,
                        attitudes=AttitudeSpec(rolls=4))
    with sessions() as s:
        obj = ObjectRow(kind="named", name="sphere", properties={})
        s.add(obj)
        s.commit()
        spec = ExplorationSpec(object_id=obj.id, gripper="robotiq_3f", grid=grid,
                               strategy={"name": "grid"}, refinement={"levels": 0})
        eid = create_exploration(s, spec=spec, tile_target_poses=4 * TILE, max_poses=10**7).id
        tiles = []
        while leased := lease_tiles(s, worker_id="bench", n=256, lease_seconds=36000):
            tiles += leased
        poses = 0

        def ingest(tile) -> int:  # type: ignore[no-untyped-def]
            n = ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                               worker_id="bench", **store_only(ingest_results),
                               results=[oracle_result(p) for p in tile.poses()]).inserted
            s.commit()
            return n

        pending = list(marks)
        for k, tile in enumerate(tiles):
            poses += ingest(tile)
            last = k == len(tiles) - 2
            if not (pending and poses >= pending[0]) and not last:
                continue
            if pending and poses >= pending[0]:
                pending.pop(0)
            service.refresh_manifolds(s, eid)  # the running map current at this tile
            s.commit()
            poses += ingest(tiles[k + 1])  # one more tile, then its refresh
            timed = {}
            modes = ("running", "snapshot", "cold") if poses <= cold_up_to \
                else ("running", "snapshot")
            for mode in modes:
                if mode != "running":  # a restart: the process's maps are gone
                    _running_maps().clear()
                    load_cpu.clear()
                if mode == "cold":  # and no snapshot either (none read, none written)
                    shutil.rmtree(f"{folder}/maps", ignore_errors=True)
                    snapshot.maybe_save = lambda *a, **k: False
                t = time.process_time()  # SQLite runs in this process: its work counts
                wall = time.perf_counter()
                service.refresh_manifolds(s, eid)
                s.commit()
                timed[mode] = (time.process_time() - t, time.perf_counter() - wall)
                snapshot.maybe_save = save
                if mode == "snapshot" and load_cpu:
                    figures[f"store_snapshot_load_cpu_s_{poses}poses"] = round(load_cpu[0], 3)
            for mode, (cpu, wall) in timed.items():
                figures[f"store_refresh_cpu_s_{mode}_{poses}poses"] = round(cpu, 3)
                figures[f"store_refresh_wall_s_{mode}_{poses}poses"] = round(wall, 3)
            print(figures, flush=True)
            if last:
                break
            tiles.pop(k + 1)
    shutil.rmtree(folder)  # the database and the snapshots: hundreds of MB at 100k poses


def baseline(ref: str, item: str, tiles: int) -> dict[str, float]:
    """One map's running-map figures with the manifolds and exploration packages of git `ref`,
    measured in a process of its own."""
    repo = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as folder:
        extract_packages(ref, folder)
        env = {**os.environ, PACKAGES_AT: folder}
        out = subprocess.run([sys.executable, "-m", "benchmarks.bench_incremental_manifolds",
                              "--maps", item, "--tiles", str(tiles), "--json"], cwd=repo,
                             env=env, check=True, capture_output=True, text=True).stdout
    got = json.loads(out.strip().splitlines()[-1])
    return {f"baseline_{k}": v for k, v in got.items() if k.startswith("running_")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", default="10:1,10:4,9:8",
                        help="maps as Δθ°:rolls (~10k, ~41k, ~101k poses)")
    parser.add_argument("--tiles", type=int, default=8, help="tiles timed at the end")
    parser.add_argument("--store", action="store_true", help="time refresh_manifolds too")
    parser.add_argument("--store-dtheta", type=float, default=0.056)
    parser.add_argument("--store-marks", default="10000,50000")
    parser.add_argument("--store-cold-up-to", type=int, default=20_000,
                        help="time the cold refresh only up to this many poses (it reads, "
                        "computes and writes the whole map: minutes at 100k on a loaded VM)")
    parser.add_argument("--baseline", metavar="REF",
                        help="also each map's running-map figures with the manifolds package "
                        "and exploration packages of git REF, in a fresh process before it")
    parser.add_argument("--results", help="results file name (default incremental_manifolds, "
                        "with --baseline incremental_manifolds_ab)")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    figures: dict[str, float] = {"tile_poses": TILE,
                                 "load_avg_1min_start": round(os.getloadavg()[0], 2)}
    for item in filter(None, args.maps.split(",")):
        dtheta, rolls = item.split(":")
        if args.baseline:
            figures.update(baseline(args.baseline, item, args.tiles))
        figures.update(measure(float(dtheta), int(rolls), args.tiles))
        if args.json:  # a baseline run: the figures only
            print(json.dumps(figures))
            return
        print(figures, flush=True)
    if args.store:
        measure_store(figures, args.store_dtheta,
                      tuple(int(x) for x in args.store_marks.split(",") if x),
                      args.store_cold_up_to)
    figures["load_avg_1min_end"] = round(os.getloadavg()[0], 2)
    # An A/B run has a file of its own: the --store figures of the last full run stay.
    name = args.results or ("incremental_manifolds_ab" if args.baseline
                            else "incremental_manifolds")
    write_results(name, figures, {"note": (
        "CPU seconds (process_time) on a shared 2-core machine, keys by the map's poses. "
        "full_*: the whole map at once (grouping.components, then summary.build_map: what a "
        "refresh computed before issue 21's running map, apart from grouping, which was "
        "already incremental). running_per_tile: RunningMap.add of one TILE-pose tile into "
        "the map fed in shuffled order (median and max over the last --tiles tiles); its "
        "table equals build_map's. store_refresh_*: one refresh_manifolds on SQLite (this "
        "process's CPU, SQLite included, and wall time) after one more tile of a grid "
        "exploration, with the running map kept (running) and dropped (cold: every row "
        "read, everything computed and written). baseline_*: the same map measured in a "
        "fresh process with the manifolds and exploration packages of --baseline, just "
        "before.")})


if __name__ == "__main__":
    main()


def _running_maps() -> Any:
    """The process's running maps (services/coordinator/state.py)."""
    try:
        from graspscape.services.coordinator.state import current
    except ImportError:  # a baseline from before the coordinator's state
        from graspscape.services.coordinator.manifolds import service

        return service.MAPS  # type: ignore[attr-defined]
    return current().maps
