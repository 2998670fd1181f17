"""The pose space P made concrete: where the open gripper starts for a pose (θ, φ, r, attitude).

Pure geometry on the object's mesh (in its centre-of-mass frame). The palm surface centre
lies on the ray from the centre of mass along direction (θ, φ), at the outermost point of that
ray whose distance to the object surface is r. The palm normal points at the nearest surface
point x_c (so it is aligned with the surface normal there). Roll turns the gripper about its
palm normal from a reference attitude in which the two-finger side (-x of the gripper frame)
faces the object's +z ("up"), as in the paper's Fig. 2 (where the palm faces straight up or
down, the same rule applied to the approach direction); pitch and yaw then tilt the palm
normal. Every choice is equivariant under rotations about z and vertical mirrors, so an
object's symmetries are symmetries of the start poses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import trimesh
from graspscape.shared.specs.pose import Pose
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class Placement:
    position: np.ndarray  # palm surface centre, object frame
    rotation: np.ndarray  # columns: gripper x, y, z (palm normal) in the object frame
    nearest_point: np.ndarray  # x_c
    surface_normal: np.ndarray  # outward, at x_c
    gap: float  # palm surface centre to x_c


def direction(theta: float, phi: float) -> np.ndarray:
    return np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                     math.cos(theta)])


def nearest_surface_point(mesh: trimesh.Trimesh, point: np.ndarray) -> tuple[np.ndarray, float]:
    closest, distance, _ = trimesh.proximity.closest_point(mesh, point[None, :])
    return closest[0], float(distance[0])


def point_at_gap(mesh: trimesh.Trimesh, u: np.ndarray, gap: float,
                 tolerance: float = 1e-5) -> np.ndarray:
    """Outermost point along the ray from the origin along u at distance `gap` from the surface.

    Sphere tracing from outside the bounding sphere: a step of (distance − gap) can never pass
    the sought point, so the march stops at the first (outermost) one.
    """
    radius = float(np.max(np.linalg.norm(mesh.vertices, axis=1)))
    rho = radius + gap + 0.01
    for _ in range(200):
        _, distance = nearest_surface_point(mesh, rho * u)
        step = distance - gap
        if step < tolerance:
            break
        rho -= step
        if rho <= 0.0:  # the ray never comes that close: take the point nearest the surface
            rho = 0.0
            break
    return rho * u


def _reference_rotation(z: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Gripper axes for palm normal z, approached from direction u (unit vectors)."""
    up = np.array([0.0, 0.0, 1.0])
    x = -(up - up.dot(z) * z)  # two-finger side (−x) toward +z
    if np.linalg.norm(x) < 1e-6:
        # The palm faces straight up or down (a flat top or bottom): "toward +z" is no
        # direction. Take the same rule for the approach direction u instead (the limit of
        # the rule on a sphere as θ → 0 or π: two-finger side toward the z axis above, away
        # from it below), so the attitude turns with φ and the map keeps the object's
        # symmetries about z. Only on the z axis itself (θ = 0 or π) is the object's x axis
        # the reference.
        x = -(up - up.dot(u) * u)
        x = x - x.dot(z) * z
        if np.linalg.norm(x) < 1e-6:
            ex = np.array([1.0, 0.0, 0.0])
            x = ex - ex.dot(z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def approach_placement(mesh: trimesh.Trimesh, theta: float, phi: float,
                       r: float) -> Placement:
    """The start pose of a pose without its attitude (roll = pitch = yaw = 0): the costly
    part, shared by every attitude of one approach point."""
    u = direction(theta, phi)
    position = point_at_gap(mesh, u, r)
    nearest, gap = nearest_surface_point(mesh, position)
    if gap > 1e-6:
        normal = (position - nearest) / gap
    else:  # touching: use the face normal there
        _, _, face = trimesh.proximity.closest_point(mesh, position[None, :])
        normal = mesh.face_normals[face[0]]
    return Placement(position=position, rotation=_reference_rotation(-normal, u),
                     nearest_point=nearest, surface_normal=normal, gap=gap)


def with_attitude(approach: Placement, roll: float, pitch: float, yaw: float) -> Placement:
    """`approach` (an attitude-free placement) turned to an attitude."""
    # Attitude: roll about the palm normal, then pitch (about gripper y) and yaw (about x).
    attitude = Rotation.from_euler("ZYX", [roll, pitch, yaw]).as_matrix()
    return replace(approach, rotation=approach.rotation @ attitude)


def place_gripper(mesh: trimesh.Trimesh, pose: Pose) -> Placement:
    return with_attitude(approach_placement(mesh, pose.theta, pose.phi, pose.r),
                         pose.roll, pose.pitch, pose.yaw)
