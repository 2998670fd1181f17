"""The object's stable resting poses on a plane, with probabilities (pure geometry).

trimesh's `compute_stable_poses` rests the convex hull on each facet whose centre-of-mass
projection falls inside it and gives each the probability of landing on it when dropped in a
uniformly random attitude (the solid angle of the directions that roll onto it). A curved
surface is many facets: a sphere gives 1,280 poses of 0.1 % each, a can's side 48 of 1.8 %.
Facets whose table normals (the table's up in the object frame) lie within `MERGE_ANGLE_RAD`
of one another, chained, are one resting pose: the object rolls between them, the grasps
differ only by a turn about the table normal. The merged pose keeps its most probable member's
transform and sums the probabilities.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh
from graspscape.shared.specs.support import RestingPose
from scipy.spatial.transform import Rotation

MERGE_ANGLE_RAD = math.radians(15.0)


def _clusters(ups: np.ndarray, angle: float) -> list[list[int]]:
    """Single-linkage groups of unit vectors within `angle` of a neighbour."""
    close = ups @ ups.T >= math.cos(angle)
    label = [-1] * len(ups)
    groups: list[list[int]] = []
    for seed in range(len(ups)):
        if label[seed] >= 0:
            continue
        label[seed] = len(groups)
        group, frontier = [seed], [seed]
        while frontier:
            i = frontier.pop()
            for j in np.flatnonzero(close[i]):
                if label[j] < 0:
                    label[j] = label[seed]
                    group.append(int(j))
                    frontier.append(int(j))
        groups.append(group)
    return groups


def stable_poses(mesh: trimesh.Trimesh) -> list[tuple[np.ndarray, float]]:
    """Every resting pose (4×4: table point = T @ object point, centre of mass over the table
    origin) and its probability, merged as the module says, most probable first."""
    transforms, probabilities = trimesh.poses.compute_stable_poses(
        mesh, center_mass=np.zeros(3), sigma=0.0, n_samples=1, threshold=0.0)
    if len(probabilities) == 0:
        return []
    ups = np.array([t[:3, :3].T @ np.array([0.0, 0.0, 1.0]) for t in transforms])
    merged = []
    for group in _clusters(ups, MERGE_ANGLE_RAD):
        best = max(group, key=lambda i: (probabilities[i], -i))
        transform = np.array(transforms[best], dtype=float)
        transform[:2, 3] = 0.0  # the centre of mass over the table origin
        merged.append((transform, float(sum(probabilities[i] for i in group))))
    total = sum(p for _, p in merged) or 1.0
    merged = [(t, p / total) for t, p in merged]
    return sorted(merged, key=_likelihood_then_upright)


def _likelihood_then_upright(pose: tuple[np.ndarray, float]) -> tuple[float, ...]:
    """Most probable first; equally probable poses (a cube's six faces) in an order of their
    own, not trimesh's facet order, which differs between its releases: the object's own +z
    nearest to up first, then +y, then +x."""
    transform, probability = pose
    up = transform[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    return (-round(probability, 6), *(-round(float(up[i]), 6) for i in (2, 1, 0)))


def chosen_resting_poses(mesh: trimesh.Trimesh, *, min_probability: float,
                         max_poses: int) -> list[RestingPose]:
    """The resting poses an exploration on a plane explores: those at least
    `min_probability` likely, at most `max_poses`, most probable first; the most probable one
    whatever its probability."""
    found = stable_poses(mesh)
    chosen = [tp for k, tp in enumerate(found) if k == 0 or tp[1] >= min_probability]
    return [RestingPose(index=k, probability=round(prob, 6),
                        position=tuple(float(v) for v in t[:3, 3]),
                        quaternion=tuple(float(v) for v in
                                         Rotation.from_matrix(t[:3, :3]).as_quat()))
            for k, (t, prob) in enumerate(chosen[:max_poses])]
