"""Exports: every pose of an exploration (CSV, Parquet) and the manifold table (JSON).

Pose rows are flat: the pose, its outcome and μs, effort, the manifold label (letters, empty
when none), where the result came from (evaluated by a worker or a shortcut), the digits in
contact, the grasp configuration and signature as JSON text, then the static grasp metrics
(μg, μf, μm) and the robustness margins and tests (empty in CSV, null in Parquet, where the
worker did not compute them), the robust map's robust_s, robust_q and robust_label
(manifolds/robust.py; empty/null before the manifolds were computed with the pose), and the
error message last.

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

ROBUST_COLUMNS = ("robust_s", "robust_q", "robust_label")
COLUMNS = (
    "pose_key", "theta", "phi", "r", "roll", "pitch", "yaw", "outcome", "viable", "mu_s",
    "effort_max_nm", "effective_r", "manifold", "source", "inferred_from", "links_in_contact",
    "grasp",
    "signature", "eval_time_s", *POSE_METRIC_COLUMNS, *ROBUST_COLUMNS, "error",
)
# Rows per cursor fetch, CSV chunk and Parquet row group: a chunk of rows with their parsed
# JSON is ~5 KB a row in Python objects, so 5,000 rows keep an export near 25 MB.
CHUNK = 5_000
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
    *(getattr(PoseRow, name) for name in POSE_METRIC_COLUMNS),
    *(getattr(PoseRow, name) for name in ROBUST_COLUMNS), PoseRow.error,
)
# One encoder for every row: json.dumps(..., sort_keys=True) would build one per call.
_to_json = json.JSONEncoder(sort_keys=True).encode


def _row(row: Any, labels: dict[int, str]) -> tuple[Any, ...]:
    """One pose as the export's values, in COLUMNS order."""
    signature, grasp = row.signature, row.grasp
    return (
        row.pose_key, row.theta, row.phi, row.r, row.roll, row.pitch, row.yaw, row.outcome,
        bool(row.viable), row.mu_s, row.effort_max_nm, row.effective_r,
        labels.get(row.manifold_id, "") if row.manifold_id else "",
        source_of(row.worker_id, row.inferred_from),
        row.inferred_from or "",
        " ".join((signature or {}).get("links_in_contact", ())),
        _to_json(grasp) if grasp else "",
        _to_json(signature) if signature else "",
        row.eval_time_s,
        *(getattr(row, name) for name in POSE_METRIC_COLUMNS),
        row.robust_s, row.robust_q, row.robust_label,
        row.error or "",
    )


def row_chunks(session: Session, exploration_id: int,
               chunk: int | None = None) -> Iterator[list[tuple[Any, ...]]]:
    """The export rows (tuples in COLUMNS order) of every pose, by key, `chunk` at a time
    from one server-side cursor; manifold labels from one small query (manifold id →
    letters), not one per row."""
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
        yield [_row(row, labels) for row in part]


def csv_chunks(chunks: Iterator[list[tuple[Any, ...]]]) -> Iterator[bytes]:
    """The CSV text, header first, one encoded piece per chunk of rows."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(COLUMNS)
    for rows in chunks:
        writer.writerows(rows)
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
                                     "effort_max_nm", "eval_time_s", *POSE_METRIC_COLUMNS,
                                     "robust_s", "robust_q")},
    }
    return pa.schema([(c, types.get(c, pa.string())) for c in COLUMNS])


def write_parquet(chunks: Iterator[list[tuple[Any, ...]]], out: IO[bytes]) -> None:
    """Parquet into `out`, one row group per chunk of rows (built column by column)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    schema = _schema()
    with pq.ParquetWriter(out, schema) as writer:
        wrote = False
        for rows in chunks:
            columns = list(zip(*rows, strict=True)) if rows else [()] * len(COLUMNS)
            writer.write_table(pa.Table.from_arrays(
                [pa.array(col, type=f.type) for col, f in zip(columns, schema, strict=True)],
                schema=schema))
            wrote = True
        if not wrote:  # no poses: the schema and an empty row group, as write_table makes
            writer.write_table(schema.empty_table())


def pose_pieces(session: Session, exploration_id: int, fmt: PoseFormat) -> Iterator[bytes]:
    """Every pose of the exploration as CSV or Parquet, in pieces to send or write in turn.
    Parquet's footer comes last, so it is written (by row groups) into a temporary file that
    stays in memory up to SPOOL_BYTES, then read back in blocks."""
    chunks = row_chunks(session, exploration_id)
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
