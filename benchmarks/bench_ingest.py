"""Sustained pose-result ingest through the coordinator store, on SQLite and on PostgreSQL.

Does what the workers' reports will do: lease tiles, then write each tile's results as one
batch in one transaction (`store.ingest.ingest_results`). Only the ingest calls are timed;
making the synthetic results (the workers' side) is not. Each backend gets a fresh database
migrated to head. Writes benchmarks/results/ingest.json.

    .venv/bin/python benchmarks/bench_ingest.py [--seconds 10] [--batch 100] [--threads 4]

With `--threads K` (K > 1), K threads, each with its own database session as the coordinator's
ingest threads have, store the tiles of one exploration at once, the results made and the
tiles leased before the clock starts: wall-clock poses/s of the K together. That is where the
exploration row's lock (store/ingest.py) makes ingests take turns; `--own-explorations` gives
each thread an exploration of its own, the same work without that lock, to compare.
`--baseline REF` adds an interleaved A/B of that K-thread run on PostgreSQL: store/ingest.py
as it was at git REF against today's, `--rounds` times each (medians in the results).

`--refresh` (ingest_refresh.json, or `--results NAME`) times the single thread with the
manifold table kept after each batch (the keeper, manifolds/keeper.py, after the commit; for
a baseline from before it, `maybe_refresh` in the transaction), and the manifold upkeep's own
CPU per pose (this process's CPU: SQLite's work included, PostgreSQL's server not); the
other runs store without keeping the table (`keeper=None`). With
`--baseline REF` it runs that `--rounds` times per backend, interleaved, each run in a fresh
process: the manifolds and exploration packages (the latter holds the lattice's Point) as
they were at git REF (`git archive`) against today's.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import queue
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import types
import uuid
from pathlib import Path
from typing import Any

import psycopg

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # for tests.factories: the same results the tests use
# before anything imports a module of the packages a baseline run swaps
from benchmarks._baseline import PACKAGES_AT, extract_packages  # noqa: E402

# isort: split
import graspscape.services.coordinator.exploration.scheduler as scheduler_module  # noqa: E402
from graspscape.services.coordinator import db  # noqa: E402
from graspscape.services.coordinator.exploration.samples import lattice_of  # noqa: E402
from graspscape.services.coordinator.exploration.scheduler import ingest_results  # noqa: E402
from graspscape.services.coordinator.exploration.specs import spec_of  # noqa: E402
from graspscape.services.coordinator.store.models import (  # noqa: E402
    ExplorationRow,
    PoseRow,
)
from graspscape.services.coordinator.store.queue import lease_tiles  # noqa: E402
from sqlalchemy import func, select  # noqa: E402

from benchmarks._explorations import create_sphere_exploration  # noqa: E402
from benchmarks._results import write_results  # noqa: E402
from benchmarks.bench_query import bench_result  # noqa: E402
from tests.factories import fake_results  # noqa: E402

try:  # the keeper runs the refresh after each committed batch (manifolds/keeper.py)
    from graspscape.services.coordinator.manifolds.keeper import current_keeper

    KEEPER: Any = current_keeper()  # the process's (no app here: services/coordinator/state.py)
except ImportError:
    try:  # a --baseline run of the packages from before the coordinator's state
        from graspscape.services.coordinator.manifolds.keeper import KEEPER
    except ImportError:  # a --baseline run of the packages from before the keeper
        KEEPER = None
        from graspscape.services.coordinator.manifolds.service import (
            maybe_refresh,
        )
# The store alone (no manifold table kept) where the refresh is not what is measured.
STORE_ONLY: dict[str, Any] = {} if KEEPER is None else {"keeper": None}


PG_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"
LEASE_CHUNK = 16  # tiles a worker asks for at once


def run_threads(url: str, *, seconds: float, batch: int, threads: int,
                own_explorations: bool, rate_guess: float = 30_000) -> dict[str, float]:
    """K threads storing already made batches at once (see the module's docstring)."""
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    explorations = [create_sphere_exploration(sessions, tile_target_poses=batch)
                    for _ in range(threads if own_explorations else 1)]
    wanted = int(rate_guess * seconds / batch) + 1
    work: queue.Queue[Any] = queue.Queue()
    with sessions() as s:  # in lease order: the explorations' tiles interleave
        while work.qsize() < wanted:
            tiles = lease_tiles(s, worker_id="bench", n=LEASE_CHUNK, lease_seconds=3600)
            if not tiles:
                break
            for tile in tiles:
                work.put((tile, fake_results(tile.poses(), seed=tile.tile_id)))
    stored = [0] * threads
    batches = [0] * threads
    deadline = [0.0]

    def ingest(k: int) -> None:
        with sessions() as s:
            while time.perf_counter() < deadline[0]:
                try:
                    tile, results = work.get_nowait()
                except queue.Empty:
                    return
                report = ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                                        worker_id="bench", results=results, **STORE_ONLY)
                assert report.inserted == len(results) and report.tile_moved
                stored[k] += report.inserted
                batches[k] += 1

    pool = [threading.Thread(target=ingest, args=(k,)) for k in range(threads)]
    start = time.perf_counter()
    deadline[0] = start + seconds
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    wall = time.perf_counter() - start
    with sessions() as s:  # the counters are the rows, after concurrent ingest
        for eid in explorations:
            row = s.get(ExplorationRow, eid)
            rows = s.scalar(select(func.count()).select_from(PoseRow)
                            .where(PoseRow.exploration_id == eid))
            assert row is not None and row.poses_done == rows, (row, rows)
    engine.dispose()
    if work.empty():
        print(f"  (ran out of leased tiles after {wall:.1f} s: raise rate_guess)")
    return {"poses": sum(stored), "batches": sum(batches), "seconds": wall,
            "poses_per_s": sum(stored) / wall}


