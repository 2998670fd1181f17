"""A worker id belongs to the session that registered it.

Every lease request and result batch carries its process's session key, a random secret the
process makes at start (workers/runtime/process.py). The first lease request under an id
binds the id to the key's hash (store/workers.py, for good: ids end with the process id and
are never reused); a request or batch under the id with another key is refused as
`worker_id_taken` before anything is leased, released or stored. So a second session cannot
take a running worker's tile by sending its id with an empty holding list, nor report under
it.

zenoh tells the application neither the session nor the login a query came from (its
`source_info` is whatever the sender writes), so the key is what tells sessions apart; logins
(docs/design/protocol.md, "Access control") still decide who may open a session at all.
"""

from __future__ import annotations

import threading

from graspscape.services.coordinator.store.workers import bound_session, session_hash
from sqlalchemy.orm import Session

_CACHE_LIMIT = 100_000


class WorkerSessions:
    """The bindings read so far, cached: a binding never changes once made, so the common
    case (a known worker's next request) costs no query."""

    def __init__(self) -> None:
        self._bound: dict[str, str] = {}
        self._lock = threading.Lock()

    def refusal(self, session: Session, worker_id: str, session_key: str) -> str | None:
        """Why a request under `worker_id` with `session_key` is refused, or None when the id
        is that session's or no session's yet (the lease binds it, store/queue.lease_tiles)."""
        bound = self._bound.get(worker_id)
        if bound is None:
            bound = bound_session(session, worker_id)
            if bound is not None:
                with self._lock:
                    if len(self._bound) >= _CACHE_LIMIT:
                        self._bound.clear()
                    self._bound[worker_id] = bound
        if bound is None or bound == session_hash(session_key):
            return None
        return (f"worker id {worker_id} belongs to another session: a process names itself "
                "with the id of its own session only; nothing leased, released or stored")
