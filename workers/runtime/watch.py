"""What a simulation process watches besides its work: its supervisor and its coordinator.

A process whose supervisor died (kill -9, OOM killer) stops as if told to: it finishes its
pose, reports, hands the rest of its tile back and exits, instead of running on unsupervised.
A process that lost its coordinator says so in its log, once when the link goes and then every
minute, so an operator reading a quiet worker can tell "no work" from "no coordinator".
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import threading
import time
from collections.abc import Callable
from multiprocessing.connection import wait

import zenoh

log = logging.getLogger("graspscape.worker")


def stop_with_parent(on_death: Callable[[], object]) -> threading.Thread | None:
    """Call `on_death` once the process that spawned this one is gone (the multiprocessing
    parent sentinel becomes ready when it exits, however it died). None outside a spawned
    process."""
    parent = mp.parent_process()
    if parent is None:
        return None

    def watch() -> None:
        wait([parent.sentinel])
        log.warning("the worker supervisor (pid %s) is gone; stopping this process",
                    parent.pid)
        on_death()

    thread = threading.Thread(target=watch, name="parent-watch", daemon=True)
    thread.start()
    return thread


def connected(session: zenoh.Session) -> bool:
    """Whether the session has a live link to any router or peer (the coordinator)."""
    info = session.info
    return any(True for _ in info.routers_zid()) or any(True for _ in info.peers_zid())


class CoordinatorWatch:
    """Logs when the link to the coordinator goes, every `every_s` while it stays gone, and
    when it comes back; `check` is cheap enough to call on every idle round."""

    def __init__(self, session: zenoh.Session, who: str, where: list[str],
                 every_s: float = 60.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.session = session
        self.who = who
        self.where = ", ".join(where)
        self.every_s = every_s
        self.clock = clock
        self.lost_at: float | None = None
        self.told_at = 0.0

    def check(self) -> bool:
        now = self.clock()
        if connected(self.session):
            if self.lost_at is not None:
                log.warning("%s: coordinator at %s reachable again after %.0f s", self.who,
                            self.where, now - self.lost_at)
                self.lost_at = None
            return True
        if self.lost_at is None:
            self.lost_at = self.told_at = now
            log.warning("%s: coordinator at %s unreachable; waiting for it (results not yet "
                        "acknowledged are kept and sent again)", self.who, self.where)
        elif now - self.told_at >= self.every_s:
            self.told_at = now
            log.warning("%s: coordinator at %s still unreachable after %.0f s", self.who,
                        self.where, now - self.lost_at)
        return False
