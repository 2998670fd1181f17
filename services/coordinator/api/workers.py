"""Routes for the worker registry: GET /workers."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any

from fastapi import APIRouter, Query
from graspscape.services.coordinator.api.deps import SessionDep
from graspscape.services.coordinator.api.finite import FiniteJSONRoute
from graspscape.services.coordinator.api.pages import Page
from graspscape.services.coordinator.store.workers import list_workers
from pydantic import BaseModel, ConfigDict

router = APIRouter(tags=["workers"], route_class=FiniteJSONRoute)


class WorkerOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: str
    host: str
    capacity: int
    first_seen: datetime
    last_seen: datetime


@router.get("/workers", response_model=Page[WorkerOut], summary="Workers seen, most recent first")
def get_workers(
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 100,
    offset: Annotated[int, Query(ge=0, le=2**31 - 1)] = 0,
) -> Any:
    rows, total = list_workers(session, limit=limit, offset=offset)
    return Page[WorkerOut](items=rows, total=total, limit=limit, offset=offset)
