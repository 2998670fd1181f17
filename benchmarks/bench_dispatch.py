"""The zenoh dispatch, end to end, with real processes on loopback.

(a) Ceiling: the coordinator's dispatch (SQLite, and PostgreSQL) and `graspscape worker
    --instant` processes that answer every pose at once with a realistic made-up result, through the
    real protocol: lease query, one reply per tile, result batch, commit, ack. Poses per
    second from the first stored result to the last (target ≥ 5,000). Measured with the
    store as it is and again without the adaptive exploration's per-batch hook, so that the
    dispatch's own cost can be told apart.
(b) Scaling: real simulation on the built-in sphere with 1 and then 2 worker processes; the
    rate is taken between 10 % and 90 % of the poses stored, so process start-up and the
    last tile's tail do not count (target: 2 processes ≥ 1.8× of 1).

Writes benchmarks/results/dispatch.json.

    .venv/bin/python benchmarks/bench_dispatch.py [--ceiling-dtheta 3] [--instant-procs 2]
"""

from __future__ import annotations

import argparse
import contextlib
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

import httpx
import psycopg

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import graspscape.services.coordinator.exploration.scheduler as scheduler_module  # noqa: E402
from graspscape.services.coordinator import db  # noqa: E402
from graspscape.services.coordinator.dispatch.service import Dispatcher  # noqa: E402
from graspscape.services.coordinator.exploration.service import create_exploration  # noqa: E402
from graspscape.services.coordinator.objects.service import create_named  # noqa: E402
from graspscape.services.coordinator.settings import Settings, ZenohSettings  # noqa: E402
from graspscape.services.coordinator.store.models import ExplorationRow  # noqa: E402
from graspscape.shared.specs.exploration import (  # noqa: E402
    ExplorationSpec,
    PoseGridSpec,
    RefinementSpec,
)
from sqlalchemy.orm import Session, sessionmaker  # noqa: E402

from benchmarks._results import write_results  # noqa: E402

PG_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _serve(url: str, data_dir: Path, endpoint: str) -> subprocess.Popen:
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "graspscape.services.local.cli", "serve", "--database-url", url,
         "--port", str(port), "--no-migrate", "--log-level", "warning",
         "--zenoh-listen", endpoint],
        cwd=REPO, env={**os.environ, "GRASPSCAPE_DATABASE__DATA_DIR": str(data_dir)},
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/healthz", timeout=1).status_code == 200:
                return proc
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("coordinator did not start")


def _worker(endpoint: str, procs: int, cache: Path, instant: bool) -> subprocess.Popen:
    args = [sys.executable, "-m", "graspscape.services.local.cli", "worker", "--connect", endpoint,
            "--procs", str(procs), "--cache-dir", str(cache), "--log-level", "warning"]
    if instant:
        # Instant tiles are short: asking for a few at once saves lease round trips.
        args += ["--instant", "--tiles-per-request", "4"]
    return subprocess.Popen(args, cwd=REPO, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)


