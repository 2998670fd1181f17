"""The equal-area nested lattice: areas, nesting, neighbours, midpoints, pose round trips."""

from __future__ import annotations

import math

import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.exploration.tiling import coarse_tiles, group_tiles
from graspscape.shared.specs.exploration import AttitudeSpec, PoseGridSpec
from graspscape.shared.specs.pose import tile_poses

GRIDS = [
    PoseGridSpec(dtheta=math.radians(30), r_max=0.02, dr=0.01),
    PoseGridSpec(dtheta=math.radians(10), r_max=0.01, dr=0.01, attitudes=AttitudeSpec(rolls=2)),
    PoseGridSpec(dtheta=0.7, r_min=0.01, r_max=0.01),
]


@pytest.mark.parametrize("grid", GRIDS)
@pytest.mark.parametrize("depth", [0, 2])
def test_cells_have_about_equal_area_and_cover_the_sphere(grid: PoseGridSpec, depth: int) -> None:
    lattice = Lattice(grid, depth)
    for level in range(depth + 1):
        areas = [lattice.cell_area(K, level) for K, _ in lattice.cells(level)]
        assert math.isclose(sum(areas), 4 * math.pi, rel_tol=1e-9)
        step2 = lattice.dtheta(level) ** 2
        # No pile-up at the poles: the polar caps are π/4·Δθ², every other cell within 30 %.
        assert min(areas) >= 0.77 * step2
        assert max(areas) <= 1.3 * step2
        ring_cells = [a for (K, _), a in zip(lattice.cells(level), areas, strict=True)
                      if not lattice.is_pole(K)]
        assert max(ring_cells) / min(ring_cells) < 1.45


# Δθ ≤ 30°: on coarser grids the rings next to the poles have fewer natural cells than the
# multiple asks for, and get smaller cells (0.7 rad, multiple 8: 0.69 Δθ²).
@pytest.mark.parametrize("grid", GRIDS[:2])
@pytest.mark.parametrize("multiple", [4, 8])
def test_a_symmetry_multiple_keeps_cells_within_a_third_of_equal_area(
    grid: PoseGridSpec, multiple: int
) -> None:
    lattice = Lattice(grid.model_copy(update={"azimuth_multiple": multiple}), 2)
    for level in range(3):
        areas = [lattice.cell_area(K, level) for K, _ in lattice.cells(level)]
        assert math.isclose(sum(areas), 4 * math.pi, rel_tol=1e-9)
        step2 = lattice.dtheta(level) ** 2
        ring_cells = [a for (K, _), a in zip(lattice.cells(level), areas, strict=True)
                      if not lattice.is_pole(K)]
        assert 0.7 * step2 <= min(ring_cells) and max(ring_cells) <= 1.35 * step2
        assert all(lattice.m_at(K, level) % multiple == 0
                   for K, _ in lattice.cells(level) if not lattice.is_pole(K))


def test_levels_are_nested_and_keys_stable() -> None:
    lattice = Lattice(GRIDS[0], 3)
    for level in range(3):
        here = {(K, J) for K, J in lattice.cells(level)}
        finer = {(K, J) for K, J in lattice.cells(level + 1)}
        assert here <= finer
        assert len(finer) > 3 * len(here)
    for p in lattice.coarse_points():
        assert lattice.birth(p) == 0
        assert lattice.point(lattice.pose(p)) == p
        # the same grid point through a shallower lattice has the same pose key
        shallow = Lattice(GRIDS[0], 0)
        q = Point(p.ring >> 3, p.azimuth >> 3 if not lattice.is_pole(p.ring) else 0,
                  p.r_index >> 3, p.attitude)
        assert shallow.pose(q).key() == lattice.pose(p).key()


def test_coarse_tiles_are_the_level_zero_points() -> None:
    grid = GRIDS[1]
    lattice = Lattice(grid, 2)
    keys = {p.key() for t in coarse_tiles(grid, target_poses=50)
            for p in tile_poses(t.cells, t.r_levels, t.attitudes)}
    assert keys == {lattice.pose(p).key() for p in lattice.coarse_points()}


def test_neighbours_are_symmetric_and_midpoints_new() -> None:
    lattice = Lattice(GRIDS[0], 2)
    for level in range(2):
        points = [Point(K, J, 0, 0) for K, J in lattice.cells(level)]
        for p in points:
            for _, q in lattice.neighbours(p, level):
                assert lattice.exists(q, level)
                assert p in [x for _, x in lattice.neighbours(q, level)], (p, q)
                mid = lattice.midpoint(p, q, level)
                assert mid is not None and lattice.birth(mid) == level + 1
                # halfway: about half the angle from either end
                assert lattice.angle(p, mid) <= 0.8 * lattice.angle(p, q) + 1e-6


def _overlapping_by_scan(lattice: Lattice, p: Point, level: int) -> list[Point]:
    """Cross neighbours by testing every azimuth of the adjacent rings for overlap."""
    phi = lattice.pose(p).phi
    half = math.pi / lattice.m_at(p.ring, level)
    out = []
    for K in (p.ring - lattice.scale(level), p.ring + lattice.scale(level)):
        if not 0 <= K <= lattice.n_rings:
            continue
        m_l = lattice.m_at(K, level)
        step = 1 if lattice.is_pole(K) else lattice.m(K) // m_l
        for j in range(m_l):
            gap = abs(math.remainder(j * 2 * math.pi / m_l - phi, 2 * math.pi))
            if lattice.is_pole(p.ring) or lattice.is_pole(K) or gap < half + math.pi / m_l - 1e-9:
                out.append(Point(K, j * step, p.r_index, p.attitude))
    return out


@pytest.mark.parametrize("degrees", [90, 45, 30, 15, pytest.param(10, marks=pytest.mark.slow)])
@pytest.mark.parametrize("multiple", [1, 4, 8])
def test_cross_neighbours_are_the_overlapping_cells_of_the_adjacent_rings(
        degrees: int, multiple: int) -> None:
    grid = PoseGridSpec(dtheta=math.radians(degrees), r_max=0.0, azimuth_multiple=multiple)
    lattice = Lattice(grid, 2)
    for level in range(3):
        for K, J in lattice.cells(level):
            p = Point(K, J, 0, 0)
            assert lattice.cross_neighbours(p, level) == _overlapping_by_scan(lattice, p, level)


def test_group_tiles_cover_exactly_the_given_poses() -> None:
    lattice = Lattice(GRIDS[1], 1)
    poses = [lattice.pose(p) for p in lattice.coarse_points()[::3]]
    tiles = group_tiles(poses, target_poses=7, first_index=5)
    got = [p.key() for t in tiles for p in tile_poses(t.cells, t.r_levels, t.attitudes)]
    assert sorted(got) == sorted(p.key() for p in poses)
    assert [t.index for t in tiles] == list(range(5, 5 + len(tiles)))
    assert max(t.n_poses for t in tiles) <= 7
