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

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as p
from graspscape.shared.specs.results import PhaseTimes, RobustnessReport
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.workers.sim.bullet import (
    get_constraint_info,
    get_dynamics_info,
    restore_state_clean,
    save_state,
)
from scipy.spatial.transform import Rotation

# --- pure helpers ------------------------------------------------------------------------


def directions() -> np.ndarray:
    """The six unit directions +x, −x, +y, −y, +z, −z (rows)."""
    return np.vstack([sign * axis for axis in np.eye(3) for sign in (1.0, -1.0)])


def relative_pose(hand_pos: np.ndarray, hand_rot: np.ndarray, obj_pos: np.ndarray,
                  obj_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The object's pose in the hand frame."""
    return hand_rot.T @ (obj_pos - hand_pos), hand_rot.T @ obj_rot


def displacement(rest: tuple[np.ndarray, np.ndarray],
                 now: tuple[np.ndarray, np.ndarray]) -> tuple[float, float]:
    """Distance (m) and angle (rad) between two relative poses of the object in the hand."""
    moved = float(np.linalg.norm(now[0] - rest[0]))
    turned = float(Rotation.from_matrix(now[1] @ rest[1].T).magnitude())
    return moved, turned


def lowest_holding(holds: Callable[[float], bool], lo: float, hi: float, trials: int,
                   hi_holds: bool | None = None) -> float | None:
    """The lowest value in [lo, hi] at which `holds`, by bisection in at most `trials` trials
    (a known `hi_holds` counts as the first, run elsewhere): None if `hi` does not hold, `lo`
    if `lo` does, else the lowest value seen to hold. Assumes holding is monotone in it."""
    if hi_holds is None:
        hi_holds = holds(hi)
    if not hi_holds:
        return None
    used = 2  # hi (run here or known) and lo
    if holds(lo):
        return lo
    while used < trials:
        mid = 0.5 * (lo + hi)
        used += 1
        if holds(mid):
            hi = mid
        else:
            lo = mid
    return hi


def torque_ratio(tau_min: float | None, tau_c: float) -> float | None:
    """1 − τ_min/τ_c: 1 holds with almost no effort, 0 needs all of it."""
    return None if tau_min is None else 1.0 - tau_min / tau_c


def ramp(t: float, top: float, ramp_s: float) -> float:
    """A linear ramp from 0 at t = 0 to `top` at `ramp_s`, flat after."""
    return top * min(1.0, max(0.0, t / ramp_s))


def shake_timing(frequency_hz: float, axis_s: float) -> float:
    """Time per axis, rounded to whole periods (at least one)."""
    return max(1, round(axis_s * frequency_hz)) / frequency_hz


def shake_offset(t: float, amplitude_m: float, frequency_hz: float, axis_s: float) -> np.ndarray:
    """World displacement of the hand at time t into the shake: A(1 − cos 2πft) along x, then
    y, then z, `axis_s` (rounded to whole periods) each; zero before and after."""
    per_axis = shake_timing(frequency_hz, axis_s)
    axis = math.floor(t / per_axis) if t >= 0.0 else 3
    offset = np.zeros(3)
    if axis < 3:
        tau = t - axis * per_axis
        offset[axis] = amplitude_m * (1.0 - math.cos(2.0 * math.pi * frequency_hz * tau))
    return offset


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


# --- hold-still tests -------------------------------------------------------------------

Exceeded = Callable[[float, float], bool]


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


def _hold_still(evaluator, grasp: SynthesizedGrasp, *, gravity: np.ndarray, settle_s: float,
                steps: int, exceeded: Exceeded,
                force: Callable[[int], np.ndarray] | None = None,
                offset: Callable[[int], np.ndarray] | None = None) -> int | None:
    """Restores the grasp, lets the fixture go with `gravity` on, holds the hand still for
    the settle, then runs `steps` steps with `force(step)` (world, N) on the object's centre of
    mass and the hand driven to its pose + `offset(step)` (world). Returns the first step at
    which `exceeded(distance, angle)` of the object in the hand since the settle (−1 where the
    object touches no link after the settle), or None if it never is."""
    scene, cid, hand = evaluator.scene, evaluator.client, evaluator.scene.hand
    restore_grasp(evaluator, grasp)
    p.changeConstraint(scene.fixture_constraint, maxForce=0.0, physicsClientId=cid)
    p.setGravity(*gravity.tolist(), physicsClientId=cid)
    hold_pos, hold_rot = hand.frame_pose()
    scene.drive_to(hold_pos, hold_rot)
    for _ in range(round(settle_s / scene.dt)):
        scene.step()
    if not scene.in_contact():
        return -1
    rest = relative_pose(*hand.frame_pose(), *scene.object_pose())
    for step in range(steps):
        if offset is not None:
            scene.drive_to(hold_pos + offset(step), hold_rot)
        if force is not None:
            p.applyExternalForce(scene.object_body, -1, force(step).tolist(),
                                 scene.object_pose()[0].tolist(), p.WORLD_FRAME,
                                 physicsClientId=cid)
        scene.step()
        now = relative_pose(*hand.frame_pose(), *scene.object_pose())
        if exceeded(*displacement(rest, now)):
            return step
    return None


def _load_directions(grasp: SynthesizedGrasp, settings: RobustnessSettings) -> np.ndarray:
    rows = directions()
    return rows @ grasp.frame_rotation.T if settings.load_frame == "hand" else rows


def gravity_test(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings) -> float:
    """Share of the six gravity directions in which the object stays in the hand."""
    s = settings
    steps = round(s.gravity_duration_s / evaluator.scene.dt)

    def exceeded(moved: float, turned: float) -> bool:
        return moved >= s.gravity_max_shift_m or turned >= s.gravity_max_turn_rad

    passed = [_hold_still(evaluator, grasp, gravity=s.gravity_m_s2 * d, settle_s=s.settle_s,
                          steps=steps, exceeded=exceeded) is None
              for d in _load_directions(grasp, s)]
    return sum(passed) / len(passed)


def force_test(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings) -> float:
    """Share of the six directions in which the object resists a force of `force_weights`
    object weights without gravity."""
    s = settings
    steps = round(s.force_duration_s / evaluator.scene.dt)
    magnitude = s.force_weights * grasp.mass_kg * s.gravity_m_s2

    def exceeded(moved: float, turned: float) -> bool:
        return moved >= s.force_max_shift_m or turned >= s.force_max_turn_rad

    passed = []
    for d in _load_directions(grasp, s):
        load = magnitude * d
        passed.append(_hold_still(evaluator, grasp, gravity=np.zeros(3), settle_s=s.settle_s,
                                  steps=steps, exceeded=exceeded,
                                  force=lambda _step, load=load: load) is None)
    return sum(passed) / len(passed)


def tug_test(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings) -> float:
    """The pull along the approach axis (N) at which the object slips out of the hand."""
    s = settings
    dt = evaluator.scene.dt
    top = s.tug_max_weights * grasp.mass_kg * s.gravity_m_s2
    axis = grasp.frame_rotation[:, 2]  # the approach axis, palm → object

    def pull(step: int) -> float:
        return ramp((step + 1) * dt, top, s.tug_ramp_s)

    slipped = _hold_still(evaluator, grasp, gravity=np.zeros(3), settle_s=s.settle_s,
                          steps=round(s.tug_ramp_s / dt),
                          exceeded=lambda moved, _turned: moved >= s.tug_slip_m,
                          force=lambda step: pull(step) * axis)
    if slipped is None:
        return top
    return 0.0 if slipped < 0 else pull(slipped)


def shake_test(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings) -> float:
    """Time into the shake (s) at which the object falls off; the full duration if never."""
    s = settings
    dt = evaluator.scene.dt
    duration = 3 * shake_timing(s.shake_frequency_hz, s.shake_axis_s)
    fell = _hold_still(
        evaluator, grasp, gravity=np.array([0.0, 0.0, -s.gravity_m_s2]), settle_s=s.settle_s,
        steps=round(duration / dt), exceeded=lambda moved, _turned: moved >= s.shake_fall_m,
        offset=lambda step: shake_offset((step + 1) * dt, s.shake_amplitude_m,
                                         s.shake_frequency_hz, s.shake_axis_s))
    if fell is None:
        return duration
    return 0.0 if fell < 0 else (fell + 1) * dt


# --- margins ----------------------------------------------------------------------------


def torque_margin(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings,
                  nominal: bool | None = None) -> float | None:
    """Least closing effort (N·m) at which the synthesized grasp still holds."""
    return lowest_holding(lambda tau: holds_along_trajectory(evaluator, grasp, effort=tau),
                          settings.torque_lo_fraction * grasp.effort, grasp.effort,
                          settings.margin_trials, hi_holds=nominal)


def friction_margin(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings,
                    nominal: bool | None = None) -> float | None:
    """Least lateral friction coefficient of the object at which the grasp still holds."""
    hi = grasp.friction
    lo = min(settings.friction_lo, hi)
    return lowest_holding(lambda mu: holds_along_trajectory(evaluator, grasp, friction=mu),
                          lo, hi, settings.margin_trials, hi_holds=nominal)


def run_tests(evaluator, grasp: SynthesizedGrasp, settings: RobustnessSettings,
              times: dict[str, float] | None = None) -> RobustnessReport:
    """Runs the tests `settings` chooses on `grasp`; `times`, if given, gets each test's
    wall time (s; the nominal trajectory shared by the margins is its own entry)."""
    out: dict[str, float | None] = {}

    def timed(name: str, fn: Callable[[], float | None]) -> float | None:
        t0 = time.perf_counter()
        value = fn()
        if times is not None:
            times[name] = time.perf_counter() - t0
        return value

    nominal = None
    if settings.runs("torque_margin") or settings.runs("friction_margin"):
        nominal = timed("nominal", lambda: holds_along_trajectory(evaluator, grasp))
    if settings.runs("torque_margin"):
        tau = timed("torque_margin", lambda: torque_margin(evaluator, grasp, settings, nominal))
        out["torque_margin_nm"] = tau
        out["torque_margin_ratio"] = torque_ratio(tau, grasp.effort)
    if settings.runs("friction_margin"):
        out["friction_margin"] = timed(
            "friction_margin", lambda: friction_margin(evaluator, grasp, settings, nominal))
    if settings.runs("gravity"):
        out["gravity_test_share"] = timed(
            "gravity", lambda: gravity_test(evaluator, grasp, settings))
    if settings.runs("force"):
        out["force_test_share"] = timed("force", lambda: force_test(evaluator, grasp, settings))
    if settings.runs("tug"):
        out["tug_force_n"] = timed("tug", lambda: tug_test(evaluator, grasp, settings))
    if settings.runs("shake"):
        out["shake_survival_s"] = timed("shake", lambda: shake_test(evaluator, grasp, settings))
    return RobustnessReport(**out)
