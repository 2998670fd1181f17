"""The running maps of the explorations this process refreshes, and what a refresh writes.

Each exploration's `RunningMap` (manifolds/running.py) is kept per process (key: database,
exploration id, creation time; the 8 most recently used) with the largest pose row id it has
read: a refresh reads only the rows stored since (`_new_rows`), feeds them in, and writes
only what changed: the manifold rows whose summary or label changed (rows are kept per main
component, so a manifold keeps its row while it grows), the manifold column of the poses
whose manifold may have changed, and the robust scores that changed. What a compute without
a write changed is kept until the next write.

The state trusts the store only as far as it can check it: the rows read must be as many as
the exploration's `poses_done` (read after them: a row committed out of id order, or a rolled
back ingest, shows as a difference), and the table must be as this state last wrote it (the
exploration's refresh mark and the set of manifold row ids); otherwise the map is read again
from every row, or written again whole. After a restart the first refresh reads everything.
"""

from __future__ import annotations

import gc
import threading
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.running import RunningMap
from graspscape.services.coordinator.manifolds.summary import ManifoldSummary
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.services.coordinator.mapspace.samples import _SAMPLE_COLUMNS, point_or_none
from graspscape.services.coordinator.store import explorations
from graspscape.services.coordinator.store.models import ExplorationRow, ManifoldRow, PoseRow
from graspscape.shared.specs.pose import Pose
from sqlalchemy import bindparam, delete, select, update
from sqlalchemy.orm import Session

_KEY_CHUNK = 500


@dataclass
class MapState:
    running: RunningMap
    last_id: int = 0  # the largest pose row id read
    rows: int = 0  # pose rows read (on the lattice or not)
    # What the last write left in the store: the refresh mark and main component → row id
    # with the summary written; None: not written by this state (write it whole).
    mark: tuple[int, bool] | None = None
    rows_of: dict[int, tuple[int, ManifoldSummary]] = field(default_factory=dict)
    dirty: set[Point] = field(default_factory=set)  # manifold may have changed since
    rescored: set[Point] = field(default_factory=set)  # robust score changed since
    saved_rows: int = 0  # rows read when last saved to disk (manifolds/snapshot.py)
    lock: threading.Lock = field(default_factory=threading.Lock)


class MapCache:
    """Running maps by key, the least recently used dropped beyond `size`."""

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self._states: dict[Hashable, MapState] = {}
        self._lock = threading.Lock()

    def get(self, key: Hashable, make: Callable[[], RunningMap],
            saved: Callable[[], MapState | None] = lambda: None) -> MapState:
        """The key's state: kept, else `saved()` (a snapshot), else a new map."""
        with self._lock:
            state = self._states.pop(key, None)
            if state is None:
                state = saved() or MapState(make())
            self._states[key] = state
            while len(self._states) > self.size:
                del self._states[next(iter(self._states))]
            return state

    def drop(self, key: Hashable) -> None:
        with self._lock:
            self._states.pop(key, None)

    def clear(self) -> None:
        with self._lock:
            self._states.clear()

    def __len__(self) -> int:
        with self._lock:
            return len(self._states)


def _new_rows(session: Session, exploration_id: int, lattice: Lattice,
              after_id: int) -> tuple[dict[Point, StoredPose], int, int]:
    """The samples of the pose rows with id > after_id: (by point, rows read, largest id)."""
    out: dict[Point, StoredPose] = {}
    rows = 0
    last = after_id
    query = (select(*_SAMPLE_COLUMNS, PoseRow.id)
             .where(PoseRow.exploration_id == exploration_id, PoseRow.id > after_id))
    for row in session.execute(query):
        rows += 1
        last = max(last, row.id)
        p = point_or_none(lattice, Pose(theta=row.theta, phi=row.phi, r=row.r, roll=row.roll,
                                        pitch=row.pitch, yaw=row.yaw))
        if p is not None:
            out[p] = StoredPose.from_row(row)
    return out, rows, last


