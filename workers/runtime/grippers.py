"""Grippers by content hash: a gripper the coordinator packed is fetched once per worker machine.

A lease names its gripper by a GripperRef: a shipped gripper by name (loaded from this
install), any other by the hash of its archive (shared/specs/gripper_archive.py). Archives are
unpacked into <cache>/grippers/<sha256>/ as meshes are kept (content_cache.py): one process
fetches while the others wait, the hash of the bytes is checked before anything is written,
and the folder appears whole or not at all (unpacked beside it, then renamed).
"""

from __future__ import annotations

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
from graspscape.shared.wire.messages import GripperData, GripperRef, GripperRequest
from graspscape.workers.runtime.content_cache import fetch_reply, fill_once
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
        if fill_once(folder, content_hash, whole=done.is_file,
                     fetch=lambda: self._archive(content_hash),
                     write=lambda archive, tmp: self._unpack(content_hash, archive, tmp),
                     error=GripperFetchError, what=f"gripper {content_hash}"):
            self.fetched += 1
        return local_path(folder, done.read_text())  # type: ignore[arg-type]

    @staticmethod
    def _unpack(content_hash: str, archive: bytes, tmp: Path) -> None:
        try:
            files = unpack(archive)
            kind = kind_of(files)
        except GripperArchiveError as exc:
            raise GripperFetchError(f"gripper {content_hash}: {exc}",
                                    transient=False) from exc
        shutil.rmtree(tmp, ignore_errors=True)
        write_members(files, tmp)
        (tmp / ".kind").write_text(kind)

    def _archive(self, content_hash: str) -> bytes:
        message = fetch_reply(self.session, keys.gripper_key(content_hash),
                              GripperRequest(content_hash=content_hash), GripperData,
                              timeout_s=self.timeout_s, error=GripperFetchError,
                              what=f"gripper {content_hash}")
        try:
            return message.archive()
        except ValueError as exc:  # not base64
            raise GripperFetchError(f"gripper {content_hash}: {exc}", transient=False) from exc
