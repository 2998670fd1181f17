"""The closing phase both policies end with: the arm holds the base where it is and the closing
effort τ_c drives the fingers until their motion halts or the time cap is reached."""

from __future__ import annotations

import time

from graspscape.shared.specs.results import Outcome, PhaseTimes
from graspscape.shared.specs.sim import BaselinePolicySettings


def close_fingers(scene, settings: BaselinePolicySettings,
                  phases: PhaseTimes) -> Outcome | None:
    """Returns NO_GRASP when nothing touches the object once the hand has closed."""
    started = time.perf_counter()
    hand = scene.hand
    held_pos, held_rot = hand.frame_pose()
    scene.drive_to(held_pos, held_rot)
    hand.begin_closing(settings.closing_speed)
    cap = max(1, round(settings.closing_cap_s / scene.dt))
    steps = 0  # stored once below: a pydantic attribute costs microseconds a step
    for step in range(1, cap + 1):
        scene.step()
        steps += 1
        if step % settings.check_every_steps == 0 and hand.update_closing(
                settings.stall_tolerance, scene.touching_links()):
            break
    phases.closing_steps += steps
    hand.settle(scene.touching_links())
    phases.closing_s = time.perf_counter() - started
    return None if scene.in_contact() else Outcome.NO_GRASP
