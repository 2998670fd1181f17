"""The robust-map benchmark fills a dense grid coarsest nested grid first, so a long grid
stopped midway still holds whole coarser grids to score (benchmarks/robust_map_dense.py)."""

from __future__ import annotations

from benchmarks.bench_exploration_accuracy import _fine_points
from benchmarks.bench_robust_map import lattice_of
from benchmarks.robust_map_dense import coarser_grids, nested_rank


def _keys(rolls: int, levels: int) -> set[str]:
    lattice = lattice_of(rolls, 1, levels)
    return {lattice.pose(p).key() for p in _fine_points(lattice)}


def test_nested_grids_are_listed_coarsest_first() -> None:
    assert coarser_grids(8, 1) == [(1, 1), (1, 2), (1, 4), (1, 8)]
    assert coarser_grids(1, 2) == [(1, 1), (2, 1)]
    assert coarser_grids(3, 1) == [(1, 1), (1, 3)]  # 2 does not divide 3: its grid is not nested


def test_each_pose_is_ranked_by_the_coarsest_grid_that_holds_it() -> None:
    rank = nested_rank(lattice_of, 2, 1, 1)
    one, two = _keys(1, 1), _keys(2, 1)
    assert one < two  # the 1-roll grid is nested in the 2-roll one
    assert set(rank) == two
    assert {k for k, r in rank.items() if r == (1, 1)} == one
    assert {k for k, r in rank.items() if r == (1, 2)} == two - one
    # Sorting by rank puts the whole 1-roll grid before any pose only the 2-roll grid has.
    ordered = sorted(two, key=rank.__getitem__)
    assert set(ordered[: len(one)]) == one
