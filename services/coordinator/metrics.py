"""Prometheus metrics: request counts and latencies, and store gauges read at scrape time.

Each app gets its own registry (tests build many apps in one process, and the global
registry refuses duplicate metric names). Store gauges are computed from the database when
scraped rather than kept in memory, so they are right after a restart and across processes.
"""

from __future__ import annotations

import time
from collections.abc import Awaitable, Callable, Iterator
from datetime import timedelta

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
from starlette.requests import Request
from starlette.responses import Response

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

    async def middleware(
        self, request: Request, call_next: Callable[[Request], Awaitable[Response]]
    ) -> Response:
        start = time.perf_counter()
        response = await call_next(request)
        # The route template, not the raw path, keeps label cardinality bounded.
        route = getattr(request.scope.get("route"), "path", "unmatched")
        self.latency.labels(request.method, route).observe(time.perf_counter() - start)
        self.requests.labels(request.method, route, str(response.status_code)).inc()
        return response

    def render(self) -> bytes:
        return generate_latest(self.registry)
