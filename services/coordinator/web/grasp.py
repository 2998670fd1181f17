"""The picture of one stored pose's grasp, for the viewer (`GET /explorations/{id}/poses/
{pose_id}/grasp.png`).

The coordinator simulates nothing itself, so the picture is drawn by a painter that the
process wires in: `services/local` gives the workers' renderer (the pose simulated again and
pictured as `graspscape render-pose` does) to every command that runs both sides (`serve`,
`explore`, `atlas`). A coordinator without one answers 409 and the page says so. Pictures are
kept per (database, exploration, pose) on the coordinator's state (state.py): simulating one
takes about a second.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from pathlib import Path

from fastapi import APIRouter, Request, Response
from graspscape.services.coordinator.api.deps import SessionDep
from graspscape.services.coordinator.errors import Conflict, NotFound
from graspscape.services.coordinator.exploration.specs import stored_spec
from graspscape.services.coordinator.objects.geometry import object_spec
from graspscape.services.coordinator.state import Bounded, current, of
from graspscape.services.coordinator.store.models import ObjectRow, PoseRow
from graspscape.services.coordinator.web.data import Id
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from sqlalchemy.orm import Session

router = APIRouter(include_in_schema=False)


@dataclass(frozen=True)
class GraspPainter:
    """Draws the grasp a pose synthesizes: (object, gripper name, exploration spec, pose) →
    PNG bytes. `cache_dir` is where uploaded meshes are written for it to read."""

    paint: Callable[[ObjectSpec, str, ExplorationSpec, Pose], bytes]
    cache_dir: Path


_painter: GraspPainter | None = None
_lock = threading.Lock()  # one simulation at a time: the painter's pybullet client is shared


def use_grasp_painter(painter: GraspPainter | None) -> None:
    """Set (or with None, clear) the process's painter. The pictures it paints are kept on the
    coordinator's state (state.py), keyed by the painter."""
    global _painter
    with _lock:
        _painter = painter


def has_painter() -> bool:
    return _painter is not None


def grasp_png(session: Session, exploration_id: int, pose_id: int,
              kept: Bounded[Hashable, bytes] | None = None) -> bytes:
    """PNG bytes of the pose's grasp, kept in `kept` (default: the current state's). NotFound,
    or Conflict where no painter is wired."""
    pose = session.get(PoseRow, pose_id)
    if pose is None or pose.exploration_id != exploration_id:
        raise NotFound(f"exploration {exploration_id} has no pose {pose_id}")
    pictures = current().grasp_pictures if kept is None else kept
    with _lock:
        painter = _painter
        if painter is None:
            raise Conflict("no grasp renderer in this coordinator: it runs without the "
                           "workers' simulation (`graspscape serve` wires one in)")
        key = (painter, str(session.get_bind().url), exploration_id, pose_id)
        if (found := pictures.get(key)) is not None:
            return found
        spec = stored_spec(session, exploration_id)
        obj_row = session.get(ObjectRow, spec.object_id)
        if obj_row is None:
            raise NotFound(f"object {spec.object_id} does not exist")
        obj = object_spec(obj_row, painter.cache_dir)
        at = Pose(theta=pose.theta, phi=pose.phi, r=pose.r, roll=pose.roll, pitch=pose.pitch,
                  yaw=pose.yaw)
        data = painter.paint(obj, spec.gripper, spec, at)
        return pictures.put(key, data)


@router.get("/explorations/{exploration_id}/poses/{pose_id}/grasp.png",
            response_class=Response)
def grasp_picture(exploration_id: Id, pose_id: Id, session: SessionDep,
                  request: Request) -> Response:
    data = grasp_png(session, exploration_id, pose_id, of(request.app).grasp_pictures)
    return Response(content=data, media_type="image/png",
                    headers={"Cache-Control": "max-age=3600"})
