"""The messages of the dispatch protocol: versioned, validated pydantic models.

Every message carries the protocol version `v` and a `kind` tag; `decode` picks the model by
the tag. A field added later gets a default so that version 1 peers keep understanding each
other; a change in meaning bumps WIRE_VERSION, and a peer refuses versions it does not know
with an error reply instead of guessing.
"""

from __future__ import annotations

import base64
from datetime import datetime
from enum import StrEnum
from typing import Annotated, Any, Literal

from graspscape.shared.specs.exploration import ConfigurationMatch
from graspscape.shared.specs.gripper_archive import MAX_ARCHIVE_BYTES
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose, tile_poses
from graspscape.shared.specs.results import DrawScales, PoseResult
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire.keys import WORKER_ID_PATTERN
from pydantic import BaseModel, ConfigDict, Field

WIRE_VERSION = 1

# Ids, epochs and counts are the store's 32-bit integers: anything beyond is refused as
# malformed when the message is decoded, instead of failing in the database driver.
INT32_MAX = 2**31 - 1
Id = Annotated[int, Field(ge=1, le=INT32_MAX)]
Count = Annotated[int, Field(ge=0, le=INT32_MAX)]
# A worker process's session key: a random secret it makes at start and sends with every
# lease request and batch. The coordinator binds the worker id to the first key it sees
# (store/workers.py), so another session cannot borrow the id without knowing the key.
SessionKey = Annotated[str, Field(pattern=r"^[0-9a-f]{32,64}$")]
EngineLabel = Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]{0,31}$")]


class _Message(BaseModel):
    # Unknown fields are ignored, not refused: a newer peer may add optional fields. NaN and
    # ±∞ are refused (JSON's `NaN` token included): no number of the protocol may be one.
    model_config = ConfigDict(frozen=True, extra="ignore", allow_inf_nan=False)

    v: Literal[1] = WIRE_VERSION


class LeaseRequest(_Message):
    """A worker process asks for up to `capacity` tiles."""

    kind: Literal["lease_request"] = "lease_request"
    worker_id: str = Field(pattern=WORKER_ID_PATTERN)
    session_key: SessionKey
    host: str = Field(default="", max_length=255)
    capacity: int = Field(ge=1, le=64, description="tiles it can take now")
    # Tiles the worker still works on. Any other tile leased to this worker id was lost on
    # the way (a lease reply that never arrived) and goes back to the queue at once.
    holding: list[Id] = Field(default_factory=list, max_length=64)
    # The physics engines it runs (SimSettings.engine); it is leased tiles of those only. A
    # worker that does not say runs pybullet alone, as every worker did before MuJoCo. Any
    # name is accepted: one this coordinator does not know simply matches no exploration.
    engines: list[EngineLabel] = Field(default_factory=lambda: ["pybullet"], min_length=1,
                                       max_length=8)


class ObjectRef(BaseModel):
    """What a worker needs to build the object: a name, or a mesh fetched by content hash."""

    model_config = ConfigDict(frozen=True)

    object_id: Id
    name: str | None = None
    content_hash: str | None = Field(default=None, pattern=r"^[0-9a-f]{64}$")
    mesh_format: str | None = Field(default=None, pattern=r"^[a-z0-9]{1,8}$")
    properties: dict[str, Any] = Field(default_factory=dict)

    def spec(self, mesh_path: str | None = None) -> ObjectSpec:
        """The ObjectSpec to simulate; mesh objects need the path of the cached mesh file."""
        if self.content_hash is not None:
            if mesh_path is None:
                raise ValueError(f"object {self.object_id} needs its mesh fetched first")
            return ObjectSpec(mesh_path=mesh_path, **self.properties)
        return ObjectSpec(name=self.name, **self.properties)


ContentHash = Annotated[str, Field(pattern=r"^[0-9a-f]{64}$")]


class GripperRef(BaseModel):
    """What a worker needs to load the gripper: a shipped gripper's name (every worker has
    those), or the content hash and kind of the archive the coordinator packed at submit."""

    model_config = ConfigDict(frozen=True)

    name: str | None = Field(default=None, max_length=1024)
    content_hash: ContentHash | None = None
    kind: Literal["toml", "urdf"] | None = None
class TileSample(BaseModel):
    """A tile of a success probability's draws: its poses are evaluated outcome only, in each
    of `engines`, each under its scales (by pose key; a pose not listed: no scale)."""

    model_config = ConfigDict(frozen=True, allow_inf_nan=False)

    engines: list[EngineLabel] = Field(min_length=1, max_length=4)
    scales: dict[str, DrawScales] = Field(default_factory=dict)


class LeasedTile(BaseModel):
    """One tile as leased: the poses to evaluate (cells × r levels × attitudes) and the lease
    to report under. The store's lease returns it (store/tiles.py) and the wire message
    `TileLease` extends it, so the two cannot drift apart."""

    model_config = ConfigDict(frozen=True, allow_inf_nan=False)

    tile_id: Id
    exploration_id: Id
    level: Count
    index: Count
    lease_epoch: Count
    lease_expires_at: datetime
    cells: list[tuple[float, float]]
    r_levels: list[float]
    attitudes: list[tuple[float, float, float]]
    sample: TileSample | None = Field(
        default=None, description="a tile of draws: evaluated outcome only (TileSample)")

    def poses(self) -> list[Pose]:
        return tile_poses(self.cells, self.r_levels, self.attitudes)


