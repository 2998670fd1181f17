"""The coarse-pass split and the grid spec: every pose exactly once, tiles of the target size."""

from __future__ import annotations

import math

import pytest
from graspscape.services.coordinator.exploration.tiling import (
    coarse_tiles,
    count_poses,
    rings,
)
from graspscape.shared.specs.exploration import AttitudeSpec, PoseGridSpec
from graspscape.shared.specs.pose import tile_poses
from pydantic import ValidationError


@pytest.mark.parametrize(
    "dtheta",
    [pytest.param(0.05, marks=pytest.mark.slow), 0.3, math.radians(10), 1.0, math.pi / 2],
)
def test_every_pose_is_in_exactly_one_tile(dtheta: float) -> None:
    grid = PoseGridSpec(dtheta=dtheta, r_max=0.03, attitudes=AttitudeSpec(rolls=2, tilts=(0.2,)))
    tiles = coarse_tiles(grid, target_poses=100)
    keys = [p.key() for t in tiles for p in tile_poses(t.cells, t.r_levels, t.attitudes)]
    assert len(keys) == len(set(keys)) == count_poses(grid) == sum(t.n_poses for t in tiles)
    assert [t.index for t in tiles] == list(range(len(tiles)))
    assert coarse_tiles(grid, target_poses=100) == tiles  # deterministic


def test_tiles_stay_near_the_target_size() -> None:
    grid = PoseGridSpec(dtheta=0.1, r_max=0.05, dr=0.01)  # 6 poses per cell
    tiles = coarse_tiles(grid, target_poses=100)
    assert max(t.n_poses for t in tiles) <= 96  # 16 cells × 6
    long_rings = [t for t in tiles if 0.3 < t.cells[0][0] < math.pi - 0.3]
    assert min(t.n_poses for t in long_rings) >= 48  # even sectors, no stub at a ring's end


def test_neighbouring_directions_are_about_dtheta_apart() -> None:
    dtheta = 0.2
    grid = PoseGridSpec(dtheta=dtheta)
    for ring in rings(grid)[1:-1]:
        theta = ring[0][0]
        step = 2 * math.pi / len(ring) * math.sin(theta)  # arc between azimuth neighbours
        assert 0.6 * dtheta < step < 1.5 * dtheta
    assert len(rings(grid)[0]) == len(rings(grid)[-1]) == 1  # one point at each pole
    assert rings(grid)[-1][0][0] == math.pi


@pytest.mark.parametrize("multiple", [2, 4, 8])
def test_an_azimuth_multiple_makes_every_ring_a_multiple_and_keeps_cells_about_dtheta(
    multiple: int,
) -> None:
    dtheta = 0.2
    grid = PoseGridSpec(dtheta=dtheta, azimuth_multiple=multiple)
    for ring in rings(grid)[1:-1]:
        assert len(ring) % multiple == 0
        ring_step = math.pi / round(math.pi / dtheta)  # Δθ as the rings divide [0, π]
        equal_area_count = 2 * math.pi * math.sin(ring[0][0]) / ring_step
        assert abs(len(ring) - equal_area_count) <= multiple / 2
    assert len(rings(grid)[0]) == len(rings(grid)[-1]) == 1


def test_grid_levels_and_attitudes() -> None:
    grid = PoseGridSpec(r_min=0.0, r_max=0.05, dr=0.01)
    assert grid.r_levels() == [0.0, 0.01, 0.02, 0.03, 0.04, 0.05]
    assert PoseGridSpec(r_min=0.02, r_max=0.02).r_levels() == [0.02]
    attitudes = AttitudeSpec(rolls=4, tilts=(0.1,)).attitudes()
    assert len(attitudes) == 4 * 5
    assert {round(a[0], 6) for a in attitudes} == {round(k * math.pi / 2, 6) for k in range(4)}
    assert (0.0, 0.1, 0.0) in attitudes and (0.0, 0.0, -0.1) in attitudes


@pytest.mark.parametrize(
    "bad",
    [
        {"rolls": 3},
        {"tilts": (0.0,)},
        {"tilts": (0.9,)},
        {"tilts": (0.1, 0.1)},
        {"tilts": (0.1, 0.2, 0.3, 0.4, 0.5)},
    ],
)
def test_attitude_spec_refuses_bad_values(bad: dict) -> None:
    with pytest.raises(ValidationError):
        AttitudeSpec(**bad)
