"""What the fault tests and `benchmarks/bench_faults.py` / `bench_soak.py` break things with:
network namespaces joined by veth pairs (a link to cut and restore), a zenoh router process,
a throwaway PostgreSQL cluster of their own (never the shared server on 5432), the coordinator
and workers as child processes (optionally inside a namespace), and the store checks.

Everything here needs root (`ip netns`, `runuser -u postgres`) and is undone by the context
managers even when the test fails.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from glob import glob
from pathlib import Path

from graspscape.services.coordinator.store.models import ExplorationRow, PoseRow, TileRow
from graspscape.shared.specs.pose import tile_poses
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

REPO = Path(__file__).resolve().parents[2]
PYTHON = sys.executable


def wait_for(check: Callable[[], object], timeout: float, what: str,
             every: float = 0.1) -> object:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(every)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def run(*args: str) -> str:
    return subprocess.run(args, check=True, capture_output=True, text=True).stdout


# -- network namespaces ------------------------------------------------------------------


@dataclass
class Link:
    """A veth pair between the coordinator's namespace and one worker's."""

    namespace: str  # the worker's
    coordinator_ip: str
    worker_ip: str
    device: str  # the coordinator's end


@dataclass
class Namespaces:
    """A namespace for the coordinator and one per worker, each joined to the coordinator's
    by its own veth pair and /24 (10.<net>.<i>.0). Cutting a link sets the coordinator's end
    down: packets vanish both ways, no TCP reset, as when a cable is pulled."""

    coordinator: str
    links: list[Link] = field(default_factory=list)

    def exec(self, namespace: str, args: Sequence[str]) -> list[str]:
        # `ip netns exec` execs the command: the child's pid is the command's pid.
        return ["ip", "netns", "exec", namespace, *args]

    def cut(self, i: int) -> None:
        run("ip", "-n", self.coordinator, "link", "set", self.links[i].device, "down")

    def restore(self, i: int) -> None:
        run("ip", "-n", self.coordinator, "link", "set", self.links[i].device, "up")


@contextmanager
def namespaces(workers: int) -> Iterator[Namespaces]:
    tag = uuid.uuid4().hex[:6]
    net = 100 + os.getpid() % 100
    ns = Namespaces(coordinator=f"gsf{tag}c")
    made: list[str] = []
    try:
        run("ip", "netns", "add", ns.coordinator)
        made.append(ns.coordinator)
        run("ip", "-n", ns.coordinator, "link", "set", "lo", "up")
        for i in range(workers):
            name, here, there = f"gsf{tag}w{i}", f"gsf{tag}c{i}", f"gsf{tag}v{i}"
            run("ip", "netns", "add", name)
            made.append(name)
            run("ip", "-n", name, "link", "set", "lo", "up")
            run("ip", "-n", ns.coordinator, "link", "add", here, "type", "veth", "peer",
                "name", there, "netns", name)
            link = Link(name, f"10.{net}.{i}.1", f"10.{net}.{i}.2", here)
            run("ip", "-n", ns.coordinator, "addr", "add", f"{link.coordinator_ip}/24", "dev",
                here)
            run("ip", "-n", name, "addr", "add", f"{link.worker_ip}/24", "dev", there)
            run("ip", "-n", ns.coordinator, "link", "set", here, "up")
            run("ip", "-n", name, "link", "set", there, "up")
            ns.links.append(link)
        yield ns
    finally:
        for name in reversed(made):  # the veth pairs go with their namespaces
            subprocess.run(["ip", "netns", "del", name], check=False, capture_output=True)


# -- processes ---------------------------------------------------------------------------


class Child:
    """A child process with its output in a log file."""

    def __init__(self, args: Sequence[str], log_path: Path, env: dict[str, str] | None = None):
        self.args, self.log_path = list(args), log_path
        self.env = {**os.environ, **(env or {})}
        self.env.pop("GRASPSCAPE_API__TOKEN", None)
        self.process: subprocess.Popen | None = None
        self.start()

    def start(self) -> None:
        log = open(self.log_path, "ab")  # noqa: SIM115 (closed with the process)
        self.process = subprocess.Popen(self.args, cwd=REPO, env=self.env, stdout=log,
                                        stderr=subprocess.STDOUT)
        log.close()

    @property
    def pid(self) -> int:
        assert self.process is not None
        return self.process.pid

    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    def output(self) -> str:
        return self.log_path.read_text(errors="replace")

    def kill(self) -> None:
        if self.alive():
            self.process.kill()
        self.process.wait(10)

    def stop(self, timeout: float = 60) -> int | None:
        if self.process is None:
            return None
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
        try:
            return self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            return self.process.wait(10)


def coordinator_args(db_url: str, port: int, *, listen: Sequence[str] = (),
                     connect: Sequence[str] = (), mode: str = "peer") -> list[str]:
    args = [PYTHON, "-m", "graspscape.services.local.cli", "serve", "--database-url", db_url,
            "--port", str(port), "--no-migrate", "--log-level", "warning", "--zenoh-mode",
            mode]
    for endpoint in listen:
        args += ["--zenoh-listen", endpoint]
    for endpoint in connect:
        args += ["--zenoh-connect", endpoint]
    return args


def worker_args(connect: str, name: str, cache_dir: Path, *, procs: int = 1,
                pose_s: float = 0.0, tiles_per_request: int = 1) -> list[str]:
    args = [PYTHON, "-m", "graspscape.services.local.cli", "worker", "--connect", connect,
            "--procs", str(procs), "--name", name, "--cache-dir", str(cache_dir),
            "--instant", "--tiles-per-request", str(tiles_per_request)]
    if pose_s:
        args += ["--instant-pose-s", str(pose_s)]
    return args


def router_args(listen: str, users_file: Path | None = None) -> list[str]:
    args = [PYTHON, "-m", "tests.faults.router", "--listen", listen]
    if users_file is not None:
        args += ["--users-file", str(users_file)]
    return args


def children_of(pid: int) -> list[int]:
    """The live pids whose parent is `pid` (a worker supervisor's simulation processes).

    A killed child stays a zombie until the supervisor's next poll reaps it; it is left out,
    or a soak would "kill" the same process twice and count one restart for two kills."""
    found = []
    for stat in glob("/proc/[0-9]*/stat"):
        try:
            fields = Path(stat).read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            found.append(int(stat.split("/")[2]))
    return sorted(found)


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def open_fds(pid: int) -> int | None:
    try:
        return len(os.listdir(f"/proc/{pid}/fd"))
    except OSError:
        return None


def fd_kinds(pid: int) -> dict[str, int]:
    """Open file descriptors by kind: socket, pipe, anon_inode:[eventfd], a file's path."""
    kinds: dict[str, int] = {}
    try:
        names = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return kinds
    for name in names:
        try:
            target = os.readlink(f"/proc/{pid}/fd/{name}")
        except OSError:
            continue
        kind = target.split(":[")[0] if ":[" in target else target
        kinds[kind] = kinds.get(kind, 0) + 1
    return kinds


def zenoh_shm_segments() -> dict[str, int]:
    """zenoh's shared-memory segments in /dev/shm (name → bytes in use)."""
    found = {}
    for path in glob("/dev/shm/*.zenoh"):
        try:
            found[path] = os.stat(path).st_blocks * 512
        except OSError:
            continue
    return found


def in_use(path: str) -> bool:
    """Whether any process has the file open or mapped."""
    return subprocess.run(["fuser", "-s", path], capture_output=True).returncode == 0


def threads(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("Threads:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


# -- a PostgreSQL cluster of our own -----------------------------------------------------


def _pg_bin() -> Path:
    found = sorted(glob("/usr/lib/postgresql/*/bin/pg_ctl"))
    if not found:
        raise RuntimeError("no PostgreSQL server binaries under /usr/lib/postgresql")
    return Path(found[-1]).parent


@dataclass
class PgCluster:
    """A throwaway cluster under /tmp on its own port, run as user postgres, trust auth on
    loopback only. Restarting it never touches the shared server on 5432."""

    data_dir: Path
    port: int
    log_path: Path

    @property
    def url(self) -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/faults"

    def _ctl(self, *args: str) -> None:
        run("runuser", "-u", "postgres", "--", str(_pg_bin() / "pg_ctl"), "-D",
            str(self.data_dir), "-l", str(self.log_path), "-w", "-t", "60", *args)

    def start(self) -> None:
        self._ctl("-o", f"-p {self.port} -k /tmp -c listen_addresses=127.0.0.1", "start")

    def stop(self, mode: str = "fast") -> None:
        self._ctl("-m", mode, "stop")

    def accepts(self) -> bool:
        done = subprocess.run([str(_pg_bin() / "pg_isready"), "-h", "127.0.0.1", "-p",
                               str(self.port)], capture_output=True)
        return done.returncode == 0


@contextmanager
def pg_cluster(port: int) -> Iterator[PgCluster]:
    root = Path(f"/tmp/gs-faults-pg-{uuid.uuid4().hex[:8]}")
    root.mkdir()
    shutil.chown(root, "postgres")
    cluster = PgCluster(root / "data", port, root / "postgres.log")
    run("runuser", "-u", "postgres", "--", str(_pg_bin() / "initdb"), "-D",
        str(cluster.data_dir), "-A", "trust", "-U", "postgres", "--no-sync")
    try:
        cluster.start()
        run("runuser", "-u", "postgres", "--", str(_pg_bin() / "createdb"), "-h",
            "127.0.0.1", "-p", str(port), "faults")
        yield cluster
    finally:
        if cluster.accepts():
            subprocess.run(["runuser", "-u", "postgres", "--", str(_pg_bin() / "pg_ctl"),
                            "-D", str(cluster.data_dir), "-m", "immediate", "-w", "stop"],
                           check=False, capture_output=True)
        shutil.rmtree(root, ignore_errors=True)


# -- the store ---------------------------------------------------------------------------


def stored(sessions: sessionmaker[Session], exploration_id: int) -> int:
    with sessions() as session:
        return session.scalar(select(func.count()).select_from(PoseRow)
                              .where(PoseRow.exploration_id == exploration_id)) or 0


def exploration_status(sessions: sessionmaker[Session], exploration_id: int) -> str:
    with sessions() as session:
        return session.scalar(select(ExplorationRow.status)
                              .where(ExplorationRow.id == exploration_id))


@dataclass
class Tally:
    """The stored poses against the plan: the tiles' pose keys."""

    planned: int
    stored_rows: int
    unique_keys: int
    missing: int
    foreign: int
    status: str
    tile_states: dict[str, int]
    poses_done_counter: int

    @property
    def complete(self) -> bool:
        return (self.status == "done" and self.missing == 0 and self.foreign == 0
                and self.stored_rows == self.unique_keys == self.planned
                == self.poses_done_counter)


def tally(sessions: sessionmaker[Session], exploration_id: int) -> Tally:
    with sessions() as session:
        row = session.get(ExplorationRow, exploration_id)
        planned: set[str] = set()
        for cells, r_levels, attitudes in session.execute(
            select(TileRow.cells, TileRow.r_levels, TileRow.attitudes)
            .where(TileRow.exploration_id == exploration_id)
        ):
            planned |= {p.key() for p in tile_poses(cells, r_levels, attitudes)}
        keys = list(session.scalars(select(PoseRow.pose_key)
                                    .where(PoseRow.exploration_id == exploration_id)))
        states = dict(session.execute(
            select(TileRow.state, func.count()).where(TileRow.exploration_id == exploration_id)
            .group_by(TileRow.state)).all())
        unique = set(keys)
        return Tally(planned=len(planned), stored_rows=len(keys), unique_keys=len(unique),
                     missing=len(planned - unique), foreign=len(unique - planned),
                     status=row.status, tile_states=states,
                     poses_done_counter=row.poses_done)


def leased_to(sessions: sessionmaker[Session], prefix: str) -> list[tuple[int, str, int]]:
    """Leased tiles whose owner's id starts with `prefix`: (tile id, owner, epoch)."""
    with sessions() as session:
        return [tuple(r) for r in session.execute(
            select(TileRow.id, TileRow.lease_owner, TileRow.lease_epoch)
            .where(TileRow.state == "leased", TileRow.lease_owner.like(f"{prefix}%")))]


def stored_by(sessions: sessionmaker[Session], exploration_id: int, prefix: str) -> int:
    with sessions() as session:
        return session.scalar(select(func.count()).select_from(PoseRow).where(
            PoseRow.exploration_id == exploration_id,
            PoseRow.worker_id.like(f"{prefix}%"))) or 0


def stored_in(sessions: sessionmaker[Session], tile_id: int) -> int:
    with sessions() as session:
        return session.scalar(select(func.count()).select_from(PoseRow)
                              .where(PoseRow.tile_id == tile_id)) or 0