class TileLease(_Message, LeasedTile):
    """One leased tile with everything needed to evaluate it (one reply per tile)."""

    kind: Literal["tile_lease"] = "tile_lease"
    object: ObjectRef
    gripper: str  # the spec's gripper string, as submitted
    # Added with a default: with a content hash, the gripper is fetched by it (a worker of
    # before that resolves `gripper` itself, as it always did).
    gripper_ref: GripperRef | None = None
    settings: SimSettings
    configuration_match: ConfigurationMatch | None = Field(
        default=None, description="shortcut 2 (see workers/sim/configuration_inference.py): "
        "its tolerance when the exploration asks for it")

    @classmethod
    def of(cls, tile: LeasedTile, *, object: ObjectRef, gripper: str, settings: SimSettings,
           configuration_match: ConfigurationMatch | None = None,
           gripper_ref: GripperRef | None = None) -> TileLease:
        """The lease message of a tile the store leased."""
        return cls(**dict(tile), object=object, gripper=gripper, settings=settings,
                   configuration_match=configuration_match, gripper_ref=gripper_ref)


class ResultBatch(_Message):
    """The results of one tile, reported under the lease epoch they were computed for.

    `final`: every pose of the tile is in it. Otherwise the worker stopped early: `release`
    hands the rest back to the queue (shutdown), `error` reports a failure (counts as an
    attempt).
    """

    kind: Literal["result_batch"] = "result_batch"
    worker_id: str = Field(pattern=WORKER_ID_PATTERN)
    session_key: SessionKey
    tile_id: Id
    lease_epoch: Count
    results: list[PoseResult]
    final: bool = True
    release: bool = False
    error: str | None = Field(default=None, max_length=4000)


class BatchHeader(BaseModel):
    """Who sent a result batch, for what lease: read alone from a batch that is refused as a
    whole (a result fails validation), so that the refusal counts as an attempt of the tile
    when its sender holds the lease (codec.batch_header)."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    kind: Literal["result_batch"]
    worker_id: str = Field(pattern=WORKER_ID_PATTERN)
    session_key: SessionKey
    tile_id: Id
    lease_epoch: Count

    @classmethod
    def of(cls, batch: ResultBatch) -> BatchHeader:
        return cls(kind=batch.kind, worker_id=batch.worker_id, session_key=batch.session_key,
                   tile_id=batch.tile_id, lease_epoch=batch.lease_epoch)


class Ack(_Message):
    """The coordinator committed a batch (or found it already committed).

    `missing`: the batch was `final` but these poses of the tile (keys) are still not stored,
    so the tile stays with its lease holder, unfinished; the worker evaluates and sends them
    (added with a default: version-1 peers of either age understand each other).
    """

    kind: Literal["ack"] = "ack"
    tile_id: Id
    lease_epoch: Count
    inserted: Count
    duplicates: Count
    tile_state: str
    missing: list[str] = Field(default_factory=list)


class ObjectRequest(_Message):
    kind: Literal["object_request"] = "object_request"
    content_hash: str = Field(pattern=r"^[0-9a-f]{64}$")


class ObjectData(_Message):
    kind: Literal["object_data"] = "object_data"
    content_hash: str = Field(pattern=r"^[0-9a-f]{64}$")
    mesh_format: str = Field(pattern=r"^[a-z0-9]{1,8}$")
    mesh_b64: str = Field(description="the mesh file, base64")

    @classmethod
    def of(cls, content_hash: str, mesh_format: str, mesh: bytes) -> ObjectData:
        return cls(content_hash=content_hash, mesh_format=mesh_format,
                   mesh_b64=base64.b64encode(mesh).decode())

    def mesh(self) -> bytes:
        return base64.b64decode(self.mesh_b64, validate=True)


class GripperRequest(_Message):
    kind: Literal["gripper_request"] = "gripper_request"
    content_hash: ContentHash


class GripperData(_Message):
    """A gripper's archive (shared/specs/gripper_archive.py), base64: at most
    MAX_ARCHIVE_BYTES once decoded."""

    kind: Literal["gripper_data"] = "gripper_data"
    content_hash: ContentHash
    gripper_kind: Literal["toml", "urdf"]
    archive_b64: str = Field(max_length=4 * (MAX_ARCHIVE_BYTES // 3 + 1))

    @classmethod
    def of(cls, content_hash: str, kind: str, archive: bytes) -> GripperData:
        return cls(content_hash=content_hash, gripper_kind=kind,
                   archive_b64=base64.b64encode(archive).decode())

    def archive(self) -> bytes:
        return base64.b64decode(self.archive_b64, validate=True)


class ErrorCode(StrEnum):
    MALFORMED = "malformed"  # not JSON, or fields fail validation
    UNSUPPORTED_VERSION = "unsupported_version"
    UNKNOWN_KIND = "unknown_kind"
    UNEXPECTED_KIND = "unexpected_kind"  # a valid message sent to the wrong key
    INVALID = "invalid"  # well formed but refused by the store (e.g. a pose key mismatch)
    # A result batch that is not from the tile's latest lease (another worker's lease, or
    # an older epoch): refused whole; final for that lease, the tile is someone else's now.
    NOT_LEASE_HOLDER = "not_lease_holder"
    # A lease request or batch under a worker id that another session registered (its
    # session key differs): refused, nothing leased, released or stored.
    WORKER_ID_TAKEN = "worker_id_taken"
    NOT_FOUND = "not_found"
    UNAVAILABLE = "unavailable"  # the coordinator could not serve it now; retry
    INTERNAL = "internal"

    @property
    def retryable(self) -> bool:
        return self in (ErrorCode.UNAVAILABLE, ErrorCode.INTERNAL)


class ErrorReply(_Message):
    kind: Literal["error"] = "error"
    code: ErrorCode
    message: str = Field(max_length=4000)


Message = Annotated[
    LeaseRequest | TileLease | ResultBatch | Ack | ObjectRequest | ObjectData | GripperRequest
    | GripperData | ErrorReply,
    Field(discriminator="kind"),
]
