"""The keeper of the manifold table: the one place that brings an exploration's stored
manifolds up to date with its stored poses, for every strategy.

The scheduler calls `keep` after each committed batch (exploration/scheduler.ingest_results),
in the ingest's thread but outside its transaction, in a transaction of its own; a cancel and
the lease sweep call it too (a table a crash or a status change left behind). Reads never
write: the routes serve the table as stored, with `manifolds_poses_done` against `poses_done`
(the lag) in the exploration's progress.

The lag it keeps, stated:
- while an exploration runs, after each batch the table is at most `due_after(done)` poses
  behind: a quarter of the poses it was refreshed at, at least REFRESH_MIN_POSES and at most
  REFRESH_MAX_POSES (1,000); a refresh costs about its new poses, so a large map is refreshed
  every 1,000 poses, each refresh bounded;
- while another thread refreshes the same exploration, a batch does not wait for it, unless
  the table is more than MAX_LAG_POSES (5,000) behind: then it waits and refreshes (back
  pressure on the ingest instead of a table falling further behind);
- a finished exploration (done, failed, cancelled): the batch or cancel that finished it
  waits for the final table before it returns, so a client that saw `done` reads it final.

Off-lattice poses (the random, CMA-ES and PPO strategies, whose poses are drawn, not placed
on the lattice) are kept apart: stored, counted in `poses_done`, listed, exported and ranked
by /best, never grouped into a manifold (the running map takes a pose only where
`samples.point_or_none` finds its lattice point, manifolds/live._new_rows). Their table is
empty and kept current all the same, so the lag reads the same for every strategy.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Hashable
from dataclasses import dataclass, field

from graspscape.services.coordinator.manifolds.service import prefeed, refresh_manifolds
from graspscape.services.coordinator.store.models import FINISHED_STATUSES, ExplorationRow
from sqlalchemy import select
from sqlalchemy.orm import Session

log = logging.getLogger("graspscape.coordinator.manifolds")

REFRESH_GROWTH = 0.25
REFRESH_MIN_POSES = 250
REFRESH_MAX_POSES = 1_000
MAX_LAG_POSES = 5_000


def due_after(refreshed_at: int) -> int:
    """Poses behind at which a running exploration's table is refreshed."""
    return int(min(max(refreshed_at * REFRESH_GROWTH, REFRESH_MIN_POSES), REFRESH_MAX_POSES))


@dataclass
class Upkeep:
    """What the keeper did in this process (benchmarks and tests read it)."""

    refreshes: int = 0
    cpu_s: float = 0.0
    wall_s: float = 0.0


@dataclass
class Keeper:
    """One per process: a lock per exploration (two threads never refresh one exploration at
    once: the second goes on, or waits where the lag is past MAX_LAG_POSES)."""

    upkeep: Upkeep = field(default_factory=Upkeep)
    _locks: dict[Hashable, threading.Lock] = field(default_factory=dict)
    _guard: threading.Lock = field(default_factory=threading.Lock)

    def _lock(self, key: Hashable) -> threading.Lock:
        with self._guard:
            return self._locks.setdefault(key, threading.Lock())

    def keep(self, session: Session, exploration_id: int) -> bool:
        """Refresh the exploration's table where it is due (module docstring), in a
        transaction of its own, committed. The session must have nothing uncommitted.
        True where this call refreshed."""
        behind = _behind(session, exploration_id)
        session.rollback()  # the read's transaction: the refresh starts its own
        if behind is None:
            return False
        finished, lag, _ = behind
        key = (str(session.get_bind().url), exploration_id)
        lock = self._lock(key)
        if not lock.acquire(blocking=finished or lag > MAX_LAG_POSES):
            return False
        try:
            behind = _behind(session, exploration_id)  # again: another may have just done it
            if behind is None:
                session.rollback()
                return False
            cpu, wall = time.process_time(), time.perf_counter()
            # The new rows fed first without the exploration's row lock: the batches of this
            # exploration wait at their counter update only for the rest and the write.
            prefeed(session, exploration_id)
            refresh_manifolds(session, exploration_id, final=behind[0])
            session.commit()
            self.upkeep.refreshes += 1
            self.upkeep.cpu_s += time.process_time() - cpu
            self.upkeep.wall_s += time.perf_counter() - wall
            return True
        except Exception:
            session.rollback()
            raise
        finally:
            lock.release()

    def catch_up(self, session: Session) -> int:
        """Keep every exploration whose table is behind (the lease sweep's turn: a table a
        crash between a batch's commit and its refresh left behind). Returns how many it
        refreshed."""
        ids = session.scalars(select(ExplorationRow.id).where(
            (ExplorationRow.manifolds_poses_done.is_(None) & (ExplorationRow.poses_done > 0))
            | (ExplorationRow.manifolds_poses_done != ExplorationRow.poses_done)
            | (ExplorationRow.status.in_(FINISHED_STATUSES)
               & ExplorationRow.manifolds_final.is_not(True))).order_by(ExplorationRow.id)).all()
        session.rollback()
        refreshed = 0
        for exploration_id in ids:
            try:
                refreshed += self.keep(session, exploration_id)
            except Exception:  # one exploration's failure must not stop the others'
                log.warning("exploration %s: the manifold table was not caught up",
                            exploration_id, exc_info=True)
        return refreshed


def _behind(session: Session, exploration_id: int) -> tuple[bool, int, int] | None:
    """(finished, poses behind, poses the table is at) where a refresh is due, else None."""
    row = session.execute(
        select(ExplorationRow.status, ExplorationRow.poses_done,
               ExplorationRow.manifolds_poses_done, ExplorationRow.manifolds_final)
        .where(ExplorationRow.id == exploration_id)).one_or_none()
    if row is None:
        return None
    at = row.manifolds_poses_done or 0
    lag = row.poses_done - at
    if row.status in FINISHED_STATUSES:
        if row.manifolds_final and lag == 0:
            return None
        if row.poses_done == 0 and row.manifolds_final:
            return None
        return True, lag, at
    return (False, lag, at) if lag > 0 and lag >= due_after(at) else None


def current_keeper() -> Keeper:
    """The keeper of the coordinator in use: the app's, else the process's (the local
    runner's): its state's `keeper` (services/coordinator/state.py)."""
    from graspscape.services.coordinator.state import current

    return current().keeper
