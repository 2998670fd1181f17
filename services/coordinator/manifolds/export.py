"""Exports: every pose of an exploration (CSV, Parquet) and the manifold table (JSON).

Pose rows are flat: the pose, its outcome and μs, effort, the manifold label (letters, empty
when none), where the result came from (evaluated by a worker or a shortcut), the digits in
contact, the grasp configuration and signature as JSON text, then the static grasp metrics
(μg, μf, μm) and the robustness margins and tests (empty in CSV, null in Parquet, where the
worker did not compute them), and the error message last.

Pose exports are written in chunks of CHUNK rows read from one server-side cursor, so memory
stays bounded however large the exploration (a 5M-pose exploration is allowed): CSV as text
chunks, Parquet as one row group per chunk. The output is the same bytes as writing the whole
table at once where the exploration fits in one chunk.
"""

from __future__ import annotations

import csv
import io
import json
import tempfile
from collections.abc import Iterator
from typing import IO, Any, Literal

from graspscape.services.coordinator.manifolds.behaviour import source_of
from graspscape.services.coordinator.manifolds.grouping import label_name
from graspscape.services.coordinator.store.models import (
    POSE_METRIC_COLUMNS,
    ManifoldRow,
    PoseRow,
)
from sqlalchemy import select
from sqlalchemy.orm import Session

COLUMNS = (
    "pose_key", "theta", "phi", "r", "roll", "pitch", "yaw", "outcome", "viable", "mu_s",
    "effort_max_nm", "effective_r", "manifold", "source", "inferred_from", "links_in_contact",
    "grasp",
    "signature", "eval_time_s", *POSE_METRIC_COLUMNS, "error",
)
CHUNK = 20_000  # rows per cursor fetch, CSV chunk and Parquet row group
SPOOL_BYTES = 32 * 2**20
BLOCK_BYTES = 2**20
PoseFormat = Literal["csv", "parquet"]
MEDIA_TYPES: dict[PoseFormat, str] = {"csv": "text/csv",
                                      "parquet": "application/vnd.apache.parquet"}

_SELECTED = (
    PoseRow.pose_key, PoseRow.theta, PoseRow.phi, PoseRow.r, PoseRow.roll, PoseRow.pitch,
    PoseRow.yaw, PoseRow.outcome, PoseRow.viable, PoseRow.mu_s, PoseRow.effort_max_nm,
    PoseRow.effective_r, PoseRow.manifold_id, PoseRow.worker_id, PoseRow.inferred_from,
    PoseRow.signature, PoseRow.grasp, PoseRow.eval_time_s,
    *(getattr(PoseRow, name) for name in POSE_METRIC_COLUMNS), PoseRow.error,
)
# One encoder for every row: json.dumps(..., sort_keys=True) would build one per call.
_to_json = json.JSONEncoder(sort_keys=True).encode


def _record(row: Any, labels: dict[int, str]) -> dict[str, Any]:
    signature, grasp = row.signature, row.grasp
    return {
        "pose_key": row.pose_key, "theta": row.theta, "phi": row.phi, "r": row.r,
        "roll": row.roll, "pitch": row.pitch, "yaw": row.yaw, "outcome": row.outcome,
        "viable": bool(row.viable), "mu_s": row.mu_s, "effort_max_nm": row.effort_max_nm,
        "effective_r": row.effective_r,
        "manifold": labels.get(row.manifold_id, "") if row.manifold_id else "",
        "source": source_of(row.worker_id, row.inferred_from),
        "inferred_from": row.inferred_from or "",
        "links_in_contact": " ".join((signature or {}).get("links_in_contact", ())),
        "grasp": _to_json(grasp) if grasp else "",
        "signature": _to_json(signature) if signature else "",
        "eval_time_s": row.eval_time_s,
        **{name: getattr(row, name) for name in POSE_METRIC_COLUMNS},
        "error": row.error or "",
    }


def record_chunks(session: Session, exploration_id: int,
                  chunk: int | None = None) -> Iterator[list[dict[str, Any]]]:
    """The export rows of every pose, by key, `chunk` at a time from one server-side cursor;
    manifold labels from one small query (manifold id → letters), not one per row."""
    labels = {
        mid: label_name(label)
        for mid, label in session.execute(
            select(ManifoldRow.id, ManifoldRow.label).where(
                ManifoldRow.exploration_id == exploration_id)
        )
    }
    query = (select(*_SELECTED).where(PoseRow.exploration_id == exploration_id)
             .order_by(PoseRow.pose_key).execution_options(yield_per=chunk or CHUNK))
    for part in session.execute(query).partitions():
        yield [_record(row, labels) for row in part]


def pose_records(session: Session, exploration_id: int) -> list[dict[str, Any]]:
    """Every export row in memory at once (small explorations, tests)."""
    return [r for part in record_chunks(session, exploration_id) for r in part]


def csv_chunks(chunks: Iterator[list[dict[str, Any]]]) -> Iterator[bytes]:
    """The CSV text, header first, one encoded piece per chunk of rows."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for records in chunks:
        writer.writerows(records)
        yield buf.getvalue().encode()
        buf.seek(0)
        buf.truncate()
    if buf.tell():  # the header of an exploration without poses
        yield buf.getvalue().encode()


def _schema() -> Any:
    import pyarrow as pa

    types = {
        "viable": pa.bool_(), "effective_r": pa.float64(),
        **{c: pa.float64() for c in ("theta", "phi", "r", "roll", "pitch", "yaw", "mu_s",
                                     "effort_max_nm", "eval_time_s", *POSE_METRIC_COLUMNS)},
    }
    return pa.schema([(c, types.get(c, pa.string())) for c in COLUMNS])


def write_parquet(chunks: Iterator[list[dict[str, Any]]], out: IO[bytes]) -> None:
    """Parquet into `out`, one row group per chunk of rows."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = _schema()
    with pq.ParquetWriter(out, schema) as writer:
        wrote = False
        for records in chunks:
            writer.write_table(pa.Table.from_pylist(records, schema=schema))
            wrote = True
        if not wrote:  # no poses: the schema and an empty row group, as write_table makes
            writer.write_table(schema.empty_table())


def pose_pieces(session: Session, exploration_id: int, fmt: PoseFormat) -> Iterator[bytes]:
    """Every pose of the exploration as CSV or Parquet, in pieces to send or write in turn.
    Parquet's footer comes last, so it is written (by row groups) into a temporary file that
    stays in memory up to SPOOL_BYTES, then read back in blocks."""
    chunks = record_chunks(session, exploration_id)
    if fmt == "csv":
        yield from csv_chunks(chunks)
        return
    with tempfile.SpooledTemporaryFile(max_size=SPOOL_BYTES) as spool:
        write_parquet(chunks, spool)
        spool.seek(0)
        while block := spool.read(BLOCK_BYTES):
            yield block


def write_poses(session: Session, exploration_id: int, fmt: PoseFormat, out: IO[bytes]) -> None:
    """Every pose of the exploration as CSV or Parquet into `out` (a file), chunk by chunk."""
    for piece in pose_pieces(session, exploration_id, fmt):
        out.write(piece)


def poses_csv(records: list[dict[str, Any]]) -> bytes:
    return b"".join(csv_chunks(iter([records])))


def poses_parquet(records: list[dict[str, Any]]) -> bytes:
    buf = io.BytesIO()
    write_parquet(iter([records]), buf)
    return buf.getvalue()
