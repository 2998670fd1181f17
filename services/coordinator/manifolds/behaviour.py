"""When two neighbouring poses show the same behaviour (pure functions).

The stored signature names links ("A_1" … "C_3", "palm" for the 3-finger gripper). Grasp types
are told apart by which digits touch (a digit is a finger — the links' common prefix — or the
palm), and by where: between neighbouring poses the contact point of each digit may slide
along with the approach, by at most the arc the approach moved at the contact's distance from
the centre of mass (plus the change of r and a slack), but not jump to another part of the
object. Contact positions are in the object frame, so this is a continuity test rather than a
global comparison: a sphere approached from any side is one behaviour, while the mug's handle
(contacts jumping several cm off the body) is another.
"""

from __future__ import annotations

import math

import numpy as np
from graspscape.services.coordinator.mapspace.pose import StoredPose as StoredPose
from graspscape.services.coordinator.mapspace.pose import digit as digit
from graspscape.services.coordinator.mapspace.pose import source_of as source_of
from scipy.spatial.transform import Rotation

SLIDE_FACTOR = 1.5
SLACK_M = 0.005
# Same grasp type between neighbours: every digit's mean joint angle within 0.25 rad.
JOINT_TOLERANCE_RAD = 0.25


def start_frame(s: StoredPose) -> np.ndarray:
    """The gripper's start attitude as placement builds it (palm normal toward the object,
    two-finger side up, then roll, pitch, yaw), taking the approach direction for the surface
    normal (the coordinator has no mesh at hand here; exact for a sphere, close elsewhere)."""
    z = -np.array(s.direction())
    up = np.array([0.0, 0.0, 1.0])
    x = -(up - up.dot(z) * z)
    if np.linalg.norm(x) < 1e-6:
        ex = np.array([1.0, 0.0, 0.0])
        x = ex - ex.dot(z) * z
    x /= np.linalg.norm(x)
    base = np.column_stack([x, np.cross(z, x), z])
    return base @ Rotation.from_euler("ZYX", [s.roll, s.pitch, s.yaw]).as_matrix()


def approach_angle(a: StoredPose, b: StoredPose) -> float:
    """Rotation angle between the two start attitudes of the gripper, rad. Near the poles the
    reference attitude turns fast with φ, so this is larger than the angle between directions."""
    rel = start_frame(a).T @ start_frame(b)
    return float(math.acos(max(-1.0, min(1.0, (np.trace(rel) - 1.0) / 2.0))))


def same_behaviour(a: StoredPose, b: StoredPose, tolerance: float | None = None) -> bool:
    """Both viable, the same digits touching, and the hand closed alike (each digit's mean
    joint angle difference within JOINT_TOLERANCE_RAD). Where joint angles are missing,
    contacts must have slid with the approach rather than jumped (`slid`)."""
    if not (a.viable and b.viable) or a.digits != b.digits:
        return False
    shared = set(a.joints) & set(b.joints)
    if shared:
        return joint_difference(a, b, shared) <= (tolerance or JOINT_TOLERANCE_RAD)
    return slid(a, b)


def joint_difference(a: StoredPose, b: StoredPose, joints: set[str]) -> float:
    """The largest per-digit mean |Δ joint angle|: one finger closing differently counts in
    full instead of being averaged away by the fingers that did not change."""
    # The hottest comparison of the running map's upkeep. The joints grouped by digit once
    # per joint set as iterated (`_PLANS`: digits in first-seen order, each digit's joints in
    # the set's order), not split and grouped on every call: the same terms summed in the
    # same order, the digits' means compared in the same order, so the same float.
    key = tuple(joints)
    plan = _PLANS.get(key)
    if plan is None:
        groups: dict[str, list[str]] = {}
        for j in key:
            groups.setdefault(j.split("_")[0], []).append(j)
        if len(_PLANS) >= 4096:  # a handful of grippers' joint sets: a bound, never reached
            _PLANS.clear()
        plan = _PLANS[key] = tuple(tuple(names) for names in groups.values())
    ja, jb = a.joints, b.joints
    return max(sum([abs(ja[j] - jb[j]) for j in names]) / len(names) for names in plan)


_PLANS: dict[tuple[str, ...], tuple[tuple[str, ...], ...]] = {}


def slid(a: StoredPose, b: StoredPose) -> bool:
    """Every digit's object-frame contact moved at most the arc the gripper turned through at
    the contact's distance from the centre of mass (× SLIDE_FACTOR, + Δr, + SLACK_M)."""
    angle = approach_angle(a, b)
    for d in a.digits:
        pa, pb = a.contacts.get(d), b.contacts.get(d)
        if pa is None or pb is None:
            continue
        radius = max(math.hypot(*pa), math.hypot(*pb))
        allowed = SLIDE_FACTOR * (radius * angle + abs(a.r - b.r)) + SLACK_M
        if math.dist(pa, pb) > allowed:
            return False
    return True


def differs(a: StoredPose, b: StoredPose, mu_step_max: float | None = None) -> bool:
    """A border (viability or grasp type) or, optionally, a steep μs slope lies between them."""
    if a.viable != b.viable:
        return True
    if not a.viable:
        return False  # the non-viable area is one class, whatever the failure
    if not same_behaviour(a, b):
        return True
    return mu_step_max is not None and abs(a.mu_s - b.mu_s) > mu_step_max
