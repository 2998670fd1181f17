"""Which workers have a liveliness token now (the orphan sweep after a coordinator start)."""

from __future__ import annotations

import threading
import time

import zenoh
from graspscape.shared.wire import keys


def alive_workers(session: zenoh.Session, timeout_s: float = 2.0) -> set[str] | None:
    """Worker ids with a liveliness token now; None when the question could not be asked."""
    found: set[str] = set()
    done = threading.Event()

    def collect(reply: zenoh.Reply) -> None:
        if reply.ok is not None:
            worker_id = keys.worker_of_alive_key(str(reply.ok.key_expr))
            if worker_id:
                found.add(worker_id)

    # A callback, not the bounded (256) default channel: a client session answers the query
    # in place, into the handler, before get() returns and under the session's lock; with
    # more workers than the channel holds, get() waited for a reader that runs only after
    # it returns, and the session's network thread for the lock (the whole session hung).
    start = time.monotonic()
    session.liveliness().get(
        keys.ALIVE_ALL, zenoh.handlers.Callback(collect, done.set), timeout=timeout_s)
    # Never half an answer (live workers' leases would go back): not one cut by its timeout.
    if not done.wait(timeout_s + 5.0) or time.monotonic() - start >= timeout_s:
        return None
    return found
