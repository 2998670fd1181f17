"""Read-only JSON the viewer needs beyond the REST API: the viable approach directions of an
exploration with their manifold labels (the 3D view), one stored pose by id (the numbers
beside a grasp picture) and the workers with their recent throughput (the workers page)."""

from __future__ import annotations

from datetime import timedelta
from typing import Annotated, Any

from fastapi import APIRouter, Path, Query, Request
from graspscape.services.coordinator.api.deps import SessionDep
from graspscape.services.coordinator.errors import NotFound
from graspscape.services.coordinator.exploration.schemas import PoseOut
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import (
    ExplorationRow,
    ManifoldRow,
    PoseRow,
    WorkerRow,
)
from graspscape.services.coordinator.web.events import CONNECTED_WITHIN_S
from pydantic import BaseModel
from sqlalchemy import func, select
from sqlalchemy.orm import Session

router = APIRouter(include_in_schema=False)

Id = Annotated[int, Path(ge=1, le=2**31 - 1)]


class Directions(BaseModel):
    """Parallel arrays, one entry per viable pose shown (a list of objects would triple the
    bytes of a 20k-pose map)."""

    exploration_id: int
    total_viable: int
    pose_id: list[int]
    theta: list[float]
    phi: list[float]
    r: list[float]
    mu_s: list[float]
    label: list[int]  # manifold label (0 = A); -1 where the pose has none yet


def directions(session: Session, exploration_id: int, limit: int) -> Directions:
    if session.get(ExplorationRow, exploration_id) is None:
        raise NotFound(f"exploration {exploration_id} does not exist")
    where = (PoseRow.exploration_id == exploration_id, PoseRow.viable.is_(True))
    total = session.scalar(select(func.count()).select_from(PoseRow).where(*where)) or 0
    # Every k-th viable pose by id: an even thinning that keeps every manifold in view.
    step = max(1, -(-total // limit))
    rows = session.execute(
        select(PoseRow.id, PoseRow.theta, PoseRow.phi, PoseRow.r, PoseRow.mu_s,
               func.coalesce(ManifoldRow.label, -1))
        .outerjoin(ManifoldRow, ManifoldRow.id == PoseRow.manifold_id)
        .where(*where).order_by(PoseRow.id)).all()[::step]
    return Directions(
        exploration_id=exploration_id, total_viable=total,
        pose_id=[r[0] for r in rows], theta=[r[1] for r in rows], phi=[r[2] for r in rows],
        r=[r[3] for r in rows], mu_s=[r[4] for r in rows], label=[r[5] for r in rows])


@router.get("/web/explorations/{exploration_id}/directions", response_model=Directions)
def get_directions(exploration_id: Id, session: SessionDep,
                   limit: Annotated[int, Query(ge=1, le=100_000)] = 20_000) -> Any:
    return directions(session, exploration_id, limit)


@router.get("/web/explorations/{exploration_id}/poses/{pose_id}", response_model=PoseOut)
def get_pose(exploration_id: Id, pose_id: Id, session: SessionDep) -> Any:
    row = session.get(PoseRow, pose_id)
    if row is None or row.exploration_id != exploration_id:
        raise NotFound(f"exploration {exploration_id} has no pose {pose_id}")
    return row


class WorkerView(BaseModel):
    id: str
    host: str
    processes: int
    first_seen: str
    last_seen: str
    connected: bool
    poses_last_window: int
    throughput_poses_per_s: float


def workers(session: Session, *, window_s: float) -> list[WorkerView]:
    now = utcnow()
    since = now - timedelta(seconds=window_s)
    recent = dict(session.execute(
        select(PoseRow.worker_id, func.count()).where(PoseRow.created_at >= since)
        .group_by(PoseRow.worker_id)).all())
    rows = session.scalars(select(WorkerRow).order_by(WorkerRow.last_seen.desc()).limit(500))
    out = []
    for w in rows:
        done = int(recent.get(w.id, 0))
        out.append(WorkerView(
            id=w.id, host=w.host, processes=w.capacity, first_seen=w.first_seen.isoformat(),
            last_seen=w.last_seen.isoformat(),
            connected=(now - w.last_seen).total_seconds() <= CONNECTED_WITHIN_S,
            poses_last_window=done, throughput_poses_per_s=done / window_s))
    return out


@router.get("/web/workers", response_model=list[WorkerView])
def get_workers(request: Request, session: SessionDep) -> Any:
    return workers(session, window_s=request.app.state.settings.queue.throughput_window_s)


class Choices(BaseModel):
    """What the submit form offers in its lists."""

    builtin_objects: list[str]
    grippers: list[str]
    policies: list[str]
    strategies: list[str]
    grasp_pictures: bool  # whether this coordinator can draw grasps (web/grasp.py)


def _strategy_names() -> list[str]:
    """The names the spec's strategy union accepts (new strategies appear by themselves)."""
    import typing

    from graspscape.shared.specs.exploration import StrategySpec

    union = typing.get_args(StrategySpec)[0]
    return [typing.get_args(m.model_fields["name"].annotation)[0]
            for m in typing.get_args(union)]


@router.get("/web/choices", response_model=Choices)
def get_choices() -> Any:
    from graspscape.services.coordinator.web.grasp import has_painter
    from graspscape.shared.specs.gripper import list_grippers
    from graspscape.shared.specs.object_names import BUILTIN_NAMES
    from graspscape.shared.specs.sim import POLICY_NAMES

    return Choices(builtin_objects=list(BUILTIN_NAMES), grippers=list_grippers(),
                   policies=list(POLICY_NAMES),
                   strategies=_strategy_names(),
                   grasp_pictures=has_painter())
