"""What a worker is answered when serving its query raised: never exception text or SQL.

A store outage (the database down, a dropped connection) is `unavailable`, which the worker
retries, and logged once per episode (dispatch/outage.py). Anything else is a bug or data the
store cannot take: one log line with its cause (the traceback at debug level). A lease or an
object fetch is answered `internal` (the worker asks again); a result batch is refused for
good as `invalid` and counted as a failed attempt of its tile, since the same batch sent
again would fail again and the tile would go round for good.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from graspscape.services.coordinator.dispatch.outage import StoreOutage, is_store_outage
from graspscape.shared.wire.codec import error
from graspscape.shared.wire.messages import ErrorCode, ErrorReply

log = logging.getLogger("graspscape.dispatch")


def failed_reply(kind: str, exc: Exception, outage: StoreOutage, count: Callable[[], str]
                 ) -> tuple[ErrorReply, str | None]:
    """The reply to a `kind` query whose handler raised `exc`, and the cause for the log line
    (None: the outage logs it). `count` counts a refused batch as its tile's attempt and says
    so (dispatch/answers.count_refusal)."""
    if is_store_outage(exc):
        outage.failed(kind, exc)
        return error(ErrorCode.UNAVAILABLE, "the coordinator's store is not reachable; "
                     "retry"), None
    log.debug("serving a %s query failed", kind, exc_info=True)
    first = str(exc).splitlines()[0][:300] if str(exc) else ""
    cause = f" [{type(exc).__name__}: {first}]"
    if kind != "results":
        return error(ErrorCode.INTERNAL, "the coordinator could not answer (its log says "
                     "why)"), cause
    return error(ErrorCode.INVALID, "the coordinator could not store this batch (its log says "
                 "why)" + count()), cause
