"""Objects by content hash: the mesh is fetched from the coordinator once per worker machine.

Meshes live in <cache>/meshes/<sha256>.<format>. The processes of a worker share the folder;
one of them fetches while the others wait and then read the file, and the hash of the bytes is
checked before the file is kept, so a cache file is always the right mesh (content_cache.py).
"""

from __future__ import annotations

from pathlib import Path

import zenoh
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.wire import keys
from graspscape.shared.wire.messages import ObjectData, ObjectRef, ObjectRequest
from graspscape.workers.runtime.content_cache import FetchError, fetch_reply, fill_once


class ObjectFetchError(FetchError):
    """A mesh (or a gripper: GripperFetchError) that could not be fetched: transient (no
    answer, retry later) or not (a refusal, bad content)."""


class ObjectCache:
    def __init__(self, session: zenoh.Session, cache_dir: Path, timeout_s: float) -> None:
        self.session = session
        self.folder = cache_dir / "meshes"
        self.folder.mkdir(parents=True, exist_ok=True)
        self.timeout_s = timeout_s
        self.fetched = 0  # meshes this process fetched over the network

    def spec(self, ref: ObjectRef) -> ObjectSpec:
        if ref.content_hash is None:
            return ref.spec()
        return ref.spec(mesh_path=str(self._mesh_file(ref.content_hash, ref.mesh_format or "")))

    def _mesh_file(self, content_hash: str, fmt: str) -> Path:
        path = self.folder / f"{content_hash}.{fmt}"
        if fill_once(path, content_hash, whole=path.exists,
                     fetch=lambda: self._fetch(content_hash).mesh(),
                     write=lambda data, tmp: tmp.write_bytes(data),
                     error=ObjectFetchError, what=f"mesh {content_hash}"):
            self.fetched += 1
        return path

    def _fetch(self, content_hash: str) -> ObjectData:
        return fetch_reply(self.session, keys.object_key(content_hash),
                           ObjectRequest(content_hash=content_hash), ObjectData,
                           timeout_s=self.timeout_s, error=ObjectFetchError,
                           what=f"mesh {content_hash}")
