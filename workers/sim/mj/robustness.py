"""The robustness margins and grasp tests of workers/sim/robustness.py in MuJoCo: the same
definitions and the same code (grasp_tests.py) through `MjTrials`, MuJoCo's way to put the
synthesized grasp back, let it go and load the object.

- The synthesized grasp is a copy of the whole mjData (positions, velocities, warm start,
  controls, the fixture's activation); restoring copies it back, the motor commands with it
  (reissued: the model holds the gains), no gravity, the object's own friction.
- Release: the fixture weld switched off, gravity set along the test's direction. The hand's
  links keep their gravity compensation (the arm carries the hand, as through the trajectory),
  so a gravity test loads the object only, where pybullet's gravity also pulls on the fingers.
- A load on the object: `xfrc_applied` at its centre of mass (the body's origin), cleared
  before the next step is loaded and on every restore.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from graspscape.shared.specs.results import PhaseTimes, RobustnessReport
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.workers.sim import grasp_tests
from graspscape.workers.sim.mj.world import HAND_LINK_FRICTION


@dataclass(frozen=True)
class MjGrasp:
    """The synthesized grasp: the whole simulation state and the motor commands."""

    state: mujoco.MjData
    commands: dict[int, tuple[int, float, float]]
    effort: float
    drive: tuple[np.ndarray, np.ndarray, float]  # target position, quaternion (w, x, y, z), cap
    friction: float  # the object's own coefficient (pybullet's lateral friction)
    frame_rotation: np.ndarray  # the gripper frame at synthesis, world
    mass_kg: float


def capture(evaluator) -> MjGrasp:
    scene, hand = evaluator.scene, evaluator.scene.hand
    state = mujoco.MjData(evaluator.world.model)
    mujoco.mj_copyData(state, evaluator.world.model, evaluator.data)
    return MjGrasp(state, dict(hand.commands), float(hand.effort),
                   (scene._target_pos.copy(), scene._target_quat.copy(), scene._cap),
                   evaluator.prepared.friction, hand.frame_pose()[1],
                   float(evaluator.prepared.mass_kg))


def _set_friction(evaluator, mu: float) -> None:
    """Every hand-object pair's coefficient for an object of friction `mu` (world.py)."""
    model = evaluator.world.model
    colliding = (model.geom_contype != 0) | (model.geom_conaffinity != 0)
    model.geom_friction[colliding, 0] = mu * HAND_LINK_FRICTION


def restore(evaluator, grasp: MjGrasp, *, effort: float | None = None) -> None:
    """The grasp as synthesis left it, the fingers' forces scaled to `effort` if given."""
    scene, hand = evaluator.scene, evaluator.scene.hand
    mujoco.mj_copyData(evaluator.data, evaluator.world.model, grasp.state)
    evaluator.data.xfrc_applied[:] = 0.0
    hand.commands = dict(grasp.commands)
    hand.effort = grasp.effort
    hand.reissue(effort)
    scene.set_gravity(0.0)
    scene._set_target(*grasp.drive)
    _set_friction(evaluator, grasp.friction)


def holds(evaluator, grasp: MjGrasp, *, effort: float | None = None,
          friction: float | None = None) -> bool:
    """Whether the grasp, restored with the closing effort `effort` and the object friction
    `friction`, holds through release and the reference task (no probes)."""
    restore(evaluator, grasp, effort=effort)
    try:
        if friction is not None:
            _set_friction(evaluator, friction)
        held, _, _ = evaluator._run_trajectory(PhaseTimes(), probes=False)
    finally:
        _set_friction(evaluator, grasp.friction)
        evaluator.scene.hand.reissue()
    return held


class MjTrials:
    """grasp_tests.GraspTrials on MuJoCo (module docstring)."""

    def __init__(self, evaluator, grasp: MjGrasp) -> None:
        self.evaluator, self.grasp, self.scene = evaluator, grasp, evaluator.scene
        self.effort, self.friction, self.mass_kg = grasp.effort, grasp.friction, grasp.mass_kg
        self.frame_rotation = grasp.frame_rotation

    def restore(self) -> None:
        restore(self.evaluator, self.grasp)

    def release(self, gravity: np.ndarray) -> None:
        self.scene.hold_object(False)
        self.evaluator.world.model.opt.gravity[:] = gravity

    def push(self, force: np.ndarray) -> None:
        self.evaluator.data.xfrc_applied[self.evaluator.world.object_body, :3] = force

    def holds(self, *, effort: float | None = None, friction: float | None = None) -> bool:
        return holds(self.evaluator, self.grasp, effort=effort, friction=friction)


def run_tests(evaluator, grasp: MjGrasp, settings: RobustnessSettings,
              times: dict[str, float] | None = None) -> RobustnessReport:
    """The tests `settings` chooses (grasp_tests.run_tests); the evaluator's own state, loads
    and friction are put back afterwards."""
    try:
        return grasp_tests.run_tests(MjTrials(evaluator, grasp), settings, times)
    finally:
        restore(evaluator, grasp)
        evaluator.scene.hand.reissue()
