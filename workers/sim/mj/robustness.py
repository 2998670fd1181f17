"""The margins of workers/sim/robustness.py in MuJoCo: the torque margin (the least closing
effort at which the synthesized grasp still holds through the task) and the friction margin
(the least object friction), by the same bisection (`lowest_holding`). The hold-still tests
(gravity, force, tug, shake) are not built for MuJoCo: their fields stay None."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from graspscape.shared.specs.results import PhaseTimes, RobustnessReport
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.workers.sim.mj.world import HAND_LINK_FRICTION
from graspscape.workers.sim.robustness import lowest_holding, torque_ratio


@dataclass(frozen=True)
class MjGrasp:
    """The synthesized grasp: the whole simulation state and the motor commands."""

    state: mujoco.MjData
    commands: dict[int, tuple[int, float, float]]
    effort: float
    drive: tuple[np.ndarray, np.ndarray, float]  # target position, quaternion (w, x, y, z), cap
    friction: float  # the object's own coefficient (pybullet's lateral friction)


def capture(evaluator) -> MjGrasp:
    scene, hand = evaluator.scene, evaluator.scene.hand
    state = mujoco.MjData(evaluator.world.model)
    mujoco.mj_copyData(state, evaluator.world.model, evaluator.data)
    return MjGrasp(state, dict(hand.commands), float(hand.effort),
                   (scene._target_pos.copy(), scene._target_quat.copy(), scene._cap),
                   evaluator.prepared.friction)


def _set_friction(evaluator, mu: float) -> None:
    """Every hand-object pair's coefficient for an object of friction `mu` (world.py)."""
    evaluator.world.model.geom_friction[:, 0] = mu * HAND_LINK_FRICTION


def holds(evaluator, grasp: MjGrasp, *, effort: float | None = None,
          friction: float | None = None) -> bool:
    """Whether the grasp, restored with the closing effort `effort` and the object friction
    `friction`, holds through release and the reference task (no probes)."""
    scene, hand = evaluator.scene, evaluator.scene.hand
    mujoco.mj_copyData(evaluator.data, evaluator.world.model, grasp.state)
    hand.commands = dict(grasp.commands)
    hand.effort = grasp.effort
    hand.reissue(effort)
    scene.set_gravity(0.0)
    scene._set_target(*grasp.drive)
    try:
        if friction is not None:
            _set_friction(evaluator, friction)
        held, _, _ = evaluator._run_trajectory(PhaseTimes(), probes=False)
    finally:
        _set_friction(evaluator, grasp.friction)
        hand.reissue()
    return held


def run_tests(evaluator, grasp: MjGrasp, settings: RobustnessSettings) -> RobustnessReport:
    out: dict[str, float | None] = {}
    if not (settings.runs("torque_margin") or settings.runs("friction_margin")):
        return RobustnessReport()
    nominal = holds(evaluator, grasp)
    if settings.runs("torque_margin"):
        tau = lowest_holding(lambda t: holds(evaluator, grasp, effort=t),
                             settings.torque_lo_fraction * grasp.effort, grasp.effort,
                             settings.margin_trials, hi_holds=nominal)
        out["torque_margin_nm"] = tau
        out["torque_margin_ratio"] = torque_ratio(tau, grasp.effort)
    if settings.runs("friction_margin"):
        hi = grasp.friction
        out["friction_margin"] = lowest_holding(
            lambda mu: holds(evaluator, grasp, friction=mu), min(settings.friction_lo, hi), hi,
            settings.margin_trials, hi_holds=nominal)
    return RobustnessReport(**out)
