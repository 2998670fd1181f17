"""Objects: create from an upload, a built-in name or a shared-folder file; list; get.

The same mesh with the same properties stored twice gives back the first object, so a client
that retries an upload does not multiply objects.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Any

from graspscape.services.coordinator.errors import InvalidInput, NotFound
from graspscape.services.coordinator.objects.mesh import (
    mesh_format,
    validate_mesh,
    validate_name,
)
from graspscape.services.coordinator.store.models import ObjectRow
from graspscape.shared.specs.objects import ObjectSpec
from pydantic import ValidationError
from sqlalchemy import func, select
from sqlalchemy.orm import Session

SHARED_PREFIX = "shared:"
_SHARED_FILE = re.compile(r"^[A-Za-z0-9_./-]{1,250}$")


def validation_message(exc: ValidationError) -> str:
    parts = []
    for err in exc.errors():
        where = ".".join(str(p) for p in err["loc"]) or "object"
        parts.append(f"{where}: {err['msg']}")
    return "; ".join(parts)


def _spec(name: str | None, mesh_path: str | None, props: dict[str, Any]) -> ObjectSpec:
    """Validate the physical properties through the shared ObjectSpec."""
    try:
        return ObjectSpec(name=name, mesh_path=mesh_path, **props)
    except ValidationError as exc:
        raise InvalidInput(validation_message(exc), loc=("body",)) from exc


def _properties(spec: ObjectSpec) -> dict[str, Any]:
    """What is stored and sent to workers: the properties that were set."""
    return spec.model_dump(mode="json", exclude={"name", "mesh_path"}, exclude_none=True)


def _existing(
    session: Session, *, kind: str, name: str, content_hash: str | None, properties: dict[str, Any]
) -> ObjectRow | None:
    candidates = session.scalars(
        select(ObjectRow).where(
            ObjectRow.kind == kind,
            ObjectRow.name == name,
            ObjectRow.content_hash.is_(None)
            if content_hash is None
            else ObjectRow.content_hash == content_hash,
        )
    ).all()
    return next((row for row in candidates if row.properties == properties), None)


def _store(
    session: Session,
    *,
    kind: str,
    name: str,
    data: bytes | None,
    fmt: str | None,
    spec: ObjectSpec,
) -> tuple[ObjectRow, bool]:
    # The one object validation (shared/specs/object_checks.py), as the workers run it.
    stored: dict[str, Any] | None = None
    if data is not None and fmt is not None:
        info, warnings = validate_mesh(data, fmt, spec, label=name)
        stored = {**info.model_dump(mode="json"), "warnings": warnings}
    else:
        warnings = validate_name(spec)
        stored = {"warnings": warnings} if warnings else None
    properties = _properties(spec)
    content_hash = hashlib.sha256(data).hexdigest() if data is not None else None
    found = _existing(
        session, kind=kind, name=name, content_hash=content_hash, properties=properties
    )
    if found is not None:
        return found, False
    row = ObjectRow(
        kind=kind,
        name=name,
        content_hash=content_hash,
        mesh_format=fmt,
        mesh=data,
        properties=properties,
        mesh_info=stored,
    )
    session.add(row)
    session.commit()
    return row, True


def create_uploaded(
    session: Session, *, filename: str | None, data: bytes, properties: dict[str, Any]
) -> tuple[ObjectRow, bool]:
    fmt = mesh_format(filename)
    spec = _spec(None, f"upload:{filename}", properties)
    return _store(
        session,
        kind="upload",
        name=Path(filename or "mesh").name,
        data=data,
        fmt=fmt,
        spec=spec,
    )


def create_named(
    session: Session, *, name: str, properties: dict[str, Any], shared_dir: Path | None
) -> tuple[ObjectRow, bool]:
    if name.startswith(SHARED_PREFIX):
        data, fmt = _read_shared(name.removeprefix(SHARED_PREFIX), shared_dir)
        spec = _spec(None, name, properties)
        return _store(session, kind="shared", name=name, data=data, fmt=fmt, spec=spec)
    spec = _spec(name, None, properties)
    return _store(session, kind="named", name=name, data=None, fmt=None, spec=spec)


def _read_shared(relative: str, shared_dir: Path | None) -> tuple[bytes, str]:
    if shared_dir is None:
        raise InvalidInput("no shared objects folder is configured (shared_objects_dir)")
    if not _SHARED_FILE.match(relative):
        raise InvalidInput(
            f"shared object name {relative!r} has characters outside [A-Za-z0-9_./-]"
        )
    root = shared_dir.resolve()
    path = (root / relative).resolve()
    if not path.is_relative_to(root):
        raise InvalidInput(f"shared object {relative!r} points outside the shared folder")
    fmt = mesh_format(path.name)
    if not path.is_file():
        raise InvalidInput(f"shared object {relative!r} does not exist in the shared folder")
    return path.read_bytes(), fmt


def get_object(session: Session, *, object_id: int) -> ObjectRow:
    row = session.get(ObjectRow, object_id)
    if row is None:
        raise NotFound(f"object {object_id} does not exist")
    return row


def list_objects(session: Session, *, limit: int, offset: int) -> tuple[list[ObjectRow], int]:
    total = session.scalar(select(func.count()).select_from(ObjectRow)) or 0
    rows = session.scalars(select(ObjectRow).order_by(ObjectRow.id).limit(limit).offset(offset))
    return list(rows), total
