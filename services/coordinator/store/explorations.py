"""The one owner of exploration state: every write of an `explorations` row is made here.

Its status, its counters (tiles_total, poses_total, poses_done, viable_count), its times
(started_at, finished_at, updated_at), its group (support_group), the manifold table's mark
(manifolds_poses_done, manifolds_final) and who keeps it (manifolds_keeper,
manifolds_keeper_until), its creation and its deletion. Nothing else in the
coordinator writes the row (tests/services/coordinator/store/test_exploration_state_owner.py
reads the source to keep it so); reads stay where they are needed. A new write of the row (a
new column, a lease on it) is one more named function here, beside these.

Status transitions (`TRANSITIONS`):

- queued → running: its first tile leased (`start`), or a strategy planned more (`count_planned`);
- queued/running → done, incomplete or failed: no tile of it queued or leased any more
  (`finish_complete`, `finish_step`): done when every tile is done, else incomplete (some
  poses stored) or failed (none);
- queued/running → cancelled (`cancel`); a cancelled exploration never changes status again;
- done/incomplete/failed → running: a strategy planned a later round (`count_planned`), or
  its failed tiles were queued again (`reopen`, POST /explorations/{id}/retry).

The statement-level writes carry their allowed starting statuses in their WHERE clause
(`start`, the finish check) or rely on their caller's check under the row lock
(`count_planned`, `count_copies`: the scheduler reacts to no batch of a cancelled
exploration); the row-level ones (`cancel`, `reopen`) check `TRANSITIONS` and refuse an
illegal move with Conflict.

Commits: each function is one statement (or one change of a loaded row) in the caller's
transaction and never commits; the caller that owns the unit of work commits:

- exploration/service.py: `create` and `group` (create_explorations, one commit for a group),
  `cancel` (cancel_exploration), `delete_row` (delete_exploration);
- store/queue.py: `start` (lease_tiles), `finish_complete` (fail_tile, requeue_where),
  `reopen` (retry_failed_tiles);
- exploration/scheduler.py, after the strategy reacted to the batch in the same transaction:
  `count_stored` and `finish_complete` (store/ingest.py; on PostgreSQL with a quiet batch the
  pipelined COMMIT of `count_stored_step`/`finish_step`), `count_planned` and `count_copies`
  (exploration/planning.py), `mark_table_final` (strategies/adaptive.py);
- whoever runs manifolds.service.refresh_manifolds (the manifold keeper, the readers that
  ensure a current table, the adaptive strategy inside the scheduler's transaction):
  `lock_for_table` and `mark_table`;
- manifolds/keeper.py, each in a short transaction of its own: `set_keeper_lease` (taking,
  renewing or giving up the lease on the manifold table), `release_keeper_leases` (at the
  coordinator's shutdown).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from datetime import datetime
from typing import Any

from graspscape.services.coordinator.errors import Conflict
from graspscape.services.coordinator.store.models import (
    TERMINAL_TILE_STATES,
    ExplorationRow,
    ExplorationStatus,
    TileRow,
    TileState,
)
from graspscape.services.coordinator.store.pipeline import Piped, Step
from sqlalchemy import Connection, Row, bindparam, case, delete, select, update
from sqlalchemy.orm import Session

_S = ExplorationStatus
# Where each status may go next (module doc); a status absent as a key goes nowhere.
TRANSITIONS: dict[ExplorationStatus, frozenset[ExplorationStatus]] = {
    _S.QUEUED: frozenset({_S.RUNNING, _S.DONE, _S.INCOMPLETE, _S.FAILED, _S.CANCELLED}),
    _S.RUNNING: frozenset({_S.RUNNING, _S.DONE, _S.INCOMPLETE, _S.FAILED, _S.CANCELLED}),
    _S.DONE: frozenset({_S.RUNNING}),
    _S.INCOMPLETE: frozenset({_S.RUNNING}),
    _S.FAILED: frozenset({_S.RUNNING}),
    _S.CANCELLED: frozenset(),
}


def check_transition(exploration_id: int, old: str, new: ExplorationStatus) -> None:
    """Refuse (Conflict) a move of an exploration's status that `TRANSITIONS` does not allow."""
    if new not in TRANSITIONS.get(ExplorationStatus(old), frozenset()):
        raise Conflict(f"exploration {exploration_id} cannot go from {old} to {new.value}")


# --- creation, grouping, deletion ------------------------------------------------------------
def create(session: Session, *, object_id: int, spec: dict[str, Any], tiles_total: int,
           poses_total: int, now: datetime, resting_index: int | None,
           resting_probability: float | None, gripper_hash: str | None) -> ExplorationRow:
    """A new queued exploration with its coarse pass counted; flushed, so it has its id."""
    row = ExplorationRow(
        object_id=object_id,
        spec=spec,
        status=ExplorationStatus.QUEUED,
        tiles_total=tiles_total,
        poses_total=poses_total,
        poses_done=0,
        viable_count=0,
        created_at=now,
        updated_at=now,
        resting_index=resting_index,
        resting_probability=resting_probability,
        gripper_hash=gripper_hash,
    )
    session.add(row)
    session.flush()
    return row


