"""The coordinator's tables. The schema itself is made only by the Alembic migrations.

The coordinator is the only process that writes here. Counters on `explorations` (poses_done,
viable_count) are kept by the ingest in the same transaction as the rows they count, so that
progress is one row read instead of a scan over millions of poses.
"""

from __future__ import annotations

from datetime import datetime
from enum import StrEnum
from typing import Any

from graspscape.services.coordinator.store.base import Base, utcnow
from graspscape.services.coordinator.store.pose_columns import (  # noqa: F401 (re-exported)
    GRASP_METRIC_COLUMNS,
    METRIC_COLUMNS,
    POSE_METRIC_COLUMNS,
    ROBUSTNESS_COLUMNS,
)
from sqlalchemy import (
    JSON,
    Boolean,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    String,
    Text,
    UniqueConstraint,
    false,
    text,
)
from sqlalchemy.orm import Mapped, mapped_column


class ExplorationStatus(StrEnum):
    QUEUED = "queued"  # no tile leased yet
    RUNNING = "running"
    DONE = "done"  # every tile done: every planned pose stored
    # No tile open any more, but some failed (tiles.last_error says why): some poses stored
    # (incomplete) or none at all (failed). POST /explorations/{id}/retry queues them again.
    INCOMPLETE = "incomplete"
    FAILED = "failed"
    CANCELLED = "cancelled"


# Statuses in which nothing more happens by itself (a retry or an adaptive step may reopen
# an incomplete or failed one).
FINISHED_STATUSES = (
    ExplorationStatus.DONE,
    ExplorationStatus.INCOMPLETE,
    ExplorationStatus.FAILED,
    ExplorationStatus.CANCELLED,
)


class TileState(StrEnum):
    QUEUED = "queued"
    LEASED = "leased"
    DONE = "done"
    FAILED = "failed"  # failed max_attempts times; last_error says why
    CANCELLED = "cancelled"  # its exploration was cancelled before it finished


TERMINAL_TILE_STATES = (TileState.DONE, TileState.FAILED, TileState.CANCELLED)


class ObjectRow(Base):
    __tablename__ = "objects"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    kind: Mapped[str] = mapped_column(String(16))  # "named" | "upload" | "shared"
    name: Mapped[str] = mapped_column(String(255))
    content_hash: Mapped[str | None] = mapped_column(String(64), index=True)
    mesh_format: Mapped[str | None] = mapped_column(String(8))
    # Meshes are small (≤ max_upload_bytes) and must survive with the database, so they live
    # in it rather than in a folder that a backup could miss.
    mesh: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    properties: Mapped[dict[str, Any]] = mapped_column(JSON)
    mesh_info: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class GripperRow(Base):
    """A gripper's archive (shared/specs/gripper_archive.py) by its content hash: packed at
    submit from the coordinator's files, or uploaded (POST /grippers). Kept in the database
    beside the meshes, for the same reason."""

    __tablename__ = "grippers"

    content_hash: Mapped[str] = mapped_column(String(64), primary_key=True)
    kind: Mapped[str] = mapped_column(String(8))  # "toml" | "urdf"
    name: Mapped[str] = mapped_column(String(255))  # the gripper's own name, for people
    archive: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class ExplorationRow(Base):
    __tablename__ = "explorations"
    # SQLite: never reuse the id of a deleted exploration (migration 0006); PostgreSQL's
    # sequences never do.
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    object_id: Mapped[int] = mapped_column(ForeignKey("objects.id"), index=True)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)
    status: Mapped[str] = mapped_column(String(16), default=ExplorationStatus.QUEUED, index=True)
    tiles_total: Mapped[int] = mapped_column(Integer, default=0)
    poses_total: Mapped[int] = mapped_column(Integer, default=0)
    poses_done: Mapped[int] = mapped_column(Integer, default=0)
    viable_count: Mapped[int] = mapped_column(Integer, default=0)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column()
    finished_at: Mapped[datetime | None] = mapped_column()
    # When the stored manifolds were last computed (manifolds/service.py): poses_done then
    # (null: never), and whether it was the final refresh of the finished exploration.
    manifolds_poses_done: Mapped[int | None] = mapped_column(Integer)
    manifolds_final: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())
    # The keeper's lease (manifolds/keeper.py): the process that keeps the table while the
    # exploration runs, and until when; null: none.
    manifolds_keeper: Mapped[str | None] = mapped_column(String(32))
    manifolds_keeper_until: Mapped[datetime | None] = mapped_column()
    # On a table (support 'plane', migration 0017): the group of explorations of one
    # submission, one per resting pose (the id of its first), and this one's resting pose's
    # rank and probability (the pose itself: spec.support.resting). Null: a free object.
    support_group: Mapped[int | None] = mapped_column(Integer, index=True)
    resting_index: Mapped[int | None] = mapped_column(Integer)
    resting_probability: Mapped[float | None] = mapped_column(Float)
    # The archive workers fetch the gripper by (grippers.content_hash); null: a shipped
    # gripper, which every worker has.
    gripper_hash: Mapped[str | None] = mapped_column(String(64))


