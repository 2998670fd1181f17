"""A worker machine's cache of content-addressed files (meshes, gripper archives): each is
fetched from the coordinator once per machine, whichever of its processes asks first.

A file lock beside the entry makes one process fetch while the others wait and then find it;
the bytes' sha256 is checked against the name before anything is written; the entry is
written beside its place and renamed into it, so readers see it whole or not at all.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import zenoh
from graspscape.shared.wire.codec import decode_as, decode_reply_error, encode
from pydantic import BaseModel

Answer = TypeVar("Answer", bound=BaseModel)


class FetchError(RuntimeError):
    def __init__(self, message: str, *, transient: bool) -> None:
        super().__init__(message)
        self.transient = transient  # no answer (retry later) vs. a refusal or bad content


def fill_once(target: Path, content_hash: str, *, whole: Callable[[], bool],
              fetch: Callable[[], bytes], write: Callable[[bytes, Path], None],
              error: type[FetchError], what: str) -> bool:
    """Makes `target` (a file or a folder, named by `content_hash`) from the fetched bytes
    unless `whole()` says it is there; `write(data, tmp)` writes it at a temporary path that
    then replaces `target`. True where this process fetched it."""
    if whole():
        return False
    with open(target.parent / f"{content_hash}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if whole():  # another process made it while this one waited
            return False
        data = fetch()
        if hashlib.sha256(data).hexdigest() != content_hash:
            raise error(f"{what}: the bytes fetched have another hash", transient=False)
        tmp = target.with_name(f"{target.name}.tmp{os.getpid()}")
        write(data, tmp)
        if target.is_dir():  # a half folder of a crashed process
            shutil.rmtree(target, ignore_errors=True)
        os.replace(tmp, target)  # atomic: readers see the whole entry or none
    return True


def fetch_reply(session: zenoh.Session, key: str, request: BaseModel, answer: type[Answer], *,
                timeout_s: float, error: type[FetchError], what: str) -> Answer:
    """The coordinator's answer to `request` on `key`: the first reply, as `answer`; a refusal
    raised as `error` (transient where its code is retryable), as is no answer at all."""
    for reply in session.get(key, payload=encode(request),
                             consolidation=zenoh.ConsolidationMode.NONE, timeout=timeout_s):
        if reply.ok is not None:
            message = decode_as(reply.ok.payload.to_bytes(), answer)
        else:
            message = decode_reply_error(reply.err.payload.to_bytes())
        if isinstance(message, answer):
            return message
        raise error(f"{what}: {message.code}: {message.message}",
                    transient=message.code.retryable)
    raise error(f"{what}: no answer from the coordinator", transient=True)
