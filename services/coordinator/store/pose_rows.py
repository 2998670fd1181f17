"""The rows of a result batch, as the driver takes them: one statement per batch.

store/ingest.py validates the batch and decides what it may store; this module builds the
rows' values and the `INSERT … ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING
viable` that stores the new ones, for SQLite (multi-row VALUES) and PostgreSQL (one array per
column through unnest()).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from functools import lru_cache
from operator import attrgetter
from typing import Any

from graspscape.services.coordinator.store.models import PoseRow
from graspscape.services.coordinator.store.pose_columns import (
    GRASP_METRIC_COLUMNS,
    POSE_METRIC_COLUMNS,
    ROBUSTNESS_COLUMNS,
)
from graspscape.shared.specs.results import PoseResult
from pydantic import BaseModel
from pydantic_core import to_json
from sqlalchemy import Connection
from sqlalchemy.orm import Session


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
        _json_text(result.sample),
        *_static(result),
    )
    if not robustness:
        return values
    rb = result.robustness
    if rb is None:
        return values + _NO_ROBUSTNESS
    return values + _report(rb)


def _getter(names: tuple[str, ...]) -> Callable[[Any], tuple[Any, ...]]:
    """The named attributes of an object as a tuple (operator.attrgetter: one C call per
    result, not one Python step per column)."""
    if not names:
        return lambda _: ()
    get = attrgetter(*names)
    return get if len(names) > 1 else lambda x: (get(x),)


# The measured qualities (store/pose_columns.py): PoseResult's, then its robustness report's.
_static = _getter(GRASP_METRIC_COLUMNS)
_report = _getter(ROBUSTNESS_COLUMNS)


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
    ("sample", "text"),
    *((name, "float8") for name in POSE_METRIC_COLUMNS),
)
# The robustness tests are chosen per exploration and off by default: a batch without any
# report leaves their columns out of the statement (NULL), which spares SQLite a quarter of
# its parameters per row and PostgreSQL seven arrays of nulls.
_WITHOUT_ROBUSTNESS = _PER_POSE[: len(_PER_POSE) - len(ROBUSTNESS_COLUMNS)]
assert tuple(name for name, _ in _PER_POSE[len(_WITHOUT_ROBUSTNESS):]) == ROBUSTNESS_COLUMNS
_PER_BATCH = ("exploration_id", "tile_id", "worker_id", "created_at")
_CONFLICT = "ON CONFLICT (exploration_id, pose_key) DO NOTHING RETURNING viable"
_JSON_COLUMNS = ("contacts_per_link", "signature", "grasp", "sample")


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


def bound_batch(connection: Connection, batch: tuple[Any, ...]) -> tuple[Any, ...]:
    """The _PER_BATCH values with the timestamp as the ORM would bind it (UTC; on SQLite the
    store's text form)."""
    dialect = connection.dialect
    created_at = PoseRow.__table__.c.created_at.type.dialect_impl(dialect).bind_processor(dialect)
    if created_at is not None:
        batch = (*batch[:3], created_at(batch[3]))
    return batch


def pg_insert(batch: tuple[Any, ...], rows: list[tuple[Any, ...]], robustness: bool = True
              ) -> tuple[str, dict[str, Any]]:
    """PostgreSQL's statement and parameters for the rows (`batch` bound by bound_batch).

    One short statement with a column array each: psycopg parses and prepares it once. A
    multi-row VALUES statement has thousands of placeholders that psycopg re-parses on every
    batch, which took half of the ingest time. (One JSON array of the rows instead saved
    little client time and cost the server more than that.)"""
    params: dict[str, Any] = dict(zip(_PER_BATCH, batch, strict=True))
    for (name, _), column in zip(_COLUMNS[robustness], zip(*rows, strict=True), strict=True):
        params[name] = list(column)
    return _PG_INSERT[robustness], params


def insert_new(session: Session, batch: tuple[Any, ...], rows: list[tuple[Any, ...]],
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
    batch = bound_batch(connection, batch)
    if dialect.name == "postgresql":
        result = connection.exec_driver_sql(*pg_insert(batch, rows, robustness))
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