def _added(running: RunningMap, batch: dict[Point, StoredPose]) -> set[Point]:
    """`running.add(batch)` with the cyclic garbage collector paused. A batch allocates
    hundreds of thousands of small objects, almost none in cycles; each 700 of them start a
    young collection, and every hundred of those a full one over the whole map (millions of
    objects at 100k poses): measured, the collector was 12 % of the keeper's CPU. Paused,
    the objects are looked at once after the batch. Process-wide: another thread's batch may
    run with it paused for as long (under a second), or find it on again (no harm either way)."""
    paused = gc.isenabled()
    gc.disable()
    try:
        return running.add(batch)
    finally:
        if paused:
            gc.enable()


def feed(session: Session, exploration_id: int, state: MapState) -> None:
    """Feed the state the rows stored since it last read, without the count check (no lock
    held: `update_state`, under the exploration's row lock, reads what came after and checks
    the count). A stored result that changed is left to `update_state` (`add` raises before it
    changes anything)."""
    batch, rows, last = _new_rows(session, exploration_id, state.running.lattice,
                                  state.last_id)
    if not rows:
        return
    try:
        dirty = _added(state.running, batch)
    except ValueError:
        return
    state.last_id, state.rows = last, state.rows + rows
    state.dirty |= dirty
    state.rescored |= state.running.rescored


def update_state(session: Session, exploration_id: int, state: MapState,
                 fresh: Callable[[], RunningMap]) -> MapState:
    """Feed the state the rows stored since it last read; start again from every row when
    the count does not add up (see the module docstring)."""
    lattice = state.running.lattice
    for attempt in range(2):
        batch, rows, last = _new_rows(session, exploration_id, lattice, state.last_id)
        done = session.scalar(select(ExplorationRow.poses_done)
                              .where(ExplorationRow.id == exploration_id)) or 0
        if state.rows + rows == done or attempt:
            break
        state.running, state.last_id, state.rows, state.mark = fresh(), 0, 0, None
        state.rows_of, state.dirty, state.rescored = {}, set(), set()
    try:
        dirty = _added(state.running, batch)
    except ValueError:  # a stored result changed: read everything again
        state.running, state.mark, state.rows_of = fresh(), None, {}
        batch, rows, last = _new_rows(session, exploration_id, lattice, 0)
        state.rows = 0
        dirty = _added(state.running, batch)
    state.last_id, state.rows = last, state.rows + rows
    state.dirty |= dirty
    state.rescored |= state.running.rescored
    return state


def _in_sync(session: Session, exploration_id: int, state: MapState) -> bool:
    if state.mark is None:
        return False
    mark = session.execute(select(ExplorationRow.manifolds_poses_done,
                                  ExplorationRow.manifolds_final)
                           .where(ExplorationRow.id == exploration_id)).one()
    ids = set(session.scalars(select(ManifoldRow.id)
                              .where(ManifoldRow.exploration_id == exploration_id)))
    return (mark[0], bool(mark[1])) == state.mark and ids == {
        row for row, _ in state.rows_of.values()}


