"""`graspscape serve` runs uvicorn with loop and http "auto" (its defaults): they resolve to
uvloop and httptools, dependencies of the package since issue 21 (a kept answer's server CPU
0.36–0.40 → 0.24–0.26 ms: benchmarks/results/query_overhead.json); without them uvicorn falls
back to asyncio and h11 without a word, so check that they resolve."""

from __future__ import annotations

import uvloop
from uvicorn.loops.auto import auto_loop_factory
from uvicorn.protocols.http.auto import AutoHTTPProtocol
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol


def test_uvicorn_auto_is_uvloop_and_httptools() -> None:
    assert AutoHTTPProtocol is HttpToolsProtocol
    loop = auto_loop_factory()()
    try:
        assert isinstance(loop, uvloop.Loop)
    finally:
        loop.close()
