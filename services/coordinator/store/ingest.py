"""Result ingest: store one batch of pose results (one tile), idempotently.

The batch is stored in the caller's transaction, which exploration/scheduler.py commits once
the exploration's strategy has decided what comes next.

`INSERT … ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING viable` stores each pose
once and tells exactly which rows are new, so the exploration's counters only count those: a
batch sent twice (a retry after a lost ack) leaves the same rows and the same counts.

A batch is taken only from the tile's latest lease: its epoch must be the tile's current
`lease_epoch`, and while the tile is leased its worker must be the `lease_owner`. Anything
else (another worker's id, an older epoch: the tile was leased again since) is refused whole
with NotLeaseHolder and stores nothing. Once the latest lease ended without a new one (expired
or lost and queued again, cancelled, failed) the row names no holder any more; a report under
that epoch is still taken, since its poses can only be the tile's own (below) and storing
them loses nothing. Every result must be a pose of the tile (its cells × r levels ×
attitudes): one foreign pose refuses the whole batch. `final` finishes the tile (leased, or
queued under the same epoch) only when every pose of the tile is stored after the batch;
otherwise the batch is stored and the report lists the poses still missing.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from datetime import datetime
from functools import lru_cache
from typing import Any, NamedTuple

from graspscape.services.coordinator.errors import InvalidInput, NotFound, NotLeaseHolder
from graspscape.services.coordinator.store import tiles
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import (
    POSE_METRIC_COLUMNS,
    ROBUSTNESS_COLUMNS,
    ExplorationRow,
    PoseRow,
    TileRow,
    TileState,
)
from graspscape.services.coordinator.store.queue import finish_complete_explorations
from graspscape.shared.specs.pose import tile_pose_keys
from graspscape.shared.specs.results import PoseResult
from pydantic import BaseModel
from pydantic_core import to_json
from sqlalchemy import bindparam, select, update
from sqlalchemy.orm import Session


class StoredBatch(NamedTuple):
    """What storing a batch did, for the scheduler that decides what comes next: the report
    for the worker, and the exploration's status and creation time when the batch changed
    anything (None otherwise: nothing to react to)."""

    report: IngestReport
    exploration_id: int
    exploration_status: str | None
    exploration_created_at: datetime | None


class IngestReport(BaseModel):
    inserted: int
    duplicates: int
    tile_state: str
    tile_moved: bool  # this batch moved the tile leased → done
    # With `final`: the tile's poses that are not stored even after this batch (sorted), so
    # the tile did not move; empty when it moved or could not move anyway.
    missing: list[str] = []


def _json_text(model: BaseModel | None) -> str | None:
    """A JSON column's text, serialized by pydantic (several times faster than json.dumps of
    model_dump). Its fields are never null, so a null in the text is a non-finite float that
    pydantic wrote as null: json.dumps keeps it as NaN/Infinity, as the column always did."""
    if model is None:
        return None
    text = model.model_dump_json()
    if "null" in text:
        return json.dumps(model.model_dump(mode="json"))
    return text


_NO_ROBUSTNESS: tuple[None, ...] = (None,) * len(ROBUSTNESS_COLUMNS)


def _values(result: PoseResult, robustness: bool = True) -> tuple[Any, ...]:
    """The per-pose columns of one result, in _PER_POSE order, as the driver takes them;
    without `robustness`, all but the trailing ROBUSTNESS_COLUMNS (left NULL)."""
    pose = result.pose
    values = (
        result.pose_key,
        pose.theta,
        pose.phi,
        pose.r,
        pose.roll,
        pose.pitch,
        pose.yaw,
        result.outcome.value,
        result.viable,
        result.mu_s,
        result.effective_r,
        result.effort_max_nm,
        to_json(result.contacts_per_link).decode() if result.contacts_per_link else None,
        _json_text(result.signature),
        _json_text(result.grasp),
        result.eval_time_s,
        result.inferred_from,
        result.error,
        result.mu_g,
        result.mu_f,
        result.mu_m,
    )
    if not robustness:
        return values
    rb = result.robustness
    if rb is None:
        return values + _NO_ROBUSTNESS
    return (
        *values,
        rb.torque_margin_nm,
        rb.torque_margin_ratio,
        rb.friction_margin,
        rb.gravity_test_share,
        rb.force_test_share,
        rb.tug_force_n,
        rb.shake_survival_s,
    )


_PER_POSE = (
    ("pose_key", "varchar"),
    ("theta", "float8"),
    ("phi", "float8"),
    ("r", "float8"),
    ("roll", "float8"),
    ("pitch", "float8"),
    ("yaw", "float8"),
    ("outcome", "varchar"),
    ("viable", "boolean"),
    ("mu_s", "float8"),
    ("effective_r", "float8"),
    ("effort_max_nm", "float8"),
    ("contacts_per_link", "text"),
    ("signature", "text"),
    ("grasp", "text"),
    ("eval_time_s", "float8"),
    ("inferred_from", "varchar"),
    ("error", "varchar"),
    *((name, "float8") for name in POSE_METRIC_COLUMNS),
)
# The robustness tests are chosen per exploration and off by default: a batch without any
# report leaves their columns out of the statement (NULL), which spares SQLite a quarter of
# its parameters per row and PostgreSQL seven arrays of nulls.
_WITHOUT_ROBUSTNESS = _PER_POSE[: len(_PER_POSE) - len(ROBUSTNESS_COLUMNS)]
assert tuple(name for name, _ in _PER_POSE[len(_WITHOUT_ROBUSTNESS):]) == ROBUSTNESS_COLUMNS
_PER_BATCH = ("exploration_id", "tile_id", "worker_id", "created_at")
_CONFLICT = "ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING viable"
_JSON_COLUMNS = ("contacts_per_link", "signature", "grasp")


def _pg_insert(per_pose: tuple[tuple[str, str], ...]) -> str:
    return (
        "INSERT INTO poses ({columns}) SELECT {batch}, {select} FROM unnest({arrays}) "
        "AS u({names}) {conflict}"
    ).format(
        columns=", ".join(_PER_BATCH + tuple(name for name, _ in per_pose)),
        batch=", ".join(f"%({name})s" for name in _PER_BATCH),
        select=", ".join(
            f"u.{name}::json" if name in _JSON_COLUMNS else f"u.{name}" for name, _ in per_pose
        ),
        # %(...)b: binary parameters, which psycopg dumps without escaping each array element.
        arrays=", ".join(f"%({name})b::{sql_type}[]" for name, sql_type in per_pose),
        names=", ".join(name for name, _ in per_pose),
        conflict=_CONFLICT,
    )


# By whether the batch has robustness columns.
_COLUMNS = {True: _PER_POSE, False: _WITHOUT_ROBUSTNESS}
_PG_INSERT = {robustness: _pg_insert(per_pose) for robustness, per_pose in _COLUMNS.items()}


@lru_cache(maxsize=64)
def _sqlite_insert(n_rows: int, robustness: bool = True) -> str:
    """SQLite: one multi-row VALUES statement (its text is cached by row count, its prepared
    form by the driver)."""
    per_pose = _COLUMNS[robustness]
    row = "(" + ", ".join("?" * (len(_PER_BATCH) + len(per_pose))) + ")"
    columns = ", ".join(_PER_BATCH + tuple(name for name, _ in per_pose))
    return f"INSERT INTO poses ({columns}) VALUES {', '.join([row] * n_rows)} {_CONFLICT}"


def _insert_new(session: Session, batch: tuple[Any, ...], rows: list[tuple[Any, ...]],
                robustness: bool = True) -> list[bool]:
    """Insert the rows not stored yet; return the `viable` flag of each row inserted.

    `batch`: the _PER_BATCH values, the same for every row; `rows`: _values() of each result,
    with or without the robustness columns as `robustness` says.
    Both backends get one driver-level statement per batch: SQLAlchemy's per-row parameter
    processing (JSON, datetime) took more time than the database itself.
    """
    per_pose = _COLUMNS[robustness]
    connection = session.connection()
    dialect = connection.dialect
    # The timestamp as the ORM would bind it (UTC; on SQLite the store's text form).
    created_at = PoseRow.__table__.c.created_at.type.dialect_impl(dialect).bind_processor(dialect)
    if created_at is not None:
        batch = (*batch[:3], created_at(batch[3]))
    if dialect.name == "postgresql":
        # One short statement with a column array each: psycopg parses and prepares it once.
        # A multi-row VALUES statement has thousands of placeholders that psycopg re-parses
        # on every batch, which took half of the ingest time. (One JSON array of the rows
        # instead saved little client time and cost the server more than that.)
        params: dict[str, Any] = dict(zip(_PER_BATCH, batch, strict=True))
        for (name, _), column in zip(per_pose, zip(*rows, strict=True), strict=True):
            params[name] = list(column)
        result = connection.exec_driver_sql(_PG_INSERT[robustness], params)
        return [bool(v) for (v,) in result]
    if dialect.name != "sqlite":
        raise RuntimeError(f"unsupported database dialect {dialect.name!r}")
    # As many rows per statement as the SQLite build takes parameters (32,766, or 999 before
    # 3.32), as SQLAlchemy's own multi-row inserts do.
    per_statement = max(
        1, dialect.insertmanyvalues_max_parameters // (len(_PER_BATCH) + len(per_pose)))
    viable: list[bool] = []
    for start in range(0, len(rows), per_statement):
        chunk = rows[start : start + per_statement]
        params_flat: list[Any] = []
        for row in chunk:
            params_flat += batch
            params_flat += row
        result = connection.exec_driver_sql(
            _sqlite_insert(len(chunk), robustness), tuple(params_flat))
        viable += [bool(v) for (v,) in result]
    return viable


# The statements of every batch, built once (building them took longer than running them).
_TILE = select(
    TileRow.exploration_id, TileRow.state, TileRow.lease_epoch, TileRow.lease_owner,
    TileRow.cells, TileRow.r_levels, TileRow.attitudes,
).where(TileRow.id == bindparam("tile_id"))
# Which of some pose keys an exploration has stored (the unique index's own columns).
_STORED = select(PoseRow.pose_key).where(
    PoseRow.exploration_id == bindparam("exploration_id"),
    PoseRow.pose_key.in_(bindparam("keys", expanding=True)),
)
_KEY_CHUNK = 500
_SHOWN_KEYS = 10
# The exploration's counters; it returns the status and creation time the scheduler needs.
_COUNT = (
    update(ExplorationRow).where(ExplorationRow.id == bindparam("exploration_id"))
    .values(poses_done=ExplorationRow.poses_done + bindparam("inserted"),
            viable_count=ExplorationRow.viable_count + bindparam("viable"),
            updated_at=bindparam("now"))
    .returning(ExplorationRow.status, ExplorationRow.created_at)
)
_KEY_SHARE = (select(ExplorationRow.id).where(ExplorationRow.id == bindparam("exploration_id"))
              .with_for_update(read=True, key_share=True))


def _not_holder(tile: Any, tile_id: int, lease_epoch: int, worker_id: str) -> str | None:
    """Why a report under (worker_id, lease_epoch) is not from the tile's latest lease, or
    None when it is."""
    if tile.lease_epoch < 1 or lease_epoch != tile.lease_epoch:
        latest = (f"its latest lease is epoch {tile.lease_epoch}" if tile.lease_epoch >= 1
                  else "it was never leased")
        return (f"tile {tile_id} has no lease of epoch {lease_epoch} to report for ({latest}, "
                f"state {tile.state}): a late or forged report, nothing of it stored")
    if tile.state == TileState.LEASED and tile.lease_owner != worker_id:
        return (f"tile {tile_id} is leased to {tile.lease_owner} under epoch {lease_epoch}, "
                f"not to {worker_id}: nothing of the report stored")
    return None


def _shown(keys: Sequence[str]) -> str:
    more = len(keys) - _SHOWN_KEYS
    return ", ".join(keys[:_SHOWN_KEYS]) + (f" and {more} more" if more > 0 else "")


def _stored_keys(connection: Any, exploration_id: int, keys: Sequence[str]) -> set[str]:
    stored: set[str] = set()
    for start in range(0, len(keys), _KEY_CHUNK):
        stored.update(connection.execute(
            _STORED,
            {"exploration_id": exploration_id, "keys": list(keys[start : start + _KEY_CHUNK])},
        ).scalars())
    return stored


def store_batch(
    session: Session,
    *,
    tile_id: int,
    lease_epoch: int,
    worker_id: str,
    results: Sequence[PoseResult],
    final: bool = True,
    now: datetime | None = None,
) -> StoredBatch:
    """Store a batch of results of one tile; with `final`, the tile is finished by it once
    every pose of the tile is stored. The caller commits (exploration/scheduler.py, after
    asking the exploration's strategy what comes next in the same transaction).

    Raises NotFound (no such tile), NotLeaseHolder (not from the tile's latest lease) or
    InvalidInput (a result whose key does not match its pose, or a pose not of this tile);
    a refused batch stores nothing."""
    now = now or utcnow()
    session.flush()  # what the session holds goes first, as autoflush would do it
    connection = session.connection()
    tile = connection.execute(_TILE, {"tile_id": tile_id}).one_or_none()
    if tile is None:
        session.rollback()
        raise NotFound(f"tile {tile_id} does not exist (was its exploration deleted?)")
    refusal = _not_holder(tile, tile_id, lease_epoch, worker_id)
    if refusal is not None:
        session.rollback()
        raise NotLeaseHolder(refusal)
    # The tile's pose keys (its cells × r levels × attitudes, as the worker expands them;
    # refinement and search tiles are such products too, exploration/tiling.group_tiles).
    tile_keys = (frozenset(tile_pose_keys(tile.cells, tile.r_levels, tile.attitudes))
                 if results or final else frozenset())
    rows: dict[str, tuple[Any, ...]] = {}
    foreign: list[str] = []
    robustness = any(result.robustness is not None for result in results)
    for result in results:
        key = result.pose.key()
        if result.pose_key != key:
            session.rollback()
            raise InvalidInput(
                f"result pose_key {result.pose_key!r} does not match its pose (key {key!r})"
            )
        if key not in tile_keys:
            foreign.append(key)
        rows[key] = _values(result, robustness)
    if foreign:
        session.rollback()
        foreign = sorted(set(foreign))
        raise InvalidInput(
            f"{len(foreign)} pose(s) of the batch are not poses of tile {tile_id}: "
            f"{_shown(foreign)}; the whole batch is refused, nothing of it stored"
        )

    inserted = viable = 0
    if rows:
        returned = _insert_new(
            session, (tile.exploration_id, tile_id, worker_id, now), list(rows.values()),
            robustness,
        )
        inserted = len(returned)
        viable = sum(1 for v in returned if v)

    moved = False
    state = tile.state
    # The epochs match (checked above).
    movable = final and tiles.finishable(tile.state)
    if not (inserted or movable):
        return StoredBatch(_report(results, 0, state, False, []), tile.exploration_id, None,
                           None)
    # A shared (key) lock on the exploration's row before the tile's, as fail_tile and the
    # requeue take their exclusive one (queue.lock_explorations): no crosswise waits. The
    # insert's foreign key check took it already.
    if not inserted:
        connection.execute(_KEY_SHARE, {"exploration_id": tile.exploration_id}).all()
    missing: list[str] = []
    if movable and len(rows) < len(tile_keys):
        # Not every pose of the tile is in the batch (rows ⊆ tile_keys): the tile is done
        # only if the rest is stored already. Under the tile's row lock, so this reads the
        # batches of this tile committed before and two such batches take turns.
        tiles.lock(session, tile_id)
        absent = sorted(tile_keys.difference(rows))
        missing = sorted(set(absent) - _stored_keys(connection, tile.exploration_id, absent))
        movable = not missing
    if movable:
        moved = tiles.finish(session, tile_id=tile_id, lease_epoch=lease_epoch, now=now)
        if moved:
            state = TileState.DONE
    report = _report(results, inserted, state, moved, missing)
    if not (inserted or moved):  # nothing to count, nothing that could end the exploration
        return StoredBatch(report, tile.exploration_id, None, None)
    # Last, the exploration's counters: their row lock, held to the commit, makes the batches
    # of one exploration take turns only from here on (the strategy reacts under it too);
    # validation, insert and tile run concurrently. A batch moves its tile before it takes the
    # lock (fail_tile and the requeue lock, then move theirs), so whichever takes it last
    # reads every other tile as committed in the finish check after it (a statement of its
    # own: one that waited on the lock would still read the tiles from before).
    exploration = connection.execute(
        _COUNT,
        {"exploration_id": tile.exploration_id, "inserted": inserted, "viable": viable,
         "now": now},
    ).one()
    if moved:
        finish_complete_explorations(session, [tile.exploration_id], now=now)
    return StoredBatch(report, tile.exploration_id, exploration.status, exploration.created_at)


def _report(results: Sequence[PoseResult], inserted: int, state: str, moved: bool,
            missing: list[str]) -> IngestReport:
    return IngestReport(inserted=inserted, duplicates=len(results) - inserted, tile_state=state,
                        tile_moved=moved, missing=missing)