def run(url: str, *, seconds: float, batch: int, refresh: bool = False) -> dict[str, float]:
    """One thread storing tile after tile; with `refresh`, each batch is followed by the
    manifold table's throttled refresh (the keeper after the commit: every quarter more
    poses, at least 250 and at most 1,000; before the keeper, `maybe_refresh`), on
    bench_query's results (a smooth two-type map with realistic signatures; random
    signatures would make every pose its own manifold), both timed."""
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    eid = create_sphere_exploration(sessions, tile_target_poses=batch)
    poses = batches = 0
    busy = upkeep = 0.0
    with sessions() as s:
        spec = spec_of(s.get(ExplorationRow, eid))
        lattice = lattice_of(spec)
        while busy < seconds:
            tiles = lease_tiles(s, worker_id="bench", n=LEASE_CHUNK, lease_seconds=600)
            if not tiles:
                break
            for tile in tiles:
                results = ([bench_result(p) for p in tile.poses()] if refresh
                           else fake_results(tile.poses(), seed=tile.tile_id))
                start = time.perf_counter()
                kept = KEEPER.upkeep.cpu_s if KEEPER is not None else 0.0
                report = ingest_results(
                    s,
                    tile_id=tile.tile_id,
                    lease_epoch=tile.lease_epoch,
                    worker_id="bench",
                    results=results,
                    **({} if refresh else STORE_ONLY),
                )
                if refresh and KEEPER is not None:  # the keeper ran after the commit
                    upkeep += KEEPER.upkeep.cpu_s - kept
                elif refresh:  # before the keeper: the adaptive strategy's throttled refresh
                    cpu = time.process_time()
                    maybe_refresh(s, eid, spec, lattice)
                    s.commit()
                    upkeep += time.process_time() - cpu
                busy += time.perf_counter() - start
                assert report.inserted == len(results) and report.tile_moved
                poses += report.inserted
                batches += 1
    engine.dispose()
    return {"poses": poses, "batches": batches, "seconds": busy, "poses_per_s": poses / busy,
            "upkeep_cpu_ms_per_pose": 1000 * upkeep / poses}


def _store_batch_at(ref: str) -> Any:
    """store_batch as store/ingest.py was at git `ref`, loaded beside today's modules (which
    it imports), for an A/B in one process."""
    source = subprocess.run(["git", "show", f"{ref}:services/coordinator/store/ingest.py"],
                            cwd=REPO, check=True, capture_output=True, text=True).stdout
    module = types.ModuleType(f"ingest_at_{ref}")
    sys.modules[module.__name__] = module  # pydantic resolves the models' annotations there
    exec(compile(source, f"ingest.py@{ref}", "exec"), module.__dict__)
    if "quiet" in source:
        return module.store_batch
    # Older than the scheduler's `quiet` (commit with the counters): called without it, its
    # result as today's StoredBatch (committed False: the scheduler commits).
    from graspscape.services.coordinator.store.ingest import StoredBatch

    def store_batch(*args: Any, quiet: Any = None, **kwargs: Any) -> Any:
        return StoredBatch(*module.store_batch(*args, **kwargs))

    return store_batch


