"""A real coordinator (`graspscape serve`, SQLite, zenoh dispatch on loopback) and a real
worker (`graspscape worker`) as child processes, and headless Chromium driven by Playwright:
what the browser tests and the screenshot script run against."""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

REPO = Path(__file__).resolve().parents[4]
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
# SwiftShader gives headless Chromium a WebGL context without a GPU (the 3D view).
CHROMIUM_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def chromium_executable() -> str | None:
    given = os.environ.get("GRASPSCAPE_CHROMIUM")
    if given:
        return given
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _command(*args: str) -> list[str]:
    return [sys.executable, "-m", "graspscape.services.local.cli", *args]


class LiveStack:
    """Coordinator + one worker with `procs` processes (none with 0); `stop()` ends both
    (SIGTERM)."""

    def __init__(self, data_dir: Path, *, procs: int = 1, tile_target_poses: int = 4) -> None:
        self.worker: subprocess.Popen[bytes] | None = None
        self.port, zport = free_port(), free_port()
        self.base = f"http://127.0.0.1:{self.port}"
        endpoint = f"tcp/127.0.0.1:{zport}"
        env = {**os.environ, "GRASPSCAPE_DATABASE__DATA_DIR": str(data_dir),
               # small tiles: the progress moves in small steps the page can be seen to follow
               "GRASPSCAPE_QUEUE__TILE_TARGET_POSES": str(tile_target_poses)}
        env.pop("GRASPSCAPE_API__TOKEN", None)
        self.log = (data_dir / "stack.log").open("wb")
        self.coordinator = subprocess.Popen(
            _command("serve", "--data-dir", str(data_dir), "--port", str(self.port),
                     "--zenoh-listen", endpoint, "--log-level", "warning"),
            cwd=REPO, env=env, stdout=self.log, stderr=subprocess.STDOUT)
        self._wait_healthy()
        if procs == 0:
            return
        self.worker = subprocess.Popen(
            _command("worker", "--connect", endpoint, "--procs", str(procs), "--name", "web",
                     "--log-level", "warning"),
            cwd=REPO, env=env, stdout=self.log, stderr=subprocess.STDOUT)

    def _wait_healthy(self, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.coordinator.poll() is not None:
                raise RuntimeError("coordinator exited early (see stack.log)")
            try:
                if httpx.get(f"{self.base}/healthz", timeout=1).status_code == 200:
                    return
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        self.stop()
        raise RuntimeError(f"coordinator not healthy in {timeout_s:.0f} s")

    def api(self, method: str, path: str, **kwargs: Any) -> Any:
        response = httpx.request(method, self.base + path, timeout=60, **kwargs)
        response.raise_for_status()
        return response.json() if response.content else None

    def explore(self, name: str, *, dtheta_deg: float, r: tuple[float, float, float],
                label: str) -> int:
        """Submit an exploration of a built-in over REST: coarse pass only, no robustness."""
        obj = self.api("POST", "/objects", data={"name": name})
        spec = {"object_id": obj["id"], "label": label,
                "grid": {"dtheta": dtheta_deg * 3.141592653589793 / 180, "r_min": r[0],
                         "r_max": r[1], "dr": r[2]},
                "settings": {"robustness": {"tests": []}}, "refinement": {"levels": 0}}
        return self.api("POST", "/explorations", json=spec)["id"]

    def wait_finished(self, exploration_id: int, timeout_s: float = 300.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            row = self.api("GET", f"/explorations/{exploration_id}")
            if row["status"] in ("done", "incomplete", "failed", "cancelled"):
                return row
            time.sleep(0.5)
        raise TimeoutError(f"exploration {exploration_id} not finished in {timeout_s:.0f} s")

    def stop(self) -> None:
        for proc in (self.worker, self.coordinator):
            if proc is None or proc.poll() is not None:
                continue
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        self.log.close()


class ConsoleLog:
    """Console errors and uncaught exceptions of a page (a failed resource load is one)."""

    def __init__(self, page: Any) -> None:
        self.errors: list[str] = []
        page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: self.errors.append(f"uncaught: {e}"))
