"""The keeper of the manifold table: the one place that brings an exploration's stored
manifolds up to date with its stored poses, for every strategy.

The scheduler calls `keep` after each committed batch (exploration/scheduler.ingest_results),
in the ingest's thread but outside its transaction, in a transaction of its own; a cancel and
the lease sweep call it too (a table a crash or a status change left behind). Reads never
write: the routes serve the table as stored, with `manifolds_poses_done` against `poses_done`
(the lag) in the exploration's progress.

The lag it keeps, stated:
- while an exploration runs, after each batch its keeper (below) stores, the table is at
  most `due_after(done)` poses behind: a quarter of the poses it was refreshed at, at least
  REFRESH_MIN_POSES and at most REFRESH_MAX_POSES (1,000); a refresh costs about its new
  poses, so a large map is refreshed every 1,000 poses, each refresh bounded;
- while another thread refreshes the same exploration, a batch does not wait for it, unless
  the table is more than MAX_LAG_POSES (5,000) behind: then it waits and refreshes (back
  pressure on the ingest instead of a table falling further behind);
- a finished exploration (done, failed, cancelled): the batch or cancel that finished it
  waits for the final table before it returns, so a client that saw `done` reads it final.

One keeper per exploration, whichever coordinator process stores its batches: the process
that refreshes a running exploration's table holds a lease on it (`manifolds_keeper`, the
process's id, and `manifolds_keeper_until`, LEASE_S ahead, renewed at each of its refreshes),
taken by one conditional UPDATE in a transaction of its own (free, its own, or run out), so
that of two processes taking it at once exactly one does. A batch stored by another process
reads the lease and goes on: it never waits on the table. The holder refreshes the table at
its own batches and at every lease sweep (`catch_up`, each `queue.requeue_interval_s`), each
time it is due; so after any batch the table is at most MAX_LAG_POSES behind, and after the
holder's batches and sweeps within the lag above. A process takes the lease over, whoever
holds it, where the table is more than MAX_LAG_POSES behind (the holder too slow, or gone:
a process that stopped without giving its leases back is waited for at most LEASE_S, or
until the table is that far behind) and to write the final table, which gives the lease up.
The process that takes a table over reads it once (manifolds/live._adopt), then refreshes
from the rows stored since. The lease decides who does the work, never what is written: two
refreshes of one exploration still take its row lock in turn, and each writes a table equal
to the whole rewrite.

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
import uuid
from collections.abc import Hashable
from dataclasses import dataclass, field
from datetime import datetime, timedelta

from graspscape.services.coordinator.manifolds.service import prefeed, refresh_manifolds
from graspscape.services.coordinator.store import explorations
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import FINISHED_STATUSES, ExplorationRow
from sqlalchemy import select
from sqlalchemy.orm import Session

log = logging.getLogger("graspscape.coordinator.manifolds")

REFRESH_GROWTH = 0.25
REFRESH_MIN_POSES = 250
REFRESH_MAX_POSES = 1_000
MAX_LAG_POSES = 5_000
LEASE_S = 30.0  # the keeper's lease: three sweeps at the default queue.requeue_interval_s


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
    """One per process, with an id of its own (`me`): a lock per exploration (two threads
    never refresh one exploration at once: the second goes on, or waits where the lag is
    past MAX_LAG_POSES), and the lease on the explorations it keeps (module docstring)."""

    upkeep: Upkeep = field(default_factory=Upkeep)
    me: str = field(default_factory=lambda: uuid.uuid4().hex)
    lease_s: float = LEASE_S
    _locks: dict[Hashable, threading.Lock] = field(default_factory=dict)
    _leased: set[str] = field(default_factory=set)  # the databases it took a lease in
    _guard: threading.Lock = field(default_factory=threading.Lock)

    def _lock(self, key: Hashable) -> threading.Lock:
        with self._guard:
            return self._locks.setdefault(key, threading.Lock())

    def keep(self, session: Session, exploration_id: int, *,
             now: datetime | None = None) -> bool:
        """Refresh the exploration's table where it is due and this process keeps it (module
        docstring), in a transaction of its own, committed. The session must have nothing
        uncommitted. True where this call refreshed."""
        now = now or utcnow()
        behind = _behind(session, exploration_id)
        session.rollback()  # the read's transaction: the refresh starts its own
        if behind is None:
            return False
        # Another process's lease: read, not taken, so that this batch waits on nothing.
        if not behind.pressing and behind.kept_by_other(self.me, now):
            return False
        key = (str(session.get_bind().url), exploration_id)
        lock = self._lock(key)
        if not lock.acquire(blocking=behind.pressing):
            return False
        try:
            behind = _behind(session, exploration_id)  # again: another may have just done it
            session.rollback()  # the lease's UPDATE first in its transaction (SQLite's WAL)
            if behind is None:
                return False
            # A lease this keeper holds is renewed in the write's transaction below; taking
            # it again first would be a second write and commit for the same refresh.
            if not behind.held_by(self.me, now) and not self._take(
                    session, exploration_id, now, force=behind.pressing):
                return False
            cpu, wall = time.process_time(), time.perf_counter()
            # The new rows fed first without the exploration's row lock: the batches of this
            # exploration wait at their counter update only for the rest and the write.
            prefeed(session, exploration_id)
            refresh_manifolds(session, exploration_id, final=behind.finished)
            # Renewed (or, final, given up) in the write's transaction: its row is locked.
            lease = (None, None) if behind.finished else (
                self.me, now + timedelta(seconds=self.lease_s + time.perf_counter() - wall))
            explorations.set_keeper_lease(session, exploration_id, *lease, holder=self.me)
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

    def _take(self, session: Session, exploration_id: int, now: datetime, *,
              force: bool) -> bool:
        """Take or renew the lease, in a short transaction of its own, committed: one
        conditional UPDATE, so that of two processes taking a free or run out lease at once
        exactly one matches the row (PostgreSQL re-checks the condition on the row the first
        committed; SQLite writes one at a time). `force`: whoever holds it (the table too far
        behind, or final). True where this process holds it now."""
        until = now + timedelta(seconds=self.lease_s)
        try:
            taken = explorations.set_keeper_lease(session, exploration_id, self.me, until,
                                                  free_at=None if force else now)
            session.commit()
        except Exception:
            session.rollback()
            raise
        if taken:
            self._leased.add(str(session.get_bind().url))
        if taken and force:
            log.info("exploration %s: the manifold table kept here (%s)", exploration_id,
                     self.me)
        return taken

    def catch_up(self, session: Session, *, now: datetime | None = None) -> int:
        """Keep every exploration whose table is behind (the lease sweep's turn: the table
        of an exploration this process keeps, between its own batches; a table a crash
        between a batch's commit and its refresh left behind). Returns how many it
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
                refreshed += self.keep(session, exploration_id, now=now)
            except Exception:  # one exploration's failure must not stop the others'
                log.warning("exploration %s: the manifold table was not caught up",
                            exploration_id, exc_info=True)
        return refreshed

    def release(self, session: Session) -> int:
        """Give up this process's leases (at its shutdown: another process keeps those
        tables at its next batch instead of after the lease runs out). Committed; returns
        how many."""
        if str(session.get_bind().url) not in self._leased:
            return 0
        try:
            released = explorations.release_keeper_leases(session, self.me)
            session.commit()
        except Exception:
            session.rollback()
            raise
        return int(released)


@dataclass(frozen=True)
class Behind:
    """Where a refresh is due: how far behind, and who keeps the table."""

    finished: bool
    lag: int
    at: int  # the poses the table is at
    keeper: str | None
    keeper_until: datetime | None

    @property
    def pressing(self) -> bool:
        """Refreshed by whoever gets here, lease or not: the final table, or a table more
        than MAX_LAG_POSES behind (its keeper too slow, or gone)."""
        return self.finished or self.lag > MAX_LAG_POSES

    def held_by(self, me: str, now: datetime) -> bool:
        return self.keeper == me and self.keeper_until is not None and self.keeper_until >= now

    def kept_by_other(self, me: str, now: datetime) -> bool:
        return (self.keeper is not None and self.keeper != me
                and self.keeper_until is not None and self.keeper_until >= now)


def _behind(session: Session, exploration_id: int) -> Behind | None:
    """Where a refresh is due, else None."""
    row = session.execute(
        select(ExplorationRow.status, ExplorationRow.poses_done,
               ExplorationRow.manifolds_poses_done, ExplorationRow.manifolds_final,
               ExplorationRow.manifolds_keeper, ExplorationRow.manifolds_keeper_until)
        .where(ExplorationRow.id == exploration_id)).one_or_none()
    if row is None:
        return None
    at = row.manifolds_poses_done or 0
    lag = row.poses_done - at
    lease = (row.manifolds_keeper, row.manifolds_keeper_until)
    if row.status in FINISHED_STATUSES:
        if row.manifolds_final and lag == 0:
            return None
        if row.poses_done == 0 and row.manifolds_final:
            return None
        return Behind(True, lag, at, *lease)
    return Behind(False, lag, at, *lease) if lag > 0 and lag >= due_after(at) else None


def current_keeper() -> Keeper:
    """The keeper of the coordinator in use: the app's, else the process's (the local
    runner's): its state's `keeper` (services/coordinator/state.py)."""
    from graspscape.services.coordinator.state import current

    return current().keeper
