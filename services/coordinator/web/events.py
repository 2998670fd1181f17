"""Live progress for the viewer as server-sent events (`GET /events/explorations`).

The page keeps one EventSource open; every `interval_s` the coordinator reads the progress of
the explorations on the first page of the list and the workers seen lately, and sends the
snapshot as one `progress` event when it changed (and a comment line as keep-alive otherwise,
so proxies do not close an idle stream). Reading the store on a timer is the coordinator's
business, not each browser's: N open pages cost N cheap reads a second, not N × (list +
detail + workers) requests.
"""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import AsyncIterator
from datetime import timedelta
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from fastapi.responses import StreamingResponse
from graspscape.services.coordinator.exploration import service
from graspscape.services.coordinator.state import of
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import (
    FINISHED_STATUSES,
    ExplorationRow,
    WorkerRow,
)
from pydantic import BaseModel
from sqlalchemy import func, select
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

router = APIRouter(include_in_schema=False)

# Set when uvicorn is told to exit. Uvicorn's graceful shutdown waits for every response to
# end, and an event stream never does: one open viewer tab kept `graspscape serve` from
# exiting on SIGTERM/Ctrl-C (measured: still up 40 s later). The streams end on this instead.
# Uvicorn offers no hook for it, so its signal handler is wrapped, as sse-starlette does. A
# fact about the process (its signal), not an app's state; a closed app's streams end too.
_shutting_down = threading.Event()


def _watch_server_exit() -> None:
    try:
        from uvicorn.server import Server
    except ImportError:  # served otherwise: streams end when clients go
        return
    original = Server.handle_exit
    if getattr(original, "graspscape_watched", False):
        return

    def handle_exit(self: Any, sig: int, frame: Any) -> None:
        _shutting_down.set()
        original(self, sig, frame)

    handle_exit.graspscape_watched = True  # type: ignore[attr-defined]
    Server.handle_exit = handle_exit  # type: ignore[method-assign]


_watch_server_exit()

CONNECTED_WITHIN_S = 30.0  # a worker heard from this recently counts as connected
LIST_LIMIT = 50


class ExplorationProgress(BaseModel):
    id: int
    object_id: int
    label: str | None
    strategy: str
    status: str
    poses_done: int
    poses_total: int
    fraction_done: float
    viable_share: float | None
    throughput_poses_per_s: float
    eta_s: float | None
    updated_at: str


class Snapshot(BaseModel):
    explorations: list[ExplorationProgress]
    total: int
    workers_connected: int
    processes_connected: int


def snapshot(session: Session, *, window_s: float) -> Snapshot:
    """The explorations list's numbers now (finished ones without the per-tile queries)."""
    total = session.scalar(select(func.count()).select_from(ExplorationRow)) or 0
    # Newest first: the one just submitted is the one a person is watching.
    rows = session.scalars(
        select(ExplorationRow).order_by(ExplorationRow.id.desc()).limit(LIST_LIMIT)).all()
    items = []
    for row in rows:
        if row.status in FINISHED_STATUSES:
            fraction = min(1.0, row.poses_done / row.poses_total) if row.poses_total else 1.0
            viable = row.viable_count / row.poses_done if row.poses_done else None
            throughput, eta = 0.0, None  # nothing left to wait for: no ETA
        else:
            p = service.progress(session, row=row, window_s=window_s)
            fraction, viable = p.fraction_done, p.viable_share
            throughput, eta = p.throughput_poses_per_s, p.eta_s
        items.append(ExplorationProgress(
            id=row.id, object_id=row.object_id, label=row.spec.get("label"),
            strategy=(row.spec.get("strategy") or {}).get("name", "adaptive"),
            status=row.status, poses_done=row.poses_done, poses_total=row.poses_total,
            fraction_done=fraction, viable_share=viable, throughput_poses_per_s=throughput,
            eta_s=eta, updated_at=row.updated_at.isoformat()))
    since = utcnow() - timedelta(seconds=CONNECTED_WITHIN_S)
    workers, procs = session.execute(
        select(func.count(), func.coalesce(func.sum(WorkerRow.capacity), 0))
        .where(WorkerRow.last_seen >= since)).one()
    return Snapshot(explorations=items, total=total, workers_connected=workers,
                    processes_connected=procs)


def _read(request: Request) -> str:
    settings = request.app.state.settings
    with request.app.state.sessionmaker() as session:
        snap = snapshot(session, window_s=settings.queue.throughput_window_s)
    return json.dumps(snap.model_dump(mode="json"), separators=(",", ":"))


async def _events(request: Request, interval_s: float, max_events: int | None
                  ) -> AsyncIterator[str]:
    # The browser reconnects after `retry` ms if the stream breaks (coordinator restart).
    yield "retry: 2000\n\n"
    last, sent = None, 0
    while True:
        data = await run_in_threadpool(_read, request)
        if data != last:
            yield f"event: progress\ndata: {data}\n\n"
            last, sent = data, sent + 1
            if max_events is not None and sent >= max_events:
                return
        else:
            yield ": idle\n\n"
        for _ in range(max(1, round(interval_s / 0.2))):  # wake often enough to end soon
            await asyncio.sleep(min(interval_s, 0.2))
            if _shutting_down.is_set() or of(request.app).closed.is_set():
                return
        if await request.is_disconnected():
            return


@router.get("/events/explorations")
async def exploration_events(
    request: Request,
    interval_s: Annotated[float, Query(ge=0.2, le=60.0)] = 1.0,
    max_events: Annotated[int | None, Query(ge=1, le=10_000,
                                            description="end after this many (tests)")] = None,
) -> StreamingResponse:
    headers: dict[str, Any] = {"Cache-Control": "no-cache", "X-Accel-Buffering": "no"}
    return StreamingResponse(_events(request, interval_s, max_events),
                             media_type="text/event-stream", headers=headers)
