"""An exploration's poses for a dataset export: what the object and gripper are, then every
stored pose in pose-key order with its gripper transform, streamed in chunks from the store
(a server-side cursor on PostgreSQL), so an export holds one chunk in memory, not the table."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from graspscape.services.coordinator.datasets.transforms import StartPoses, grasp_transforms
from graspscape.services.coordinator.errors import Conflict, NotFound
from graspscape.services.coordinator.objects.geometry import object_mesh
from graspscape.services.coordinator.store.models import (
    POSE_METRIC_COLUMNS,
    ExplorationRow,
    ObjectRow,
    PoseRow,
)
from graspscape.shared.specs.objects import METRES_PER
from graspscape.shared.specs.support import resting_document
from pydantic import BaseModel, Field
from sqlalchemy import select
from sqlalchemy.orm import Session

CHUNK_ROWS = 2000
# The per-pose qualities every export carries besides success: μs, the largest joint torque,
# the stored grasp metrics and margins, and the robust map's robust success and quality
# (manifolds/robust.py) (NaN where not computed).
QUALITIES = ("mu_s", "effort_max_nm", *POSE_METRIC_COLUMNS, "robust_s", "robust_q")
# P(success) under the exploration's uncertainty model, where the certification drew around
# the pose (manifolds/p_success.py): k/n, the anytime-valid 95 % bounds, n (NaN elsewhere).
SUCCESS_QUALITIES = ("p_success", "p_success_lower", "p_success_upper", "p_success_n")
_POSE = (PoseRow.theta, PoseRow.phi, PoseRow.r, PoseRow.roll, PoseRow.pitch, PoseRow.yaw)


class DatasetObject(BaseModel):
    id: int
    file: str = Field(description="file name of the object's mesh in its centre-of-mass frame, "
                      "the frame of the transforms (`object.obj` export)")
    scale: float = Field(description="scale of `file` at which the grasps were evaluated: 1, "
                         "since that mesh is already in metres at the explored scale")
    source: str = Field(description="the object as stored: a name or an uploaded file's name")
    source_scale: float = Field(description="metres per unit of the source mesh (scale × units)")
    mass_kg: float | None = Field(description="the stored mass; None: the named object's own")
    friction: float | None


class DatasetSource(BaseModel):
    exploration_id: int
    object: DatasetObject
    gripper: str
    resting_pose: dict[str, Any] | None = None  # on a table: support.resting_document


@dataclass(frozen=True)
class Chunk:
    """Consecutive stored poses: keys, N×4×4 transforms, which came from a grasp (else the
    start pose), outcome, success and the qualities (NaN where not computed)."""

    pose_keys: list[str]
    poses: np.ndarray  # N×6: θ, φ, r, roll, pitch, yaw
    transforms: np.ndarray
    from_grasp: np.ndarray  # bool
    outcomes: list[str]
    success: np.ndarray  # bool: viable, the grasp formed and held along the trajectory
    qualities: dict[str, np.ndarray]


def object_file_name(exploration_id: int) -> str:
    return f"exploration-{exploration_id}-object.obj"


def dataset_source(session: Session, exploration_id: int,
                   object_file: str | None = None) -> DatasetSource:
    """Where the dataset comes from; `object_file`: the name under which its writer puts the
    mesh beside it (default: the download name of GET …/export/object.obj)."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    obj = session.get(ObjectRow, row.object_id)
    assert obj is not None  # a foreign key
    props = obj.properties or {}
    return DatasetSource(
        exploration_id=exploration_id,
        object=DatasetObject(
            id=obj.id, file=object_file or object_file_name(exploration_id), scale=1.0,
            source=obj.name,
            source_scale=float(props.get("scale", 1.0)) * METRES_PER[props.get("units") or "m"],
            mass_kg=props.get("mass_kg"), friction=props.get("friction")),
        gripper=str(row.spec["gripper"]),
        resting_pose=resting_document(row.spec),
    )


def exploration_mesh(session: Session, exploration_id: int) -> Any | None:
    """The object's mesh in the frame of the transforms, None where this process cannot
    prepare it (a coordinator without the workers' object preparation)."""
    row = session.get(ExplorationRow, exploration_id)
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    return object_mesh(session, row.object_id)


def pose_chunks(session: Session, exploration_id: int, mesh: Any | None,
                chunk_rows: int | None = None) -> Iterator[Chunk]:
    """Every stored pose but the draws, in pose-key order, `chunk_rows` (default CHUNK_ROWS)
    at a time. A pose that formed no grasp needs `mesh` (a Conflict without it)."""
    from graspscape.services.coordinator.manifolds.p_success import estimates

    starts = StartPoses(mesh) if mesh is not None else None
    chances = estimates(session, exploration_id)
    columns = (PoseRow.pose_key, *_POSE, PoseRow.effective_r, PoseRow.outcome, PoseRow.viable,
               PoseRow.grasp, *(getattr(PoseRow, q) for q in QUALITIES))
    # A draw of P(success) is evaluated outcome only (no grasp configuration, no μs): it is
    # in its centre's p_success columns, not a grasp of the dataset.
    query = (select(*columns).where(PoseRow.exploration_id == exploration_id,
                                    PoseRow.sample.is_(None))
             .order_by(PoseRow.pose_key).execution_options(yield_per=chunk_rows or CHUNK_ROWS))
    for part in session.execute(query).partitions():
        yield _chunk(part, starts, chances)


def _chunk(rows: Any, starts: StartPoses | None, chances: dict[str, Any]) -> Chunk:
    n = len(rows)
    poses = np.array([row[1:7] for row in rows], dtype=float).reshape(n, 6)
    from_grasp = np.array([row.grasp is not None for row in rows], dtype=bool)
    transforms = np.zeros((n, 4, 4))
    transforms[from_grasp] = grasp_transforms([row.grasp for row in rows if row.grasp is not None])
    for i in np.flatnonzero(~from_grasp):
        if starts is None:
            raise Conflict(f"pose {rows[i].pose_key} formed no grasp, so its transform is its "
                           "start pose, placed on the object's mesh, which is unavailable here "
                           "(a coordinator without the workers' object preparation)")
        transforms[i] = starts.transform(*poses[i], rows[i].effective_r)
    return Chunk(
        pose_keys=[row.pose_key for row in rows], poses=poses, transforms=transforms,
        from_grasp=from_grasp, outcomes=[row.outcome for row in rows],
        success=np.array([bool(row.viable) for row in rows], dtype=bool),
        qualities={**{q: np.array([np.nan if getattr(row, q) is None else getattr(row, q)
                                   for row in rows], dtype=float) for q in QUALITIES},
                   **_success_columns([row.pose_key for row in rows], chances)},
    )


def _success_columns(keys: list[str], chances: dict[str, Any]) -> dict[str, np.ndarray]:
    def column(read: Any) -> np.ndarray:
        return np.array([read(chances[k]) if k in chances else np.nan for k in keys],
                        dtype=float)
    return {"p_success": column(lambda e: e.p), "p_success_lower": column(lambda e: e.lower),
            "p_success_upper": column(lambda e: e.upper), "p_success_n": column(lambda e: e.n)}
