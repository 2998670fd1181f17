"""Routes for explorations: submit, list, one with progress, cancel, delete, its poses, its
failed tiles and their retry."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path, Query, Response, status
from graspscape.services.coordinator.api.deps import Mutating, SessionDep, SettingsDep
from graspscape.services.coordinator.api.finite import FiniteJSONRoute
from graspscape.services.coordinator.api.pages import CursorPage, Page
from graspscape.services.coordinator.api.responses import (
    UNAUTHORIZED,
    encoded,
    error,
    json_response,
)
from graspscape.services.coordinator.exploration import service, support
from graspscape.services.coordinator.exploration.schemas import (
    ExplorationCreated,
    ExplorationDetail,
    ExplorationOut,
    ExplorationRetried,
    FailedTileOut,
    PoseFilter,
    PoseOut,
)
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.results import Outcome

router = APIRouter(tags=["explorations"], route_class=FiniteJSONRoute)

Id = Annotated[int, Path(ge=1, le=2**31 - 1, description="exploration id")]
_NOT_FOUND: dict[int | str, dict[str, Any]] = {404: error("no such exploration")}


def _float(description: str) -> Any:
    return Query(allow_inf_nan=False, description=description)


@router.post(
    "/explorations",
    response_model=ExplorationCreated,
    status_code=status.HTTP_201_CREATED,
    dependencies=Mutating,
    responses={
        **UNAUTHORIZED,
        400: error("body is not valid JSON"),
        422: {"description": "invalid spec or unknown object (detail names it)"},
    },
    summary="Submit an exploration; its coarse-pass tiles are queued at once",
)
def submit(spec: ExplorationSpec, session: SessionDep, settings: SettingsDep) -> Any:
    rows = service.create_explorations(
        session,
        spec=spec,
        tile_target_poses=settings.queue.tile_target_poses,
        max_poses=settings.queue.max_poses_per_exploration,
    )
    row = rows[0]
    return ExplorationCreated(
        id=row.id, status=row.status, tiles_total=row.tiles_total, poses_total=row.poses_total,
        group=[r.id for r in rows] if row.support_group is not None else [])


@router.get("/explorations", response_model=Page[ExplorationOut], summary="List explorations")
def list_explorations(
    session: SessionDep,
    status_: Annotated[
        Literal["queued", "running", "done", "incomplete", "failed", "cancelled"] | None,
        Query(alias="status"),
    ] = None,
    object_id: Annotated[int | None, Query(ge=1, le=2**31 - 1)] = None,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=2**31 - 1)] = 0,
) -> Any:
    rows, total = service.list_explorations(
        session, status=status_, object_id=object_id, limit=limit, offset=offset
    )
    return Page[ExplorationOut](items=rows, total=total, limit=limit, offset=offset)


@router.get(
    "/explorations/{exploration_id}",
    response_model=ExplorationDetail,
    responses=_NOT_FOUND,
    summary="One exploration with its progress and a summary of its failed tiles",
)
def get_exploration(exploration_id: Id, session: SessionDep, settings: SettingsDep) -> Any:
    row = service.get_exploration(session, exploration_id=exploration_id)
    progress = service.progress(session, row=row, window_s=settings.queue.throughput_window_s)
    failures = service.failure_summary(session, exploration_id=exploration_id)
    return ExplorationDetail.model_validate(
        {**ExplorationOut.model_validate(row).model_dump(), "progress": progress,
         "failures": failures}
    )


@router.get(
    "/explorations/{exploration_id}/group",
    response_model=list[ExplorationOut],
    responses=_NOT_FOUND,
    summary="On a table: every exploration submitted with this one, one per resting pose, "
    "most probable first (a free object's: itself alone)",
)
def get_group(exploration_id: Id, session: SessionDep) -> Any:
    return support.group_rows(session, exploration_id)


@router.get(
    "/explorations/{exploration_id}/failures",
    response_model=Page[FailedTileOut],
    responses=_NOT_FOUND,
    summary="Its failed tiles (after max_attempts), with attempts and the last error",
)
def list_failures(
    exploration_id: Id,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=2**31 - 1)] = 0,
) -> Any:
    rows, total = service.list_failures(
        session, exploration_id=exploration_id, limit=limit, offset=offset
    )
    return Page[FailedTileOut](items=rows, total=total, limit=limit, offset=offset)


@router.post(
    "/explorations/{exploration_id}/retry",
    response_model=ExplorationRetried,
    dependencies=Mutating,
    responses={
        **_NOT_FOUND,
        **UNAUTHORIZED,
        409: error("the exploration is cancelled, or has no failed tiles"),
    },
    summary="Queue its failed tiles again (attempts from zero) and set it running",
)
def retry(exploration_id: Id, session: SessionDep) -> Any:
    row, requeued = service.retry_exploration(session, exploration_id=exploration_id)
    return ExplorationRetried(id=row.id, status=row.status, tiles_requeued=requeued)


@router.post(
    "/explorations/{exploration_id}/cancel",
    response_model=ExplorationOut,
    dependencies=Mutating,
    responses={
        **_NOT_FOUND,
        **UNAUTHORIZED,
        409: error("the exploration is already finished (done, incomplete or failed)"),
    },
    summary="Cancel: no more tiles are handed out; stored results stay",
)
def cancel(exploration_id: Id, session: SessionDep) -> Any:
    return service.cancel_exploration(session, exploration_id=exploration_id)


@router.delete(
    "/explorations/{exploration_id}",
    status_code=status.HTTP_204_NO_CONTENT,
    dependencies=Mutating,
    responses={**_NOT_FOUND, **UNAUTHORIZED},
    summary="Delete an exploration with its tiles and poses",
)
def delete(exploration_id: Id, session: SessionDep) -> Response:
    service.delete_exploration(session, exploration_id=exploration_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get(
    "/explorations/{exploration_id}/poses",
    response_model=CursorPage[PoseOut],
    responses={**_NOT_FOUND, 422: {"description": "bad filter (detail names it)"}},
    summary="Evaluated poses, oldest first, keyset-paginated, with filters",
)
def list_poses(
    exploration_id: Id,
    session: SessionDep,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
    cursor: Annotated[int | None, Query(ge=0, le=2**31 - 1, description="next_cursor")] = None,
    viable: bool | None = None,
    outcome: Annotated[Outcome | None, Query(description="only poses with this outcome, "
                                             "e.g. error")] = None,
    manifold_id: Annotated[int | None, Query(ge=1, le=2**31 - 1)] = None,
    mu_min: Annotated[float | None, _float("μs ≥ this")] = None,
    mu_max: Annotated[float | None, _float("μs ≤ this")] = None,
    theta_min: Annotated[float | None, _float("θ ≥ this, rad")] = None,
    theta_max: Annotated[float | None, _float("θ ≤ this, rad")] = None,
    phi_min: Annotated[float | None, _float("φ ≥ this, rad")] = None,
    phi_max: Annotated[float | None, _float("φ ≤ this, rad")] = None,
    r_min: Annotated[float | None, _float("r ≥ this, m")] = None,
    r_max: Annotated[float | None, _float("r ≤ this, m")] = None,
) -> Any:
    filters = PoseFilter(
        viable=viable,
        outcome=outcome,
        manifold_id=manifold_id,
        mu_min=mu_min,
        mu_max=mu_max,
        theta_min=theta_min,
        theta_max=theta_max,
        phi_min=phi_min,
        phi_max=phi_max,
        r_min=r_min,
        r_max=r_max,
    )
    rows, next_cursor = service.list_poses(
        session, exploration_id=exploration_id, filters=filters, limit=limit, cursor=cursor
    )
    # Validated once, here, and answered as bytes (FastAPI would validate the page again).
    return json_response(encoded(CursorPage[PoseOut](items=rows, limit=limit,
                                                     next_cursor=next_cursor)))
