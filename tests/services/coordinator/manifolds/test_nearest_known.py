"""grouping.nearest_known is the nearest known pose of every position by `sq_dist`, ties to
the smaller point, whatever few candidates the tree is asked for first: checked against every
pose, on lattices whose symmetry makes ties common (the full recompute and the running map
both rely on it, so comparing those two would not catch a wrong choice)."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.grouping import fine_grid, nearest_known, sq_dist
from graspscape.shared.specs.exploration import PoseGridSpec


def every_pose(grid, known: list[Point]) -> tuple[np.ndarray, np.ndarray]:  # type: ignore[no-untyped-def]
    own = grid.embedding[[grid.position(p) for p in known]]
    d2 = sq_dist(grid.embedding[:, None, :], own[None, :, :])  # (positions, known)
    best = np.lexsort((np.broadcast_to(np.arange(len(known)), d2.shape), d2), axis=-1)[:, 0]
    return best, d2[np.arange(len(d2)), best]


@pytest.mark.parametrize(("dtheta", "depth", "share", "seed"), [
    (30, 1, 0.05, 0), (30, 1, 0.3, 1), (45, 2, 0.02, 2), (20, 1, 0.01, 3), (20, 1, 0.6, 4),
])
def test_the_nearest_is_the_smallest_sq_dist_ties_to_the_smaller_point(
        dtheta: float, depth: int, share: float, seed: int) -> None:
    spec = PoseGridSpec(dtheta=math.radians(dtheta), r_min=0.0, r_max=0.02, dr=0.01)
    lattice = Lattice(spec, depth)
    grid = fine_grid(lattice, lambda d: np.full(len(d), 0.05))
    rng = random.Random(seed)
    points = [Point(K, J, i, 0) for K, J in grid.cells for i in range(grid.n_i)]
    # Coarse points only on some runs: a regular pattern, so many positions tie.
    if seed % 2:
        points = [p for p in points if lattice.birth(p) == 0]
    known = sorted(rng.sample(points, max(2, int(share * len(points)))))
    got, got_d2 = nearest_known(grid, known)
    want, want_d2 = every_pose(grid, known)
    assert got.tolist() == want.tolist()
    assert got_d2.tolist() == want_d2.tolist()
    some = np.array(sorted(rng.sample(range(len(grid.weights)), 50)))
    part, part_d2 = nearest_known(grid, known, some)
    assert part.tolist() == want[some].tolist() and part_d2.tolist() == want_d2[some].tolist()