def _stop(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(60)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def _submit(sessions: sessionmaker[Session], grid: PoseGridSpec, tile_poses: int) -> int:
    with sessions() as s:
        obj, _ = create_named(s, name="sphere", properties={}, shared_dir=None)
        spec = ExplorationSpec(object_id=obj.id, grid=grid, refinement=RefinementSpec(levels=0))
        return create_exploration(s, spec=spec, tile_target_poses=tile_poses,
                                  max_poses=10**7).id


def _children_cpu_s(pid: int) -> float:
    """CPU seconds used so far by the processes a worker supervisor started."""
    total = 0.0
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return 0.0
    for child in children:
        try:
            fields = Path(f"/proc/{child}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def _trace(sessions: sessionmaker[Session], exploration_id: int, timeout: float,
           every: float, worker_pid: int) -> list[tuple[float, int, int, float]]:
    """(time, poses done, poses total, worker CPU s) samples until the exploration is done."""
    samples = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        with sessions() as s:
            row = s.get(ExplorationRow, exploration_id)
            samples.append((time.monotonic(), row.poses_done, row.poses_total,
                            _children_cpu_s(worker_pid)))
            if row.status == "done":
                return samples
        time.sleep(every)
    raise RuntimeError(f"exploration not done in {timeout} s: {samples[-1]}")


def _rate_between(samples: list[tuple[float, int, int, float]], lo: float,
                  hi: float) -> tuple[float, float]:
    """Poses per second between two fractions done, and the worker cores busy meanwhile."""
    total = samples[-1][2]

    def when(fraction: float) -> tuple[float, int, float]:
        for t, done, _, cpu in samples:
            if done >= fraction * total:
                return t, done, cpu
        return samples[-1][0], samples[-1][1], samples[-1][3]

    (t0, d0, c0), (t1, d1, c1) = when(lo), when(hi)
    if t1 <= t0:
        return float("nan"), float("nan")
    return (d1 - d0) / (t1 - t0), (c1 - c0) / (t1 - t0)


def _run(url: str, *, grid: PoseGridSpec, tile_poses: int, procs: int, instant: bool,
         timeout: float, every: float, lo: float, hi: float,
         in_process: bool = False) -> tuple[float, int, float]:
    """Rate of one exploration through a coordinator and one worker with `procs` processes.

    in_process: the coordinator's Dispatcher runs in this process (what `serve` runs in its
    lifespan, without the REST server), so that the store can be instrumented here.
    """
    db.upgrade(url)
    engine = db.make_engine(url)
    sessions = db.make_sessionmaker(engine)
    exploration_id = _submit(sessions, grid, tile_poses)
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    with tempfile.TemporaryDirectory() as tmp:
        if in_process:
            settings = Settings(database={"url": url}, zenoh=ZenohSettings(enabled=True,
                                                                      listen=[endpoint]))
            dispatcher = Dispatcher(settings, sessions)
            dispatcher.start()
            stop_coordinator = dispatcher.stop
        else:
            serve = _serve(url, Path(tmp), endpoint)
            stop_coordinator = lambda: _stop(serve)  # noqa: E731
        worker = _worker(endpoint, procs, Path(tmp) / "cache", instant)
        try:
            samples = _trace(sessions, exploration_id, timeout, every, worker.pid)
        finally:
            _stop(worker)
            stop_coordinator()
    engine.dispose()
    rate, cores = _rate_between(samples, lo, hi)
    return rate, samples[-1][2], cores


@contextlib.contextmanager
def _without_adaptive_hook():
    """Ingest without exploration.scheduler.after_batch (refinement planning on every batch),
    to tell the dispatch + ingest cost apart from the adaptive pass's."""
    saved = scheduler_module.after_batch
    scheduler_module.after_batch = lambda *args, **kwargs: None
    try:
        yield
    finally:
        scheduler_module.after_batch = saved


def _ceiling(url_of, grid: PoseGridSpec, procs: int,
             adaptive: bool) -> tuple[float, int, float]:
    with contextlib.ExitStack() as stack:
        if not adaptive:
            stack.enter_context(_without_adaptive_hook())
        url = stack.enter_context(url_of())
        return _run(url, grid=grid, tile_poses=100, procs=procs, instant=True, timeout=900,
                    every=0.05, lo=0.05, hi=1.0, in_process=True)


@contextlib.contextmanager
def _sqlite_url():
    with tempfile.TemporaryDirectory() as tmp:
        yield f"sqlite:///{tmp}/bench.db"


@contextlib.contextmanager
def _postgres_url():
    url, schema = _pg_url()
    try:
        yield url
    finally:
        _drop(schema)


def _pg_url() -> tuple[str, str]:
    schema = f"gs_bench_{uuid.uuid4().hex[:10]}"
    with psycopg.connect(PG_URL.replace("+psycopg", ""), autocommit=True) as conn:
        conn.execute(f'CREATE SCHEMA "{schema}"')
    return f"{PG_URL}?options=-csearch_path%3D{schema}", schema


def _drop(schema: str) -> None:
    with psycopg.connect(PG_URL.replace("+psycopg", ""), autocommit=True) as conn:
        conn.execute(f'DROP SCHEMA "{schema}" CASCADE')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ceiling-dtheta", type=float, default=3.0, help="degrees")
    parser.add_argument("--instant-procs", type=int, default=2)
    parser.add_argument("--real-dtheta", type=float, default=30.0, help="degrees")
    parser.add_argument("--repeats", type=int, default=2, help="runs of 1 and of 2 processes")
    parser.add_argument("--skip-postgres", action="store_true")
    args = parser.parse_args()

    figures: dict[str, float] = {}
    load_before = os.getloadavg()[0]
    ceiling_grid = PoseGridSpec(dtheta=math.radians(args.ceiling_dtheta), r_min=0.0,
                                r_max=0.05, dr=0.01)
    backends = [("sqlite", _sqlite_url)]
    if not args.skip_postgres:
        backends.append(("postgresql", _postgres_url))
    for name, url_of in backends:
        for adaptive in (True, False):
            rate, n, _ = _ceiling(url_of, ceiling_grid, args.instant_procs, adaptive)
            label = "" if adaptive else "_without_adaptive_hook"
            figures[f"ceiling_{name}{label}_poses_per_s"] = round(rate)
            print(name, "adaptive" if adaptive else "no adaptive hook", round(rate), flush=True)
    figures["ceiling_poses"] = n

    # Small tiles so that two processes stay busy until close to the end. Runs of 1 and 2
    # processes alternate and the best of each counts: the development machine is shared,
    # and a burst of someone else's load should not decide the comparison.
    real_grid = PoseGridSpec(dtheta=math.radians(args.real_dtheta), r_min=0.01, r_max=0.03,
                             dr=0.01)
    best = {1: (0.0, 0.0), 2: (0.0, 0.0)}
    for _ in range(args.repeats):
        for procs in (1, 2):
            with tempfile.TemporaryDirectory() as tmp:
                rate, n, cores = _run(f"sqlite:///{tmp}/bench.db", grid=real_grid,
                                      tile_poses=6, procs=procs, instant=False, timeout=900,
                                      every=0.25, lo=0.1, hi=0.9)
            print(f"real, {procs} processes: {rate:.2f} poses/s on {cores:.2f} cores",
                  flush=True)
            best[procs] = max(best[procs], (rate, cores))
    for procs, (rate, cores) in best.items():
        figures[f"real_{procs}_proc_poses_per_s"] = round(rate, 3)
        # Cores the worker processes actually got: on a shared machine two processes may
        # get far less than two cores, which the speed-up alone would hide.
        figures[f"real_{procs}_proc_cores_used"] = round(cores, 3)
        figures[f"real_{procs}_proc_poses_per_cpu_s"] = round(rate / cores, 3) if cores else 0
    figures["real_poses"] = n
    figures["real_speedup_2_over_1"] = round(
        figures["real_2_proc_poses_per_s"] / figures["real_1_proc_poses_per_s"], 3)
    figures["load_average_before"] = round(load_before, 2)
    figures["load_average_after"] = round(os.getloadavg()[0], 2)
    write_results(
        "dispatch",
        figures,
        extra={
            "setup": {
                "ceiling": f"coordinator dispatch (in the bench process, as serve runs it) + "
                f"worker --instant --tiles-per-request 4 --procs {args.instant_procs}, dtheta "
                f"{args.ceiling_dtheta} deg, 6 r levels, 100-pose tiles, rate from 5 % of the "
                "poses stored to the end; '_without_adaptive_hook': the same with "
                "exploration.scheduler.after_batch replaced by a no-op",
                "real": f"serve + worker --procs 1|2, sphere, robotiq_3f, dtheta "
                f"{args.real_dtheta} deg, 3 r levels, 6-pose tiles, rate between 10 % and "
                f"90 % of the poses stored, best of {args.repeats} alternating runs each",
            },
            "targets": {"ceiling_poses_per_s": 5000, "real_speedup_2_over_1": 1.8},
        },
    )


if __name__ == "__main__":
    main()
