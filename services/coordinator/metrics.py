"""Prometheus metrics: request counts and latencies, and store gauges read at scrape time.

Each app gets its own registry (tests build many apps in one process, and the global
registry refuses duplicate metric names). Store gauges are computed from the database when
scraped rather than kept in memory, so they are right after a restart and across processes.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from datetime import timedelta
from typing import Any

from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    ExplorationStatus,
    TileRow,
    TileState,
    WorkerRow,
)
from prometheus_client import CollectorRegistry, Counter, Histogram, generate_latest
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker
from starlette.types import ASGIApp, Message, Receive, Scope, Send

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
WORKER_ACTIVE_S = 300


class StoreCollector(Collector):
    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def collect(self) -> Iterator[GaugeMetricFamily]:
        with self._sessions() as session:
            tiles = dict(
                session.execute(select(TileRow.state, func.count()).group_by(TileRow.state)).all()
            )
            explorations = dict(
                session.execute(
                    select(ExplorationRow.status, func.count()).group_by(ExplorationRow.status)
                ).all()
            )
            poses = session.scalar(select(func.coalesce(func.sum(ExplorationRow.poses_done), 0)))
            active = session.scalar(
                select(func.count())
                .select_from(WorkerRow)
                .where(WorkerRow.last_seen >= utcnow() - timedelta(seconds=WORKER_ACTIVE_S))
            )
        g = GaugeMetricFamily("graspscape_tiles", "tiles by state", labels=["state"])
        for state in TileState:
            g.add_metric([state.value], tiles.get(state.value, 0))
        yield g
        g = GaugeMetricFamily(
            "graspscape_explorations", "explorations by status", labels=["status"]
        )
        for st in ExplorationStatus:
            g.add_metric([st.value], explorations.get(st.value, 0))
        yield g
        yield GaugeMetricFamily("graspscape_poses_stored", "pose results stored", value=poses or 0)
        yield GaugeMetricFamily(
            "graspscape_workers_active",
            f"workers seen in the last {WORKER_ACTIVE_S} s",
            value=active or 0,
        )


class Metrics:
    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "graspscape_http_requests",
            "HTTP requests",
            ["method", "route", "status"],
            registry=self.registry,
        )
        self.latency = Histogram(
            "graspscape_http_request_seconds",
            "HTTP request latency",
            ["method", "route"],
            registry=self.registry,
        )
        self.registry.register(StoreCollector(sessions))
        # The children of the two metrics per (method, route[, status]): `labels()` takes the
        # metric's lock and builds its key on every call; a route's children are looked up once.
        self._children: dict[tuple[str, str, int], tuple[Any, Any]] = {}

    def _pair(self, method: str, route: str, status: int) -> tuple[Any, Any]:
        key = (method, route, status)
        pair = self._children.get(key)
        if pair is None:  # a race here makes the same children twice: labels() is idempotent
            pair = (self.latency.labels(method, route),
                    self.requests.labels(method, route, str(status)))
            self._children[key] = pair
        return pair

    def middleware(self, app: ASGIApp) -> ASGIApp:
        """A plain ASGI middleware (Starlette's BaseHTTPMiddleware, which `app.middleware("http")`
        makes, cost ~0.2 ms per request in task groups and memory streams; issue 21). It
        records what the http middleware did: the latency up to the response's start, counted
        with its status; a request whose app raised is not counted (ServerErrorMiddleware,
        outside, answers it)."""

        async def metered(scope: Scope, receive: Receive, send: Send) -> None:
            if scope["type"] != "http":
                await app(scope, receive, send)
                return
            start = time.perf_counter()

            async def timed_send(message: Message) -> None:
                if message["type"] == "http.response.start":
                    # The route template, not the raw path, keeps label cardinality bounded.
                    route = getattr(scope.get("route"), "path", "unmatched")
                    latency, count = self._pair(scope["method"], route, message["status"])
                    latency.observe(time.perf_counter() - start)
                    count.inc()
                await send(message)

            await app(scope, receive, timed_send)

        return metered

    def render(self) -> bytes:
        return generate_latest(self.registry)
