"""A fleet of simulated workers against one coordinator on PostgreSQL: N = 10, 100, 1,000.

Each simulated worker is a zenoh client session of its own that speaks the real protocol
(lease query → one TileLease per tile → a ResultBatch query → the Ack) and, instead of
simulating, sleeps `--pose-s` (0.1 s) per pose, then reports a result the size of a real one
(`workers.runtime.instant.instant_result`'s fields, the pose and key its own). Many workers
share an OS process (`--per-proc`, one thread per worker), so N = 1,000 fits a small machine.
A worker asks for one tile at a time, sends its batch and waits for the ack before it leases
again (a real worker overlaps the ack with its next tile; at 10 s per tile the difference is
the ack latency); with nothing to lease it backs off 0.5 → 5 s as a real one does.

The coordinator is `graspscape serve` with its embedded zenoh peer, in a process of its own;
its CPU (user + system) and resident memory are sampled from /proc. Each N gets a fresh
schema in database `bench_query` and one grid exploration sized for about `--seconds` of work
at the fleet's speed (N × 10 poses/s), with 100-pose tiles (the coordinator's default).
Reported per N: sustained poses/s (stored, between 10 % and 90 % of the exploration), lease
and ack latency p50/p99 as the workers saw them, coordinator cores used and peak RSS, and the
accounting: every pose stored once (rows = planned poses = Σ acks' inserted, Σ duplicates = 0,
every tile done). Writes benchmarks/results/fleet.json.

    .venv/bin/python benchmarks/bench_fleet.py [--workers 10,100,1000] [--per-proc 125]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import psycopg

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks._results import write_results  # noqa: E402

PG_ADMIN = "postgresql://postgres@127.0.0.1:5432/postgres"
PG_DB = "bench_query"
TILE_POSES = 100


# --- the simulated workers (one OS process runs many) ----------------------------------------
class Tally:
    """What one fleet process saw, written as JSON when it is told to stop."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.lease_ms: list[float] = []
        self.ack_ms: list[float] = []
        self.tiles = self.poses_sent = self.inserted = self.duplicates = 0
        self.missing = self.refused = self.empty_leases = 0
        self.connected = self.connect_failures = self.resent = 0

    def as_dict(self) -> dict[str, object]:
        return {k: v for k, v in vars(self).items() if k != "lock"}


def _result_template() -> dict[str, object]:
    """A real-sized held result as JSON-ready data (pose, key and effective r set per pose)."""
    from graspscape.shared.specs.pose import Pose
    from graspscape.workers.runtime.instant import instant_result

    return json.loads(instant_result(Pose(theta=0.0, phi=0.0, r=0.0)).model_dump_json())


def _batch_payload(template: dict[str, object], worker_id: str, tile) -> tuple[bytes, int]:  # type: ignore[no-untyped-def]
    """The ResultBatch of a whole tile, as bytes: one template dict per pose, dumped by the
    C json encoder (pydantic per pose would cost the fleet's processes more than the
    coordinator's work being measured)."""
    from graspscape.shared.wire.messages import WIRE_VERSION

    results = []
    for pose in tile.poses():
        result = dict(template)
        result["pose"] = pose.model_dump(mode="json")
        result["pose_key"] = pose.key()
        result["effective_r"] = pose.r
        results.append(result)
    batch = {"v": WIRE_VERSION, "kind": "result_batch", "worker_id": worker_id,
             "tile_id": tile.tile_id, "lease_epoch": tile.lease_epoch, "results": results,
             "final": True, "release": False, "error": None}
    return json.dumps(batch).encode(), len(results)


