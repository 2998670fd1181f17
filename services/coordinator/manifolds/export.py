"""Exports: every pose of an exploration (CSV, Parquet) and the manifold table (JSON).

Pose rows are flat: the pose, its outcome and μs, effort, the manifold label (letters, empty
when none), where the result came from (evaluated by a worker or a shortcut), the digits in
contact, the grasp configuration and signature as JSON text, then the static grasp metrics
(μg, μf, μm) and the robustness margins and tests (empty in CSV, null in Parquet, where the
worker did not compute them).
"""

from __future__ import annotations

import csv
import io
import json
from typing import Any

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


def pose_records(session: Session, exploration_id: int) -> list[dict[str, Any]]:
    labels = {
        mid: label_name(label)
        for mid, label in session.execute(
            select(ManifoldRow.id, ManifoldRow.label).where(
                ManifoldRow.exploration_id == exploration_id)
        )
    }
    out = []
    rows = session.scalars(
        select(PoseRow).where(PoseRow.exploration_id == exploration_id).order_by(PoseRow.pose_key)
    )
    for row in rows:
        out.append({
            "pose_key": row.pose_key, "theta": row.theta, "phi": row.phi, "r": row.r,
            "roll": row.roll, "pitch": row.pitch, "yaw": row.yaw, "outcome": row.outcome,
            "viable": bool(row.viable), "mu_s": row.mu_s, "effort_max_nm": row.effort_max_nm,
            "effective_r": row.effective_r,
            "manifold": labels.get(row.manifold_id, "") if row.manifold_id else "",
            "source": source_of(row.worker_id, row.inferred_from),
            "inferred_from": row.inferred_from or "",
            "links_in_contact": " ".join((row.signature or {}).get("links_in_contact", ())),
            "grasp": json.dumps(row.grasp, sort_keys=True) if row.grasp else "",
            "signature": json.dumps(row.signature, sort_keys=True) if row.signature else "",
            "eval_time_s": row.eval_time_s,
            **{name: getattr(row, name) for name in POSE_METRIC_COLUMNS},
            "error": row.error or "",
        })
    return out


def poses_csv(records: list[dict[str, Any]]) -> bytes:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(records)
    return buf.getvalue().encode()


def poses_parquet(records: list[dict[str, Any]]) -> bytes:
    import pyarrow as pa
    import pyarrow.parquet as pq

    types = {
        "viable": pa.bool_(), "effective_r": pa.float64(),
        **{c: pa.float64() for c in ("theta", "phi", "r", "roll", "pitch", "yaw", "mu_s",
                                     "effort_max_nm", "eval_time_s", *POSE_METRIC_COLUMNS)},
    }
    schema = pa.schema([(c, types.get(c, pa.string())) for c in COLUMNS])
    table = pa.Table.from_pylist(records, schema=schema)
    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()
