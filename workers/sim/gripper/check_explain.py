"""What `graspscape gripper check` says beyond pass or fail: why a hand held nothing, and
held grasps whose quality metric reads zero. Pure functions of the check's findings."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

# μs at or under this counts as zero: the grasp holds in the simulation, but the metric sees
# no force closure (contacts that cannot push back in some direction).
MU_S_ZERO = 0.005


class _Trial(Protocol):
    object: str
    start: str
    viable: bool
    mu_s: float
    links_in_contact: list[str]


class _Joint(Protocol):
    joint: str
    vendor: str
    moved: bool


def _digit(link: str) -> str:
    return link.split("_", 1)[0]


def why_no_hold(obj: str, trials: Sequence[_Trial], joints: Sequence[_Joint],
                digits: dict[str, list[str]]) -> list[str]:
    """The reasons a hand held `obj` from none of its starts: fingers that never touched it,
    joints that never moved, starts where it touched with one link only or not at all."""
    tried = [t for t in trials if t.object == obj]
    reasons = []
    touched = {_digit(link) for t in tried for link in t.links_in_contact}
    fingers = sorted(d for d in digits if d != "palm")
    silent = [d for d in fingers if d not in touched]
    if silent and len(silent) < len(fingers):
        reasons.append(f"finger{'s' if len(silent) > 1 else ''} {', '.join(silent)} never "
                       f"touched the {obj}")
    stuck = [f"{j.joint} ({j.vendor})" for j in joints
             if not j.moved and not j.joint.endswith("_spread")]
    if stuck:
        reasons.append(f"joint{'s' if len(stuck) > 1 else ''} {', '.join(stuck)} never moved "
                       "(check the closing sign and the effort's units: N·m for a revolute "
                       "joint, N for a prismatic one)")
    nothing = [t.start for t in tried if not t.links_in_contact]
    if nothing:
        reasons.append(f"from {', '.join(nothing)} nothing touched the {obj} (the hand "
                       "closes short of it: the opening, the reach or the palm origin)")
    for t in tried:
        if len(t.links_in_contact) == 1:
            reasons.append(f"from {t.start} only {t.links_in_contact[0]} touched it (one link "
                           "cannot hold an object against gravity)")
    return reasons


def zero_quality_warnings(trials: Sequence[_Trial]) -> list[str]:
    """Held grasps with μs ≈ 0: they passed the hold test, but the metric finds no margin."""
    return [f"{t.object}, {t.start}: held with μs {t.mu_s:.2f} — the contacts "
            f"({', '.join(t.links_in_contact) or 'none recorded'}) resist no disturbance in "
            "the metric's sense; the hold may rest on friction alone or on the palm's "
            "origin and axes being off (docs/howto/add-gripper.md)"
            for t in trials if t.viable and t.mu_s <= MU_S_ZERO]
