"""Coordinator processes for the fleet benchmarks: `graspscape serve` on a database, started
and answering on a free loopback port (benchmarks/bench_fleet.py)."""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_coordinators(k: int, url: str, zenoh_args: list[str], tmp: str,  # type: ignore[type-arg]
                       logs: contextlib.ExitStack, log: str | None) -> list[subprocess.Popen]:
    """`graspscape serve` k times on the one database (a free HTTP port and a data folder
    each), answering. --coordinator-log: each one's log at info level (the orphan sweep's and
    requeues' lines); otherwise warnings, discarded."""
    started, ports = [], []
    for i in range(k):
        ports.append(free_port())
        name = log if log is None or k == 1 else f"{log}.c{i + 1}"
        sink = logs.enter_context(open(name, "w")) if name else subprocess.DEVNULL  # noqa: SIM115
        (data := Path(tmp) / f"coordinator_{i + 1}").mkdir()
        started.append(subprocess.Popen(
            [sys.executable, "-m", "graspscape.services.local.cli", "serve",
             "--database-url", url, "--port", str(ports[-1]), "--no-migrate",
             "--log-level", "info" if log is not None else "warning", *zenoh_args],
            cwd=REPO, env={**os.environ, "GRASPSCAPE_DATABASE__DATA_DIR": str(data)},
            stdout=sink, stderr=sink))
    for port, proc in zip(ports, started, strict=True):
        wait_http(port, proc)
    return started


def wait_http(port: int, coordinator: subprocess.Popen) -> None:
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
