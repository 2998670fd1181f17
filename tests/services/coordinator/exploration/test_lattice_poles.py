"""The south pole's θ is never beyond π, whatever the ring count: K·π/n rounded to π + 1 ulp for
n = 13, 26, 47, … (a 14° grid), and the tile holding that pole could not be expanded into
poses (Pose refuses θ > π), so its worker process crashed three times and the exploration
ended incomplete (found by the soak, tests/faults/test_soak.py)."""

from __future__ import annotations

import math

import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice
from graspscape.services.coordinator.exploration.tiling import coarse_tiles
from graspscape.shared.specs.exploration import PoseGridSpec
from graspscape.shared.specs.pose import tile_poses


def test_the_last_ring_is_never_beyond_pi() -> None:
    for n in range(2, 300):  # dtheta ≤ π/2, ≥ 0.01
        lattice = Lattice(PoseGridSpec(dtheta=math.pi / n))
        assert lattice.n_rings == n
        assert math.pi - 1e-12 < lattice.theta(n) <= math.pi


@pytest.mark.parametrize("dtheta_deg", [14.0, 13.85, 6.9])
def test_every_coarse_tile_expands_into_poses(dtheta_deg: float) -> None:
    grid = PoseGridSpec(dtheta=math.radians(dtheta_deg), r_min=0.01, r_max=0.03)
    for tile in coarse_tiles(grid, target_poses=30):
        assert tile_poses(tile.cells, tile.r_levels, tile.attitudes)
