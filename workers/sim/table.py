"""The table under an object at rest (support 'plane', `SimSettings.table`), on pybullet.

World frame = table frame (plus the evaluator's offset): z up, the plane at the height that
puts the object's lowest point on it at its resting pose. The object is free on the plane
while the hand approaches and closes; its weight is applied to it alone, as a force each step
(`Scene.object_weight_n`), because the arm that carries the hand compensates the hand's own
weight: under global gravity a hand pushed by the approach force f_c (a few newtons) would
sink under its ~20 N. From lift-off on, gravity is global as in the free-object trajectory.
"""

from __future__ import annotations

import numpy as np
import pybullet as p
from graspscape.shared.specs.results import Outcome, PhaseTimes
from graspscape.shared.specs.support import TableScene
from graspscape.workers.sim.bullet import get_closest_points
from graspscape.workers.sim.trajectory import min_jerk, rotation_angle

# The plane is the top face of a static box, wide and thick enough that nothing the hand
# reaches passes its edge or through it in a step.
TABLE_HALF_EXTENTS = (1.0, 1.0, 0.05)


def add_table(client: int, table: TableScene, offset: np.ndarray, object_friction: float) -> int:
    """The static table body under the object centred at `offset`. The spec's friction is the
    object–table pair's: pybullet multiplies the two bodies' coefficients, so the table body
    gets the spec's value divided by the object's."""
    half = np.array(TABLE_HALF_EXTENTS)
    top = offset[2] - table.resting.position[2]
    shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half.tolist(), physicsClientId=client)
    visual = p.createVisualShape(p.GEOM_BOX, halfExtents=half.tolist(),
                                 rgbaColor=[0.55, 0.5, 0.45, 1.0], physicsClientId=client)
    body = p.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape,
                             baseVisualShapeIndex=visual,
                             basePosition=[offset[0], offset[1], top - half[2]],
                             physicsClientId=client)
    p.changeDynamics(body, -1, lateralFriction=table.friction / max(object_friction, 1e-6),
                     physicsClientId=client)
    return body


def set_table(scene, table: TableScene, object_friction: float) -> None:
    """Puts the table under the scene's object, at rest at its resting pose, and its watch."""
    scene.table_body = add_table(scene.client, table, scene.offset, object_friction)
    scene.rest_rotation = table.resting.rotation()
    scene.watch = TableWatch(table, scene.object_pose())


def start_outcome(scene) -> Outcome | None:
    """`infeasible_table` where the hand placed at its start reaches into the table."""
    if scene.table_body is not None and hand_in_table(scene):
        return Outcome.INFEASIBLE_TABLE
    return None


def closing_outcome(scene) -> Outcome | None:
    """`knocked` where the watch saw the hand tip or drag the object before lift-off."""
    return Outcome.KNOCKED if scene.watch is not None and scene.watch.knocked else None


def hand_in_table(scene) -> bool:
    """Whether any collision shape of the hand, where it is placed now, reaches into the
    table: a start no robot can take (checked before any physics step)."""
    points = get_closest_points(scene.client, scene.hand.body, scene.table_body, 0.0)
    return any(pt.contact_distance < 0.0 for pt in points)


class TableWatch:
    """Tells whether the hand knocked the object over or dragged it before lift-off: looked
    at once in `EVERY_STEPS` steps, the object stayed moved or turned from its resting pose
    beyond the table's tolerances, with fewer than two of the hand's links touching it, for
    `LOOKS` looks in a row (a push, a flick, a tip: not a grasp). An object the closing
    fingers squeeze up into the palm moves too, in the hand: it flies free for a step or two,
    not for `LOOKS` looks."""

    EVERY_STEPS = 8
    LOOKS = 3

    def __init__(self, table: TableScene, rest: tuple[np.ndarray, np.ndarray]) -> None:
        self.table, self.rest = table, rest
        self.knocked = False
        self._steps = self._outside = 0

    def reset(self) -> None:
        self.knocked, self._steps, self._outside = False, 0, 0

    def look(self, scene) -> None:
        self._steps += 1
        if self.knocked or self._steps % self.EVERY_STEPS:
            return
        if disturbed(scene, self.table, self.rest) and len(scene.touching_links()) < 2:
            self._outside += 1
            self.knocked = self._outside >= self.LOOKS
        else:
            self._outside = 0


def disturbed(scene, table: TableScene, rest: tuple[np.ndarray, np.ndarray]) -> bool:
    """Whether the object is moved or turned from its resting pose `rest` (position,
    rotation) beyond the table's tolerances."""
    pos, rot = scene.object_pose()
    moved = float(np.linalg.norm(pos - rest[0]))
    turned = rotation_angle(rot @ rest[1].T)
    return moved > table.moved_tolerance_m or turned > table.turned_tolerance_rad


def lift_off(scene, table: TableScene, phases: PhaseTimes) -> None:
    """The first phase of the reference trajectory on a table: the hand, gripping, straight up
    by `lift_off_m` on a minimum-jerk profile, under global gravity."""
    start_pos, start_rot = scene.hand.frame_pose()
    steps = max(1, round(table.lift_off_s / scene.dt))
    up = np.array([0.0, 0.0, table.lift_off_m])
    for step in range(1, steps + 1):
        scene.drive_to(start_pos + up * min_jerk(step / steps), start_rot)
        scene.step()
    phases.trajectory_steps += steps
