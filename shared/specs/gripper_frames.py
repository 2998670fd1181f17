"""Re-expressing the exports' gripper frame in the frames other tools use
(docs/reference/formats.md, "Other gripper frames"). Pure functions of a gripper's description.

The exports' gripper frame is the palm surface centre, z the palm normal toward the object and
x the palm's x axis as the description gives it (the closing axis of every shipped parallel
jaw). A transform T (gripper frame in the object frame) becomes another frame's by the right
product: T @ `to_base_link(spec)` is the URDF base link's pose, T @ `to_acronym(spec)` the
ACRONYM/GraspGen convention's (origin on the approach axis at the hand's base, z the approach,
x the closing axis; for `franka_hand` the frame of ACRONYM's Franka gripper).
"""

from __future__ import annotations

import numpy as np
from graspscape.shared.specs.gripper import AnyGripperSpec, GripperSpec


def palm_in_base_link(spec: AnyGripperSpec) -> np.ndarray:
    """4×4: the exports' gripper frame in the gripper's URDF base link frame (identity for a
    TOML of boxes, whose palm frame is its base)."""
    out = np.eye(4)
    if isinstance(spec, GripperSpec):
        return out
    normal = np.asarray(spec.palm.normal, dtype=float)
    normal /= np.linalg.norm(normal)
    x = np.asarray(spec.palm.x_axis, dtype=float)
    x = x - normal * (x @ normal)  # orthogonal to the normal, as placement makes it
    x /= np.linalg.norm(x)
    out[:3, :3] = np.column_stack([x, np.cross(normal, x), normal])
    out[:3, 3] = spec.palm.origin
    return out


def to_base_link(spec: AnyGripperSpec) -> np.ndarray:
    """Right factor from the exports' frame to the URDF base link's frame."""
    return np.linalg.inv(palm_in_base_link(spec))


def base_depth_m(spec: AnyGripperSpec) -> float:
    """How far behind the palm surface the base link's origin lies along the approach axis."""
    palm = palm_in_base_link(spec)
    return float(palm[:3, 3] @ palm[:3, 2])


def to_acronym(spec: AnyGripperSpec) -> np.ndarray:
    """Right factor from the exports' frame to the ACRONYM convention: the same axes, the
    origin moved back along z to the depth of the hand's base."""
    out = np.eye(4)
    out[2, 3] = -base_depth_m(spec)
    return out
