"""Coordinator CPU per lease and per result batch, this checkout against an earlier commit.

What one dispatcher handler thread does per query, without zenoh: a lease (decode the
`LeaseRequest`, `dispatch.answers.lease_for` in a session of its own, encode the replies) and
a result batch of one 100-pose tile (decode and validate the `ResultBatch` bytes,
`dispatch.answers.report_batch` in a session of its own, encode the ack), on PostgreSQL, one
thread, one worker at a time. Timed per query: the thread's CPU (`time.thread_time`) and the
wall clock (which adds PostgreSQL's side and the round trips). The worker's side (making the
results, encoding the batch) is not timed.

Each variant runs in a process of its own: this checkout's `graspscape` packages, or those of
`--baseline REF` unpacked by `git archive` into a temporary folder (the same benchmark code
drives both, through the entry points both have). Rounds alternate the two, each on a fresh
schema; the figures are medians over rounds of each round's median per query. Writes
benchmarks/results/batch_cpu.json.

    .venv/bin/python benchmarks/bench_batch_cpu.py --baseline HEAD --rounds 4 --batches 300
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import uuid
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
PG_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"
_ROOTS = ("services", "shared", "workers")
# What the packages read beside them (the migrations, the gripper configs).
_ARCHIVED = (*_ROOTS, "migrations", "alembic.ini", "configs")


def _use_tree(tree: Path) -> None:
    """Import graspscape.* from `tree` instead of this checkout (the editable install's
    finder maps the three packages to folders; point it elsewhere before the first import)."""
    import __editable___graspscape_0_1_0_finder as finder  # type: ignore[import-not-found]

    for root in _ROOTS:
        finder.MAPPING[f"graspscape.{root}"] = str(tree / root)


def child(args: argparse.Namespace) -> dict[str, Any]:
    """One variant's run: lease a tile, store its batch, `args.batches` times."""
    if args.tree:
        _use_tree(Path(args.tree))
    sys.path.insert(0, str(REPO))  # tests.factories: the results the tests use
    import graspscape.services.coordinator as coordinator
    from graspscape.services.coordinator import db
    from graspscape.services.coordinator.dispatch.answers import lease_for, report_batch
    from graspscape.services.coordinator.dispatch.catalog import WorkContexts
    from graspscape.services.coordinator.store.models import ExplorationRow
    from graspscape.shared.wire.codec import decode_as, encode
    from graspscape.shared.wire.messages import LeaseRequest, ResultBatch

    from benchmarks._explorations import create_sphere_exploration
    from tests.factories import fake_results

    assert Path(coordinator.__file__).is_relative_to(Path(args.tree or REPO)), coordinator.__file__
    db.upgrade(args.url)
    sessions = db.make_sessionmaker(db.make_engine(args.url))
    eid = create_sphere_exploration(sessions, tile_target_poses=100)
    contexts = WorkContexts()
    request = LeaseRequest(worker_id="bench-1", session_key="b" * 32, host="bench",
                           capacity=1).model_dump_json()
    lease_cpu, lease_wall, batch_cpu, batch_wall = [], [], [], []
    stored = 0
    for _ in range(args.warmup + args.batches):
        c0, w0 = time.thread_time(), time.perf_counter()
        lease = decode_as(request.encode(), LeaseRequest)
        assert isinstance(lease, LeaseRequest)
        with sessions() as s:
            leased = lease_for(s, lease, n=1, lease_seconds=600, contexts=contexts)
        replies = [encode(m) for m in leased.messages()]
        c1, w1 = time.thread_time(), time.perf_counter()
        assert len(replies) == 1
        tile = leased.tiles[0]
        data = ResultBatch(worker_id="bench-1", session_key="b" * 32, tile_id=tile.tile_id,
                           lease_epoch=tile.lease_epoch,
                           results=fake_results(tile.poses(), seed=tile.tile_id)
                           ).model_dump_json().encode()
        c2, w2 = time.thread_time(), time.perf_counter()
        batch = decode_as(data, ResultBatch)
        assert isinstance(batch, ResultBatch)
        with sessions() as s:
            reported = report_batch(s, batch, max_attempts=3)
        ack = encode(reported.reply)
        c3, w3 = time.thread_time(), time.perf_counter()
        assert reported.reply.tile_state == "done", ack  # type: ignore[union-attr]
        stored += reported.reply.inserted  # type: ignore[union-attr]
        lease_cpu.append(c1 - c0)
        lease_wall.append(w1 - w0)
        batch_cpu.append(c3 - c2)
        batch_wall.append(w3 - w2)
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert row is not None and row.poses_done == stored, (row.poses_done, stored)
    n = args.warmup
    ms = 1000.0
    return {"lease_cpu_ms": statistics.median(lease_cpu[n:]) * ms,
            "lease_wall_ms": statistics.median(lease_wall[n:]) * ms,
            "batch_cpu_ms": statistics.median(batch_cpu[n:]) * ms,
            "batch_wall_ms": statistics.median(batch_wall[n:]) * ms,
            "batches": len(batch_cpu) - n}


