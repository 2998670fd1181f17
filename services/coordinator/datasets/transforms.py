"""4×4 homogeneous transforms of the gripper frame in the object frame, for dataset exports.

The gripper frame is the palm surface centre, z along the palm normal (toward the object),
−x toward the two-finger side (shared/specs/placement.py). The object frame is the object's
centre-of-mass frame as the workers simulate it (the prepared mesh, principal axes where the
source's axes were not). A pose that formed a grasp stores that frame at grasp time in its
grasp configuration (`workers/sim/evaluate.py`: position and xyzw quaternion relative to the
object's pose then); a pose that formed none gets its start pose, placed as the worker placed
it, including the back-off its `effective_r` records.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from graspscape.shared.specs.placement import Placement, approach_placement, with_attitude
from scipy.spatial.transform import Rotation


def homogeneous(rotations: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """N×4×4 transforms from N×3×3 rotations and N×3 positions."""
    out = np.zeros((len(positions), 4, 4))
    out[:, :3, :3] = rotations
    out[:, :3, 3] = positions
    out[:, 3, 3] = 1.0
    return out


def grasp_transforms(grasps: Sequence[Mapping[str, Any]]) -> np.ndarray:
    """The transforms of stored grasp configurations (`GraspConfiguration` as JSON)."""
    if not grasps:
        return np.zeros((0, 4, 4))
    positions = np.array([g["base_position"] for g in grasps], dtype=float)
    rotations = Rotation.from_quat([g["base_orientation"] for g in grasps]).as_matrix()
    return homogeneous(rotations, positions)


class StartPoses:
    """Start transforms of poses on one object's mesh. The approach placement (the sphere
    tracing of the mesh) is the costly part and the same for every attitude of one approach
    point, so the last `cache_size` of them are kept."""

    def __init__(self, mesh: Any, cache_size: int = 4096) -> None:
        self.mesh = mesh
        self.cache_size = cache_size
        self._approaches: OrderedDict[tuple[float, float, float], Placement] = OrderedDict()

    def _approach(self, theta: float, phi: float, r: float) -> Placement:
        key = (theta, phi, r)
        found = self._approaches.get(key)
        if found is None:
            found = approach_placement(self.mesh, theta, phi, r)
            self._approaches[key] = found
            if len(self._approaches) > self.cache_size:
                self._approaches.popitem(last=False)
        else:
            self._approaches.move_to_end(key)
        return found

    def transform(self, theta: float, phi: float, r: float, roll: float, pitch: float,
                  yaw: float, effective_r: float | None) -> np.ndarray:
        placed = with_attitude(self._approach(theta, phi, r), roll, pitch, yaw)
        position = placed.position
        if effective_r is not None and effective_r > placed.gap:
            # The worker backed off along the surface normal until nothing interpenetrated;
            # the gap it reached is the stored effective_r.
            position = position + placed.surface_normal * (effective_r - placed.gap)
        return homogeneous(placed.rotation[None], position[None])[0]