def group(rows: Sequence[ExplorationRow]) -> None:
    """The explorations of one submission on a table as one group, named by the first's id."""
    for row in rows:
        row.support_group = rows[0].id


def delete_row(session: Session, exploration_id: int) -> None:
    """The exploration's row (its children are the caller's to delete first)."""
    session.execute(delete(ExplorationRow).where(ExplorationRow.id == exploration_id))


# --- status ------------------------------------------------------------------------------------
_START = (
    update(ExplorationRow)
    .where(
        ExplorationRow.id.in_(bindparam("ids", expanding=True)),
        ExplorationRow.status == ExplorationStatus.QUEUED,
    )
    .values(status=ExplorationStatus.RUNNING, started_at=bindparam("now"),
            updated_at=bindparam("now"))
)


def start(session: Session, exploration_ids: Sequence[int], now: datetime) -> None:
    """Queued explorations of tiles just leased are running from now (running ones stay)."""
    session.connection().execute(_START, {"ids": list(exploration_ids), "now": now})


# Tiles that still have work ahead. `state IN` these (not `NOT IN` the terminal ones) looks
# the exploration's open tiles up in the (state, exploration_id, ...) index instead of reading
# every tile of the exploration, each time a tile finishes.
_OPEN_TILE_STATES = tuple(s for s in TileState if s not in TERMINAL_TILE_STATES)
# An exploration is done only when every tile is done, i.e. every planned pose is stored;
# with failed tiles it is incomplete, or failed when not a single pose was stored. Read in the
# statement that finishes it, under the exploration's row lock (see queue.lock_explorations).
_ANY_FAILED = (
    select(TileRow.id)
    .where(TileRow.exploration_id == ExplorationRow.id, TileRow.state == TileState.FAILED)
    .exists()
)
_FINISH = (
    update(ExplorationRow)
    .where(
        ExplorationRow.id.in_(bindparam("ids", expanding=True)),
        ExplorationRow.status.in_((ExplorationStatus.QUEUED, ExplorationStatus.RUNNING)),
        ~select(TileRow.id)
        .where(TileRow.exploration_id == ExplorationRow.id)
        .where(TileRow.state.in_(_OPEN_TILE_STATES))
        .exists(),
    )
    .values(
        status=case(
            (_ANY_FAILED & (ExplorationRow.poses_done > 0), ExplorationStatus.INCOMPLETE.value),
            (_ANY_FAILED, ExplorationStatus.FAILED.value),
            else_=ExplorationStatus.DONE.value,
        ),
        finished_at=bindparam("now"),
        updated_at=bindparam("now"),
    )
)
_FINISH_PIPED = Piped(_FINISH, {"ids": [0], "now": None})


def finish_complete(session: Session, exploration_ids: Iterable[int], *, now: datetime) -> None:
    """Finish running explorations once none of their tiles is queued or leased: done when
    every tile is done, else incomplete (some poses stored) or failed (none)."""
    ids = sorted(set(exploration_ids))
    if not ids:
        return
    session.connection().execute(_FINISH, {"ids": ids, "now": now})


def finish_step(exploration_id: int, now: datetime) -> Step:
    """finish_complete of one exploration as a step of a PostgreSQL pipeline."""
    return _FINISH_PIPED.step(ids_1=exploration_id, now=now)


def cancel(row: ExplorationRow, now: datetime) -> None:
    """A queued or running exploration cancelled (its open tiles are tiles.cancel_open's)."""
    check_transition(row.id, row.status, ExplorationStatus.CANCELLED)
    row.status = ExplorationStatus.CANCELLED
    row.finished_at = now
    row.updated_at = now


def reopen(session: Session, exploration_id: int, status: str, now: datetime) -> None:
    """Running again after its failed tiles were queued again; `status`: its status now, read
    under its row lock."""
    check_transition(exploration_id, status, ExplorationStatus.RUNNING)
    session.execute(
        update(ExplorationRow)
        .where(ExplorationRow.id == exploration_id)
        .values(status=ExplorationStatus.RUNNING, finished_at=None, updated_at=now)
        .execution_options(synchronize_session=False)
    )


# --- counters --------------------------------------------------------------------------------
# The counters of a stored batch, built once (ingest runs it for every batch); it returns the
# status and creation time the scheduler needs.
_COUNT_STORED = (
    update(ExplorationRow).where(ExplorationRow.id == bindparam("exploration_id"))
    .values(poses_done=ExplorationRow.poses_done + bindparam("inserted"),
            viable_count=ExplorationRow.viable_count + bindparam("viable"),
            updated_at=bindparam("now"))
    .returning(ExplorationRow.status, ExplorationRow.created_at)
)
_COUNT_STORED_PIPED = Piped(_COUNT_STORED,
                            {"exploration_id": 0, "inserted": 0, "viable": 0, "now": None})


