"""A manifold's local maxima of μs on the lattice (pure): what the adaptive search starts from
and what a manifold's summary lists."""

from __future__ import annotations

from collections.abc import Callable

from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.services.coordinator.mapspace.pose import StoredPose

Lookup = Callable[[Point], StoredPose | None]


def local_maxima(
    lattice: Lattice, members: list[Point], lookup: Lookup, *, top: int
) -> list[Point]:
    """Viable members whose μs is at least that of every known neighbour in the manifold."""
    member_set = set(members)
    maxima = []
    for p in members:
        a = lookup(p)
        if a is None:
            continue
        best = True
        for level in range(lattice.birth(p), lattice.depth + 1):
            for _, q in lattice.neighbours(p, level):
                b = lookup(q)
                if q in member_set and b is not None and b.mu_s > a.mu_s:
                    best = False
                    break
            if not best:
                break
        if best:
            maxima.append(p)
    maxima.sort(key=lambda q: (-lookup(q).mu_s, q))  # type: ignore[union-attr]
    return maxima[:top]