def ab_rounds(pg_url: str, *, baseline: str, rounds: int, threads: int, seconds: float,
              batch: int) -> dict[str, float]:
    """Interleaved rounds of the same K-thread ingest into one exploration on PostgreSQL with
    the store_batch of `baseline` and with today's: median poses/s of each."""
    current = scheduler_module.store_batch
    before = _store_batch_at(baseline)
    got: dict[str, list[float]] = {"baseline": [], "current": []}
    try:
        for _ in range(rounds):
            for name, store_batch in (("baseline", before), ("current", current)):
                scheduler_module.store_batch = store_batch
                with _pg_schema(pg_url) as url:
                    rate = run_threads(url, seconds=seconds, batch=batch, threads=threads,
                                       own_explorations=False)["poses_per_s"]
                print(f"A/B {name}: {rate:.0f} poses/s", flush=True)
                got[name].append(rate)
    finally:
        scheduler_module.store_batch = current
    return {f"ab_postgres_{threads}_threads_{name}_median_poses_per_s":
            round(statistics.median(rates)) for name, rates in got.items()}


def _pg_schema(pg_url: str):
    """A fresh schema for one PostgreSQL run, dropped after it."""
    schema = f"bench_ingest_{uuid.uuid4().hex[:8]}"
    conninfo = pg_url.replace("postgresql+psycopg://", "postgresql://")

    class Schema:
        def __enter__(self) -> str:
            with psycopg.connect(conninfo, autocommit=True) as conn:
                conn.execute(f'CREATE SCHEMA "{schema}"')
            return f"{pg_url}?options=-csearch_path%3D{schema}"

        def __exit__(self, *exc: object) -> None:
            with psycopg.connect(conninfo, autocommit=True) as conn:
                conn.execute(f'DROP SCHEMA "{schema}" CASCADE')

    return Schema()


def _backend_url(stack: contextlib.ExitStack, backend: str, pg_url: str) -> str:
    """A fresh database of `backend` for one run, removed when `stack` closes."""
    if backend == "sqlite":
        return f"sqlite:///{stack.enter_context(tempfile.TemporaryDirectory())}/bench.db"
    return stack.enter_context(_pg_schema(pg_url))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="ingest time per backend")
    parser.add_argument("--batch", type=int, default=100, help="target poses per tile")
    parser.add_argument("--threads", type=int, default=4,
                        help="also K threads into one exploration (1: only the single thread)")
    parser.add_argument("--own-explorations", action="store_true",
                        help="the K threads each into an exploration of its own")
    parser.add_argument("--backends", default="sqlite,postgresql")
    parser.add_argument("--no-write", action="store_true", help="print, write no results file")
    parser.add_argument("--baseline", metavar="REF",
                        help="also an A/B on PostgreSQL with --threads threads: store_batch of "
                        "git REF against today's, interleaved")
    parser.add_argument("--rounds", type=int, default=3, help="A/B rounds (each one of both)")
    parser.add_argument("--pg-url", default=PG_URL)
    parser.add_argument("--refresh-run", metavar="BACKEND", help=argparse.SUPPRESS)
    parser.add_argument("--refresh", action="store_true",
                        help="single-thread ingest with the manifold table's refresh after "
                             "each batch, as the adaptive strategy does (results file "
                             "ingest_refresh.json)")
    parser.add_argument("--results", help="results file name (default ingest, with --refresh "
                        "ingest_refresh)")
    args = parser.parse_args()
    backends = args.backends.split(",")

    if args.refresh_run:  # one run of an A/B (`refresh_ab`), in a process of its own
        with contextlib.ExitStack() as stack:
            url = _backend_url(stack, args.refresh_run, args.pg_url)
            print(json.dumps(run(url, seconds=args.seconds, batch=args.batch, refresh=True)))
        return 0
    figures: dict[str, float] = {"load_average_1min_start": round(os.getloadavg()[0], 1)}
    if args.refresh:
        return run_refresh(args, backends, figures)
    label = "own_explorations" if args.own_explorations else "one_exploration"
    for backend in backends:
        for threads in ([1, args.threads] if args.threads > 1 else [1]):
            with contextlib.ExitStack() as stack:
                url = _backend_url(stack, backend, args.pg_url)
                if threads == 1:
                    got = run(url, seconds=args.seconds, batch=args.batch)
                    key = f"ingest_poses_per_s_{backend.replace('postgresql', 'postgres')}"
                else:
                    got = run_threads(url, seconds=args.seconds, batch=args.batch,
                                      threads=threads, own_explorations=args.own_explorations)
                    key = (f"ingest_poses_per_s_{backend.replace('postgresql', 'postgres')}"
                           f"_{threads}_threads_{label}")
            print(f"{backend} x{threads}: {got}", flush=True)
            figures[key] = round(got["poses_per_s"])
    if args.baseline:
        figures.update(ab_rounds(args.pg_url, baseline=args.baseline, rounds=args.rounds,
                                 threads=args.threads, seconds=args.seconds, batch=args.batch))
    figures["load_average_1min_end"] = round(os.getloadavg()[0], 1)
    if not args.no_write:
        write_results(args.results or "ingest", figures)
    return 0


