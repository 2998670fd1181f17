"""The margins and the hold-still tests of workers/sim/robustness.py (the definitions are in its
docstring and docs/concepts/quality.md), run through `GraspTrials`: what one engine does to put a
synthesized grasp back, let it go, and load the object. pybullet's trials are
robustness.BulletTrials, MuJoCo's mj/robustness.MjTrials; nothing below branches on the engine.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Protocol

import numpy as np
from graspscape.shared.specs.results import RobustnessReport
from graspscape.shared.specs.robustness import RobustnessSettings
from graspscape.workers.sim.engine import SceneLike
from graspscape.workers.sim.robustness_math import (
    directions,
    displacement,
    lowest_holding,
    ramp,
    relative_pose,
    shake_offset,
    shake_timing,
    torque_ratio,
)


class GraspTrials(Protocol):
    """One synthesized grasp in one engine."""

    scene: SceneLike
    effort: float  # the closing effort the grasp was made with
    friction: float  # the object's own coefficient
    mass_kg: float
    frame_rotation: np.ndarray  # the gripper frame at synthesis, world

    def restore(self) -> None:
        """The grasp as synthesis left it: bodies, motor commands, drive, fixture holding,
        no gravity, the object's own friction, no load."""

    def release(self, gravity: np.ndarray) -> None:
        """The fixture lets the object go; `gravity` (world, m/s²) on."""

    def push(self, force: np.ndarray) -> None:
        """`force` (world, N) on the object's centre of mass through the next step."""

    def holds(self, *, effort: float | None = None, friction: float | None = None) -> bool:
        """Restored with the closing effort `effort` and the object friction `friction`,
        whether the grasp holds through the release and the reference task (no probes)."""


Exceeded = Callable[[float, float], bool]


def hold_still(trials: GraspTrials, *, gravity: np.ndarray, settle_s: float, steps: int,
               exceeded: Exceeded, force: Callable[[int], np.ndarray] | None = None,
               offset: Callable[[int], np.ndarray] | None = None) -> int | None:
    """Restores the grasp, lets the fixture go with `gravity` on, holds the hand still for
    the settle, then runs `steps` steps with `force(step)` (world, N) on the object's centre of
    mass and the hand driven to its pose + `offset(step)` (world). Returns the first step at
    which `exceeded(distance, angle)` of the object in the hand since the settle (−1 where the
    object touches no link after the settle), or None if it never is."""
    scene, hand = trials.scene, trials.scene.hand
    trials.restore()
    trials.release(gravity)
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
            trials.push(force(step))
        scene.step()
        now = relative_pose(*hand.frame_pose(), *scene.object_pose())
        if exceeded(*displacement(rest, now)):
            return step
    return None


def _load_directions(trials: GraspTrials, settings: RobustnessSettings) -> np.ndarray:
    rows = directions()
    return rows @ trials.frame_rotation.T if settings.load_frame == "hand" else rows


def gravity_test(trials: GraspTrials, settings: RobustnessSettings) -> float:
    """Share of the six gravity directions in which the object stays in the hand."""
    s = settings
    steps = round(s.gravity_duration_s / trials.scene.dt)

    def exceeded(moved: float, turned: float) -> bool:
        return moved >= s.gravity_max_shift_m or turned >= s.gravity_max_turn_rad

    passed = [hold_still(trials, gravity=s.gravity_m_s2 * d, settle_s=s.settle_s,
                         steps=steps, exceeded=exceeded) is None
              for d in _load_directions(trials, s)]
    return sum(passed) / len(passed)


def force_test(trials: GraspTrials, settings: RobustnessSettings) -> float:
    """Share of the six directions in which the object resists a force of `force_weights`
    object weights without gravity."""
    s = settings
    steps = round(s.force_duration_s / trials.scene.dt)
    magnitude = s.force_weights * trials.mass_kg * s.gravity_m_s2

    def exceeded(moved: float, turned: float) -> bool:
        return moved >= s.force_max_shift_m or turned >= s.force_max_turn_rad

    passed = []
    for d in _load_directions(trials, s):
        load = magnitude * d
        passed.append(hold_still(trials, gravity=np.zeros(3), settle_s=s.settle_s,
                                 steps=steps, exceeded=exceeded,
                                 force=lambda _step, load=load: load) is None)
    return sum(passed) / len(passed)


