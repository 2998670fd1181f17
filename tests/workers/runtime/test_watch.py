"""A worker's processes follow their supervisor out (kill -9 of `graspscape worker` leaves no
simulation process behind) and say in their log when the coordinator goes and comes back."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh
from graspscape.shared.wire.session import zenoh_config

pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _children(pid: int) -> list[int]:
    path = Path(f"/proc/{pid}/task/{pid}/children")
    return [int(c) for c in path.read_text().split()] if path.exists() else []


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    status = Path(f"/proc/{pid}/status")
    return status.exists() and "State:\tZ" not in status.read_text()


def _wait(check, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if check():
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def test_processes_stop_with_their_supervisor_and_log_the_coordinators_absence(
    tmp_path: Path,
) -> None:
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    coordinator = zenoh.open(zenoh_config(mode="peer", listen=[endpoint]))
    log_path = tmp_path / "worker.log"
    with log_path.open("w") as log_file:
        supervisor = subprocess.Popen(
            [str(Path(sys.executable).parent / "graspscape"), "worker", "--connect", endpoint,
             "--procs", "1", "--instant", "--cache-dir", str(tmp_path / "cache"),
             "--log-level", "info"],
            stdout=log_file, stderr=subprocess.STDOUT, start_new_session=True,
        )
    child: list[int] = []
    try:
        _wait(lambda: "connected to" in log_path.read_text(), 120, "the process to connect")
        child[:] = _children(supervisor.pid)
        assert len(child) >= 1

        coordinator.close()  # the coordinator goes away…
        _wait(lambda: "unreachable" in log_path.read_text(), 30, "the absence to be logged")
        coordinator = zenoh.open(zenoh_config(mode="peer", listen=[endpoint]))  # …and back
        _wait(lambda: "reachable again" in log_path.read_text(), 60, "the return to be logged")

        os.kill(supervisor.pid, signal.SIGKILL)
        supervisor.wait(10)
        _wait(lambda: not any(_alive(pid) for pid in child), 30,
              "the simulation process to stop after its supervisor died")
        assert "supervisor" in log_path.read_text()
    finally:
        for pid in [supervisor.pid, *child]:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        coordinator.close()
