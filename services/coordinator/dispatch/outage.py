"""One warning per store outage, not a traceback per refused query.

While PostgreSQL is down every lease and result query fails the same way; a thousand workers
retrying made the log a wall of identical tracebacks that hid when the outage began and
ended. A store failure (the database unreachable, a connection dropped, the pool exhausted)
is answered "unavailable" as before, and logged here: one warning when an episode starts,
with its reason, a reminder at most every `remind_s` while it lasts (how many queries were
refused since), and one line when a query succeeds again. Anything else raised while serving
a query is a bug and keeps its traceback (dispatch/service.py).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

from sqlalchemy.exc import DBAPIError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeout

log = logging.getLogger("graspscape.dispatch")

REMIND_S = 60.0


def is_store_outage(exc: BaseException) -> bool:
    """Whether `exc` says the store could not be reached or used (not a bug of ours): the
    driver's operational and interface errors (connection refused or dropped, the server
    shutting down, a lock timeout), a connection found invalid, or no pooled connection free
    in time. A data or integrity error is a bug and not an outage."""
    if isinstance(exc, DBAPIError) and exc.connection_invalidated:
        return True
    return isinstance(exc, OperationalError | InterfaceError | PoolTimeout)


def _reason(exc: BaseException) -> str:
    # The driver's own message, first line: "connection refused", "terminating connection
    # due to administrator command", ... without SQLAlchemy's statement and parameters.
    inner = getattr(exc, "orig", None) or exc
    text = str(inner).strip().splitlines()
    return f"{type(inner).__name__}: {text[0] if text else ''}"


class StoreOutage:
    """Thread-safe: the handler threads report each store failure and each success."""

    def __init__(self, *, remind_s: float = REMIND_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._lock = threading.Lock()
        self._remind_s = remind_s
        self._clock = clock
        self._since: float | None = None  # when the episode began; None: no outage
        self._reminded = 0.0
        self._refused = 0  # queries refused in this episode
        self._unreported = 0  # ... since the last line about it

    @property
    def ongoing(self) -> bool:
        return self._since is not None

    def failed(self, kind: str, exc: BaseException) -> None:
        """A `kind` query was refused because the store failed with `exc`."""
        now = self._clock()
        with self._lock:
            self._refused += 1
            self._unreported += 1
            if self._since is None:
                self._since = self._reminded = now
                self._unreported = 0
                log.warning("store unavailable (%s); refusing queries as 'unavailable' until "
                            "it is back (first: a %s query), one line per minute meanwhile",
                            _reason(exc), kind)
            elif now - self._reminded >= self._remind_s:
                self._reminded = now
                log.warning("store still unavailable after %.0f s (%s): %d queries refused "
                            "since the last line", now - self._since, _reason(exc),
                            self._unreported)
                self._unreported = 0

    def succeeded(self) -> None:
        """A query was served from the store: ends an episode, if one is on."""
        if self._since is None:  # the common case, without the lock
            return
        now = self._clock()
        with self._lock:
            if self._since is None:
                return
            log.warning("store available again after %.1f s; %d queries were refused",
                        now - self._since, self._refused)
            self._since = None
            self._refused = self._unreported = 0
