"""The baseline grasp synthesis policy G_c (paper, Sec. III-C).

A constant force f_c pushes the open gripper from its start pose toward x_c, the object point
nearest the palm. It is realised by the base drive following the motion f_c gives the free
hand (a = f_c / m, capped at an arm's speed limit) with its force capped at f_c, so once
something resists, the hand is pushed by no more than f_c. The open fingers reach ~12 cm past
the palm and often brush the object first; the force is removed when the palm touches the
object or when the hand is blocked (it advances less than 0.5 mm in a check interval), not at
the first fingertip touch (which would close the hand on its fingertips almost everywhere).
The arm then holds the base where it is; a constant closing effort τ_c drives the fingers until
their motion halts (windowed change below a tolerance) or a time cap is reached.
"""

from __future__ import annotations

import time

import numpy as np
from graspscape.shared.specs.results import Outcome, PhaseTimes
from graspscape.shared.specs.sim import SimSettings
from graspscape.workers.sim.policies.closing import close_fingers
from graspscape.workers.sim.policies.registry import register_policy

BLOCKED_ADVANCE_M = 0.0005
APPROACH_TIME_CAP_S = 1.5


def on_table(scene) -> bool:
    """Whether the hand rests on a table (support 'plane'): fingertips stopped by the table
    close from there, as a hand lowered onto a small object does."""
    touching = getattr(scene, "hand_on_table", None)
    return bool(touching is not None and touching())


@register_policy("baseline")
class BaselinePolicy:

    def synthesize(self, scene, position: np.ndarray, rotation: np.ndarray, target: np.ndarray,
                   sim: SimSettings, phases: PhaseTimes) -> Outcome | None:
        settings = sim.policy
        t0 = time.perf_counter()
        hand, dt = scene.hand, scene.dt
        gap = float(np.linalg.norm(target - position))
        direction = (target - position) / gap if gap > 1e-9 else rotation[:, 2]
        accel = settings.approach_force_n / hand.mass
        travel_limit = gap + settings.approach_overshoot_m
        # The drive pulls toward a point past x_c with at most f_c: a constant force until
        # something resists; the speed cap stands for the arm's own limit.
        goal = position + direction * travel_limit
        commanded = position.copy()
        speed = 0.0
        stopped = scene.palm_in_contact()
        last = start = hand.frame_pose()[0]
        max_steps = round(APPROACH_TIME_CAP_S / dt)
        # Counted here and stored once: a pydantic attribute costs microseconds a step.
        steps = phases.approach_steps
        while not stopped and steps < max_steps:
            speed = min(speed + accel * dt, settings.approach_speed_cap_m_s)
            commanded = commanded + direction * speed * dt
            if np.dot(goal - commanded, direction) < 0:
                commanded = goal
            scene.drive_to(commanded, rotation, max_force=settings.approach_force_n)
            scene.step()
            steps += 1
            if scene.palm_in_contact():
                break
            if steps % settings.check_every_steps == 0:
                now = hand.frame_pose()[0]
                if np.dot(now - start, direction) >= travel_limit:
                    break
                stopped = bool(np.linalg.norm(now - last) < BLOCKED_ADVANCE_M
                               and (scene.in_contact() or on_table(scene)))
                last = now
        phases.approach_steps = steps
        phases.approach_s = time.perf_counter() - t0
        if not scene.in_contact() and not on_table(scene):
            return Outcome.NO_CONTACT

        return close_fingers(scene, settings, phases)