def tug_test(trials: GraspTrials, settings: RobustnessSettings) -> float:
    """The pull along the approach axis (N) at which the object slips out of the hand."""
    s = settings
    dt = trials.scene.dt
    top = s.tug_max_weights * trials.mass_kg * s.gravity_m_s2
    axis = trials.frame_rotation[:, 2]  # the approach axis, palm → object

    def pull(step: int) -> float:
        return ramp((step + 1) * dt, top, s.tug_ramp_s)

    slipped = hold_still(trials, gravity=np.zeros(3), settle_s=s.settle_s,
                         steps=round(s.tug_ramp_s / dt),
                         exceeded=lambda moved, _turned: moved >= s.tug_slip_m,
                         force=lambda step: pull(step) * axis)
    if slipped is None:
        return top
    return 0.0 if slipped < 0 else pull(slipped)


def shake_test(trials: GraspTrials, settings: RobustnessSettings) -> float:
    """Time into the shake (s) at which the object falls off; the full duration if never."""
    s = settings
    dt = trials.scene.dt
    duration = 3 * shake_timing(s.shake_frequency_hz, s.shake_axis_s)
    fell = hold_still(
        trials, gravity=np.array([0.0, 0.0, -s.gravity_m_s2]), settle_s=s.settle_s,
        steps=round(duration / dt), exceeded=lambda moved, _turned: moved >= s.shake_fall_m,
        offset=lambda step: shake_offset((step + 1) * dt, s.shake_amplitude_m,
                                         s.shake_frequency_hz, s.shake_axis_s))
    if fell is None:
        return duration
    return 0.0 if fell < 0 else (fell + 1) * dt


def torque_margin(trials: GraspTrials, settings: RobustnessSettings,
                  nominal: bool | None = None) -> float | None:
    """Least closing effort at which the synthesized grasp still holds."""
    return lowest_holding(lambda tau: trials.holds(effort=tau),
                          settings.torque_lo_fraction * trials.effort, trials.effort,
                          settings.margin_trials, hi_holds=nominal)


def friction_margin(trials: GraspTrials, settings: RobustnessSettings,
                    nominal: bool | None = None) -> float | None:
    """Least friction coefficient of the object at which the grasp still holds."""
    hi = trials.friction
    return lowest_holding(lambda mu: trials.holds(friction=mu), min(settings.friction_lo, hi),
                          hi, settings.margin_trials, hi_holds=nominal)


def run_tests(trials: GraspTrials, settings: RobustnessSettings,
              times: dict[str, float] | None = None) -> RobustnessReport:
    """Runs the tests `settings` chooses; `times`, if given, gets each test's wall time (s;
    the nominal trajectory shared by the margins is its own entry)."""
    out: dict[str, float | None] = {}

    def timed(name: str, fn: Callable[[], float | None]) -> float | None:
        t0 = time.perf_counter()
        value = fn()
        if times is not None:
            times[name] = time.perf_counter() - t0
        return value

    nominal = None
    if settings.runs("torque_margin") or settings.runs("friction_margin"):
        nominal = timed("nominal", lambda: trials.holds())
    if settings.runs("torque_margin"):
        tau = timed("torque_margin", lambda: torque_margin(trials, settings, nominal))
        out["torque_margin_nm"] = tau
        out["torque_margin_ratio"] = torque_ratio(tau, trials.effort)
    if settings.runs("friction_margin"):
        out["friction_margin"] = timed(
            "friction_margin", lambda: friction_margin(trials, settings, nominal))
    if settings.runs("gravity"):
        out["gravity_test_share"] = timed("gravity", lambda: gravity_test(trials, settings))
    if settings.runs("force"):
        out["force_test_share"] = timed("force", lambda: force_test(trials, settings))
    if settings.runs("tug"):
        out["tug_force_n"] = timed("tug", lambda: tug_test(trials, settings))
    if settings.runs("shake"):
        out["shake_survival_s"] = timed("shake", lambda: shake_test(trials, settings))
    return RobustnessReport(**out)