def run_refresh(args: argparse.Namespace, backends: list[str],
                figures: dict[str, float]) -> int:
    for backend in backends:
        for refresh in (False, True):
            with contextlib.ExitStack() as stack:
                url = _backend_url(stack, backend, args.pg_url)
                got = run(url, seconds=args.seconds, batch=args.batch, refresh=refresh)
            name = backend.replace("postgresql", "postgres")
            key = (f"ingest_with_manifolds_poses_per_s_{name}" if refresh
                   else f"ingest_poses_per_s_{name}")
            print(f"{backend} refresh={refresh}: {got}", flush=True)
            figures[key] = round(got["poses_per_s"])
            figures[key.replace("poses_per_s", "poses_stored")] = got["poses"]
            if refresh:
                figures[f"manifold_upkeep_cpu_ms_per_pose_{name}"] = round(
                    got["upkeep_cpu_ms_per_pose"], 3)
        if args.baseline:
            figures.update(refresh_ab(args, backend))
    figures["load_average_1min_end"] = round(os.getloadavg()[0], 1)
    if not args.no_write:
        write_results(args.results or "ingest_refresh", figures, {"note": (
            "Shared 2-core VM (other work running: see the load averages). "
            "manifold_upkeep_cpu_ms_per_pose: the keeper's refresh CPU (before it: "
            "maybe_refresh's) in this process per pose "
            "stored (SQLite's work included; PostgreSQL's server not). ab_*: --rounds "
            "interleaved runs per backend, each in a fresh process, with the manifolds "
            "and exploration packages of --baseline (git archive) and today's; medians.")})
    return 0


def refresh_ab(args: argparse.Namespace, backend: str) -> dict[str, float]:
    """Interleaved refresh runs of `backend`: the manifolds and exploration packages at
    args.baseline, then today's, `args.rounds` times; the medians of poses/s and upkeep CPU
    per pose."""
    got: dict[str, list[dict[str, float]]] = {"baseline": [], "current": []}
    with tempfile.TemporaryDirectory() as folder:
        extract_packages(args.baseline, folder)
        for _ in range(args.rounds):
            for name in ("baseline", "current"):
                env = {k: v for k, v in os.environ.items() if k != PACKAGES_AT}
                if name == "baseline":
                    env[PACKAGES_AT] = folder
                out = subprocess.run(
                    [sys.executable, __file__, "--refresh-run", backend, "--seconds",
                     str(args.seconds), "--batch", str(args.batch), "--pg-url", args.pg_url],
                    env=env, check=True, capture_output=True, text=True).stdout
                got[name].append(json.loads(out.strip().splitlines()[-1]))
                print(f"A/B {backend} {name}: {got[name][-1]}", flush=True)
    short = backend.replace("postgresql", "postgres")
    out: dict[str, float] = {}
    for name, runs in got.items():
        out[f"ab_{short}_{name}_with_manifold_refresh_median_poses_per_s"] = round(
            statistics.median(r["poses_per_s"] for r in runs))
        out[f"ab_{short}_{name}_manifold_upkeep_median_cpu_ms_per_pose"] = round(
            statistics.median(r["upkeep_cpu_ms_per_pose"] for r in runs), 3)
        out[f"ab_{short}_{name}_median_poses_stored"] = statistics.median(
            r["poses"] for r in runs)
    return out


if __name__ == "__main__":
    sys.exit(main())