def write(session: Session, exploration_id: int, state: MapState, *, final: bool) -> None:
    """Store the state's table: only what changed when the store is as this state left it,
    else all of it. Sets the exploration's refresh mark; the caller commits."""
    exploration = session.get(ExplorationRow, exploration_id)
    assert exploration is not None
    running = state.running
    whole = not _in_sync(session, exploration_id, state) and not _adopt(
        session, exploration_id, state)
    if whole:
        session.execute(update(PoseRow).where(PoseRow.exploration_id == exploration_id)
                        .values(manifold_id=None).execution_options(synchronize_session=False))
        session.execute(delete(ManifoldRow).where(ManifoldRow.exploration_id == exploration_id))
        state.rows_of = {}
    table = running.table
    keep = {main: row for main, (row, _) in state.rows_of.items()}
    wanted = dict(zip(table.mains, table.manifolds, strict=True))
    changed = [(main, m) for main, m in wanted.items()
               if main in keep and state.rows_of[main][1] != m]
    gone = [row for main, row in keep.items() if main not in wanted]
    manifolds = ManifoldRow.__table__
    moving = gone + [keep[main] for main, m in changed
                     if state.rows_of[main][1].label != m.label]
    if moving:  # out of the way of the labels being written ((exploration, label) is unique)
        session.connection().execute(
            manifolds.update().where(manifolds.c.id == bindparam("i"))
            .values(label=bindparam("v_label")), [{"i": i, "v_label": -i - 1} for i in moving])
    signature_of = _signatures(session, exploration_id,
                               {m.best.key for main, m in wanted.items()
                                if main not in keep or state.rows_of[main][1].best != m.best})
    added = [(main, m) for main, m in wanted.items() if main not in keep]
    rows = [ManifoldRow(exploration_id=exploration_id, **_columns(m, signature_of))
            for _, m in added]
    session.add_all(rows)
    session.flush()
    for (main, _), row in zip(added, rows, strict=True):
        keep[main] = row.id
    if changed:
        session.connection().execute(
            manifolds.update().where(manifolds.c.id == bindparam("i")).values(
                {k: bindparam("v_" + k) for k in _columns(changed[0][1], signature_of,
                                                          with_signature=False)}),
            [{"i": keep[main], **{"v_" + k: v for k, v in _columns(
                m, signature_of, with_signature=False).items()}} for main, m in changed])
        resigned = [{"i": keep[main], "v_signature": signature_of[m.best.key]}
                    for main, m in changed if m.best.key in signature_of]
        if resigned:
            session.connection().execute(
                manifolds.update().where(manifolds.c.id == bindparam("i"))
                .values(signature=bindparam("v_signature")), resigned)
    points = (p for p, s in running.samples.items() if s.viable) if whole else sorted(
        p for p in state.dirty if running.samples[p].viable)
    assignments = [{"m": keep[running.final(p)], "k": running.samples[p].key}  # type: ignore[index]
                   for p in points]
    poses = PoseRow.__table__
    if assignments:
        session.connection().execute(
            poses.update()
            .where(poses.c.exploration_id == exploration_id, poses.c.pose_key == bindparam("k"))
            .values(manifold_id=bindparam("m")), assignments)
    if gone:
        session.execute(delete(ManifoldRow).where(ManifoldRow.id.in_(gone)))
    rescored = running.scores.keys() if whole else state.rescored
    scores = [{"k": running.samples[p].key, "s": sc.s, "q": sc.q, "l": sc.label.value}
              for p in sorted(rescored) if (sc := running.scores.get(p)) is not None]
    if scores:
        session.connection().execute(
            poses.update()
            .where(poses.c.exploration_id == exploration_id, poses.c.pose_key == bindparam("k"))
            .values(robust_s=bindparam("s"), robust_q=bindparam("q"),
                    robust_label=bindparam("l")), scores)
    explorations.mark_table(session, exploration, final=final)
    state.rows_of = {main: (keep[main], m) for main, m in wanted.items()}
    state.mark = (exploration.poses_done, final)
    state.dirty, state.rescored = set(), set()


