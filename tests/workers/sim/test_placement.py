"""Start poses (pure geometry): the gap, the palm normal, the reference attitude, and that an
object's symmetries about z are symmetries of the start poses (the symmetry shortcut needs it)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from graspscape.shared.specs.placement import place_gripper
from graspscape.shared.specs.pose import Pose
from graspscape.workers.sim.geometry import axis_rotation

CUBE = trimesh.creation.box(extents=(0.06, 0.06, 0.06))
SPHERE = trimesh.creation.icosphere(subdivisions=4, radius=0.04)
MIRROR_XZ = np.diag([1.0, -1.0, 1.0])

# θ = 20° and 160° end on the flat top and bottom faces (palm facing straight down or up),
# 45° on the top edge, 90° on a side face.
THETAS = [math.radians(t) for t in (20, 45, 90, 135, 160)]
PHIS = [math.radians(f) for f in (10, 30, 75, 200)]


@pytest.mark.parametrize("theta", THETAS)
def test_the_palm_starts_at_gap_r_facing_the_nearest_point(theta: float) -> None:
    placed = place_gripper(CUBE, Pose(theta=theta, phi=0.3, r=0.015))
    assert placed.gap == pytest.approx(0.015, abs=1e-4)
    toward = (placed.nearest_point - placed.position) / placed.gap
    assert placed.rotation[:, 2] == pytest.approx(toward, abs=1e-6)
    assert placed.rotation.T @ placed.rotation == pytest.approx(np.eye(3), abs=1e-12)
    assert np.linalg.det(placed.rotation) == pytest.approx(1.0)


def test_at_roll_zero_the_two_finger_side_faces_up_from_the_side() -> None:
    placed = place_gripper(SPHERE, Pose(theta=math.pi / 2, phi=1.0, r=0.01))
    assert placed.rotation[:, 0] == pytest.approx([0.0, 0.0, -1.0], abs=1e-6)  # −x is up


@pytest.mark.parametrize("theta", THETAS)
@pytest.mark.parametrize("phi", PHIS)
def test_a_quarter_turn_of_the_cube_turns_its_start_poses(theta: float, phi: float) -> None:
    turn = axis_rotation(2, math.pi / 2)
    for roll in (0.0, math.pi / 2):
        a = place_gripper(CUBE, Pose(theta=theta, phi=phi, r=0.01, roll=roll))
        b = place_gripper(CUBE, Pose(theta=theta, phi=phi + math.pi / 2, r=0.01, roll=roll))
        assert turn @ a.position == pytest.approx(b.position, abs=1e-9)
        assert turn @ a.rotation == pytest.approx(b.rotation, abs=1e-9)


@pytest.mark.parametrize("theta", THETAS)
@pytest.mark.parametrize("phi", PHIS)
def test_a_mirrored_pose_is_the_mirror_image_with_the_hand_mirrored(theta: float,
                                                                   phi: float) -> None:
    # Mirror in the xz plane: φ → −φ, roll → −roll, and the gripper's y axis (the side B
    # and C sit on) flips, which is the hand mirrored onto itself with B and C swapped.
    roll = 0.7
    a = place_gripper(CUBE, Pose(theta=theta, phi=phi, r=0.01, roll=roll))
    b = place_gripper(CUBE, Pose(theta=theta, phi=-phi % (2 * math.pi), r=0.01,
                                 roll=-roll % (2 * math.pi)))
    assert MIRROR_XZ @ a.position == pytest.approx(b.position, abs=1e-9)
    assert MIRROR_XZ @ a.rotation @ MIRROR_XZ == pytest.approx(b.rotation, abs=1e-9)