def _archive(ref: str, into: Path) -> Path:
    """The packages of git `ref`, unpacked under `into`."""
    archive = subprocess.run(["git", "archive", "--format=tar", ref, *_ARCHIVED], cwd=REPO,
                             check=True, capture_output=True).stdout
    tar_path = into / "tree.tar"
    tar_path.write_bytes(archive)
    with tarfile.open(tar_path) as tar:
        tar.extractall(into / "tree", filter="data")
    return into / "tree"


def _schema_url(pg_url: str, schema: str, create: bool) -> str:
    import psycopg

    conninfo = pg_url.replace("postgresql+psycopg://", "postgresql://")
    with psycopg.connect(conninfo, autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"' if create else f'DROP SCHEMA "{schema}" CASCADE')
    return f"{pg_url}?options=-csearch_path%3D{schema}"


def _run_variant(tree: Path | None, args: argparse.Namespace, batches: int | None = None,
                 strace: Path | None = None) -> dict[str, Any]:
    schema = f"bench_cpu_{uuid.uuid4().hex[:8]}"
    url = _schema_url(args.pg_url, schema, create=True)
    try:
        command = [sys.executable, __file__, "--child", "--url", url,
                   "--batches", str(batches or args.batches), "--warmup", str(args.warmup)]
        if tree is not None:
            command += ["--tree", str(tree)]
        if strace is not None:
            command = ["strace", "-f", "-c", "-e", "trace=recvfrom", "-o", str(strace), *command]
        out = subprocess.run(command, cwd=REPO, check=True, capture_output=True, text=True,
                             env={**os.environ, "PYTHONHASHSEED": "0"})
        return json.loads(out.stdout.strip().splitlines()[-1])
    finally:
        _schema_url(args.pg_url, schema, create=False)


def _answers_read(tree: Path | None, args: argparse.Namespace, tmp: Path) -> float:
    """The database answers read per lease + batch: recvfrom calls (strace) of a run of 40
    minus one of 20, over 20. A round trip reads at least one; a pipeline's statements come
    back in one."""
    calls = []
    for n in (20, 40):
        trace = tmp / f"strace-{n}.txt"
        _run_variant(tree, args, batches=n, strace=trace)
        found = re.search(r"^\s*\S+\s+\S+\s+\S+\s+(\d+)\s+(?:\d+\s+)?recvfrom$",
                          trace.read_text(), re.MULTILINE)
        assert found, trace.read_text()
        calls.append(int(found.group(1)))
    return (calls[1] - calls[0]) / 20


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default="HEAD", metavar="REF")
    parser.add_argument("--rounds", type=int, default=4, help="each: baseline, then this one")
    parser.add_argument("--batches", type=int, default=300, help="timed leases + batches")
    parser.add_argument("--warmup", type=int, default=30)
    parser.add_argument("--pg-url", default=PG_URL)
    parser.add_argument("--no-write", action="store_true")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--url", help=argparse.SUPPRESS)
    parser.add_argument("--tree", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args)))
        return 0
    load_start = os.getloadavg()[0]
    commit = subprocess.run(["git", "rev-parse", "--short", args.baseline], cwd=REPO,
                            check=True, capture_output=True, text=True).stdout.strip()
    got: dict[str, list[dict[str, Any]]] = {"baseline": [], "current": []}
    with tempfile.TemporaryDirectory(prefix="bench-cpu-") as tmp:
        tree = _archive(args.baseline, Path(tmp))
        # The answers read first, in runs of their own (strace slows them; untimed).
        answers = ({name: _answers_read(variant, args, Path(tmp))
                    for name, variant in (("baseline", tree), ("current", None))}
                   if shutil.which("strace") else {})
        print(f"database answers read per lease + batch: {answers}", flush=True)
        for k in range(args.rounds):
            for name, variant in (("baseline", tree), ("current", None)):
                figures = _run_variant(variant, args)
                got[name].append(figures)
                print(f"round {k + 1} {name}: " + ", ".join(
                    f"{key} {value:.2f}" for key, value in figures.items()), flush=True)
    figures: dict[str, float] = {}
    for name, runs in got.items():
        for key in ("lease_cpu_ms", "lease_wall_ms", "batch_cpu_ms", "batch_wall_ms"):
            if runs:
                figures[f"{name}_{key}"] = round(statistics.median(r[key] for r in runs), 3)
        if name in answers:
            figures[f"{name}_recvfrom_per_lease_and_batch"] = round(answers[name], 2)
    extra = {"baseline": f"{args.baseline} ({commit})", "current": "this checkout",
             "rounds": args.rounds, "batches_per_round": args.batches,
             "load_avg_1m_start": load_start, "load_avg_1m_end": os.getloadavg()[0],
             "note": "PostgreSQL, one thread, a session per query as the dispatcher opens "
                     "them, 100-pose tiles; the machine is shared with other sessions"}
    print(json.dumps({**figures, **extra}, indent=1))
    if not args.no_write:
        sys.path.insert(0, str(REPO))
        from benchmarks._results import write_results

        write_results("batch_cpu", figures, extra)
    return 0


if __name__ == "__main__":
    sys.exit(main())
