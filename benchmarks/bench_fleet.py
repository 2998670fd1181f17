"""A fleet of simulated workers against one coordinator on PostgreSQL: N = 10, 100, 1,000.

Each simulated worker is a zenoh client session of its own that speaks the real protocol
(lease query → one TileLease per tile → a ResultBatch query → the Ack) and, instead of
simulating, sleeps `--pose-s` (0.1 s) per pose, then reports a result the size of a real one
(`workers.runtime.instant.instant_result`'s fields, the pose and key its own). Many workers
share an OS process (`--per-proc`, one thread per worker), so N = 1,000 fits a small machine.
A worker asks for one tile at a time, sends its batch and waits for the ack before it leases
again (a real worker overlaps the ack with its next tile; at 10 s per tile the difference is
the ack latency); with nothing to lease it backs off 0.5 → 5 s as a real one does.

The coordinator is `graspscape serve` in a process of its own, with its embedded zenoh peer
or, with `--via-router`, as a zenoh client of a router in a process of its own that the
workers connect to (docker-compose.yml's topology); the CPU (user + system) and resident
memory of both are sampled from /proc. The workers are benchmarks/fleet_workers.py.
Each N gets a fresh schema in database `bench_query` and one grid exploration sized for
about `--seconds` of work at the fleet's speed (N × 10 poses/s), with 100-pose tiles (the
coordinator's default).
Reported per N: sustained poses/s (stored, between 10 % and 90 % of the exploration), lease
and ack latency p50/p99 as the workers saw them, coordinator cores used and peak RSS, and the
accounting: every pose stored once (rows = planned poses = Σ acks' inserted, Σ duplicates = 0,
every tile done). Writes benchmarks/results/fleet.json (or `--results NAME`).

    .venv/bin/python benchmarks/bench_fleet.py [--workers 10,100,1000] [--per-proc 125]
        [--via-router [--coordinators K]] [--results fleet]

`--coordinators K` (with `--via-router`): K coordinators on the one database, each a zenoh
client of the router; coordinator_<i>_* figures are each one's, coordinator_cores_nN the sum.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import numpy as np
import psycopg

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks._results import write_results  # noqa: E402
from benchmarks._serve import start_coordinators  # noqa: E402

PG_ADMIN = "postgresql://postgres@127.0.0.1:5432/postgres"
PG_DB = "bench_query"
TILE_POSES = 100


# --- the coordinator and the run ---------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _proc_cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _proc_kb(pid: int, field: str, where: str = "status") -> int:
    """A kB field of /proc/<pid>/status (VmRSS, VmHWM) or smaps_rollup (Anonymous: the
    process's own memory; RSS also counts the shared-memory segments zenoh maps per local
    transport)."""
    for line in Path(f"/proc/{pid}/{where}").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1])
    return 0


def _schema_url() -> tuple[str, str]:
    with psycopg.connect(PG_ADMIN, autocommit=True) as conn:
        if not conn.execute("SELECT 1 FROM pg_database WHERE datname = %s", (PG_DB,)).fetchone():
            conn.execute(f'CREATE DATABASE "{PG_DB}"')
    schema = f"fleet_{uuid.uuid4().hex[:8]}"
    with psycopg.connect(f"{PG_ADMIN.rsplit('/', 1)[0]}/{PG_DB}", autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    return (f"postgresql+psycopg://postgres@127.0.0.1:5432/{PG_DB}"
            f"?options=-csearch_path%3D{schema}", schema)


def _drop(schema: str) -> None:
    with psycopg.connect(f"{PG_ADMIN.rsplit('/', 1)[0]}/{PG_DB}", autocommit=True) as conn:
        conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


def _exploration(url: str, poses: int) -> int:
    """A grid exploration of about `poses` poses (6 r levels, 1 roll), 100-pose tiles."""
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.exploration.service import create_exploration
    from graspscape.services.coordinator.objects.service import create_named
    from graspscape.shared.specs.exploration import (
        ExplorationSpec,
        PoseGridSpec,
        RefinementSpec,
    )

    db.upgrade(url)
    engine = db.make_engine(url)
    dtheta = math.sqrt(4 * math.pi * 6 / poses)
    with db.make_sessionmaker(engine)() as s:
        obj, _ = create_named(s, name="sphere", properties={}, shared_dir=None)
        spec = ExplorationSpec(object_id=obj.id, strategy={"name": "grid"},
                               grid=PoseGridSpec(dtheta=dtheta, r_min=0.0, r_max=0.05, dr=0.01),
                               refinement=RefinementSpec(levels=0))
        eid = create_exploration(s, spec=spec, tile_target_poses=TILE_POSES,
                                 max_poses=10**7).id
    engine.dispose()
    return eid


def _state(url: str, eid: int) -> tuple[int, int, str]:
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.store.models import ExplorationRow

    engine = db.make_engine(url)
    with db.make_sessionmaker(engine)() as s:
        row = s.get(ExplorationRow, eid)
        out = (row.poses_done, row.poses_total, row.status)
    engine.dispose()
    return out


def _accounting(url: str, eid: int) -> dict[str, int]:
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.store.models import PoseRow, TileRow
    from sqlalchemy import func, select

    engine = db.make_engine(url)
    with db.make_sessionmaker(engine)() as s:
        rows = s.scalar(select(func.count()).select_from(PoseRow)
                        .where(PoseRow.exploration_id == eid)) or 0
        keys = s.scalar(select(func.count(func.distinct(PoseRow.pose_key)))
                        .where(PoseRow.exploration_id == eid)) or 0
        planned = s.scalar(select(func.sum(TileRow.n_poses))
                           .where(TileRow.exploration_id == eid)) or 0
        not_done = s.scalar(select(func.count()).select_from(TileRow).where(
            TileRow.exploration_id == eid, TileRow.state != "done")) or 0
    engine.dispose()
    return {"rows": rows, "distinct_keys": keys, "planned": planned, "tiles_not_done": not_done}


def run(n: int, *, per_proc: int, pose_s: float, seconds: float, timeout: float,
        via_router: bool, log: Path | None = None,
        router_args: list[str] | None = None, coordinators: int = 1) -> dict[str, float]:
    url, schema = _schema_url()
    try:
        target = max(20 * TILE_POSES, int(n / pose_s * seconds))
        eid = _exploration(url, target)
        endpoint = f"tcp/127.0.0.1:{_free_port()}"
        router = None
        if via_router:
            # The topology docker-compose.yml runs: workers and the coordinator are clients
            # of one router (a router-mode session in its own process, as the fault tests'),
            # so the coordinator holds a single transport however many workers there are.
            router = subprocess.Popen(
                [sys.executable, "-m", "tests.faults.router", "--listen", endpoint,
                 *(router_args or [])],
                cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            assert router.stdout is not None
            router.stdout.readline()  # "router listening on ...": it accepts from now on
            zenoh_args = ["--zenoh-mode", "client", "--zenoh-connect", endpoint]
        else:
            zenoh_args = ["--zenoh-listen", endpoint]
        with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as logs:
            started = start_coordinators(coordinators, url, zenoh_args, tmp, logs,
                                    None if log is None else f"{log}.n{n}")
            fleet, outs = [], []
            for first in range(0, n, per_proc):
                out = Path(tmp) / f"tally_{first}.json"
                outs.append(out)
                fleet.append(subprocess.Popen(
                    [sys.executable, str(REPO / "benchmarks" / "fleet_workers.py"), endpoint,
                     str(min(per_proc, n - first)), str(first), str(pose_s), str(out)],
                    cwd=REPO))
            pids = [c.pid for c in started] + ([router.pid] if router is not None else [])
            samples = _trace(url, eid, pids, timeout, [proc.pid for proc in fleet])
            for proc in fleet:
                proc.send_signal(signal.SIGTERM)
            for proc in fleet:
                proc.wait(timeout=120)
            rss_peak_kb = [_proc_kb(pid, "VmHWM") for pid in pids]
            for proc in (*started, router):
                if proc is None:
                    continue
                proc.send_signal(signal.SIGTERM)
                try:
                    proc.wait(timeout=60)
                except subprocess.TimeoutExpired:  # closing a thousand sessions can hang
                    proc.kill()
                    proc.wait()
            tallies = [json.loads(out.read_text()) for out in outs]
        accounting = _accounting(url, eid)
    finally:
        _drop(schema)
    return _figures(n, samples, tallies, accounting, rss_peak_kb, coordinators)


# What the database's sessions of the run do, sampled with each progress sample: batches
# waiting on the exploration's row lock (store/ingest.py: the counter update), backends in a
# COMMIT (its WAL flush), and all that are not idle (busy, waiting or between statements of an
# open transaction).
_ACTIVITY = """
SELECT count(*) FILTER (WHERE wait_event_type = 'Lock'
                          AND query LIKE 'UPDATE explorations SET poses_done%%'),
       count(*) FILTER (WHERE state = 'active' AND query LIKE 'COMMIT%%'),
       count(*) FILTER (WHERE state <> 'idle')
