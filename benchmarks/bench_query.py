"""Read latency of the map routes on large explorations, under 8 concurrent clients.

Each exploration is built through the real ingest path (`lease_tiles` + `ingest_results`, the
grid strategy on a real lattice), with `tests.factories.oracle_result`'s results (two grasp types
split at φ = π, realistic signatures: three contacts, nine joint angles, a grasp configuration)
plus, on held poses, the static metrics and robustness margins a default exploration stores
(deterministic per pose key), so the default `/best` ranking (torque margin ratio) has values to
sort. The manifold table is then stored as `bench_reads.store_manifolds` does (the oracle's split;
grouping a million poses is issue 21's incremental-manifold work, not a read).

The coordinator runs as a real `uvicorn` server in a subprocess (one process, FastAPI's thread
pool for the sync routes; uvloop and httptools, as `graspscape serve`); 8 client threads
(query_clients.py: http.client, or httpx with --client httpx; one keep-alive connection each)
in this process send each route's requests as fast as answers come. Per route: p50/p95/p99
latency in ms. `map.png` is cached per map version, so its first (cold) request is reported
apart from the warm ones; the CSV export is timed to its first body byte. Sizes: 10k, 100k,
1m poses (`--sizes`, `--pg-sizes`). Databases are kept (SQLite files under `--keep`,
PostgreSQL schemas `q_<size>` in database `bench_query`) and reused, migrated to head before
measuring, so a rerun after a migration measures the same rows. Writes
benchmarks/results/query.json (--results NAME: NAME.json).

    .venv/bin/python benchmarks/bench_query.py [--sizes 10k,100k] [--pg-sizes 10k,100k]
        [--keep DIR] [--rebuild]
"""

from __future__ import annotations

import argparse
import hashlib
import os
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psycopg

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # for tests.factories: the same results the tests use

from benchmarks import query_clients  # noqa: E402
from benchmarks._explorations import store_only  # noqa: E402
from benchmarks._results import write_results  # noqa: E402
from benchmarks.query_clients import CLIENTS, routes, run_route  # noqa: E402

# Coarse Δθ giving about this many poses with 6 r levels and 4 rolls.
SIZES = {"10k": 0.174, "100k": 0.056, "1m": 0.017}
TILE_POSES = 2000
PG_ADMIN = "postgresql://postgres@127.0.0.1:5432/postgres"
PG_DB = "bench_query"
DEFAULT_KEEP = Path("/tmp/graspscape_bench_query")


