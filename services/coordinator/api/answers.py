"""Answers of the map's read routes, kept per exploration version (issue 21).

A read route's answer depends only on the exploration's stored rows, and every write that can
change them moves one of the exploration row's columns read here: an ingest bumps
`poses_done` and `updated_at` (in the transaction that stores the poses, the certification
marks and the shortcuts' copies), a manifold refresh moves `manifolds_poses_done` /
`manifolds_final`, a status change moves `status` and `updated_at`, and a deleted and
re-created exploration has another `created_at`. So (database, exploration, those columns)
names a version of the map, and an answer computed at that version, keyed by the route and
every one of its parameters, is the answer for as long as the version stands. A finished
exploration's version never moves again: its reads become one indexed row read and a dict
look-up. A read never refreshes the table (the keeper does, after committed batches:
manifolds/keeper.py), so the version a route reads is the table it answers from.

On the coordinator's state (state.py: `answers`, `routes`), in memory, bounded by count and
by bytes (a `/best?limit=100` answer with its poses' signatures and grasps is a few hundred
kB), least recently used out. Entries are
response bodies (bytes), never objects a caller could change. The fast path's entries
(`KeptRoutes`, below: the same answers keyed by the raw request) have bounds of their own, the
same; mostly they share their bodies with this store's.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Hashable
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

import anyio.to_thread
from graspscape.services.coordinator.errors import NotFound
from graspscape.services.coordinator.state import Bounded, CoordinatorState, current
from graspscape.services.coordinator.store.models import ExplorationRow
from sqlalchemy import Engine, bindparam, select
from sqlalchemy.orm import Session
from starlette.types import ASGIApp, Message, Receive, Scope, Send

_VERSION = select(
    ExplorationRow.created_at, ExplorationRow.updated_at, ExplorationRow.status,
    ExplorationRow.poses_done, ExplorationRow.manifolds_poses_done,
    ExplorationRow.manifolds_final,
).where(ExplorationRow.id == bindparam("exploration_id"))


def version(session: Session, exploration_id: int) -> tuple[Any, ...]:
    """The exploration's map version (see the module docstring). NotFound: no exploration."""
    # One prebuilt statement on the session's connection: ~25 µs, against ~115 µs through the
    # ORM's execute with a new WHERE each call (its cache key and compile state; issue 21).
    row = session.connection().execute(_VERSION, {"exploration_id": exploration_id}).one_or_none()
    if row is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    return (str(session.get_bind().url), exploration_id, *row)


def answer(key: Hashable, compute: Callable[[], bytes],
           kept: Bounded[Hashable, bytes] | None = None) -> bytes:
    """The answer filed under `key` (a version and the request's parameters), computed once,
    in `kept` (default: the current state's `answers`). Two requests missing at once both
    compute (the same bytes); neither waits on the other. `key[0]` is the map version
    (`version`): noted for `KeptRoutes`."""
    _note(key)
    answers = current().answers if kept is None else kept
    body = answers.get(key)
    if body is not None:
        return body
    return answers.setdefault(key, compute())


def clear(state: CoordinatorState | None = None) -> None:
    """Forget every answer of `state` (default: the current one; tests that compare a
    computed answer with a kept one)."""
    state = current() if state is None else state
    state.answers.clear()
    state.routes.clear()


# --- the kept routes' fast path ---------------------------------------------------------------
# A kept answer still cost ~1 ms of the server's CPU, most of it FastAPI's: routing over every
# route, then solving the dependencies and validating each query parameter, all before the
# route's dict look-up (in-process profile on the 10k map, issue 21). `KeptRoutes` answers a
# repeated request before that: keyed by its exact path and raw query string, it serves the
# bytes FastAPI answered for it when the map's version read now is the version that answer was
# computed at, and hands every other request to FastAPI unchanged.
#
# Only a settled version is served this way: manifolds_final set and the manifold table at
# every stored pose, which no later write moves; a route at any other version goes through
# FastAPI (whose own kept answers still apply). The version an answer was computed at is the
# one the route filed it under (`answer`'s key), noted through a context variable the route's
# thread inherits, not a version read around it: a write in between cannot file an answer
# under the wrong version.
_ROUTES = re.compile(r"/explorations/([1-9][0-9]{0,9})/(?:best|manifolds(?:/[^/]+)?)")
_MAX_ID = 2**31 - 1
_noted: ContextVar[list[Any] | None] = ContextVar("graspscape_kept_versions", default=None)


