"""Grippers by content hash: a gripper the coordinator packed is fetched once per worker machine.

A lease names its gripper by a GripperRef: a shipped gripper by name (loaded from this
install), any other by the hash of its archive (shared/specs/gripper_archive.py). Archives are
unpacked into <cache>/grippers/<sha256>/ as meshes are kept (workers/runtime/objects.py): a
file lock makes one process fetch while the others wait, the hash of the bytes is checked
before anything is written, and the folder appears whole or not at all (unpacked beside it,
then renamed).
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
from pathlib import Path

import zenoh
from graspscape.shared.specs.gripper_archive import (
    GripperArchiveError,
    kind_of,
    local_path,
    unpack,
    write_members,
)
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode_as, decode_reply_error, encode
from graspscape.shared.wire.messages import GripperData, GripperRef, GripperRequest
from graspscape.workers.runtime.objects import ObjectFetchError


class GripperFetchError(ObjectFetchError):
    """A gripper that could not be fetched: transient (no answer) or not (refused, corrupt)."""


class GripperCache:
    def __init__(self, session: zenoh.Session, cache_dir: Path, timeout_s: float) -> None:
        self.session = session
        self.folder = cache_dir / "grippers"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.timeout_s = timeout_s
        self.fetched = 0  # archives this process fetched over the network
        self._paths: dict[str, str] = {}  # hash -> the unpacked path, once known

    def gripper(self, ref: GripperRef | None, name: str) -> str:
        """What evaluate_pose is given: the shipped gripper's name, or the path of the
        unpacked archive. `name`: the lease's gripper string (a lease without a ref)."""
        if ref is None or ref.content_hash is None:
            return ref.name if ref is not None and ref.name else name
        path = self._paths.get(ref.content_hash)
        if path is None:
            path = self._paths[ref.content_hash] = str(self._unpacked(ref.content_hash))
        return path

    def _unpacked(self, content_hash: str) -> Path:
        folder = self.folder / content_hash
        done = folder / ".kind"  # written last: its presence means the folder is whole
        if done.is_file():
            return local_path(folder, done.read_text())  # type: ignore[arg-type]
        with open(self.folder / f"{content_hash}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if done.is_file():  # another process unpacked it while this one waited
                return local_path(folder, done.read_text())  # type: ignore[arg-type]
            try:
                archive = self._fetch(content_hash).archive()
            except ValueError as exc:  # not base64
                raise GripperFetchError(f"gripper {content_hash}: {exc}",
                                        transient=False) from exc
            if hashlib.sha256(archive).hexdigest() != content_hash:
                raise GripperFetchError(f"gripper {content_hash}: the archive fetched has "
                                        "another hash", transient=False)
            try:
                files = unpack(archive)
                kind = kind_of(files)
            except GripperArchiveError as exc:
                raise GripperFetchError(f"gripper {content_hash}: {exc}",
                                        transient=False) from exc
            tmp = self.folder / f"{content_hash}.tmp{os.getpid()}"
            shutil.rmtree(tmp, ignore_errors=True)
            write_members(files, tmp)
            (tmp / ".kind").write_text(kind)
            shutil.rmtree(folder, ignore_errors=True)  # a half folder of a crashed process
            os.replace(tmp, folder)  # atomic: readers see the whole folder or none
            self.fetched += 1
        return local_path(folder, kind)

    def _fetch(self, content_hash: str) -> GripperData:
        request = GripperRequest(content_hash=content_hash)
        for reply in self.session.get(
            keys.gripper_key(content_hash),
            payload=encode(request),
            consolidation=zenoh.ConsolidationMode.NONE,
            timeout=self.timeout_s,
        ):
            if reply.ok is not None:
                message = decode_as(reply.ok.payload.to_bytes(), GripperData)
            else:
                message = decode_reply_error(reply.err.payload.to_bytes())
            if isinstance(message, GripperData):
                return message
            raise GripperFetchError(f"gripper {content_hash}: {message.code}: "
                                    f"{message.message}", transient=message.code.retryable)
        raise GripperFetchError(f"gripper {content_hash}: no answer from the coordinator",
                                transient=True)