def _unit(key: str, salt: str) -> float:
    """A deterministic number in [0, 1) per pose key (the same rows on every build)."""
    digest = hashlib.blake2b(f"{salt}:{key}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "big") / 2**64


def bench_result(pose):  # type: ignore[no-untyped-def]
    """`oracle_result` with what a default exploration also stores on a held pose."""
    from graspscape.shared.specs.results import RobustnessReport

    from tests.factories import oracle_result

    result = oracle_result(pose)
    key = result.pose_key
    extra: dict[str, object] = {"effective_r": pose.r, "eval_time_s": 0.3 + _unit(key, "t")}
    if result.viable:
        margin = 0.2 + 2.0 * _unit(key, "tm")
        extra.update(
            contacts_per_link={"A_3": 1, "B_3": 1, "C_3": 1},
            mu_g=0.05 * _unit(key, "g"), mu_f=0.02 * _unit(key, "f"), mu_m=3 * _unit(key, "m"),
            robustness=RobustnessReport(
                torque_margin_nm=margin, torque_margin_ratio=1.0 - margin / 2.5,
                friction_margin=0.1 + _unit(key, "fm"),
                gravity_test_share=round(6 * _unit(key, "gt")) / 6,
                force_test_share=round(6 * _unit(key, "ft")) / 6,
                tug_force_n=20 * _unit(key, "tug"), shake_survival_s=2 * _unit(key, "sh")))
    return result.model_copy(update=extra)


REVISION = "head"  # --revision: the schema the databases are migrated to
PER_CLIENT: int | None = None  # --per-client: requests per client of each route but the
# picture and the CSV (default: the route's own, 6: 48 requests, whose p95 is their 3rd worst)


def build(url: str, dtheta: float) -> tuple[int, float]:
    """An exploration of the grid made through the real ingest; (poses, ingest seconds)."""
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.exploration.scheduler import ingest_results
    from graspscape.services.coordinator.store.queue import lease_tiles

    from benchmarks.bench_reads import create_grid_exploration, store_manifolds

    db.upgrade(url, REVISION)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    with sessions() as s:
        eid = create_grid_exploration(s, dtheta)
    assert eid == 1, "a fresh database: the exploration measured is id 1"
    poses, busy = 0, 0.0
    with sessions() as s:
        while tiles := lease_tiles(s, worker_id="bench", n=8, lease_seconds=3600):
            for tile in tiles:
                results = [bench_result(p) for p in tile.poses()]
                start = time.perf_counter()
                poses += ingest_results(s, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                                        worker_id="bench", results=results,
                                        **store_only(ingest_results)).inserted
                busy += time.perf_counter() - start
        store_manifolds(s, eid)
        store_robust_scores(s, eid)
    engine.dispose()
    return poses, busy


def store_robust_scores(session, eid: int) -> None:  # type: ignore[no-untyped-def]
    """Robust scores on the viable poses, as the manifold refresh stores them (issue 18's
    columns): 60 % robust, 20 % uncertain, 15 % fragile, 5 % futile by row id, q ≤ μs."""
    from graspscape.services.coordinator.store.models import PoseRow
    from sqlalchemy import case, update

    k = PoseRow.id % 20
    label = case((k < 12, "robust"), (k < 16, "uncertain"), (k < 19, "fragile"),
                 else_="futile")
    session.execute(update(PoseRow).where(PoseRow.exploration_id == eid, PoseRow.viable)
                    .values(robust_label=label, robust_s=0.05 * k,
                            robust_q=PoseRow.mu_s * (0.5 + 0.025 * k))
                    .execution_options(synchronize_session=False))
    session.commit()


def _pose_count(url: str) -> int:
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.store.models import ExplorationRow

    engine = db.make_engine(url)
    try:
        with db.make_sessionmaker(engine)() as s:
            row = s.get(ExplorationRow, 1)
            return 0 if row is None or not row.manifolds_final else row.poses_done
    except Exception:  # no tables yet
        return 0
    finally:
        engine.dispose()


# --- the server ------------------------------------------------------------------------------
# uvicorn's event loop and HTTP parser: "auto" (uvloop and httptools, dependencies of the
# package, as `graspscape serve` runs) or "plain" (asyncio and h11: what uvicorn falls back to
# without them; the stack's share in an A/B, query_overhead.py --stack-ab).
STACKS = {"auto": ("auto", "auto"), "plain": ("asyncio", "h11")}


def serve(url: str, port: int, stack: str = "auto") -> None:
    """The coordinator's app under uvicorn, as `graspscape serve` runs it (zenoh off)."""
    import uvicorn
    from graspscape.services.coordinator.app import create_app
    from graspscape.services.coordinator.settings import Settings

    settings = Settings(database={"url": url})
    loop, http = STACKS[stack]
    uvicorn.run(create_app(settings), host="127.0.0.1", port=port, log_level="warning",
                loop=loop, http=http)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Server:
    def __init__(self, url: str, code: Path | None = None, stack: str = "auto") -> None:
        """`code`: serve the graspscape package of another checkout (a git worktree of an
        earlier commit: the before of a before/after in one run), put first on the path;
        `stack`: uvicorn's loop and parser (STACKS)."""
        self.port = _free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        env = dict(os.environ)
        if code is not None:
            shim = Path(f"/tmp/graspscape_bench_query_code_{os.getpid()}")
            shim.mkdir(exist_ok=True)
            link = shim / "graspscape"
            if not link.exists():
                link.symlink_to(code.resolve())
            env["PYTHONPATH"] = f"{shim}{os.pathsep}{env.get('PYTHONPATH', '')}"
        # Run from the checkout served: its own configs/ (settings it knows).
        self.proc = subprocess.Popen(
            [sys.executable, __file__, "--serve", url, str(self.port), "--stack", stack],
            cwd=REPO if code is None else code, env=env)

    def __enter__(self) -> Server:
        import httpx

        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                # Any answer: a database kept at an older --revision answers 503 here.
                if httpx.get(f"{self.base}/healthz", timeout=2).status_code:
                    return self
            except httpx.HTTPError:
                time.sleep(0.2)
        raise RuntimeError("the coordinator did not start")

    def cpu_s(self) -> float:
        """User + system CPU seconds the server process has used so far."""
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def __exit__(self, *exc: object) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=30)


