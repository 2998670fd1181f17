"""Grippers the workers fetch: archives stored by content hash, packed at submit or uploaded.

A spec's gripper that is one of the shipped ones travels by name (every worker has those).
Any other (a name from the coordinator's GRASPSCAPE_GRIPPER_PATH, an absolute path, or a
`sha256:` name of an upload) is packed here once into a deterministic archive
(shared/specs/gripper_archive.py) and its hash recorded on the exploration, so that workers
on other machines load exactly the files the coordinator saw.
"""

from __future__ import annotations

import hashlib
import tempfile
from pathlib import Path, PurePosixPath

from graspscape.services.coordinator.errors import InvalidInput
from graspscape.services.coordinator.store.models import GripperRow
from graspscape.shared.specs.gripper import (
    STORED_GRIPPER,
    STORED_PREFIX,
    URDF_DESCRIPTION,
    find_gripper,
    is_shipped,
    load_gripper,
)
from graspscape.shared.specs.gripper_archive import (
    TOML_MEMBER,
    GripperArchiveError,
    GripperKind,
    archive_of,
    archive_of_name,
    local_path,
    unpack,
    write_members,
)
from sqlalchemy import select
from sqlalchemy.orm import Session


def _loc() -> tuple[str, ...]:
    return ("body", "gripper")


def _store(session: Session, kind: GripperKind, archive: bytes, name: str) -> GripperRow:
    content_hash = hashlib.sha256(archive).hexdigest()
    row = session.get(GripperRow, content_hash)
    if row is None:
        row = GripperRow(content_hash=content_hash, kind=kind, name=name[:255],
                         archive=archive)
        session.add(row)
        session.flush()
    return row


def gripper_hash_for(session: Session, gripper: str) -> str | None:
    """The archive hash the exploration's workers fetch its gripper by; None for a shipped
    gripper. Stores the archive (in the caller's transaction). InvalidInput when the gripper
    names nothing usable, or an upload this coordinator does not hold."""
    if STORED_GRIPPER.match(gripper):
        content_hash = gripper.removeprefix(STORED_PREFIX)
        if session.get(GripperRow, content_hash) is None:
            raise InvalidInput(f"no gripper {gripper} is stored here; upload it with "
                               "POST /grippers first", loc=_loc())
        return content_hash
    found = find_gripper(gripper)
    bare = not PurePosixPath(gripper).suffix and len(PurePosixPath(gripper).parts) == 1
    if found is not None and bare and is_shipped(found):
        return None  # a name every worker resolves the same; a path may not exist there
    try:
        kind, archive = archive_of_name(gripper)
    except ValueError as exc:
        raise InvalidInput(str(exc), loc=_loc()) from exc
    return _store(session, kind, archive, load_gripper(gripper).name).content_hash


def store_upload(session: Session, *, filename: str | None, data: bytes) -> tuple[GripperRow,
                                                                                bool]:
    """An uploaded gripper: a TOML spec file, or a zip of a URDF gripper's folder (its
    gripper.toml at the top, or inside one folder). Checked as a submit would check it, then
    stored under the hash of its repacked archive, so the same files give the same name
    however they were zipped. (row, created)."""
    suffix = PurePosixPath(filename or "").suffix.lower()
    if suffix == ".toml":
        files = {TOML_MEMBER: data}
    elif suffix == ".zip":
        try:
            files = _top(unpack(data))
        except GripperArchiveError as exc:
            raise InvalidInput(f"{filename}: {exc}", loc=("body", "file")) from exc
        if URDF_DESCRIPTION not in files:
            raise InvalidInput(f"{filename}: no {URDF_DESCRIPTION} at the top of the zip; zip "
                               "the URDF gripper's folder (docs/howto/add-gripper.md)",
                               loc=("body", "file"))
    else:
        raise InvalidInput(f"{filename!r}: upload a gripper's TOML spec (.toml) or a zip of a "
                           "URDF gripper's folder (.zip)", loc=("body", "file"))
    with tempfile.TemporaryDirectory(prefix="graspscape-gripper-") as tmp:
        kind = "toml" if suffix == ".toml" else "urdf"
        try:
            write_members(files, Path(tmp))
            path = local_path(Path(tmp), kind)
            kind, archive = archive_of(path)
            name = load_gripper(str(path)).name
        except (ValueError, OSError) as exc:  # pydantic's and the archive's errors included
            raise InvalidInput(f"{filename}: {' '.join(str(exc).split())}",
                               loc=("body", "file")) from exc
    created = session.get(GripperRow, hashlib.sha256(archive).hexdigest()) is None
    row = _store(session, kind, archive, name)
    session.commit()
    return row, created


def _top(files: dict[str, bytes]) -> dict[str, bytes]:
    """A zip of the folder itself (`hand/gripper.toml`, ...) is taken as its contents."""
    tops = {name.split("/", 1)[0] for name in files}
    if len(tops) == 1 and all("/" in name for name in files):
        head = tops.pop() + "/"
        return {name.removeprefix(head): body for name, body in files.items()}
    return files


def archive_by_hash(session: Session, content_hash: str) -> tuple[bytes, str] | None:
    row = session.execute(
        select(GripperRow.archive, GripperRow.kind).where(GripperRow.content_hash == content_hash)
    ).one_or_none()
    return None if row is None else (bytes(row.archive), row.kind)
