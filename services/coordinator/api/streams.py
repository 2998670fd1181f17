"""Streamed bodies that stop, and give back what they hold, when the client goes away.

Starlette's StreamingResponse stops sending when the client disconnects, but it neither
closes a synchronous iterator it was given nor the async one it makes of it: a generator
that holds a database session (the pose exports read a server-side cursor) kept it until
garbage collection or the export's end, so abandoned downloads exhausted the pool (issue 21,
seen with 16 abandoned CSV streams). `ClosingStream` pulls the pieces in the thread pool and
closes the generator (in a thread: its cleanup may talk to the database) however the
response ends: sent, failed, or cancelled by the client's disconnect.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Iterator

import anyio
from starlette.responses import StreamingResponse
from starlette.types import Receive, Scope, Send

log = logging.getLogger("graspscape.coordinator.api")


async def _pieces(pieces: Iterator[bytes], what: str) -> AsyncIterator[bytes]:
    sent = 0
    finished = False
    try:
        while (piece := await anyio.to_thread.run_sync(next, pieces, None)) is not None:
            yield piece
            sent += 1
        finished = True
    finally:
        # Shielded: this runs when the client's disconnect cancelled the response.
        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(_close, pieces)
        if not finished:
            log.info("%s stopped: client went away after %d pieces", what, sent)


def _close(pieces: Iterator[bytes]) -> None:
    close = getattr(pieces, "close", None)
    if close is not None:
        close()


class ClosingStream(StreamingResponse):
    """A StreamingResponse of a synchronous iterator of bytes, closed when the response
    ends for any reason (`what` names it in the log line of an abandoned stream)."""

    def __init__(self, pieces: Iterator[bytes], *, what: str, media_type: str,
                 headers: dict[str, str] | None = None) -> None:
        super().__init__(_pieces(pieces, what), media_type=media_type, headers=headers)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await super().__call__(scope, receive, send)
        finally:
            with anyio.CancelScope(shield=True):
                await self.body_iterator.aclose()  # type: ignore[attr-defined]