def count_stored(connection: Connection, counted: dict[str, Any]) -> Row[Any]:
    """A stored batch's poses counted, on the session's connection: `counted` holds
    exploration_id, inserted (new poses), viable (new viable poses) and now. Returns the
    row's (status, created_at)."""
    return connection.execute(_COUNT_STORED, counted).one()


def count_stored_step(**counted: Any) -> Step:
    """count_stored as a step of a PostgreSQL pipeline; its cursor returns the same row."""
    return _COUNT_STORED_PIPED.step(**counted)


def count_planned(session: Session, exploration_id: int, *, tiles_added: int,
                  poses_counted: int, now: datetime) -> None:
    """Tiles of newly planned poses counted; the exploration runs again (it may have finished
    with its last tile)."""
    session.execute(
        update(ExplorationRow)
        .where(ExplorationRow.id == exploration_id)
        .values(
            tiles_total=ExplorationRow.tiles_total + tiles_added,
            poses_total=ExplorationRow.poses_total + poses_counted,
            status=ExplorationStatus.RUNNING,
            finished_at=None,
            updated_at=now,
        )
        .execution_options(synchronize_session=False)
    )


def count_copies(session: Session, exploration_id: int, *, stored: int, counted: int,
                 viable: int) -> None:
    """Inferred results (copies under other poses' keys) counted: `stored` new poses, of
    which `counted` add to poses_total and `viable` are viable."""
    session.execute(
        update(ExplorationRow)
        .where(ExplorationRow.id == exploration_id)
        .values(poses_done=ExplorationRow.poses_done + stored,
                poses_total=ExplorationRow.poses_total + counted,
                viable_count=ExplorationRow.viable_count + viable)
        .execution_options(synchronize_session=False)
    )


# --- the manifold table's mark ---------------------------------------------------------------
def lock_for_table(session: Session, exploration_id: int) -> None:
    """The exploration's row lock before a refresh of its manifold table (PostgreSQL: its
    row lock; SQLite: the write lock), by an update that changes nothing: an ingest holds the
    same lock from its counter update, so both take the locks in one order."""
    session.execute(update(ExplorationRow).where(ExplorationRow.id == exploration_id)
                    .values(manifolds_final=ExplorationRow.manifolds_final))


def mark_table(session: Session, row: ExplorationRow, *, final: bool) -> None:
    """The manifold table now counts the poses stored (and is the finished exploration's
    with `final`); flushed with the table's own writes."""
    row.manifolds_poses_done = row.poses_done
    row.manifolds_final = final
    session.flush()


def mark_table_final(session: Session, exploration_id: int) -> None:
    """The stored table is the finished exploration's (written at the caller's commit)."""
    row = session.get(ExplorationRow, exploration_id)
    if row is not None:
        row.manifolds_final = True


# --- the manifold table's keeper lease (manifolds/keeper.py) ---------------------------------
def set_keeper_lease(session: Session, exploration_id: int, keeper: str | None,
                     until: datetime | None, *, holder: str | None = None,
                     free_at: datetime | None = None) -> bool:
    """The lease set to (keeper, until), in one conditional UPDATE: where `holder`, only on a
    row it holds; where `free_at`, only on a row whose lease is free, this keeper's own or run
    out at that time. Two processes taking a free lease at once: exactly one matches the row
    (PostgreSQL re-checks the condition on the row the first committed; SQLite writes one at a
    time). True where the row matched."""
    statement = update(ExplorationRow).where(ExplorationRow.id == exploration_id)
    if holder is not None:
        statement = statement.where(ExplorationRow.manifolds_keeper == holder)
    if free_at is not None:
        statement = statement.where(
            ExplorationRow.manifolds_keeper.is_(None)
            | (ExplorationRow.manifolds_keeper == keeper)
            | (ExplorationRow.manifolds_keeper_until < free_at))
    result = session.execute(
        statement.values(manifolds_keeper=keeper, manifolds_keeper_until=until)
        .execution_options(synchronize_session=False))
    return result.rowcount == 1  # type: ignore[attr-defined]


def release_keeper_leases(session: Session, keeper: str) -> int:
    """Every lease `keeper` holds given up; how many."""
    result = session.execute(
        update(ExplorationRow).where(ExplorationRow.manifolds_keeper == keeper)
        .values(manifolds_keeper=None, manifolds_keeper_until=None)
        .execution_options(synchronize_session=False))
    return int(result.rowcount)  # type: ignore[attr-defined]
