"""The viewer's grasp pictures drawn by the workers' renderer (`workers/sim/render.py`): the
painter `compose.wire` hands the coordinator (services/coordinator/web/grasp.py)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from graspscape.services.coordinator.web.grasp import GraspPainter
from graspscape.shared.specs.exploration import ExplorationSpec
from graspscape.shared.specs.objects import ObjectSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.workers.sim.evaluate import default_cache_dir, render_pose


def paint(obj: ObjectSpec, gripper: str, spec: ExplorationSpec, pose: Pose) -> bytes:
    """PNG of the grasp the pose synthesizes, simulated with the exploration's settings. The
    robustness tests are left out: they change nothing in the picture and cost seconds."""
    settings = spec.settings.model_copy(update={"robustness": RobustnessSettings()})
    with tempfile.TemporaryDirectory(prefix="graspscape-grasp-") as folder:
        path, _ = render_pose(pose, Path(folder) / "grasp.png", obj=obj, gripper=gripper,
                              settings=settings)
        return path.read_bytes()


def painter() -> GraspPainter:
    return GraspPainter(paint=paint, cache_dir=default_cache_dir())