def _adopt(session: Session, exploration_id: int, state: MapState) -> bool:
    """Take the stored table as this state's last write (after a restart the state comes
    from a snapshot older than the store's table; another process may have written it):
    each manifold keeps the row its best pose is stored in, rows left over go, and the
    poses whose stored manifold or robust score is not this state's are marked to be
    written. The write then costs what differs, not the map. False (write it whole) where
    a stored summary cannot be read."""
    running = state.running
    stored: dict[int, ManifoldSummary] = {}
    try:
        for row_id, summary in session.execute(
                select(ManifoldRow.id, ManifoldRow.summary)
                .where(ManifoldRow.exploration_id == exploration_id)):
            stored[row_id] = ManifoldSummary.model_validate(summary)
    except ValueError:  # a summary of another format: written whole
        return False
    point_of = {s.key: p for p, s in running.samples.items()}
    held: dict[Point, int | None] = {}
    scores: dict[Point, tuple[Any, Any, Any]] = {}
    loose: list[str] = []  # a manifold stored for a pose that has none
    for key, manifold_id, rs, rq, rl in session.execute(
            select(PoseRow.pose_key, PoseRow.manifold_id, PoseRow.robust_s, PoseRow.robust_q,
                   PoseRow.robust_label).where(PoseRow.exploration_id == exploration_id)):
        p = point_of.get(key)
        if p is None or not running.samples[p].viable:
            if manifold_id is not None:
                loose.append(key)
            continue
        held[p] = manifold_id
        scores[p] = (rs, rq, rl)
    table = running.table
    rows_of: dict[int, tuple[int, ManifoldSummary]] = {}
    taken: set[int] = set()
    for main, m in zip(table.mains, table.manifolds, strict=True):
        row_id = held.get(point_of[m.best.key])
        if row_id is not None and row_id in stored and row_id not in taken:
            taken.add(row_id)
            rows_of[main] = (row_id, stored[row_id])
    for n, row_id in enumerate(sorted(stored.keys() - taken)):
        rows_of[-1 - n] = (row_id, stored[row_id])  # no main: the write deletes it
    row_of = {main: row_id for main, (row_id, _) in rows_of.items()}
    state.dirty = {p for p, row_id in held.items()
                   if row_id is None or row_of.get(running.final(p)) != row_id}
    state.rescored = {p for p, sc in running.scores.items()
                      if scores.get(p) != (sc.s, sc.q, sc.label.value)}
    if loose:
        poses = PoseRow.__table__
        session.connection().execute(
            poses.update()
            .where(poses.c.exploration_id == exploration_id, poses.c.pose_key == bindparam("k"))
            .values(manifold_id=None), [{"k": key} for key in loose])
    state.rows_of = rows_of
    return True


def _signatures(session: Session, exploration_id: int, keys: set[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    wanted = sorted(keys)
    for i in range(0, len(wanted), _KEY_CHUNK):
        out.update((key, signature) for key, signature in session.execute(
            select(PoseRow.pose_key, PoseRow.signature).where(
                PoseRow.exploration_id == exploration_id,
                PoseRow.pose_key.in_(wanted[i : i + _KEY_CHUNK]))))
    return out


def _columns(m: ManifoldSummary, signature_of: dict[str, Any], *,
             with_signature: bool = True) -> dict[str, Any]:
    out = {
        "label": m.label, "size": m.pose_count, "best_pose_key": m.best.key,
        "best_mu_s": m.best.mu_s, "summary": m.model_dump(mode="json"),
        "core_volume_cm3": m.core_volume_cm3, "volume_cm3": m.volume_cm3,
        "robust_best_key": m.robust_best.key if m.robust_best else None,
        "robust_best_q": m.robust_best.q if m.robust_best else None, "large": m.large,
    }
    if with_signature:
        out["signature"] = signature_of.get(m.best.key)
    return out


def labels_of(running: RunningMap) -> dict[Point, int]:
    """Every viable sample's manifold label (a pass over the map: for callers that want it
    all, not for a refresh)."""
    label = {main: i for i, main in enumerate(running.table.mains)}
    return {p: label[running.final(p)] for p, s in running.samples.items()  # type: ignore[index]
            if s.viable}


def fine_labels_of(running: RunningMap) -> Any:
    """The running map's finest-lattice labels (grouping.FineLabels), by label."""
    from graspscape.services.coordinator.manifolds.grouping import NON_VIABLE, FineLabels

    grid = running.grid
    n_a = grid.n_a
    label = {main: i for i, main in enumerate(running.table.mains)}
    owner = running.owners.owner
    owned = owner >= 0
    keys = np.unique(owner[owned])
    of_key = np.array([label[running.final(p)]  # type: ignore[index]
                       if running.samples[p].viable else NON_VIABLE
                       for p in (running.owners.point[k] for k in keys.tolist())], dtype=int)
    labels = np.full(len(owner), NON_VIABLE)
    labels[owned] = of_key[np.searchsorted(keys, owner[owned])]
    points = [Point(K, J, i, a) for K, J in grid.cells for i in range(grid.n_i)
              for a in range(n_a)]
    n_pos = len(grid.weights)
    return FineLabels(points, labels, np.repeat(grid.weights, n_a),
                      np.repeat(np.arange(n_pos), n_a))
