"""Tiles of work: the coarse pass of a grid, and any set of lattice poses, split into jobs.

The approach directions come from the equal-area lattice (`lattice.py`): rings of constant θ
whose azimuth count is ∝ sin θ, so every cell covers about Δθ² of the sphere and the poles
hold one point each. A coarse tile is a contiguous φ sector of one ring × every r level ×
every attitude. Refinement and local-search poses are arbitrary sets; `group_tiles` cuts them
into tiles whose poses are exactly a product cells × r levels × attitudes (grouped by r level
and attitude), which is what the tiles table and the workers expect.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.shared.specs.exploration import PoseGridSpec
from graspscape.shared.specs.pose import Pose
from graspscape.shared.wire.messages import TileSample

Cell = tuple[float, float]  # (θ, φ)
Attitude = tuple[float, float, float]  # (roll, pitch, yaw)


@dataclass(frozen=True)
class TilePlan:
    index: int
    cells: list[Cell]
    r_levels: list[float]
    attitudes: list[Attitude]
    sample: TileSample | None = None  # a tile of draws: evaluated outcome only

    @property
    def n_poses(self) -> int:
        return len(self.cells) * len(self.r_levels) * len(self.attitudes)


def _rings(lattice: Lattice, level: int) -> list[list[Cell]]:
    out: list[list[Cell]] = []
    for K, J in lattice.cells(level):
        cell = (lattice.theta(K), 0.0 if lattice.is_pole(K) else J * 2 * math.pi / lattice.m(K))
        if not out or out[-1][0][0] != cell[0]:
            out.append([])
        out[-1].append(cell)
    return out


def rings(grid: PoseGridSpec) -> list[list[Cell]]:
    """The coarse grid's approach directions, ring by ring from θ = 0 to θ = π."""
    return _rings(Lattice(grid), 0)


def coarse_tiles(grid: PoseGridSpec, *, target_poses: int = 100) -> list[TilePlan]:
    """The level-0 tiles of a grid, in a fixed order."""
    return dense_tiles(Lattice(grid), target_poses=target_poses)


def dense_tiles(lattice: Lattice, *, target_poses: int = 100) -> list[TilePlan]:
    """Tiles of every pose of the lattice at its finest level, ring by ring, in a fixed
    order (with depth 0: the coarse grid's tiles)."""
    level = lattice.depth
    r_levels = [lattice.pose(Point(0, 0, i, 0)).r
                for i in range(lattice.n_r * lattice.scale(0) + 1)]
    attitudes = lattice.attitudes
    per_tile = max(1, target_poses // (len(r_levels) * len(attitudes)))
    tiles: list[TilePlan] = []
    for ring in _rings(lattice, level):
        sectors = math.ceil(len(ring) / per_tile)
        # Even sector sizes (differing by at most one) rather than a short last sector.
        bounds = [round(k * len(ring) / sectors) for k in range(sectors + 1)]
        for a, b in pairwise(bounds):
            tiles.append(TilePlan(len(tiles), ring[a:b], r_levels, attitudes))
    return tiles


def count_poses(grid: PoseGridSpec) -> int:
    cells = sum(len(ring) for ring in rings(grid))
    return cells * len(grid.r_levels()) * len(grid.attitudes.attitudes())


def group_tiles(
    poses: list[Pose], *, target_poses: int = 100, first_index: int = 0
) -> list[TilePlan]:
    """Any set of poses as tiles: same r and attitude share a tile, cells sorted, chunked."""
    groups: dict[tuple[float, Attitude], list[Cell]] = {}
    for pose in sorted(poses, key=lambda p: p.key()):
        key = (pose.r, (pose.roll, pose.pitch, pose.yaw))
        groups.setdefault(key, []).append((pose.theta, pose.phi))
    tiles: list[TilePlan] = []
    for (r, attitude), cells in sorted(groups.items()):
        for start in range(0, len(cells), max(1, target_poses)):
            chunk = cells[start : start + target_poses]
            tiles.append(TilePlan(first_index + len(tiles), chunk, [r], [attitude]))
    return tiles