class TileRow(Base):
    __tablename__ = "tiles"
    __table_args__ = (
        UniqueConstraint("exploration_id", "round", "level", "index"),
        Index("ix_tiles_state_lease_expires_at", "state", "lease_expires_at"),
        # Leasing reads queued tiles in this order; the index makes it a range scan instead of
        # a sort of every queued tile on each lease.
        Index("ix_tiles_queue_order", "state", "exploration_id", "round", "level", "id"),
        Index("ix_tiles_exploration_id_state", "exploration_id", "state"),
        # Tile ids travel on the wire: a deleted tile's id must never name another tile.
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    exploration_id: Mapped[int] = mapped_column(ForeignKey("explorations.id", ondelete="CASCADE"))
    # The strategy's round of work that planned the tile: 0 for the first pass and all that
    # refines it, k ≥ 1 for the k-th later round (adaptive: local search round k; random: its
    # slice k + 1). Tiles are leased by round, then level, then id.
    round: Mapped[int] = mapped_column(Integer, default=0, server_default="0")
    level: Mapped[int] = mapped_column(Integer, default=0)  # lattice level; 0 = coarse pass
    index: Mapped[int] = mapped_column(Integer)
    cells: Mapped[list[Any]] = mapped_column(JSON)  # [[θ, φ], ...]
    r_levels: Mapped[list[Any]] = mapped_column(JSON)
    attitudes: Mapped[list[Any]] = mapped_column(JSON)  # [[roll, pitch, yaw], ...]
    n_poses: Mapped[int] = mapped_column(Integer)
    state: Mapped[str] = mapped_column(String(16), default=TileState.QUEUED)
    lease_owner: Mapped[str | None] = mapped_column(String(128))
    lease_expires_at: Mapped[datetime | None] = mapped_column()
    # Bumped on every lease; results carry the epoch they were leased under, and ingest takes
    # them only under the tile's current epoch (and from lease_owner while it is leased), so
    # a late report from a lease that was given to another worker is refused.
    lease_epoch: Mapped[int] = mapped_column(Integer, default=0)
    # The worker the lease of `lease_epoch` went to, kept after the lease ends (lease_owner
    # is cleared): a late batch under that epoch is taken only from it (migration 0016).
    lease_holder: Mapped[str | None] = mapped_column(String(128))
    # A tile of a success probability's draws (migration 0017): the engines each draw runs in
    # and each pose's friction, mass and effort scales (wire TileSample); its poses are
    # evaluated outcome only. `needs_engines`: those engines sorted and comma-joined, which a
    # lease compares with the sets of engines the asking worker runs. NULL for other tiles.
    sample: Mapped[dict[str, Any] | None] = mapped_column(JSON(none_as_null=True), nullable=True)
    needs_engines: Mapped[str | None] = mapped_column(String(64), nullable=True)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    last_error: Mapped[str | None] = mapped_column(Text)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow)
    done_at: Mapped[datetime | None] = mapped_column()