def simulated_worker(endpoint: str, worker_id: str, pose_s: float, stop: threading.Event,
                     tally: Tally, template: dict[str, object]) -> None:
    import zenoh
    from graspscape.shared.wire import keys
    from graspscape.shared.wire.codec import decode_as, decode_reply_error, encode
    from graspscape.shared.wire.messages import Ack, LeaseRequest, TileLease
    from graspscape.shared.wire.session import zenoh_config

    session = None
    while session is None:  # as a real worker does: retry until the coordinator lets it in
        try:
            session = zenoh.open(zenoh_config(mode="client", connect=[endpoint],
                                              connect_timeout_ms=10_000))
        except zenoh.ZError:
            with tally.lock:
                tally.connect_failures += 1
            if stop.wait(1.0):
                return
    with tally.lock:
        tally.connected += 1
    token = session.liveliness().declare_token(keys.alive_key(worker_id))
    request = encode(LeaseRequest(worker_id=worker_id, host="fleet", capacity=1))
    idle = 0.5
    try:
        while not stop.is_set():
            start = time.perf_counter()
            tiles = []
            for reply in session.get(keys.LEASE_QUERY, payload=request, timeout=60.0,
                                     consolidation=zenoh.ConsolidationMode.NONE):
                if reply.ok is not None:
                    message = decode_as(reply.ok.payload.to_bytes(), TileLease)
                    if isinstance(message, TileLease):
                        tiles.append(message)
            lease_ms = (time.perf_counter() - start) * 1000
            with tally.lock:
                tally.lease_ms.append(lease_ms)
                tally.empty_leases += not tiles
            if not tiles:
                stop.wait(idle)
                idle = min(idle * 2, 5.0)
                continue
            idle = 0.5
            for tile in tiles:
                payload, n = _batch_payload(template, worker_id, tile)
                if stop.wait(pose_s * n):
                    return  # told to stop: the lease runs out and the tile goes round again
                start = time.perf_counter()
                ack = None
                for _attempt in range(5):  # as a real worker: sent again until acknowledged
                    for reply in session.get(keys.results_key(tile.tile_id, tile.lease_epoch),
                                             payload=payload, timeout=60.0,
                                             consolidation=zenoh.ConsolidationMode.NONE):
                        message = (decode_as(reply.ok.payload.to_bytes(), Ack)
                                   if reply.ok is not None
                                   else decode_reply_error(reply.err.payload.to_bytes()))
                        if isinstance(message, Ack):
                            ack = message
                    if ack is not None:
                        break
                    with tally.lock:
                        tally.resent += 1
                ack_ms = (time.perf_counter() - start) * 1000
                with tally.lock:
                    tally.ack_ms.append(ack_ms)
                    tally.tiles += 1
                    tally.poses_sent += n
                    if ack is None:
                        tally.refused += 1
                    else:
                        tally.inserted += ack.inserted
                        tally.duplicates += ack.duplicates
                        tally.missing += len(ack.missing)
    finally:
        token.undeclare()
        session.close()


def fleet_main(endpoint: str, count: int, first: int, pose_s: float, out: Path) -> None:
    """One OS process of the fleet: `count` workers until SIGTERM, then the tally to `out`."""
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    tally, template = Tally(), _result_template()
    threads = [threading.Thread(target=simulated_worker, daemon=True,
                                args=(endpoint, f"fleet-{first + i}", pose_s, stop, tally,
                                      template))
               for i in range(count)]
    for t in threads:
        t.start()
        time.sleep(0.01)  # not a thousand handshakes in the same millisecond
    stop.wait()
    for t in threads:
        t.join(timeout=30)
    out.write_text(json.dumps(tally.as_dict()))


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


def run(n: int, *, per_proc: int, pose_s: float, seconds: float,
        timeout: float) -> dict[str, float]:
    url, schema = _schema_url()
    try:
        target = max(20 * TILE_POSES, int(n / pose_s * seconds))
        eid = _exploration(url, target)
        endpoint = f"tcp/127.0.0.1:{_free_port()}"
        port = _free_port()
        with tempfile.TemporaryDirectory() as tmp:
            coordinator = subprocess.Popen(
                [sys.executable, "-m", "graspscape.services.local.cli", "serve",
                 "--database-url", url, "--port", str(port), "--no-migrate",
                 "--log-level", "warning", "--zenoh-listen", endpoint],
                cwd=REPO, env={**os.environ, "GRASPSCAPE_DATABASE__DATA_DIR": tmp},
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            _wait_http(port, coordinator)
            fleet, outs = [], []
            for first in range(0, n, per_proc):
                out = Path(tmp) / f"tally_{first}.json"
                outs.append(out)
                fleet.append(subprocess.Popen(
                    [sys.executable, __file__, "--fleet", endpoint, str(min(per_proc, n - first)),
                     str(first), str(pose_s), str(out)], cwd=REPO))
            samples = _trace(url, eid, coordinator.pid, timeout)
            for proc in fleet:
                proc.send_signal(signal.SIGTERM)
            for proc in fleet:
                proc.wait(timeout=120)
            rss_peak_kb = _proc_kb(coordinator.pid, "VmHWM")
            coordinator.send_signal(signal.SIGTERM)
            try:
                coordinator.wait(timeout=60)
            except subprocess.TimeoutExpired:  # closing a thousand sessions can hang: not measured
                coordinator.kill()
                coordinator.wait()
            tallies = [json.loads(out.read_text()) for out in outs]
        accounting = _accounting(url, eid)
    finally:
        _drop(schema)
    return _figures(n, samples, tallies, accounting, rss_peak_kb)


def _wait_http(port: int, coordinator: subprocess.Popen) -> None:
    import httpx

    deadline = time.monotonic() + 300  # a loaded machine: imports alone can take a minute
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=5).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.5)
    coordinator.kill()
    raise RuntimeError("the coordinator did not start")


