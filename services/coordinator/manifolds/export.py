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
import tempfile
import uuid
from collections.abc import Callable, Iterator
from typing import IO, Any, Literal

from graspscape.services.coordinator.manifolds.grouping import label_name
from graspscape.services.coordinator.store.models import (
    POSE_METRIC_COLUMNS,
    ManifoldRow,
    PoseRow,
)
from sqlalchemy import Text, case, cast, func, literal, or_, select
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

def _cells(labels: dict[int, str], dialect: str, *, for_csv: bool) -> tuple[Any, ...]:
    """The export's columns computed by the database, in COLUMNS order, so that a row
    leaves the driver as the tuple the writer takes and no Python runs per row: the JSON
    columns as their stored text (written once at ingest, see store/pose_rows._json_text), the
    manifold's letters and the source by CASE, the digits in contact from the signature's
    JSON. Decoding and encoding the JSON again per row was two thirds of an export's time."""
    # The digits in contact: the signature's `links_in_contact` array, '["palm","finger_1"]'
    # (pydantic's text; '", "' where json.dumps wrote it), to 'palm finger_1' by string
    # replacement (link names are URDF identifiers: no quotes, commas or spaces).
    if dialect == "postgresql":
        array = PoseRow.signature.op("->>")(literal("links_in_contact"))
    else:
        array = func.json_extract(PoseRow.signature, "$.links_in_contact")
    links = func.replace(func.replace(func.replace(
        func.trim(array, "[]"), '", "', " "), '","', " "), '"', "")
    manifold = (case(labels, value=PoseRow.manifold_id, else_=literal(""))
                if labels else literal(""))
    source = case(
        # a P(success) draw, evaluated outcome only: its μs of 0 is not a measurement
        (PoseRow.sample.is_not(None), literal("draw")),
        (PoseRow.worker_id.like("shortcut:%"), PoseRow.worker_id),
        (func.coalesce(PoseRow.inferred_from, "") != "", literal("shortcut:configuration")),
        else_=literal("evaluated"),
    )
    viable = (case((PoseRow.viable, literal("True")), else_=literal("False")) if for_csv
              else PoseRow.viable)
    texts = {"pose_key": PoseRow.pose_key, "outcome": PoseRow.outcome, "manifold": manifold,
             "source": source, "inferred_from": func.coalesce(PoseRow.inferred_from, ""),
             "links_in_contact": func.coalesce(links, ""),
             "robust_label": PoseRow.robust_label, "error": func.coalesce(PoseRow.error, "")}
    grasp = func.coalesce(cast(PoseRow.grasp, Text), "")
    signature = func.coalesce(cast(PoseRow.signature, Text), "")
    if for_csv:  # JSON always holds '"', so the CSV writer would always quote it so
        grasp, signature = _quoted(grasp), _quoted(signature)
    cells = (
        texts["pose_key"], PoseRow.theta, PoseRow.phi, PoseRow.r, PoseRow.roll, PoseRow.pitch,
        PoseRow.yaw, texts["outcome"], viable, PoseRow.mu_s, PoseRow.effort_max_nm,
        PoseRow.effective_r, texts["manifold"], texts["source"], texts["inferred_from"],
        texts["links_in_contact"], grasp, signature, PoseRow.eval_time_s,
        *(getattr(PoseRow, name) for name in POSE_METRIC_COLUMNS),
        PoseRow.robust_s, PoseRow.robust_q, texts["robust_label"], texts["error"],
    )
    if not for_csv:
        return cells
    # Whether another text of the row needs the CSV writer's quoting (rare: an error
    # message with a comma): such rows go through csv.writer, the others are joined.
    special = or_(*(text.like(f"%{c}%") for text in texts.values() for c in _SPECIAL))
    return (*cells, case((special, literal(1)), else_=literal(0)))


_SPECIAL = (",", '"', "\n", "\r")


def _quoted(text: Any) -> Any:
    """A CSV field as csv.writer quotes one holding a quote: in quotes, quotes doubled."""
    return case((text == "", literal("")),
                else_=literal('"') + func.replace(text, '"', '""') + literal('"'))


def row_chunks(session: Session, exploration_id: int, chunk: int | None = None, *,
               for_csv: bool = True) -> Iterator[list[tuple[Any, ...]]]:
    """The export rows (tuples in COLUMNS order) of every pose, by key, `chunk` at a time
    from one server-side cursor; manifold labels from one small query (manifold id →
    letters), not one per row. `for_csv`: `viable` as the text CSV has always shown
    ("True"/"False"), else a bool."""
    labels = {
        mid: label_name(label)
        for mid, label in session.execute(
            select(ManifoldRow.id, ManifoldRow.label).where(
                ManifoldRow.exploration_id == exploration_id)
        )
    }
    dialect = session.get_bind().dialect.name
    query = (select(*_cells(labels, dialect, for_csv=for_csv))
             .where(PoseRow.exploration_id == exploration_id)
             .order_by(PoseRow.pose_key))
    # The driver's own cursor on the session's connection (server-side on PostgreSQL), its
    # rows plain tuples: the ORM's row loading cost as much as the query, SQLAlchemy's rows
    # a fifth of an export.
    sql = str(query.compile(dialect=session.get_bind().dialect,
                            compile_kwargs={"literal_binds": True}))
    dbapi = session.connection().connection.dbapi_connection
    size = chunk or CHUNK
    if dialect == "postgresql":
        cursor = dbapi.cursor(name=f"pose_export_{exploration_id}_{uuid.uuid4().hex[:8]}")
        cursor.itersize = size
    else:
        cursor = dbapi.cursor()
    try:
        cursor.execute(sql)
        while rows := cursor.fetchmany(size):
            yield rows
    finally:
        cursor.close()


