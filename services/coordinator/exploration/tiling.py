"""The coarse-pass split of a pose grid into tiles of work.

Deliberately simple and deterministic, so that the queue, leasing and progress are real before
the spherical tiling and the adaptive refinement (a later issue) replace it; everything that
depends on the split goes through `coarse_tiles` and `tile_poses`.

The split: approach directions lie on rings of constant θ, θ_i = i·π/n with n = round(π/Δθ);
ring i holds m_i = max(1, round(2π·sin θ_i / Δθ)) evenly spaced azimuths φ_j = j·2π/m_i (one
point at each pole), so neighbouring points are about Δθ apart everywhere. Each ring is cut
into contiguous φ sectors of at most `cells_per_tile` cells; a tile is its sector's cells ×
every r level × every attitude.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import pairwise

from graspscape.shared.specs.exploration import PoseGridSpec
from graspscape.shared.specs.pose import Pose

Cell = tuple[float, float]  # (θ, φ)
Attitude = tuple[float, float, float]  # (roll, pitch, yaw)


@dataclass(frozen=True)
class TilePlan:
    index: int
    cells: list[Cell]
    r_levels: list[float]
    attitudes: list[Attitude]

    @property
    def n_poses(self) -> int:
        return len(self.cells) * len(self.r_levels) * len(self.attitudes)


def rings(dtheta: float) -> list[list[Cell]]:
    """The grid's approach directions, ring by ring from θ = 0 to θ = π."""
    n = max(1, round(math.pi / dtheta))
    out = []
    for i in range(n + 1):
        theta = i * math.pi / n
        m = max(1, round(2 * math.pi * math.sin(theta) / dtheta))
        out.append([(theta, j * 2 * math.pi / m) for j in range(m)])
    return out


def cells_per_tile_for(grid: PoseGridSpec, target_poses: int) -> int:
    """How many cells make a tile of about `target_poses` poses (at least one cell)."""
    per_cell = len(grid.r_levels()) * len(grid.attitudes.attitudes())
    return max(1, target_poses // per_cell)


def coarse_tiles(grid: PoseGridSpec, *, target_poses: int = 100) -> list[TilePlan]:
    """The level-0 tiles of a grid, in a fixed order."""
    r_levels = grid.r_levels()
    attitudes = grid.attitudes.attitudes()
    per_tile = cells_per_tile_for(grid, target_poses)
    tiles: list[TilePlan] = []
    for ring in rings(grid.dtheta):
        sectors = math.ceil(len(ring) / per_tile)
        # Even sector sizes (differing by at most one) rather than a short last sector.
        bounds = [round(k * len(ring) / sectors) for k in range(sectors + 1)]
        for a, b in pairwise(bounds):
            tiles.append(TilePlan(len(tiles), ring[a:b], r_levels, attitudes))
    return tiles


def count_poses(grid: PoseGridSpec) -> int:
    cells = sum(len(ring) for ring in rings(grid.dtheta))
    return cells * len(grid.r_levels()) * len(grid.attitudes.attitudes())


def tile_poses(
    cells: list[Cell] | list[list[float]],
    r_levels: list[float],
    attitudes: list[Attitude] | list[list[float]],
) -> list[Pose]:
    """Every pose a tile covers (accepts the JSON-decoded lists stored on a tile row)."""
    return [
        Pose(theta=theta, phi=phi, r=r, roll=roll, pitch=pitch, yaw=yaw)
        for theta, phi in cells
        for r in r_levels
        for roll, pitch, yaw in attitudes
    ]
