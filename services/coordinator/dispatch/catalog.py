"""What a lease reply needs besides the tile: the object reference, gripper and settings.

An exploration's spec and its object never change after submission, so they are read once per
exploration and kept (the spec through the one spec cache, exploration/specs.py). The cache
key includes the exploration's creation time: SQLite may give a deleted exploration's id to a
new one, which must not inherit the old object and gripper.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from datetime import datetime

from graspscape.services.coordinator.exploration.specs import stored_spec
from graspscape.services.coordinator.objects.grippers import archive_by_hash
from graspscape.services.coordinator.store.models import ExplorationRow, GripperRow, ObjectRow
from graspscape.shared.specs.exploration import ConfigurationMatch, ExplorationSpec
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode_as, error
from graspscape.shared.wire.messages import (
    ErrorCode,
    ErrorReply,
    GripperData,
    GripperRef,
    GripperRequest,
    ObjectData,
    ObjectRef,
    ObjectRequest,
)
from sqlalchemy import bindparam, select
from sqlalchemy.orm import Session

_MAX_CACHED = 256
# Built once and run as Core (each lease reads it): building the statement and the ORM's
# execution took about a quarter of a lease's CPU.
_CREATED = select(ExplorationRow.id, ExplorationRow.created_at).where(
    ExplorationRow.id.in_(bindparam("ids", expanding=True)))


@dataclass(frozen=True)
class WorkContext:
    object: ObjectRef
    gripper: str
    settings: SimSettings
    configuration_match: ConfigurationMatch | None = None  # shortcut 2 on: its tolerance
    gripper_ref: GripperRef | None = None


def configuration_match_of(spec: ExplorationSpec) -> ConfigurationMatch | None:
    """What workers are told about shortcut 2: its tolerance, or None when it is off."""
    shortcuts = spec.shortcuts
    return shortcuts.configuration_match if shortcuts.configuration_inference else None


class WorkContexts:
    """The work context of each exploration a lease reply names, cached per exploration."""

    def __init__(self) -> None:
        self._contexts: dict[tuple[int, datetime], WorkContext] = {}
        self._lock = threading.Lock()

    def contexts(self, session: Session, exploration_ids: set[int]) -> dict[int, WorkContext]:
        """The context of each exploration (one small query, plus one per uncached one)."""
        if not exploration_ids:
            return {}
        created = dict(session.connection().execute(
            _CREATED, {"ids": sorted(exploration_ids)}).all())
        out = {}
        for exploration_id in exploration_ids:
            if exploration_id not in created:
                raise LookupError(f"exploration {exploration_id} does not exist")
            out[exploration_id] = self.context(session, exploration_id,
                                               created[exploration_id])
        return out

    def context(self, session: Session, exploration_id: int, created_at: datetime) -> WorkContext:
        key = (exploration_id, created_at)
        with self._lock:
            found = self._contexts.get(key)
        if found is not None:
            return found
        spec = stored_spec(session, exploration_id, created_at)
        obj = session.execute(
            select(
                ObjectRow.id,
                ObjectRow.name,
                ObjectRow.content_hash,
                ObjectRow.mesh_format,
                ObjectRow.properties,
            ).where(ObjectRow.id == spec.object_id)
        ).one()
        ref = ObjectRef(
            object_id=obj.id,
            name=None if obj.content_hash else obj.name,
            content_hash=obj.content_hash,
            mesh_format=obj.mesh_format,
            properties=obj.properties or {},
        )
        context = WorkContext(object=ref, gripper=spec.gripper, settings=spec.settings,
                              configuration_match=configuration_match_of(spec),
                              gripper_ref=gripper_ref(session, exploration_id, spec.gripper))
        with self._lock:
            if len(self._contexts) >= _MAX_CACHED:
                self._contexts.clear()
            self._contexts[key] = context
        return context


def gripper_ref(session: Session, exploration_id: int, gripper: str) -> GripperRef:
    """A shipped gripper by name; any other by the archive packed at submit."""
    row = session.execute(
        select(GripperRow.content_hash, GripperRow.kind)
        .join(ExplorationRow, ExplorationRow.gripper_hash == GripperRow.content_hash)
        .where(ExplorationRow.id == exploration_id)
    ).one_or_none()
    if row is None:
        return GripperRef(name=gripper)
    return GripperRef(content_hash=row.content_hash, kind=row.kind)


def mesh_by_hash(session: Session, content_hash: str) -> tuple[bytes, str] | None:
    row = session.execute(
        select(ObjectRow.mesh, ObjectRow.mesh_format)
        .where(ObjectRow.content_hash == content_hash, ObjectRow.mesh.is_not(None))
        .limit(1)
    ).one_or_none()
    if row is None or row.mesh is None or row.mesh_format is None:
        return None
    return bytes(row.mesh), row.mesh_format


def fetch_answer(session: Session, data: bytes, kind: str
                 ) -> tuple[str, ObjectData | GripperData] | ErrorReply:
    """A worker's fetch of a mesh (`kind` "object") or a gripper's archive ("gripper") by
    content hash: the reply key and message, or the refusal."""
    if kind == "object":
        request = decode_as(data, ObjectRequest)
        if isinstance(request, ErrorReply):
            return request
        found = mesh_by_hash(session, request.content_hash)
        if found is None:
            return error(ErrorCode.NOT_FOUND, f"no mesh with content hash {request.content_hash}")
        return (keys.object_key(request.content_hash),
                ObjectData.of(request.content_hash, found[1], found[0]))
    asked = decode_as(data, GripperRequest)
    if isinstance(asked, ErrorReply):
        return asked
    archive = archive_by_hash(session, asked.content_hash)
    if archive is None:
        return error(ErrorCode.NOT_FOUND, f"no gripper with content hash {asked.content_hash}")
    return (keys.gripper_key(asked.content_hash),
            GripperData.of(asked.content_hash, archive[1], archive[0]))
