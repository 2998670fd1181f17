"""What a lease reply needs besides the tile: the object reference, gripper and settings.

An exploration's spec and its object never change after submission, so they are read once per
exploration and kept (a lease reply then costs no extra query).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

from graspscape.services.coordinator.store.models import ExplorationRow, ObjectRow
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.sim import SimSettings
from graspscape.shared.wire.messages import ObjectRef
from sqlalchemy import select
from sqlalchemy.orm import Session

_MAX_CACHED = 256


@dataclass(frozen=True)
class WorkContext:
    object: ObjectRef
    gripper: str
    settings: SimSettings


class Catalog:
    def __init__(self) -> None:
        self._contexts: dict[int, WorkContext] = {}
        self._lock = threading.Lock()

    def context(self, session: Session, exploration_id: int) -> WorkContext:
        with self._lock:
            found = self._contexts.get(exploration_id)
        if found is not None:
            return found
        spec_json = session.scalar(
            select(ExplorationRow.spec).where(ExplorationRow.id == exploration_id)
        )
        if spec_json is None:
            raise LookupError(f"exploration {exploration_id} does not exist")
        spec = ExplorationSpec.model_validate(spec_json)
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
        context = WorkContext(object=ref, gripper=spec.gripper, settings=spec.settings)
        with self._lock:
            if len(self._contexts) >= _MAX_CACHED:
                self._contexts.clear()
            self._contexts[exploration_id] = context
        return context


def mesh_by_hash(session: Session, content_hash: str) -> tuple[bytes, str] | None:
    row = session.execute(
        select(ObjectRow.mesh, ObjectRow.mesh_format)
        .where(ObjectRow.content_hash == content_hash, ObjectRow.mesh.is_not(None))
        .limit(1)
    ).one_or_none()
    if row is None or row.mesh is None or row.mesh_format is None:
        return None
    return bytes(row.mesh), row.mesh_format
