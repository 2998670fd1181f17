"""Where the open hand starts for a pose: placed at the lattice pose, then moved out along the
surface normal until it no longer interpenetrates the object (the simulator side of
`placement.start_gap`; the search itself is `start_gap.first_clear_gap`).

Modes (`PlacementSettings.start_gap`): "palm" backs the hand off in `backoff_step_m` steps
from the nominal palm gap; "clearance" makes r the open hand's free travel along its approach
axis (docs/design/simulation.md "Start gap").
"""

from __future__ import annotations

import numpy as np
from graspscape.shared.specs.placement import Placement, place_gripper
from graspscape.shared.specs.pose import Pose
from graspscape.shared.specs.sim import PlacementSettings
from graspscape.workers.sim.engine import SceneLike as Scene
from graspscape.workers.sim.start_gap import first_clear_gap

# World start position of the gripper frame, its rotation, the target x_c and the palm gap.
StartPose = tuple[np.ndarray, np.ndarray, np.ndarray, float]


def at_rest(placement: Placement, rotation: np.ndarray | None) -> Placement:
    """The placement turned with the object to its resting attitude on a table (None: the
    free object, whose frame is the world's)."""
    if rotation is None:
        return placement
    return Placement(position=rotation @ placement.position,
                     rotation=rotation @ placement.rotation,
                     nearest_point=rotation @ placement.nearest_point,
                     surface_normal=rotation @ placement.surface_normal, gap=placement.gap)


def place_hand(client: object, scene: Scene, position: np.ndarray, rotation: np.ndarray) -> None:
    """The open hand at rest with its gripper frame at (position, rotation); `client` is
    unused (the scene knows its engine), kept for callers."""
    del client
    scene.place_hand(position, rotation)


def penetrating(client: object, scene: Scene, tolerance: float) -> bool:
    del client
    return scene.penetrating(tolerance)


def start_pose(client: int, scene: Scene, mesh: object, pose: Pose,
               settings: PlacementSettings) -> StartPose | None:
    """World start pose of the gripper frame, the target x_c and the effective r; None where
    the hand cannot start clear of the object (`on_interpenetration`, `max_backoff_m`)."""
    placement = at_rest(place_gripper(mesh, pose), getattr(scene, "rest_rotation", None))
    position = scene.offset + placement.position
    gap = placement.gap
    if settings.start_gap == "clearance":
        return _clearance_start(client, scene, placement, position, pose.r, settings)
    backed = 0.0
    while True:
        place_hand(client, scene, position, placement.rotation)
        if not penetrating(client, scene, settings.penetration_tolerance_m):
            break
        if settings.on_interpenetration == "infeasible" or backed >= settings.max_backoff_m:
            return None
        position = position + placement.surface_normal * settings.backoff_step_m
        backed += settings.backoff_step_m
        gap += settings.backoff_step_m
    return position, placement.rotation, scene.offset + placement.nearest_point, gap


def _clearance_start(client: int, scene: Scene, placement: Placement, position: np.ndarray,
                     clearance: float, settings: PlacementSettings) -> StartPose | None:
    """`start_pose` where r is the open hand's clearance along its approach axis: the palm
    gap d₀ at which the hand along the surface normal first clears the object (from the
    surface out, in `backoff_step_m` steps, then bisected to `clearance_tolerance_m`; clear:
    no penetration deeper than `penetration_tolerance_m`), plus r. The hand can then travel r
    toward x_c before it touches, whatever its fingers meet first."""
    normal = placement.surface_normal

    def at(gap: float) -> np.ndarray:
        return position + normal * (gap - placement.gap)

    def clear(gap: float) -> bool:
        # "Touching" as the back-off has it (penetration_tolerance_m), so both modes call the
        # same starts clear.
        place_hand(client, scene, at(gap), placement.rotation)
        return not penetrating(client, scene, settings.penetration_tolerance_m)

    step, tolerance = settings.backoff_step_m, settings.clearance_tolerance_m
    # As far out as the back-off may go (the nominal palm gap + max_backoff_m: where the ray
    # passes the mug's opening that gap is 2 cm at r = 0).
    reach = placement.gap + settings.max_backoff_m
    touching = first_clear_gap(clear, 0.0, step, reach, tolerance)
    # Backing off further almost always stays clear; where it does not (a finger moving back
    # into a handle), the first clear gap beyond is taken the same way.
    gap = None if touching is None else first_clear_gap(
        clear, touching + clearance, step, settings.max_backoff_m, tolerance)
    if gap is None or (settings.on_interpenetration == "infeasible"
                       and gap > placement.gap + tolerance):
        return None
    place_hand(client, scene, at(gap), placement.rotation)  # the search may have ended elsewhere
    return (at(gap), placement.rotation, scene.offset + placement.nearest_point, gap)
