"""Server CPU per request of the kept read routes and paged /poses, an earlier commit against this
checkout, interleaved on one SQLite map (issue 21: the framework's share of a read).

bench_query.py's 48 requests per route measure a ~1.5 ms route to ±0.2 ms (the process's CPU
time comes in 10 ms ticks); this sends CLIENTS × --per-client requests per route and server, and
alternates the two servers --rounds times, so that the machine's other work falls on both. Same
server (`bench_query.Server`: uvicorn in a subprocess), routes and map builder as bench_query.

    .venv/bin/python benchmarks/query_overhead.py --before-code DIR [--keep DIR]
        [--per-client 40] [--rounds 2]

DIR: an earlier commit unpacked (`git archive REF | tar -x -C DIR`); its server runs from there.
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks import bench_query as bq  # noqa: E402
from benchmarks._results import write_results  # noqa: E402

ROUTES = ("best", "best_mu_s", "manifolds", "manifold_label", "poses_page", "poses_viable_page")


def one_server(url: str, code: Path | None, per_client: int, max_id: int
               ) -> dict[str, tuple[float, list[float]]]:
    """Route → (server CPU ms per request, latencies ms) for one server process."""
    import httpx

    out: dict[str, tuple[float, list[float]]] = {}
    with bq.Server(url, code) as server:
        for name, (path, _) in bq.routes(1, max_id).items():
            if name not in ROUTES:
                continue
            # The first request computes the answer; the measured ones are kept answers
            # (paged /poses: random pages, never kept).
            first = path(random.Random(-1)) if callable(path) else path
            httpx.get(f"{server.base}{first}", timeout=600).raise_for_status()
            cpu = server.cpu_s()
            ms = bq.run_route(server.base, name, path, per_client)
            out[name] = ((server.cpu_s() - cpu) * 1000 / len(ms), ms)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before-code", type=Path, required=True)
    parser.add_argument("--keep", type=Path, default=bq.DEFAULT_KEEP)
    parser.add_argument("--per-client", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--results", default="query_overhead")
    args = parser.parse_args()

    path = args.keep / "query_10k.db"  # bench_query's name for its 10k SQLite map
    url = f"sqlite:///{path}"
    figures: dict[str, float] = {"load_avg_1min_start": bq._load(), "clients": bq.CLIENTS,
                                 "requests_per_route_per_server_and_round":
                                     bq.CLIENTS * args.per_client, "rounds": args.rounds}
    if bq._pose_count(url) == 0:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.unlink(missing_ok=True)
        bq.build(url, bq.SIZES["10k"])
    from graspscape.services.coordinator import db

    db.upgrade(url, bq.REVISION)
    figures["poses"] = bq._pose_count(url)
    cpu: dict[str, list[float]] = {}
    latency: dict[str, list[float]] = {}
    for _ in range(args.rounds):
        for tag, code in (("before", args.before_code), ("after", None)):
            for name, (ms_cpu, ms) in one_server(url, code, args.per_client,
                                                 int(figures["poses"])).items():
                cpu.setdefault(f"{name}_{tag}", []).append(ms_cpu)
                latency.setdefault(f"{name}_{tag}", []).extend(ms)
                print(f"{tag} {name}: {ms_cpu:.2f} ms CPU per request", flush=True)
    for key, values in cpu.items():
        name, tag = key.rsplit("_", 1)
        figures[f"{name}_server_cpu_ms_per_request_{tag}"] = round(statistics.median(values), 2)
        figures[f"{name}_server_cpu_ms_per_request_rounds_{tag}"] = [round(v, 2) for v in values]
        figures[f"{name}_p50_ms_{tag}"] = round(float(np.percentile(latency[key], 50)), 1)
        figures[f"{name}_p95_ms_{tag}"] = round(float(np.percentile(latency[key], 95)), 1)
    figures["load_avg_1min_end"] = bq._load()
    write_results(args.results, figures, extra={"note": (
        "before: the server of --before-code, after: this checkout's, alternated per round on "
        "the same 10k SQLite map (bench_query's builder); CPU: median over rounds of the "
        "server process's user+system CPU per request; p50/p95 pooled over rounds, 8 httpx "
        "client threads on the same loaded machine (queueing for its 2 cores)")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
