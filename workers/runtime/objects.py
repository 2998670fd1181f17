"""Objects by content hash: the mesh is fetched from the coordinator once per worker machine.

Meshes live in <cache>/meshes/<sha256>.<format>. The processes of a worker share the folder;
a file lock makes one of them fetch while the others wait and then read the file. The hash of
the bytes is checked before the file is kept, so a cache file is always the right mesh.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
from pathlib import Path

import zenoh
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.wire import keys
from graspscape.shared.wire.codec import decode_as, decode_reply_error, encode
from graspscape.shared.wire.messages import ObjectData, ObjectRef, ObjectRequest


class ObjectFetchError(RuntimeError):
    def __init__(self, message: str, *, transient: bool) -> None:
        super().__init__(message)
        self.transient = transient  # no answer (retry later) vs. a refusal or a bad mesh


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
        if path.exists():
            return path
        with open(self.folder / f"{content_hash}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if path.exists():  # another process fetched it while this one waited
                return path
            data = self._fetch(content_hash)
            if hashlib.sha256(data.mesh()).hexdigest() != content_hash:
                raise ObjectFetchError(f"mesh fetched for {content_hash} has another hash",
                                       transient=False)
            tmp = path.with_suffix(f".tmp{os.getpid()}")
            tmp.write_bytes(data.mesh())
            os.replace(tmp, path)  # atomic: readers see the whole file or none
            self.fetched += 1
        return path

    def _fetch(self, content_hash: str) -> ObjectData:
        request = ObjectRequest(content_hash=content_hash)
        for reply in self.session.get(
            keys.object_key(content_hash),
            payload=encode(request),
            consolidation=zenoh.ConsolidationMode.NONE,
            timeout=self.timeout_s,
        ):
            if reply.ok is not None:
                message = decode_as(reply.ok.payload.to_bytes(), ObjectData)
            else:
                message = decode_reply_error(reply.err.payload.to_bytes())
            if isinstance(message, ObjectData):
                return message
            raise ObjectFetchError(f"mesh {content_hash}: {message.code}: {message.message}",
                                   transient=message.code.retryable)
        raise ObjectFetchError(f"mesh {content_hash}: no answer from the coordinator",
                               transient=True)
