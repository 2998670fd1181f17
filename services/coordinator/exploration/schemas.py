"""Pydantic shapes of explorations, progress and poses at the HTTP boundary."""

from __future__ import annotations

from datetime import datetime
from typing import Any

from graspscape.services.coordinator.mapspace.pose import PoseValues as PoseValues
from graspscape.services.coordinator.store.pose_columns import METRIC_COLUMNS
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.results import Outcome
from pydantic import BaseModel, ConfigDict, Field, create_model


class ExplorationOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    object_id: int
    spec: ExplorationSpec
    status: str = Field(
        description="queued, running, done (every planned pose stored), incomplete (tiles "
        "failed, some poses stored), failed (tiles failed, no pose stored) or cancelled")
    tiles_total: int
    poses_total: int = Field(description="poses of the coarse pass")
    poses_done: int
    viable_count: int
    created_at: datetime
    updated_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    support_group: int | None = Field(
        default=None, description="on a table: the id of the first exploration of the group "
        "submitted together, one per resting pose (null: a free object)")
    resting_index: int | None = Field(
        default=None, description="on a table: the rank of this exploration's resting pose")
    resting_probability: float | None = Field(
        default=None, description="on a table: how likely the object comes to rest so")


class Progress(BaseModel):
    tiles: dict[str, int] = Field(description="tiles by state")
    poses_done: int
    poses_total: int
    fraction_done: float
    viable_share: float | None = Field(description="viable / done; null before any pose")
    throughput_poses_per_s: float = Field(
        description="poses stored per second over the last throughput window (over the part "
        "of it since the window's first pose, for a run younger than the window)")
    eta_s: float | None = Field(
        description="remaining planned poses / throughput; null when it cannot be estimated "
        "(fewer than 10 poses in the window, stalled, all planned poses stored) and for a "
        "finished exploration (done, incomplete, failed, cancelled)")
    manifolds_poses_done: int = Field(
        default=0, description="the poses the stored manifold table is at (the keeper's "
        "last refresh); reads serve that table")
    manifolds_lag_poses: int = Field(
        default=0, description="poses stored but not yet in the manifold table: at most "
        "1,000 after a batch while the exploration runs (5,000 while another refresh of it "
        "runs), 0 once it is finished and the table final")


class FailureReason(BaseModel):
    reason: str | None = Field(description="the tiles' last_error")
    tiles: int = Field(description="failed tiles with this reason")


class FailureSummary(BaseModel):
    tiles: int = Field(description="tiles failed (after max_attempts)")
    poses_with_errors: int = Field(
        default=0, description="poses stored with outcome `error` (their evaluation raised; "
        "GET /explorations/{id}/poses?outcome=error lists them with the message)")
    reasons: list[FailureReason] = Field(
        description="their distinct reasons, most frequent first (at most 20; the whole list "
        "is at /explorations/{id}/failures)")


class ExplorationDetail(ExplorationOut):
    progress: Progress
    failures: FailureSummary


class FailedTileOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    tile_id: int = Field(validation_alias="id")
    level: int = Field(description="0 = coarse pass")
    index: int
    n_poses: int
    attempts: int
    last_error: str | None
    updated_at: datetime


class ExplorationRetried(BaseModel):
    id: int
    status: str
    tiles_requeued: int


class ExplorationCreated(BaseModel):
    id: int
    status: str
    tiles_total: int
    poses_total: int
    group: list[int] = Field(
        default_factory=list, description="on a table: every exploration submitted, one per "
        "resting pose, most probable first (`id` is the first); empty for a free object")


class _PoseHead(PoseValues):
    model_config = ConfigDict(from_attributes=True)

    id: int
    pose_key: str
    tile_id: int | None
    outcome: str
    viable: bool
    effective_r: float | None
    contacts_per_link: dict[str, Any] | None
    signature: dict[str, Any] | None
    grasp: dict[str, Any] | None
    manifold_id: int | None
    worker_id: str | None
    eval_time_s: float
    created_at: datetime


# The measured qualities (store/pose_columns.py), in the row's order; null where the worker
# did not compute the value (see SimSettings; held poses only).
_PoseMetrics: Any = create_model(
    "_PoseMetrics", __base__=_PoseHead,
    **{c.name: (float | None, Field(default=None, description=c.description))
       for c in METRIC_COLUMNS})


class PoseOut(_PoseMetrics):  # type: ignore[misc]
    error: str | None = Field(
        default=None, description="outcome `error` only: what the evaluation of this pose "
        "raised")
    # The robust map at the finest step (manifolds/robust.py); null until the manifolds were
    # computed with this pose stored, and for poses off the lattice.
    robust_s: float | None = Field(default=None, description="robust success s_δ")
    robust_q: float | None = Field(default=None, description="robust quality q_δ")
    robust_label: str | None = Field(default=None, description="robust, fragile, futile or "
                                     "uncertain")
    certifies: str | None = Field(default=None, description="the key of the pose whose "
                                  "certification this evaluation serves")
    sample: dict[str, Any] | None = Field(
        default=None, description="a draw of a success probability, evaluated outcome only: "
        "its friction, mass and effort scales, its outcome and links in contact per engine, "
        "and the fields it leaves out (`absent`: μs is 0 there, not measured)")


class PoseFilter(BaseModel):
    """Filters of GET /explorations/{id}/poses; every range is inclusive."""

    viable: bool | None = None
    outcome: Outcome | None = None
    manifold_id: int | None = None
    mu_min: float | None = None
    mu_max: float | None = None
    theta_min: float | None = None
    theta_max: float | None = None
    phi_min: float | None = None
    phi_max: float | None = None
    r_min: float | None = None
    r_max: float | None = None

    def inverted_ranges(self) -> list[str]:
        bad = []
        for name in ("mu", "theta", "phi", "r"):
            lo, hi = getattr(self, f"{name}_min"), getattr(self, f"{name}_max")
            if lo is not None and hi is not None and lo > hi:
                bad.append(f"{name}_min ({lo}) is greater than {name}_max ({hi})")
        return bad
