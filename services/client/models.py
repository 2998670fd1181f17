"""Typed answers of the coordinator's REST API, as the client returns them.

Kept apart from the server's schemas on purpose: the client installs and imports without
SQLAlchemy, FastAPI or the workers. Every model ignores fields it does not know, so a newer
server's answers still parse; the fields named here are those the client's users read.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field
from scipy.spatial.transform import Rotation


class _Answer(BaseModel):
    model_config = ConfigDict(extra="allow", frozen=True)


class Progress(_Answer):
    poses_done: int
    poses_total: int
    fraction_done: float
    viable_share: float | None = None
    throughput_poses_per_s: float = 0.0
    eta_s: float | None = Field(default=None, description="seconds left; None when unknown")
    tiles: dict[str, int] = Field(default_factory=dict)


class FailureReason(_Answer):
    reason: str | None
    tiles: int


class Failures(_Answer):
    tiles: int
    poses_with_errors: int = 0
    reasons: list[FailureReason] = Field(default_factory=list)


FINISHED = frozenset({"done", "incomplete", "failed", "cancelled"})


class Exploration(_Answer):
    """GET /explorations/{id}: the spec, status and progress of one exploration."""

    id: int
    object_id: int
    status: str
    spec: dict[str, Any]
    poses_total: int
    poses_done: int
    viable_count: int
    created_at: datetime
    finished_at: datetime | None = None
    progress: Progress | None = None
    failures: Failures | None = None

    @property
    def finished(self) -> bool:
        return self.status in FINISHED


class StoredGripper(_Answer):
    """A gripper stored on the coordinator: `gripper` is what a spec names it by."""

    gripper: str
    content_hash: str
    kind: str
    name: str
    size_bytes: int


class Submitted(_Answer):
    id: int
    status: str
    tiles_total: int
    poses_total: int
    group: list[int] = Field(default_factory=list)  # on a table: one id per resting pose


class Retried(_Answer):
    id: int
    status: str
    tiles_requeued: int


class FailedTile(_Answer):
    tile_id: int
    level: int
    n_poses: int
    attempts: int
    last_error: str | None


class StoredObject(_Answer):
    id: int
    name: str


def _transform(position: Any, quaternion_xyzw: Any) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_quat(quaternion_xyzw).as_matrix()
    out[:3, 3] = position
    return out


class Success(_Answer):
    """A pose's P(success) under the exploration's uncertainty model: k of n draws held with its
    grasp type, the anytime-valid 95 % bounds, and whether the lower bound clears the level."""

    k: int
    n: int
    p: float
    lower: float
    upper: float
    certified: bool
    engines: list[str] = []


class Pose(_Answer):
    """A stored pose (GET …/poses, …/best). Angles are radians and lengths metres, as the API
    answers them."""

    id: int
    pose_key: str
    theta: float
    phi: float
    r: float
    roll: float
    pitch: float = 0.0
    yaw: float = 0.0
    outcome: str
    viable: bool
    mu_s: float
    effort_max_nm: float
    grasp: dict[str, Any] | None = None
    manifold_id: int | None = None
    robust_s: float | None = None
    robust_q: float | None = None
    robust_label: str | None = None
    success: Success | None = None  # /best's answers only

    @property
    def transform(self) -> np.ndarray | None:
        """The gripper frame (palm surface centre, z the palm normal toward the object) in the
        object's centre-of-mass frame at the end of closing, 4×4; None where no grasp formed
        (the dataset exports place those poses: `Client.export`)."""
        if not self.grasp:
            return None
        return _transform(self.grasp["base_position"], self.grasp["base_orientation"])


class Best(_Answer):
    """GET /explorations/{id}/best."""

    exploration_id: int
    manifold: str | None = None
    rank: str
    delta_deg: float
    delta_mm: float
    uncertainty: dict[str, Any] = {}
    level: float = 0.9
    engines: list[str] | None = None
    poses: list[Pose]


class PoseBrief(_Answer):
    key: str
    theta: float
    phi: float
    r: float
    roll: float
    mu_s: float
    effort_max_nm: float


class Manifold(_Answer):
    label: int
    name: str
    description: str
    pose_count: int
    volume_cm3: float
    mu_s_mean: float
    mu_s_max: float
    best: PoseBrief
    core_volume_cm3: float | None = None
    robust_best: PoseBrief | None = None
    large: bool = True


class Dust(_Answer):
    manifolds: int
    poses: int
    volume_cm3: float


class Manifolds(_Answer):
    """GET /explorations/{id}/manifolds: the large manifolds and the dust (the smaller ones)."""

    exploration_id: int
    final: bool
    manifolds: list[Manifold]
    dust: Dust | None = None

    @property
    def large(self) -> list[Manifold]:
        return [m for m in self.manifolds if m.large]
