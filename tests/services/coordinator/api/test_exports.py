"""Pose exports (CSV, Parquet) through the real app on both databases: streamed in chunks,
the same bytes whatever the chunk size, and the rows exactly as the export has always
written them."""

from __future__ import annotations

import csv
import io

import pyarrow.parquet as pq
import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator.manifolds import export
from graspscape.services.coordinator.manifolds.grouping import label_name
from graspscape.services.coordinator.store.models import (
    POSE_METRIC_COLUMNS,
    ManifoldRow,
    PoseRow,
)
from sqlalchemy import Text, cast, select, update
from sqlalchemy.orm import Session, sessionmaker

from tests.services.coordinator.api.test_explorations import submit, work


def expected_csv(sessions: sessionmaker[Session], eid: int) -> bytes:
    """The export as it was written before streaming: every ORM row in memory, one writer;
    the JSON columns as the text stored at ingest (since 2026-12 the export copies it: it
    was decoded and encoded again with sorted keys, two thirds of an export's time)."""
    with sessions() as s:
        labels = {mid: label for mid, label in s.execute(select(ManifoldRow.id, ManifoldRow.label))}
        stored = {key: (grasp, signature) for key, grasp, signature in s.execute(
            select(PoseRow.pose_key, cast(PoseRow.grasp, Text), cast(PoseRow.signature, Text))
            .where(PoseRow.exploration_id == eid))}
        rows = s.scalars(select(PoseRow).where(PoseRow.exploration_id == eid)
                         .order_by(PoseRow.pose_key)).all()
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=export.COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            source = row.worker_id if (row.worker_id or "").startswith("shortcut:") else (
                "shortcut:configuration" if row.inferred_from else "evaluated")
            writer.writerow({
                "pose_key": row.pose_key, "theta": row.theta, "phi": row.phi, "r": row.r,
                "roll": row.roll, "pitch": row.pitch, "yaw": row.yaw, "outcome": row.outcome,
                "viable": bool(row.viable), "mu_s": row.mu_s,
                "effort_max_nm": row.effort_max_nm, "effective_r": row.effective_r,
                "manifold": label_name(labels[row.manifold_id]) if row.manifold_id else "",
                "source": source, "inferred_from": row.inferred_from or "",
                "links_in_contact": " ".join((row.signature or {}).get("links_in_contact", ())),
                "grasp": stored[row.pose_key][0] or "",
                "signature": stored[row.pose_key][1] or "",
                "eval_time_s": row.eval_time_s,
                **{name: getattr(row, name) for name in POSE_METRIC_COLUMNS},
                **{name: getattr(row, name) for name in export.ROBUST_COLUMNS},
                "error": row.error or "",
            })
    return buf.getvalue().encode()


def test_exports_stream_in_chunks_with_the_same_content(
    client: TestClient, object_id: int, sessions: sessionmaker[Session],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    eid = submit(client, object_id)["id"]
    empty = client.get(f"/explorations/{eid}/export/poses.csv")
    assert empty.status_code == 200 and empty.content == (",".join(export.COLUMNS) + "\n").encode()
    assert pq.read_table(io.BytesIO(
        client.get(f"/explorations/{eid}/export/poses.parquet").content)).num_rows == 0
    work(sessions, 10_000)
    with sessions() as s:  # texts the CSV must quote: the writer's own path for those rows
        keys = s.scalars(select(PoseRow.pose_key).where(PoseRow.exploration_id == eid)
                         .order_by(PoseRow.pose_key).limit(3)).all()
        for key, error in zip(keys, ['ValueError: a, b', 'KeyError: "x"', 'a "b", c'],
                              strict=True):
            s.execute(update(PoseRow).where(PoseRow.pose_key == key).values(error=error))
        s.commit()
    whole = client.get(f"/explorations/{eid}/export/poses.csv")
    assert whole.headers["content-type"].startswith("text/csv")
    assert whole.content == expected_csv(sessions, eid)
    n_rows = whole.content.count(b"\n") - 1
    assert n_rows > 20 and b",A," in whole.content  # labelled manifolds are in there
    labels = {r["robust_label"] for r in csv.DictReader(io.StringIO(whole.text))}
    assert labels and labels <= {"robust", "fragile", "futile", "uncertain"}
    one_group = pq.ParquetFile(io.BytesIO(
        client.get(f"/explorations/{eid}/export/poses.parquet").content))
    assert one_group.metadata.num_row_groups == 1

    monkeypatch.setattr(export, "CHUNK", 7)
    chunked = client.get(f"/explorations/{eid}/export/poses.csv")
    assert chunked.content == whole.content
    groups = pq.ParquetFile(io.BytesIO(
        client.get(f"/explorations/{eid}/export/poses.parquet").content))
    assert groups.metadata.num_row_groups == -(-n_rows // 7)
    assert groups.read().to_pylist() == one_group.read().to_pylist()
    assert groups.read().column("pose_key").to_pylist() == [
        line.split(",", 1)[0] for line in whole.text.splitlines()[1:]]
    assert client.get("/explorations/999/export/poses.csv").status_code == 404
    assert client.get("/explorations/999/export/poses.parquet").status_code == 404
