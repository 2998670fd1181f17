"""The slip test of the reference trajectory: whether the object has moved in the hand."""

from __future__ import annotations

import numpy as np
from graspscape.workers.sim.trajectory import rotation_angle


def slip_check(scene, spec, rel_pos0: np.ndarray, rel_rot0: np.ndarray):
    """A function telling whether the object has slipped in the hand: moved more than the
    spec's slip distance or turned more than its slip angle from where it rested at the start
    (rel_pos0, rel_rot0: its pose in the hand's frame then). Either engine's scene."""
    hand = scene.hand

    def slipped() -> bool:
        pos, rot = hand.frame_pose()
        o_pos, o_rot = scene.object_pose()
        moved = np.linalg.norm(rot.T @ (o_pos - pos) - rel_pos0)
        turned = rotation_angle((rot.T @ o_rot) @ rel_rot0.T)
        return moved > spec.slip_distance_m or turned > spec.slip_angle_rad

    return slipped
