"""`graspscape worker`: start N simulation processes and keep them running until told to stop.

Processes are started with the spawn method: each builds its own zenoh session and pybullet
clients from scratch (fork would copy a live session's threads and sockets). A process that
crashes is started again under a new worker id (its old tile comes back to the queue through
its vanished liveliness token); SIGTERM/SIGINT are passed on and each process finishes its
pose, reports, releases the rest and exits.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import signal
import threading
import time

from graspscape.workers.runtime.config import WorkerConfig
from graspscape.workers.runtime.process import process_main

log = logging.getLogger("graspscape.worker")


class Supervisor:
    def __init__(self, config: WorkerConfig, log_level: str = "info") -> None:
        self.config = config
        self.log_level = log_level
        self.ctx = mp.get_context("spawn")
        self.stop = threading.Event()
        self.procs: dict[int, mp.process.BaseProcess] = {}

    def _start(self, index: int) -> None:
        proc = self.ctx.Process(
            target=process_main,
            # The password too (spawn hands the arguments over a pipe, not the command line).
            args=(self.config.model_dump_json(context={"secrets": True}), index,
                  self.log_level),
            name=f"graspscape-worker-{index}",
        )
        proc.start()
        self.procs[index] = proc

    def request_stop(self, *_: object) -> None:
        self.stop.set()

    def start(self) -> None:
        for index in range(self.config.procs):
            self._start(index)
        log.info("worker %s: %d processes, coordinator %s", self.config.name,
                 self.config.procs, self.config.connect)

    def poll(self) -> None:
        """Start again the processes that crashed (never those that were told to stop)."""
        if self.stop.is_set() or not self.config.restart_crashed:
            return
        for index, proc in list(self.procs.items()):
            if proc.exitcode is not None:
                log.warning("process %d exited with %s; starting it again", index,
                            proc.exitcode)
                self._start(index)

    def shutdown(self) -> None:
        self.stop.set()
        for proc in self.procs.values():
            if proc.is_alive():
                proc.terminate()  # SIGTERM: finish the pose, report, release, exit
        # A pose in flight can take a while; the grace covers the last delivery.
        deadline = time.monotonic() + self.config.shutdown_grace_s + 120
        for proc in self.procs.values():
            proc.join(max(0.0, deadline - time.monotonic()))
            if proc.is_alive():
                proc.kill()

    def run(self) -> int:
        signal.signal(signal.SIGTERM, self.request_stop)
        signal.signal(signal.SIGINT, self.request_stop)
        self.start()
        while not self.stop.wait(0.5):
            self.poll()
        self.shutdown()
        return 0


def run_worker(config: WorkerConfig, log_level: str = "info") -> int:
    logging.basicConfig(level=log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return Supervisor(config, log_level).run()