class MapPictureRow(Base):
    """An exploration's default map picture (PNG, as `GET …/map.png` draws it), rendered when
    its manifold table was last refreshed to final (maps/stored.py, migration 0014), so that the
    first read of a finished map, in any process, is a row read and not a render. `version`:
    the map version it was drawn at (maps/stored.version_text); a picture of an older version
    is never served."""

    __tablename__ = "map_pictures"

    exploration_id: Mapped[int] = mapped_column(
        ForeignKey("explorations.id", ondelete="CASCADE"), primary_key=True)
    version: Mapped[str] = mapped_column(String(200))
    png: Mapped[bytes] = mapped_column(LargeBinary)
    manifolds: Mapped[int] = mapped_column(Integer)
    poses: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    # The map's points at `version`, packed (maps/points.points_bytes; migration 0015): a
    # process that has not read this version loads them instead of reading every pose.
    points: Mapped[bytes | None] = mapped_column(LargeBinary, nullable=True, deferred=True)


class ManifoldRow(Base):
    """A behavioral manifold: poses that lead to the same grasp type (filled by clustering)."""

    __tablename__ = "manifolds"
    __table_args__ = (UniqueConstraint("exploration_id", "label"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    exploration_id: Mapped[int] = mapped_column(ForeignKey("explorations.id", ondelete="CASCADE"))
    label: Mapped[int] = mapped_column(Integer)
    signature: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    size: Mapped[int] = mapped_column(Integer, default=0)
    best_pose_key: Mapped[str | None] = mapped_column(String(128))
    best_mu_s: Mapped[float | None] = mapped_column(Float)
    # Description, volume, μs statistics, local maxima (services/coordinator/manifolds).
    summary: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    # The robust map (manifolds/robust.py, migration 0010): volume of the robust core, the
    # member with the best robust quality q_δ, and whether the manifold is large (≥ 1 % of the
    # viable volume; the rest is dust, shown as one entry of the table).
    core_volume_cm3: Mapped[float | None] = mapped_column(Float)
    robust_best_key: Mapped[str | None] = mapped_column(String(128))
    robust_best_q: Mapped[float | None] = mapped_column(Float)
    large: Mapped[bool] = mapped_column(Boolean, default=False, server_default=false())
    # The summary's volume (migration 0012), so that /manifolds writes the dust line from
    # columns and copies the summaries' stored text without decoding it.
    volume_cm3: Mapped[float | None] = mapped_column(Float)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class PosePlanRow(Base):
    """A pose the adaptive exploration decided to evaluate beyond the coarse pass.

    The unique key makes "never evaluate the same pose twice" hold across concurrent ingests:
    a pose is put in a tile only by the transaction whose insert here succeeded.
    """

    __tablename__ = "pose_plans"
    __table_args__ = (UniqueConstraint("exploration_id", "pose_key"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    exploration_id: Mapped[int] = mapped_column(ForeignKey("explorations.id", ondelete="CASCADE"))
    pose_key: Mapped[str] = mapped_column(String(128))
    level: Mapped[int] = mapped_column(Integer)
    reason: Mapped[str] = mapped_column(String(16))  # refine | normal | search
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class PoseRow(Base):
    __tablename__ = "poses"
    __table_args__ = (
        # One row per pose of an exploration: the ingest's ON CONFLICT target.
        UniqueConstraint("exploration_id", "pose_key"),
        # Keyset pages of /poses (by id), alone or with the viable or manifold filter
        # (migration 0011; /best's indexes follow the class).
        Index("ix_poses_exploration_id_id", "exploration_id", "id"),
        Index("ix_poses_exploration_id_viable_id", "exploration_id", "viable", "id"),
        Index("ix_poses_exploration_id_manifold_id_id", "exploration_id", "manifold_id", "id"),
        Index("ix_poses_exploration_id_created_at", "exploration_id", "created_at"),
        # /best's certification evidence: the few poses evaluated for another's certification.
        Index("ix_poses_exploration_id_certifies", "exploration_id", "certifies",
              sqlite_where=text("certifies IS NOT NULL"),
              postgresql_where=text("certifies IS NOT NULL")),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    exploration_id: Mapped[int] = mapped_column(ForeignKey("explorations.id", ondelete="CASCADE"))
    tile_id: Mapped[int | None] = mapped_column(ForeignKey("tiles.id", ondelete="SET NULL"))
    pose_key: Mapped[str] = mapped_column(String(128))
    theta: Mapped[float] = mapped_column(Float)
    phi: Mapped[float] = mapped_column(Float)
    r: Mapped[float] = mapped_column(Float)
    roll: Mapped[float] = mapped_column(Float)
    pitch: Mapped[float] = mapped_column(Float)
    yaw: Mapped[float] = mapped_column(Float)
    outcome: Mapped[str] = mapped_column(String(16))
    viable: Mapped[bool] = mapped_column(Boolean)
    mu_s: Mapped[float] = mapped_column(Float)
    effective_r: Mapped[float | None] = mapped_column(Float)
    effort_max_nm: Mapped[float] = mapped_column(Float)
    contacts_per_link: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    signature: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    grasp: Mapped[dict[str, Any] | None] = mapped_column(JSON)
    manifold_id: Mapped[int | None] = mapped_column(ForeignKey("manifolds.id", ondelete="SET NULL"))
    worker_id: Mapped[str | None] = mapped_column(String(128))
    eval_time_s: Mapped[float] = mapped_column(Float)
    # Shortcut 2: the pose whose outcome, μs and effort this one reuses (same tile and normal).
    inferred_from: Mapped[str | None] = mapped_column(String(128))
    # Outcome `error` only: what the evaluation of this pose raised (PoseResult.error).
    error: Mapped[str | None] = mapped_column(String(2000))
    # The measured qualities, one nullable float column each, defined in
    # store/pose_columns.py (static grasp metrics of the synthesized grasp, its robustness
    # margins and grasp tests): NULL where the worker did not compute them (not chosen in
    # SimSettings, or the pose was not held). Made here from that tuple, in its order.
    for _metric in METRIC_COLUMNS:
        locals()[_metric.name] = mapped_column(Float)
    del _metric
    # The robust map (manifolds/robust.py, migration 0010), kept current with the manifolds:
    # robust success s_δ, robust quality q_δ and the label (robust, fragile, futile,
    # uncertain); NULL until the manifolds are computed with the pose stored.
    robust_s: Mapped[float | None] = mapped_column(Float)
    robust_q: Mapped[float | None] = mapped_column(Float)
    robust_label: Mapped[str | None] = mapped_column(String(16))
    # The key of the pose whose certification this evaluation serves (a jittered or extra
    # evaluation of its neighbourhood); NULL for every other pose.
    certifies: Mapped[str | None] = mapped_column(String(128))
    # A draw's record (PoseResult.sample, migration 0017): its scales, outcome and links in
    # contact per engine, and the fields an outcome-only evaluation leaves out (μs stored as 0
    # there is no μs). NULL for every evaluation that is not a draw.
    sample: Mapped[dict[str, Any] | None] = mapped_column(JSON(none_as_null=True), nullable=True)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


# /best reads one of these in its answer's order and stops at `limit` (store/queries.py): by
# the robust ranking (its default, overall and in one manifold), the torque margin ratio
# (rank=point) and μs (migration 0011).
Index("ix_poses_best_robust", PoseRow.exploration_id, PoseRow.viable, PoseRow.robust_label,
      PoseRow.robust_q.desc(), PoseRow.mu_s.desc(), PoseRow.pose_key)
Index("ix_poses_manifold_best_robust", PoseRow.manifold_id, PoseRow.viable,
      PoseRow.robust_label, PoseRow.robust_q.desc(), PoseRow.mu_s.desc(), PoseRow.pose_key)
Index("ix_poses_best_torque_margin_ratio", PoseRow.exploration_id, PoseRow.viable,
      PoseRow.torque_margin_ratio.desc(), PoseRow.mu_s.desc(), PoseRow.pose_key)
Index("ix_poses_best_mu_s", PoseRow.exploration_id, PoseRow.viable, PoseRow.mu_s.desc(),
      PoseRow.pose_key)


class WorkerRow(Base):
    __tablename__ = "workers"

    id: Mapped[str] = mapped_column(String(128), primary_key=True)
    host: Mapped[str] = mapped_column(String(255))
    capacity: Mapped[int] = mapped_column(Integer)
    # SHA-256 of the session key of the process that registered the id: requests under the
    # id with another key are refused (dispatch/sessions.py, migration 0016).
    session_hash: Mapped[str | None] = mapped_column(String(64))
    first_seen: Mapped[datetime] = mapped_column(default=utcnow)
    last_seen: Mapped[datetime] = mapped_column(default=utcnow)