def measure(url: str, tag: str, figures: dict[str, float], code: Path | None = None,
            only: set[str] | None = None) -> None:
    import httpx
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.store.models import PoseRow
    from sqlalchemy import func, select

    db.upgrade(url, REVISION)  # a kept database gets the indexes of later migrations
    engine = db.make_engine(url)
    with db.make_sessionmaker(engine)() as s:
        max_id = s.scalar(select(func.max(PoseRow.id))) or 1
        if code is None and (only is None or "map_png" in only):
            # What the coordinator does after the commit that notes the map final (in a
            # background thread there; here before the server starts): draw the default
            # picture and store it (maps/stored.py, migration 0014).
            from graspscape.services.coordinator.maps.stored import store_default

            start = time.perf_counter()
            store_default(s, 1)
            s.commit()
            figures[f"map_png_draw_ahead_ms_{tag}"] = round(
                (time.perf_counter() - start) * 1000, 1)
    engine.dispose()
    with Server(url, code) as server:
        if only is None or "map_png" in only:
            # Cold map.png: the first read of this map version in a fresh server process (the
            # stored picture where it was drawn ahead), then a picture with other parameters,
            # drawn on demand.
            for name, path in (("map_png_cold_ms", "map.png"),
                               ("map_png_other_cold_ms", "map.png?cut=vertical")):
                start = time.perf_counter()
                httpx.get(f"{server.base}/explorations/1/{path}", timeout=600).raise_for_status()
                figures[f"{name}_{tag}"] = round((time.perf_counter() - start) * 1000, 1)
        for name, (path, per_client) in routes(1, max_id).items():
            if PER_CLIENT is not None and name not in ("map_png", "csv_first_byte"):
                per_client = PER_CLIENT
            if only is not None and name not in only:
                continue
            if name not in ("map_png", "csv_first_byte"):
                # The route's first request alone: computed, where later ones of the same
                # parameters are kept answers (api/answers.py).
                first = path(random.Random(-1)) if callable(path) else path
                start = time.perf_counter()
                httpx.get(f"{server.base}{first}", timeout=600).raise_for_status()
                figures[f"{name}_first_ms_{tag}"] = round((time.perf_counter() - start) * 1000, 1)
            cpu, own = server.cpu_s(), time.process_time()
            try:
                ms = np.array(run_route(server.base, name, path, per_client))
            except Exception as exc:  # reported in the results, the other routes still run
                print(f"{tag} {name}: failed: {exc!r}", flush=True)
                figures[f"{name}_failed_{tag}"] = 1
                continue
            # The server's CPU time per request: what a route costs, whatever else runs here;
            # and the 8 clients' (this process's), which competes with it for the cores.
            figures[f"{name}_server_cpu_ms_per_request_{tag}"] = round(
                (server.cpu_s() - cpu) * 1000 / len(ms), 2)
            figures[f"{name}_client_cpu_ms_per_request_{tag}"] = round(
                (time.process_time() - own) * 1000 / len(ms), 2)
            for q in (50, 95, 99):
                figures[f"{name}_p{q}_ms_{tag}"] = round(float(np.percentile(ms, q)), 1)
            print(f"{tag} {name}: p50 {np.percentile(ms, 50):.1f} p95 "
                  f"{np.percentile(ms, 95):.1f} p99 {np.percentile(ms, 99):.1f} ms", flush=True)