FROM pg_stat_activity WHERE datname = %s AND pid <> pg_backend_pid()
"""


def _machine_busy_s() -> float:
    """CPU seconds every core of the machine has spent not idle (/proc/stat)."""
    fields = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    return (sum(fields[:8]) - fields[3] - fields[4]) / os.sysconf("SC_CLK_TCK")


def _trace(url: str, eid: int, pids: list[int], timeout: float,
           fleet_pids: list[int]) -> list[tuple]:  # type: ignore[type-arg]
    """(time, poses done, poses total, CPU s and anonymous kB of each of `pids`: the
    coordinator, then the router if any, _ACTIVITY's counts, the fleet processes' CPU s
    together, the whole machine's busy CPU s) until done or timeout: where the cores go."""
    samples = []
    deadline = time.monotonic() + timeout
    with psycopg.connect(f"{PG_ADMIN.rsplit('/', 1)[0]}/{PG_DB}", autocommit=True) as conn:
        while time.monotonic() < deadline:
            done, total, status = _state(url, eid)
            activity = conn.execute(_ACTIVITY, (PG_DB,)).fetchone()
            samples.append((time.monotonic(), done, total, [_proc_cpu_s(p) for p in pids],
                            [_proc_kb(p, "Anonymous", "smaps_rollup") for p in pids],
                            activity, sum(_proc_cpu_s(p) for p in fleet_pids),
                            _machine_busy_s()))
            if status == "done":
                break
            time.sleep(0.5)
    return samples


def _figures(n: int, samples, tallies, accounting, rss_peak_kb: list[int],  # type: ignore[no-untyped-def]
             coordinators: int = 1) -> dict[str, float]:
    total = samples[-1][2]

    def at(fraction: float):  # type: ignore[no-untyped-def]
        return next((s for s in samples if s[1] >= fraction * total), samples[-1])

    (t0, d0, _, c0, _, _, f0, m0), (t1, d1, _, c1, _, _, f1, m1) = at(0.1), at(0.9)
    steady = [s[5] for s in samples if t0 <= s[0] <= t1] or [samples[-1][5]]
    lease = np.concatenate([t["lease_ms"] for t in tallies]) if tallies else np.zeros(1)
    ack = np.concatenate([t["ack_ms"] for t in tallies]) if tallies else np.zeros(1)
    inserted = sum(t["inserted"] for t in tallies)
    duplicates = sum(t["duplicates"] for t in tallies)
    figures: dict[str, float] = {
        f"poses_per_s_n{n}": round((d1 - d0) / (t1 - t0), 1) if t1 > t0 else float("nan"),
        f"demand_poses_per_s_n{n}": round(n / 0.1, 1),
        f"poses_n{n}": total,
        f"finished_n{n}": int(samples[-1][1] >= total),
        f"lease_p50_ms_n{n}": round(float(np.percentile(lease, 50)), 1),
        f"lease_p99_ms_n{n}": round(float(np.percentile(lease, 99)), 1),
        f"ack_p50_ms_n{n}": round(float(np.percentile(ack, 50)), 1),
        f"ack_p99_ms_n{n}": round(float(np.percentile(ack, 99)), 1),
        # Means over the samples between 10 % and 90 % (_ACTIVITY).
        f"pg_waiting_exploration_lock_n{n}": round(float(np.mean([a[0] for a in steady])), 2),
        f"pg_committing_n{n}": round(float(np.mean([a[1] for a in steady])), 2),
        f"pg_not_idle_n{n}": round(float(np.mean([a[2] for a in steady])), 2),
        # Where the machine's cores went meanwhile: the simulated fleet's own processes, and
        # everything (coordinator, router, PostgreSQL, fleet, the rest of the machine).
        f"fleet_processes_cores_n{n}": round((f1 - f0) / (t1 - t0), 2) if t1 > t0 else 0.0,
        f"machine_busy_cores_n{n}": round((m1 - m0) / (t1 - t0), 2) if t1 > t0 else 0.0,
    }
    names = [f"coordinator_{i + 1}" for i in range(coordinators)] if coordinators > 1 else [
        "coordinator"]
    for i, who in enumerate([*names, "router"][:len(rss_peak_kb)]):
        figures.update({
            f"{who}_cores_n{n}": round((c1[i] - c0[i]) / (t1 - t0), 2) if t1 > t0 else 0.0,
            f"{who}_rss_peak_mb_n{n}": round(rss_peak_kb[i] / 1024, 1),
            f"{who}_anonymous_peak_mb_n{n}": round(max(s[4][i] for s in samples) / 1024, 1),
        })
    if coordinators > 1:  # the coordinators together
        figures[f"coordinator_cores_n{n}"] = round(sum(
            figures[f"{who}_cores_n{n}"] for who in names), 2)
    figures.update({
        f"rows_stored_n{n}": accounting["rows"],
        f"rows_planned_n{n}": accounting["planned"],
        f"distinct_keys_n{n}": accounting["distinct_keys"],
        f"acked_inserted_n{n}": inserted,
        f"acked_duplicates_n{n}": duplicates,
        f"acks_missing_poses_n{n}": sum(t["missing"] for t in tallies),
        f"batches_unacked_n{n}": sum(t["refused"] for t in tallies),
        f"tiles_not_done_n{n}": accounting["tiles_not_done"],
        f"workers_connected_n{n}": sum(t["connected"] for t in tallies),
        f"connect_timeouts_n{n}": sum(t["connect_failures"] for t in tallies),
        f"batches_resent_n{n}": sum(t["resent"] for t in tallies),
        # Lost: a planned pose not stored (the exploration finished) or a pose acknowledged
        # but not stored; doubled: a pose stored twice. A batch sent again after its ack did
        # not arrive in time comes back as duplicates: stored once, acknowledged twice.
        f"lost_n{n}": max(accounting["planned"] - accounting["rows"], 0)
        * int(samples[-1][1] >= total) + max(inserted - accounting["rows"], 0),
        f"doubled_n{n}": accounting["rows"] - accounting["distinct_keys"],
    })
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="10,100,1000")
    parser.add_argument("--per-proc", type=int, default=125, help="workers per OS process")
    parser.add_argument("--pose-s", type=float, default=0.1, help="sleep per pose, s")
    parser.add_argument("--seconds", type=float, default=30.0,
                        help="exploration sized for this long at the fleet's own speed")
    parser.add_argument("--timeout", type=float, default=600.0, help="per N, s")
    parser.add_argument("--via-router", action="store_true",
                        help="workers and coordinator connect to a zenoh router (its own "
                        "process) instead of the coordinator's embedded peer")
    parser.add_argument("--router-accept-pending", type=int, default=None,
                        help="the router's transport/unicast/accept_pending (zenoh: 100)")
    parser.add_argument("--router-max-sessions", type=int, default=None,
                        help="the router's transport/unicast/max_sessions (zenoh: 1,000)")
    parser.add_argument("--coordinator-log", type=Path, default=None,
                        help="the coordinator's log at info level into PATH.n<N>")
    parser.add_argument("--coordinators", type=int, default=1,
                        help="coordinators on the one database (> 1: with --via-router)")
    parser.add_argument("--results", default="fleet",
                        help="results file name, benchmarks/results/<name>.json")
    args = parser.parse_args()
    if args.coordinators > 1 and not args.via_router:
        parser.error("--coordinators above 1 needs --via-router")
    figures: dict[str, float] = {"load_avg_1min_start": round(os.getloadavg()[0], 2)}
    for n in (int(x) for x in args.workers.split(",")):
        got = run(n, per_proc=args.per_proc, pose_s=args.pose_s, seconds=args.seconds,
                  timeout=args.timeout, via_router=args.via_router, log=args.coordinator_log,
                  router_args=[*(["--accept-pending", str(args.router_accept_pending)]
                                 if args.router_accept_pending else []),
                               *(["--max-sessions", str(args.router_max_sessions)]
                                 if args.router_max_sessions else [])],
                  coordinators=args.coordinators)
        print(json.dumps(got), flush=True)
        figures.update(got)
        figures[f"load_avg_1min_after_n{n}"] = round(os.getloadavg()[0], 2)
    topology = ("a zenoh router (tests/faults/router.py: a router-mode session, its own "
                "process) that the coordinator (zenoh client) and the workers connect to; "
                "router_* figures are that process's" if args.via_router
                else "the coordinator's embedded zenoh peer, which the workers connect to")
    who = ("coordinator: graspscape serve" if args.coordinators == 1 else
           f"coordinators: {args.coordinators} × graspscape serve on the one database, each")
    write_results(args.results, figures, extra={"note": (
        f"{who} (PostgreSQL 127.0.0.1) in its own process; zenoh: "
        f"{topology}; workers: zenoh client sessions, one per simulated worker, --per-proc "
        "per OS process, all on the same machine as the coordinator and the database; "
        "poses_per_s between 10 % and 90 % of the exploration stored; latencies as the "
        "workers saw them (lease: query to last reply; ack: batch query to its ack); "
        "finished_nN = 0 where the exploration did not finish within --timeout (the rate is "
        "then over what was stored); pg_*_nN: PostgreSQL sessions of the run's database "
        "(pg_stat_activity, with each 0.5 s progress sample, mean between 10 % and 90 %): "
        "waiting on the exploration's row lock at the counter update, in a COMMIT, not idle")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