def _trace(url: str, eid: int, pid: int,
           timeout: float) -> list[tuple[float, int, int, float, int]]:
    """(time, poses done, poses total, coordinator CPU s, anonymous kB) until done or
    timeout."""
    samples = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        done, total, status = _state(url, eid)
        samples.append((time.monotonic(), done, total, _proc_cpu_s(pid),
                        _proc_kb(pid, "Anonymous", "smaps_rollup")))
        if status == "done":
            break
        time.sleep(0.5)
    return samples


def _figures(n: int, samples, tallies, accounting, rss_peak_kb: int) -> dict[str, float]:  # type: ignore[no-untyped-def]
    total = samples[-1][2]

    def at(fraction: float):  # type: ignore[no-untyped-def]
        return next((s for s in samples if s[1] >= fraction * total), samples[-1])

    (t0, d0, _, c0, _), (t1, d1, _, c1, _) = at(0.1), at(0.9)
    lease = np.concatenate([t["lease_ms"] for t in tallies]) if tallies else np.zeros(1)
    ack = np.concatenate([t["ack_ms"] for t in tallies]) if tallies else np.zeros(1)
    inserted = sum(t["inserted"] for t in tallies)
    duplicates = sum(t["duplicates"] for t in tallies)
    return {
        f"poses_per_s_n{n}": round((d1 - d0) / (t1 - t0), 1) if t1 > t0 else float("nan"),
        f"demand_poses_per_s_n{n}": round(n / 0.1, 1),
        f"poses_n{n}": total,
        f"finished_n{n}": int(samples[-1][1] >= total),
        f"lease_p50_ms_n{n}": round(float(np.percentile(lease, 50)), 1),
        f"lease_p99_ms_n{n}": round(float(np.percentile(lease, 99)), 1),
        f"ack_p50_ms_n{n}": round(float(np.percentile(ack, 50)), 1),
        f"ack_p99_ms_n{n}": round(float(np.percentile(ack, 99)), 1),
        f"coordinator_cores_n{n}": round((c1 - c0) / (t1 - t0), 2) if t1 > t0 else 0.0,
        f"coordinator_rss_peak_mb_n{n}": round(rss_peak_kb / 1024, 1),
        f"coordinator_anonymous_peak_mb_n{n}": round(max(s[4] for s in samples) / 1024, 1),
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
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="10,100,1000")
    parser.add_argument("--per-proc", type=int, default=125, help="workers per OS process")
    parser.add_argument("--pose-s", type=float, default=0.1, help="sleep per pose, s")
    parser.add_argument("--seconds", type=float, default=30.0,
                        help="exploration sized for this long at the fleet's own speed")
    parser.add_argument("--timeout", type=float, default=600.0, help="per N, s")
    parser.add_argument("--fleet", nargs=5, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.fleet:
        endpoint, count, first, pose_s, out = args.fleet
        fleet_main(endpoint, int(count), int(first), float(pose_s), Path(out))
        return 0
    figures: dict[str, float] = {"load_avg_1min_start": round(os.getloadavg()[0], 2)}
    for n in (int(x) for x in args.workers.split(",")):
        got = run(n, per_proc=args.per_proc, pose_s=args.pose_s, seconds=args.seconds,
                  timeout=args.timeout)
        print(json.dumps(got), flush=True)
        figures.update(got)
        figures[f"load_avg_1min_after_n{n}"] = round(os.getloadavg()[0], 2)
    write_results("fleet", figures, extra={"note": (
        "coordinator: graspscape serve (embedded zenoh peer, PostgreSQL 127.0.0.1) in its own "
        "process; workers: zenoh client sessions, one per simulated worker, --per-proc per OS "
        "process, all on the same machine as the coordinator and the database; poses_per_s "
        "between 10 % and 90 % of the exploration stored; latencies as the workers saw them "
        "(lease: query to last reply; ack: batch query to its ack); finished_nN = 0 where the "
        "exploration did not finish within --timeout (the rate is then over what was stored)")})
    return 0


if __name__ == "__main__":
    sys.exit(main())