def csv_chunks(chunks: Iterator[list[tuple[Any, ...]]]) -> Iterator[bytes]:
    """The CSV text, header first, one encoded piece per chunk of rows (row_chunks's rows
    for CSV: JSON quoted already, the `special` flag last). A row is its cells' str()
    joined by commas, which is what csv.writer writes for cells that need no quoting
    (str(float) is repr, None is empty); a flagged row goes through csv.writer itself."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(COLUMNS)
    yield buf.getvalue().encode()
    for rows in chunks:
        lines = []
        for row in rows:
            if row[-1]:
                lines.append(_through_writer(row[:-1]))
            else:
                lines.append(",".join(["" if v is None else str(v) for v in row[:-1]]))
        lines.append("")
        yield "\n".join(lines).encode()


_JSON_AT = (COLUMNS.index("grasp"), COLUMNS.index("signature"))


def _through_writer(row: tuple[Any, ...]) -> str:
    cells = list(row)
    for i in _JSON_AT:  # undo the quoting the database did: the writer does its own
        cells[i] = cells[i][1:-1].replace('""', '"')
    buf = io.StringIO()
    # The same line terminator as the whole file's writer: csv quotes a field that holds
    # one of its characters.
    csv.writer(buf, lineterminator="\n").writerow(cells)
    return buf.getvalue()[:-1]


def _schema() -> Any:
    import pyarrow as pa

    types = {
        "viable": pa.bool_(), "effective_r": pa.float64(),
        **{c: pa.float64() for c in ("theta", "phi", "r", "roll", "pitch", "yaw", "mu_s",
                                     "effort_max_nm", "eval_time_s", *POSE_METRIC_COLUMNS,
                                     "robust_s", "robust_q")},
    }
    return pa.schema([(c, types.get(c, pa.string())) for c in COLUMNS])


def _arrow(pa: Any, values: Any, kind: Any) -> Any:
    if kind == pa.bool_():  # SQLite's driver gives 0/1: converted by arrow, not per row
        return pa.array(values, type=pa.int8()).cast(kind) if values and not isinstance(
            values[0], bool) else pa.array(values, type=kind)
    return pa.array(values, type=kind)


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
                [_arrow(pa, col, f.type) for col, f in zip(columns, schema, strict=True)],
                schema=schema))
            wrote = True
        if not wrote:  # no poses: the schema and an empty row group, as write_table makes
            writer.write_table(schema.empty_table())


def pose_pieces(session: Session, exploration_id: int, fmt: PoseFormat) -> Iterator[bytes]:
    """Every pose of the exploration as CSV or Parquet, in pieces to send or write in turn.
    Parquet's footer comes last, so it is written (by row groups) into a temporary file that
    stays in memory up to SPOOL_BYTES, then read back in blocks."""
    chunks = row_chunks(session, exploration_id, for_csv=fmt == "csv")
    if fmt == "csv":
        yield from csv_chunks(chunks)
        return
    with tempfile.SpooledTemporaryFile(max_size=SPOOL_BYTES) as spool:
        write_parquet(chunks, spool)
        spool.seek(0)
        while block := spool.read(BLOCK_BYTES):
            yield block


def session_pieces(sessionmaker: Callable[[], Session], exploration_id: int,
                   fmt: PoseFormat) -> Iterator[bytes]:
    """`pose_pieces` in a session of its own, held no longer than the database is read: to
    the CSV's last row, or until the Parquet file is written (its blocks are then sent from
    the spool with the connection given back)."""
    if fmt == "csv":
        with sessionmaker() as own:
            yield from pose_pieces(own, exploration_id, fmt)
        return
    with tempfile.SpooledTemporaryFile(max_size=SPOOL_BYTES) as spool:
        with sessionmaker() as own:
            write_parquet(row_chunks(own, exploration_id, for_csv=False), spool)
        spool.seek(0)
        while block := spool.read(BLOCK_BYTES):
            yield block


def write_poses(session: Session, exploration_id: int, fmt: PoseFormat, out: IO[bytes]) -> None:
    """Every pose of the exploration as CSV or Parquet into `out` (a file), chunk by chunk."""
    for piece in pose_pieces(session, exploration_id, fmt):
        out.write(piece)
