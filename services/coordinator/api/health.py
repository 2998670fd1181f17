"""Routes for operations: GET /healthz (database reachable, schema at head), GET /metrics."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, Response
from graspscape.services.coordinator import db
from graspscape.services.coordinator.api.finite import FiniteJSONRoute
from graspscape.services.coordinator.metrics import CONTENT_TYPE
from pydantic import BaseModel

router = APIRouter(tags=["operations"], route_class=FiniteJSONRoute)


class Health(BaseModel):
    status: str
    database: str
    schema_revision: str | None
    schema_head: str | None


@router.get(
    "/healthz",
    response_model=Health,
    responses={503: {"model": Health, "description": "database down or not migrated"}},
)
def healthz(request: Request) -> Any:
    engine = request.app.state.engine
    head = request.app.state.schema_head
    try:
        current = db.current_revision(engine)
    except Exception as exc:
        body = Health(
            status="unavailable",
            database=f"error: {type(exc).__name__}",
            schema_revision=None,
            schema_head=head,
        )
        return JSONResponse(body.model_dump(), status_code=503)
    if current != head:
        body = Health(
            status="unavailable",
            database="schema not at head: run 'graspscape db upgrade'",
            schema_revision=current,
            schema_head=head,
        )
        return JSONResponse(body.model_dump(), status_code=503)
    return Health(
        status="ok", database=engine.dialect.name, schema_revision=current, schema_head=head
    )


@router.get(
    "/metrics",
    response_class=Response,
    responses={
        200: {
            "content": {CONTENT_TYPE: {"schema": {"type": "string"}}},
            "description": "Prometheus text exposition format",
        }
    },
)
def metrics(request: Request) -> Response:
    return Response(request.app.state.metrics.render(), media_type=CONTENT_TYPE)