def _pg_url(size: str, rebuild: bool) -> str:
    with psycopg.connect(PG_ADMIN, autocommit=True) as conn:
        if not conn.execute("SELECT 1 FROM pg_database WHERE datname = %s", (PG_DB,)).fetchone():
            conn.execute(f'CREATE DATABASE "{PG_DB}"')
    schema = f"q_{size}"
    with psycopg.connect(PG_ADMIN.rsplit("/", 1)[0] + f"/{PG_DB}", autocommit=True) as conn:
        if rebuild:
            conn.execute(f'DROP SCHEMA IF EXISTS "{schema}" CASCADE')
        conn.execute(f'CREATE SCHEMA IF NOT EXISTS "{schema}"')
    return (f"postgresql+psycopg://postgres@127.0.0.1:5432/{PG_DB}"
            f"?options=-csearch_path%3D{schema}")


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10k,100k", help="SQLite sizes (10k, 100k, 1m)")
    parser.add_argument("--pg-sizes", default="10k,100k", help="PostgreSQL sizes")
    parser.add_argument("--keep", type=Path, default=DEFAULT_KEEP,
                        help="where the SQLite databases are kept and reused")
    parser.add_argument("--rebuild", action="store_true", help="build again even if kept")
    parser.add_argument("--revision", default="head",
                        help="migrate to this revision (e.g. 0010: before the query indexes)")
    parser.add_argument("--build-only", action="store_true",
                        help="build (or find) the databases, measure nothing, write no file")
    parser.add_argument("--before-code", type=Path,
                        help="a checkout of an earlier commit (git worktree): its server is "
                        "measured too on --before-routes, tags ending _before")
    parser.add_argument("--before-routes", default="manifolds,manifold_label")
    parser.add_argument("--routes", help="measure only these routes (comma-separated)")
    parser.add_argument("--results", default="query",
                        help="results file name (benchmarks/results/NAME.json)")
    parser.add_argument("--pg-db", default="bench_query",
                        help="PostgreSQL database the schemas are kept in (DROP it when done)")
    parser.add_argument("--per-client", type=int,
                        help="requests per client of each route but map_png and the CSV "
                        "(default 6)")
    parser.add_argument("--client", choices=["http.client", "httpx"],
                        default=query_clients.CLIENT,
                        help="the 8 clients' HTTP library (default http.client)")
    parser.add_argument("--serve", nargs=2, metavar=("URL", "PORT"), help=argparse.SUPPRESS)
    parser.add_argument("--stack", choices=sorted(STACKS), default="auto",
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        serve(args.serve[0], int(args.serve[1]), args.stack)
        return 0

    global REVISION, PG_DB, PER_CLIENT
    REVISION = args.revision
    PER_CLIENT = args.per_client
    PG_DB = args.pg_db
    query_clients.CLIENT = args.client
    figures: dict[str, float] = {"clients": CLIENTS, "load_avg_1min_start": _load(),
                                 "requests_per_client": args.per_client or 6}
    print(f"clients: {CLIENTS} threads of {query_clients.CLIENT}", flush=True)
    targets: list[tuple[str, str, str]] = []
    args.keep.mkdir(parents=True, exist_ok=True)
    for size in filter(None, args.sizes.split(",")):
        path = args.keep / f"query_{size}.db"
        if args.rebuild and path.exists():
            path.unlink()
        targets.append((size, f"sqlite:///{path}", f"{size}_sqlite"))
    for size in filter(None, args.pg_sizes.split(",")):
        targets.append((size, _pg_url(size, args.rebuild), f"{size}_pg"))
    for size, url, tag in targets:
        poses = _pose_count(url)
        if poses == 0:
            if url.startswith("sqlite"):
                Path(url.removeprefix("sqlite:///")).unlink(missing_ok=True)
            else:
                url = _pg_url(size, True)
            poses, seconds = build(url, SIZES[size])
            figures[f"ingest_poses_per_s_{tag}"] = round(poses / seconds)
            print(f"{tag}: {poses} poses ingested in {seconds:.0f} s", flush=True)
        figures[f"poses_{tag}"] = poses
        if args.build_only:
            continue
        only = set(args.routes.split(",")) if args.routes else None
        if args.before_code is not None:  # the earlier code first, on the same rows
            measure(url, f"{tag}_before", figures, args.before_code,
                    set(args.before_routes.split(",")))
            figures[f"load_avg_1min_after_{tag}_before"] = _load()
        measure(url, tag, figures, None, only)
        figures[f"load_avg_1min_after_{tag}"] = _load()
    if args.build_only:
        print(figures)
        return 0
    write_results(args.results, figures, extra={"note": (
        "uvicorn in a subprocess (one process, FastAPI's thread pool; uvloop and httptools), "
        f"8 client threads ({query_clients.CLIENT}, one keep-alive connection each) in the "
        "bench process on the same machine (client_cpu: their CPU per request); map_png "
        "percentiles are warm (cached per map version) after the cold first request; "
        "map_png_cold: the first read in a fresh server of the picture drawn ahead "
        "(map_png_draw_ahead: drawing and storing it, as the coordinator does once a map is "
        "final), map_png_other_cold: a picture with other parameters (cut=vertical), drawn "
        "on read; NAME_first: the route's first request "
        "alone (computed; the 8 clients' repeats of the same parameters are kept answers, "
        "api/answers.py); csv_first_byte to the first body byte; "
        "ingest_poses_per_s only where this run built the database (results made outside the "
        "timing); math.pi split: manifold A = φ < π")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
