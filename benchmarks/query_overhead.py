"""Server CPU per request of the kept read routes and paged /poses, an earlier commit against this
checkout, interleaved on one 10k map, SQLite or PostgreSQL (issue 21: the framework's share).

bench_query.py's 48 requests per route measure a ~1.5 ms route to ±0.2 ms (the process's CPU
time comes in 10 ms ticks); this sends CLIENTS × --per-client requests per route and server, and
alternates the servers --rounds times, so that the machine's other work falls on all. Same
server (`bench_query.Server`: uvicorn in a subprocess), routes, clients and map builder as
bench_query.

    .venv/bin/python benchmarks/query_overhead.py --before-code DIR [--keep DIR]
        [--per-client 40] [--rounds 2] [--before-stack plain] [--stack-ab] [--client-ab]
        [--postgresql --pg-db NAME] [--results NAME]

DIR: an earlier commit unpacked (`git archive REF | tar -x -C DIR`); its server runs from there
(tag `before`, on uvicorn's --before-stack: auto = uvloop and httptools, plain = asyncio and
h11). `after`: this checkout's server on auto. --stack-ab adds `after_plain` (this code on
plain: the stack's share); --client-ab adds `after_httpx` (this server, httpx clients: their
CPU). Per server and route: its CPU and the clients' CPU per request, p50 and p95.
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks import bench_query as bq  # noqa: E402
from benchmarks import query_clients  # noqa: E402
from benchmarks._results import write_results  # noqa: E402

ROUTES = ("best", "best_mu_s", "manifolds", "manifold_label", "poses_page", "poses_viable_page")


def one_server(url: str, code: Path | None, stack: str, client: str, per_client: int,
               max_id: int) -> dict[str, tuple[float, float, list[float]]]:
    """Route → (server CPU ms per request, clients' CPU ms per request, latencies ms) for one
    server process."""
    import httpx

    out: dict[str, tuple[float, float, list[float]]] = {}
    query_clients.CLIENT = client
    with bq.Server(url, code, stack) as server:
        for name, (path, _) in bq.routes(1, max_id).items():
            if name not in ROUTES:
                continue
            # The first request computes the answer; the measured ones are kept answers
            # (paged /poses: random pages, never kept).
            first = path(random.Random(-1)) if callable(path) else path
            httpx.get(f"{server.base}{first}", timeout=600).raise_for_status()
            cpu, own = server.cpu_s(), time.process_time()
            ms = bq.run_route(server.base, name, path, per_client)
            out[name] = ((server.cpu_s() - cpu) * 1000 / len(ms),
                         (time.process_time() - own) * 1000 / len(ms), ms)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before-code", type=Path, required=True)
    parser.add_argument("--keep", type=Path, default=bq.DEFAULT_KEEP)
    parser.add_argument("--per-client", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--results", default="query_overhead")
    parser.add_argument("--before-stack", choices=sorted(bq.STACKS), default="auto")
    parser.add_argument("--stack-ab", action="store_true")
    parser.add_argument("--client-ab", action="store_true")
    parser.add_argument("--client", choices=["http.client", "httpx"], default="http.client")
    parser.add_argument("--postgresql", action="store_true",
                        help="the 10k map on PostgreSQL (bench_query's schema q_10k in --pg-db)")
    parser.add_argument("--pg-db", default="bench_query")
    args = parser.parse_args()
    variants: list[tuple[str, Path | None, str, str]] = [
        ("before", args.before_code, args.before_stack, args.client)]
    if args.stack_ab:
        variants.append(("after_plain", None, "plain", args.client))
    if args.client_ab:
        variants.append(("after_httpx", None, "auto", "httpx"))
    variants.append(("after", None, "auto", args.client))

    path = args.keep / "query_10k.db"  # bench_query's name for its 10k SQLite map
    url = f"sqlite:///{path}"
    if args.postgresql:  # bench_query's 10k PostgreSQL schema, in --pg-db
        bq.PG_DB = args.pg_db
        url = bq._pg_url("10k", False)
    figures: dict[str, float] = {"load_avg_1min_start": bq._load(), "clients": bq.CLIENTS,
                                 "requests_per_route_per_server_and_round":
                                     bq.CLIENTS * args.per_client, "rounds": args.rounds}
    if bq._pose_count(url) == 0:
        if args.postgresql:
            url = bq._pg_url("10k", True)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.unlink(missing_ok=True)
        bq.build(url, bq.SIZES["10k"])
    from graspscape.services.coordinator import db

    db.upgrade(url, bq.REVISION)
    figures["poses"] = bq._pose_count(url)
    cpu: dict[tuple[str, str], list[float]] = {}
    own: dict[tuple[str, str], list[float]] = {}
    latency: dict[tuple[str, str], list[float]] = {}
    for _ in range(args.rounds):
        for tag, code, stack, client in variants:
            for name, (ms_cpu, ms_own, ms) in one_server(
                    url, code, stack, client, args.per_client, int(figures["poses"])).items():
                cpu.setdefault((name, tag), []).append(ms_cpu)
                own.setdefault((name, tag), []).append(ms_own)
                latency.setdefault((name, tag), []).extend(ms)
                print(f"{tag} {name}: {ms_cpu:.2f} ms server CPU, {ms_own:.2f} ms client CPU "
                      f"per request; p95 {np.percentile(ms, 95):.1f} ms", flush=True)
    for (name, tag), values in cpu.items():
        figures[f"{name}_server_cpu_ms_per_request_{tag}"] = round(statistics.median(values), 2)
        figures[f"{name}_server_cpu_ms_per_request_rounds_{tag}"] = [round(v, 2) for v in values]
        figures[f"{name}_client_cpu_ms_per_request_{tag}"] = round(
            statistics.median(own[(name, tag)]), 2)
        figures[f"{name}_p50_ms_{tag}"] = round(float(np.percentile(latency[(name, tag)], 50)), 1)
        figures[f"{name}_p95_ms_{tag}"] = round(float(np.percentile(latency[(name, tag)], 95)), 1)
    figures["load_avg_1min_end"] = bq._load()
    backend = "PostgreSQL" if args.postgresql else "SQLite"
    write_results(args.results, figures, extra={"note": (
        f"servers alternated per round on the same 10k {backend} map (bench_query's "
        "builder): "
        + "; ".join(f"{tag}: {'--before-code' if code else 'this checkout'}, uvicorn "
                    f"{'/'.join(bq.STACKS[stack])}, {client} clients"
                    for tag, code, stack, client in variants)
        + ". CPU: median over rounds of the server process's user+system CPU per request, "
        "and of the 8 client threads' (the bench process); p50/p95 pooled over rounds; "
        "clients and server share the machine's 2 cores (with other sessions' work: see the "
        "load averages)")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