@dataclass(frozen=True)
class Kept:
    """What FastAPI sent for one request at one settled version."""

    version: tuple[Any, ...]
    route: Any  # scope["route"]: the metrics middleware labels the request by its template
    headers: tuple[tuple[bytes, bytes], ...]
    body: bytes


def _note(key: Hashable) -> None:
    noted = _noted.get()
    if noted is not None and isinstance(key, tuple) and key and isinstance(key[0], tuple):
        noted.append(key[0])


def _settled(v: tuple[Any, ...]) -> bool:
    # (url, id, created_at, updated_at, status, poses_done, manifolds_poses_done, final)
    return bool(v[7]) and v[6] == v[5]


def _read_version(engine: Engine, url: str, exploration_id: int) -> tuple[Any, ...] | None:
    # The statement `version` runs, on a pooled connection of the app's engine (the session's
    # bind): the same tuple a route reads. On PostgreSQL in autocommit: one round trip, not
    # BEGIN, SELECT and the pool's ROLLBACK (a kept answer's server CPU 0.44–0.52 → 0.37–0.45
    # ms, query_overhead_pg.json); SQLite begins no transaction for a SELECT, and switching
    # the connection's mode costs it ~0.02 ms.
    options = {} if engine.dialect.name == "sqlite" else {"isolation_level": "AUTOCOMMIT"}
    with engine.connect().execution_options(**options) as conn:
        row = conn.execute(_VERSION, {"exploration_id": exploration_id}).one_or_none()
    return None if row is None else (url, exploration_id, *row)


class KeptRoutes:
    """ASGI middleware: kept answers of /best, /manifolds and /manifolds/{label} served before
    FastAPI's routing and validation (see above); everything else passes through."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        # The app's engine and str(its url), the version's first item, made once (str: µs).
        self._url: tuple[Engine, str] | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        match = (_ROUTES.fullmatch(scope["path"])
                 if scope["type"] == "http" and scope["method"] == "GET" else None)
        if match is None or int(match[1]) > _MAX_ID:
            await self.app(scope, receive, send)
            return
        exploration_id = int(match[1])
        engine: Engine = scope["app"].state.engine
        if self._url is None or self._url[0] is not engine:
            self._url = (engine, str(engine.url))
        url = self._url[1]
        key = (url, scope["path"], scope["query_string"])
        state: CoordinatorState = scope["app"].state.coordinator
        kept = state.routes.get(key)
        if kept is not None:
            try:
                now = await anyio.to_thread.run_sync(_read_version, engine, url, exploration_id)
            except Exception:  # the store's error is FastAPI's to answer, as on any request
                now = None
            if now == kept.version:
                state.route_hits += 1
                scope["route"] = kept.route
                await send({"type": "http.response.start", "status": 200,
                            "headers": kept.headers})
                await send({"type": "http.response.body", "body": kept.body})
                return
        await self._answer_and_keep(scope, receive, send, key, state)

    async def _answer_and_keep(self, scope: Scope, receive: Receive, send: Send,
                               key: Hashable, state: CoordinatorState) -> None:
        noted: list[Any] = []
        start: Message | None = None
        chunks: list[bytes] = []
        complete = False

        async def capture(message: Message) -> None:
            nonlocal start, complete
            if message["type"] == "http.response.start":
                start = message
            elif message["type"] == "http.response.body":
                chunks.append(message.get("body", b""))
                complete = not message.get("more_body", False)
            await send(message)

        token = _noted.set(noted)
        try:
            await self.app(scope, receive, capture)
        finally:
            _noted.reset(token)
        # One answer filed under one settled version, sent whole with 200: the request's
        # answer for as long as that version stands.
        if (start is not None and start["status"] == 200 and complete and len(noted) == 1
                and _settled(noted[0]) and not start.get("trailers")):
            state.routes.put(key, Kept(noted[0], scope.get("route"),
                                       tuple(start["headers"]), b"".join(chunks)))
