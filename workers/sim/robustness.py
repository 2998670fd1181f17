"""Robustness margins and the community's grasp tests, run on a synthesized grasp.

Every test starts from the *synthesized grasp*: the state right after the policy has closed
the hand, before the fixture lets the object go (`Evaluator.synthesized` saves it). Each trial
restores it with `restore_grasp`: bodies through a contact-free state (no contact
cache carries over, so a trial does not depend on what ran before it), the motor commands the
policy left (pybullet's saved states hold none), the drive and fixture constraints, zero
gravity and the object's friction. Only the fixture is then released; the hand keeps its joint
configuration and its motors, nothing is synthesized again. docs/concepts/quality.md, "Robustness
margins and grasp tests", has the same list; `RobustnessSettings` (shared/specs/robustness.py)
holds every parameter.

Margins (bisection over trials of the release + the reference trajectory, without μs probes;
`margin_trials` = 6 trajectories per margin: the nominal trial, shared by both margins, the
lower bound, then 4 halvings, so the bracket is 1/16 of the range):

- torque margin τ_min (N·m): the lowest closing effort at which the synthesized grasp still
  holds along the trajectory. Every finger motor's force is scaled to τ/τ_c (a blocked phalanx
  pushes with its share of τ, a held one holds with hold_factor × τ); the spread motors keep
  theirs (the scissor is its own actuator). Range [0.02 τ_c, τ_c], τ_c the closing effort the
  grasp was made with. torque_margin_ratio = 1 − τ_min/τ_c: 1 holds with almost no effort, 0
  needs all of it. Unlike workers/sim/effort.py (which synthesizes the grasp again at each
  torque, as the paper's Table 1), this keeps the grasp and asks how much squeeze it needs.
- friction margin: the lowest lateral friction coefficient of the object (pybullet
  `changeDynamics(lateralFriction=…)` on the object's base) at which the grasp still holds.
  pybullet combines friction as the product of the two bodies' coefficients and the hand's
  links keep 0.5, so the contact's Coulomb coefficient is 0.5 × the reported value. Range
  [0.02, the object's own coefficient]. Restoring drops every contact manifold, so the new
  coefficient is the one each contact is made with (a manifold point keeps the combined
  friction of its creation).

A margin is None where the grasp drops even at the nominal value (τ_c, the object's friction)
from the restored state, and the lower bound where it holds there.

Hold-still tests: the drive holds the hand at its synthesized pose, the fixture lets go and,
with no load, the grasp takes the object for `settle_s` = 0.1 s (the trajectory's settle:
released, an enveloped object is drawn into the palm by centimetres, which is the grasp taking
hold, not a slip). Motion is then measured relative to the hand from where the object came to
rest; a test fails at the first step the motion passes its threshold, and at once where the
object touches no link after the settle.

- gravity test (DexGraspNet, Wang et al. ICRA 2023): gravity 9.81 m/s² (pybullet's, so it
  acts on the hand's links too, as turning the hand would) along each of ±x ±y ±z of the
  gripper frame (z the approach axis; `load_frame="world"` for the world's) for 1 s; a
  direction passes if the object moves < 2 cm and turns < 15°. Report: share of the 6 passed.
- force test (DexGraspBench, Chen et al. 2025): no gravity; an external force of one object
  weight m·g (so the test reads "would the grasp hold the object's weight in any direction",
  without the links' own weight) on the object's centre of mass along each of ±x ±y ±z of the
  gripper frame for 1 s; passes if the object moves < 5 cm and turns < 15°. Report: share.
- tug test (GraspDataGen-style): no gravity; a pull on the object's centre of mass along the
  approach axis, away from the palm (gripper +z), ramping linearly 0 → 50 m·g over 1 s (50
  weights: a few times what the closing effort can hold by friction, so the ramp's top means
  "did not slip"); report the pull (N) at the first step the object is > 1 cm from where it
  rested in the hand, or the ramp's top if it never is (0 where nothing touches it).
- shake test (MultiGripperGrasp, Casas et al. 2024): gravity on (world −z); the hand is driven
  along world x, then y, then z, each for 0.5 s, by d(t) = A(1 − cos 2πft), A = 2 cm, f = 4 Hz:
  a ±2 cm swing about a point 2 cm off the start, 2 whole periods per axis, so each axis starts
  and ends at rest in the synthesized pose (no velocity step between axes; the time per axis is
  rounded to whole periods), peak acceleration A(2πf)² = 12.6 m/s² ≈ 1.3 g. Report: the time
  into the shake at which the object first is > 3 cm from where it rested in the hand, or the
  full 1.5 s if it never is (0 where nothing touches it after the settle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pybullet as p
from graspscape.shared.specs.results import PhaseTimes, RobustnessReport
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.workers.sim import grasp_tests
from graspscape.workers.sim.bullet import (
    get_constraint_info,
    get_dynamics_info,
    restore_state_clean,
    save_state,
)
from graspscape.workers.sim.robustness_math import (  # noqa: F401 (the tests' names, here too)
    directions,
    displacement,
    lowest_holding,
    ramp,
    relative_pose,
    shake_offset,
    shake_timing,
    torque_ratio,
)

# --- the synthesized grasp --------------------------------------------------------------


@dataclass(frozen=True)
class SynthesizedGrasp:
    """What `restore_grasp` needs to put a synthesized grasp back."""

    state: int  # pybullet saved state (bodies, joints, velocities)
    commands: dict[int, tuple[int, float, float]]  # the hand's motor commands
    effort: float  # the closing effort τ_c the commands were made with, N·m
    drive: tuple[list[float], list[float], float]  # pivot, orientation, max force
    fixture: tuple[list[float], list[float], float]
    friction: float  # the object's lateral friction coefficient
    frame_position: np.ndarray  # gripper frame at synthesis, world
    frame_rotation: np.ndarray
    mass_kg: float


def _constraint(client: int, uid: int) -> tuple[list[float], list[float], float]:
    info = get_constraint_info(client, uid)
    return (list(info.joint_pivot_in_child), list(info.joint_frame_orientation_child),
            float(info.max_applied_force))


def capture_grasp(scene) -> SynthesizedGrasp:
    """Saves the present state (the end of synthesis) and what a restore cannot recover."""
    cid, hand = scene.client, scene.hand
    frame_position, frame_rotation = hand.frame_pose()
    dynamics = get_dynamics_info(cid, scene.object_body)
    return SynthesizedGrasp(
        state=save_state(cid),
        commands=dict(hand.commands),
        effort=float(hand.effort),
        drive=_constraint(cid, scene.drive_constraint),
        fixture=_constraint(cid, scene.fixture_constraint),
        friction=float(dynamics.lateral_friction),
        frame_position=frame_position,
        frame_rotation=frame_rotation,
        mass_kg=float(dynamics.mass),
    )


# --- restoring a grasp ----------------------------------------------------------------


def restore_grasp(evaluator, grasp: SynthesizedGrasp, *, effort: float | None = None) -> None:
    """Puts the simulation back where synthesis left it: bodies (through a contact-free
    state, so no contact cache carries over from what ran before), motor commands (with
    `effort`, the fingers' forces scaled to that closing effort), drive and fixture
    constraints, zero gravity and the object's own friction."""
    scene, cid = evaluator.scene, evaluator.client
    restore_state_clean(cid, grasp.state, contact_free=evaluator.pristine)
    scene.hand.commands = dict(grasp.commands)
    scene.hand.effort = grasp.effort
    scene.hand.reissue(effort)
    pivot, orientation, force = grasp.drive
    p.changeConstraint(scene.drive_constraint, jointChildPivot=pivot,
                       jointChildFrameOrientation=orientation, maxForce=force,
                       physicsClientId=cid)
    pivot, orientation, force = grasp.fixture
    p.changeConstraint(scene.fixture_constraint, jointChildPivot=pivot,
                       jointChildFrameOrientation=orientation, maxForce=force,
                       physicsClientId=cid)
    p.setGravity(0, 0, 0, physicsClientId=cid)
    p.changeDynamics(scene.object_body, -1, lateralFriction=grasp.friction,
                     physicsClientId=cid)


def holds_along_trajectory(evaluator, grasp: SynthesizedGrasp, *, effort: float | None = None,
                       friction: float | None = None) -> bool:
    """Whether the synthesized grasp, restored with the fingers' closing effort `effort`
    (N·m) and the object's lateral friction `friction`, holds through the release and the
    reference trajectory (no μs probes). The object's friction is put back afterwards."""
    restore_grasp(evaluator, grasp, effort=effort)
    try:
        if friction is not None:
            p.changeDynamics(evaluator.scene.object_body, -1, lateralFriction=friction,
                             physicsClientId=evaluator.client)
        held, _, _ = evaluator._run_trajectory(PhaseTimes(), probes=False)
    finally:
        p.changeDynamics(evaluator.scene.object_body, -1, lateralFriction=grasp.friction,
                         physicsClientId=evaluator.client)
    return held


# --- the tests, through pybullet's trials ------------------------------------------------


@dataclass
class BulletTrials:
    """grasp_tests.GraspTrials on pybullet: the synthesized grasp restored from a saved state,
    the fixture a constraint whose force cap drops to 0, the load an external force."""

    evaluator: object
    grasp: SynthesizedGrasp

    def __post_init__(self) -> None:
        self.scene = self.evaluator.scene
        g = self.grasp
        self.effort, self.friction, self.mass_kg = g.effort, g.friction, g.mass_kg
        self.frame_rotation = g.frame_rotation

    def restore(self) -> None:
        restore_grasp(self.evaluator, self.grasp)

    def release(self, gravity: np.ndarray) -> None:
        cid = self.evaluator.client
        p.changeConstraint(self.scene.fixture_constraint, maxForce=0.0, physicsClientId=cid)
        p.setGravity(*gravity.tolist(), physicsClientId=cid)

    def push(self, force: np.ndarray) -> None:
        p.applyExternalForce(self.scene.object_body, -1, force.tolist(),
                             self.scene.object_pose()[0].tolist(), p.WORLD_FRAME,
                             physicsClientId=self.evaluator.client)

    def holds(self, *, effort: float | None = None, friction: float | None = None) -> bool:
        return holds_along_trajectory(self.evaluator, self.grasp, effort=effort,
                                      friction=friction)


def run_tests(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings,
              times: dict[str, float] | None = None) -> RobustnessReport:
    """Runs the tests `settings` chooses on `grasp` (grasp_tests.run_tests); `times`, if given,
    gets each test's wall time."""
    return grasp_tests.run_tests(BulletTrials(evaluator, grasp), settings, times)
