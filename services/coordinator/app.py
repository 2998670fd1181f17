"""The FastAPI app factory: wires settings, database, routers, errors, metrics, lease sweeper.

`create_app(settings)` builds an independent app (tests make one per database); the lease
sweeper puts expired leases back in the queue at start (so a restart recovers the tiles of
workers that died meanwhile) and then every requeue_interval_s. With `settings.zenoh.enabled`
the lifespan also runs the zenoh dispatch (services/coordinator/dispatch). Each app has its own
caches and background threads (`app.state.coordinator`: services/coordinator/state.py), which
the lifespan's end joins and empties, after the dispatcher has stopped.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from graspscape.services.coordinator import db, state, web
from graspscape.services.coordinator.api import (
    answers,
    budget,
    datasets,
    explorations,
    grippers,
    health,
    manifolds,
    objects,
    workers,
)
from graspscape.services.coordinator.api.finite import validation_error_handler
from graspscape.services.coordinator.errors import CoordinatorError, InvalidInput
from graspscape.services.coordinator.maps.stored import start_warm_up
from graspscape.services.coordinator.metrics import Metrics
from graspscape.services.coordinator.settings import Settings, get_settings
from graspscape.services.coordinator.store.queue import requeue_expired
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import compile_path

log = logging.getLogger("graspscape.coordinator")


def _sweep(app: FastAPI) -> None:
    with app.state.sessionmaker() as session:
        report = requeue_expired(session, max_attempts=app.state.settings.queue.max_attempts)
    if report.requeued or report.failed:
        log.info("expired leases: %d tiles queued again, %d failed", report.requeued, report.failed)


def _catch_up(app: FastAPI) -> None:
    # A manifold table left behind (a crash between a batch's commit and the keeper's turn,
    # a failed exploration): the keeper's backstop, each sweep interval. Not in the first
    # sweep of the lifespan, which the app's start waits for.
    with app.state.sessionmaker() as session:
        state.of(app).keeper.catch_up(session)


def _release(app: FastAPI) -> None:
    # Another coordinator keeps these tables at its next batch, not after the leases run out.
    with app.state.sessionmaker() as session:
        state.of(app).keeper.release(session)


async def _sweeper(app: FastAPI) -> None:
    while True:
        await asyncio.sleep(app.state.settings.queue.requeue_interval_s)
        try:
            await run_in_threadpool(_sweep, app)
            await run_in_threadpool(_catch_up, app)
        except Exception:  # a database hiccup must not kill the sweeper for good
            log.exception("lease sweep failed; retrying next interval")


@contextlib.asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    # The app's state current for the lifespan: the sweeper task and the thread pool's
    # calls made from here inherit it (state.py).
    with state.using(state.of(app)):
        async with _running(app):
            yield


@contextlib.asynccontextmanager
async def _running(app: FastAPI) -> AsyncIterator[None]:
    try:
        await run_in_threadpool(_sweep, app)
    except Exception:  # e.g. not migrated yet: /healthz reports it, the sweeper retries
        log.exception("initial lease sweep failed")
    task = asyncio.create_task(_sweeper(app))
    dispatcher = None
    if app.state.settings.zenoh.enabled:
        # Imported here so that an app without dispatch never loads zenoh.
        from graspscape.services.coordinator.dispatch.service import Dispatcher

        dispatcher = Dispatcher(
            app.state.settings, app.state.sessionmaker, app.state.metrics.registry
        )
        await run_in_threadpool(dispatcher.start)
    app.state.dispatcher = dispatcher
    start_warm_up(state.of(app))
    try:
        yield
    finally:
        if dispatcher is not None:
            await run_in_threadpool(dispatcher.stop)
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        try:
            await run_in_threadpool(_release, app)
        except Exception:  # the leases run out by themselves (manifolds/keeper.LEASE_S)
            log.exception("the manifold tables' leases were not given back")
        # Its threads (draw-aheads, read-aheads, the warm-up) may still use the engine.
        await run_in_threadpool(state.of(app).close)
        app.state.engine.dispose()


_HTTP_METHODS = {"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS", "TRACE"}


def allowed_methods(app: FastAPI, path: str) -> list[str]:
    """The methods the OpenAPI document lists for a request path. Starlette's 405 names only
    those of the first route that matched the path, and FastAPI makes one route per method, so
    a PUT to /explorations/1 said `Allow: GET` although DELETE is documented there too."""
    documented = getattr(app.state, "documented_methods", None)
    if documented is None:
        documented = [
            (compile_path(template)[0], {m.upper() for m in ops} & _HTTP_METHODS)
            for template, ops in app.openapi()["paths"].items()
        ]
        app.state.documented_methods = documented
    methods: set[str] = set()
    for regex, ops in documented:
        if regex.match(path):
            methods |= ops
    return sorted(methods)


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or get_settings()
    app = FastAPI(
        title="Graspscape coordinator",
        version="0.1.0",
        description="Explorations of grasp affordances: objects, explorations, results, workers.",
        lifespan=_lifespan,
    )
    app.state.settings = settings
    app.state.engine = db.make_engine(settings.database.resolved_url)
    app.state.sessionmaker = db.make_sessionmaker(app.state.engine)
    app.state.schema_head = db.head_revision()
    # This app's caches and background threads (state.py); running maps are saved for a
    # restart (manifolds/snapshot.py) beside a SQLite file, else in its snapshot folder.
    app.state.coordinator = state.CoordinatorState(
        snapshot_dir=settings.database.data_dir / "manifold-maps")
    app.state.metrics = Metrics(app.state.sessionmaker)
    # Kept answers of the map's read routes before FastAPI's routing (api/answers.py); inside
    # the metrics middleware, which times and counts them as any request; all of it with the
    # app's state current (outermost).
    app.add_middleware(answers.KeptRoutes)
    app.add_middleware(app.state.metrics.middleware)
    app.add_middleware(state.UseState, state=app.state.coordinator)

    @app.exception_handler(CoordinatorError)
    async def _domain_error(_request: Request, exc: CoordinatorError) -> JSONResponse:
        if isinstance(exc, InvalidInput):
            detail: Any = [{"loc": list(exc.loc), "msg": exc.message, "type": "value_error"}]
        else:
            detail = exc.message
        return JSONResponse({"detail": detail}, status_code=exc.status_code)

    # FastAPI's 422, except that it can always write what it echoes (NaN in a body was a 500).
    app.add_exception_handler(RequestValidationError, validation_error_handler)

    @app.exception_handler(StarletteHTTPException)
    async def _http_error(request: Request, exc: StarletteHTTPException) -> Response:
        if exc.status_code == 405:
            methods = allowed_methods(app, request.url.path)
            if methods:
                exc.headers = {**(exc.headers or {}), "Allow": ", ".join(methods)}
        return await http_exception_handler(request, exc)

    for router in (objects.router, grippers.router, explorations.router, budget.router,
                   workers.router, health.router):
        app.include_router(router)
    app.include_router(manifolds.router)
    app.include_router(datasets.router)
    web.mount(app)  # the viewer at / (services/coordinator/web)
    return app
