"""Key expressions of the dispatch protocol, in one place for both sides.

Queryables are declared on wildcard expressions and replies go out on concrete keys inside
them: zenoh refuses a reply whose key does not intersect the query's key expression, and it
collapses replies on one key unless the querier asks with ConsolidationMode.NONE.
"""

from __future__ import annotations

import re

PREFIX = "gs"

# A worker asks for tiles with a get on LEASE_QUERY; the coordinator answers once per tile on
# lease_reply_key(tile_id) (distinct keys, so no consolidation can merge them).
LEASE_QUERYABLE = f"{PREFIX}/lease/**"
LEASE_QUERY = f"{PREFIX}/lease/**"

# A worker reports one tile's batch with a get on results_key(); the reply is the ack.
RESULTS_QUERYABLE = f"{PREFIX}/results/**"

# A worker fetches a mesh by content hash with a get on object_key(); the reply is the mesh.
OBJECT_QUERYABLE = f"{PREFIX}/object/**"
# A gripper's archive, the same way by its content hash on gripper_key().
GRIPPER_QUERYABLE = f"{PREFIX}/gripper/**"

# Each worker process holds one liveliness token on alive_key(worker_id) while it runs.
ALIVE_PREFIX = f"{PREFIX}/alive"
ALIVE_ALL = f"{ALIVE_PREFIX}/**"

# Worker ids travel inside key expressions, so they must not hold '/', '*', '$', '?', '#'.
WORKER_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.:@-]{0,127}$"
_WORKER_ID = re.compile(WORKER_ID_PATTERN)
_HASH = re.compile(r"^[0-9a-f]{64}$")


def lease_reply_key(tile_id: int) -> str:
    return f"{PREFIX}/lease/tile/{tile_id}"


def results_key(tile_id: int, lease_epoch: int) -> str:
    return f"{PREFIX}/results/{tile_id}/{lease_epoch}"


def object_key(content_hash: str) -> str:
    if not _HASH.match(content_hash):
        raise ValueError(f"content hash {content_hash!r} is not 64 lower-case hex digits")
    return f"{PREFIX}/object/{content_hash}"


def gripper_key(content_hash: str) -> str:
    if not _HASH.match(content_hash):
        raise ValueError(f"content hash {content_hash!r} is not 64 lower-case hex digits")
    return f"{PREFIX}/gripper/{content_hash}"


def alive_key(worker_id: str) -> str:
    if not _WORKER_ID.match(worker_id):
        raise ValueError(f"worker id {worker_id!r} does not match {WORKER_ID_PATTERN}")
    return f"{ALIVE_PREFIX}/{worker_id}"


def worker_of_alive_key(key: str) -> str | None:
    """The worker id of a liveliness key, or None when the key is not one of ours."""
    head = ALIVE_PREFIX + "/"
    if not key.startswith(head):
        return None
    worker_id = key[len(head) :]
    return worker_id if _WORKER_ID.match(worker_id) else None
