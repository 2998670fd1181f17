"""Adaptive decisions: which poses to evaluate next, from stored results only (pure functions).

Every decision is a function of the results of two lattice neighbours (or of the two ends of
a normal segment) and of nothing else: not of arrival order, not of which worker sent what.
The set of poses an exploration evaluates is therefore the least set closed under these rules,
the same for one worker or eight (see docs/design/exploration.md, "Determinism").

- Border refinement: for neighbours p, q at level L that differ (viability, grasp type, or a
  μs step above the slope criterion), the level-L+1 point between them is evaluated. The new
  point has level-L+1 neighbours, among them p or q, so the border is bisected recursively
  down to the refinement depth.
- Normal reuse (shortcut 1): along one surface normal (fixed cell and attitude) the coarse r
  levels are bisected: the two ends first; if both give the same grasp the levels between are
  inferred from the nearer end (ties: the inner one), else the middle level is evaluated and
  both halves are decided the same way.
- Local search: at quiescence (no tile open), from the best local maxima of each manifold,
  the finest-level neighbours not yet known are evaluated (one step of discrete gradient
  ascent on μs per round).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose, differs
from graspscape.services.coordinator.mapspace.maxima import local_maxima as local_maxima

Lookup = Callable[[Point], StoredPose | None]


@dataclass(frozen=True)
class Proposal:
    point: Point
    level: int
    reason: str  # "refine" | "normal" | "search"


@dataclass(frozen=True)
class Inference:
    point: Point
    source: Point  # whose result is reused
    reason: str  # "normal"


def lookup_points(lattice: Lattice, p: Point) -> set[Point]:
    """Every point whose result a decision about p may read."""
    out = set()
    for level in range(lattice.birth(p), lattice.depth + 1):
        for _, q in lattice.neighbours(p, level):
            out.add(q)
            mid = lattice.midpoint(p, q, level)
            if mid is not None:
                out.add(mid)
    s = lattice.scale(0)
    if p.r_index % s == 0 and lattice.birth(p) == 0:
        out |= {p.at_r(i * s) for i in range(lattice.n_r + 1)}
    return out


def border_proposals(
    lattice: Lattice, p: Point, lookup: Lookup, mu_step_max: float | None
) -> list[Proposal]:
    a = lookup(p)
    if a is None:
        return []
    out = []
    for level in range(lattice.birth(p), lattice.depth):
        for _, q in lattice.neighbours(p, level):
            b = lookup(q)
            if b is not None and differs(a, b, mu_step_max):
                mid = lattice.midpoint(p, q, level)
                if mid is not None:
                    out.append(Proposal(mid, level + 1, "refine"))
    return out


def normal_segments(n_r: int) -> Iterator[tuple[int, int]]:
    """The bisection tree of coarse r indices [0, n_r], parents before children."""
    stack = [(0, n_r)]
    while stack:
        lo, hi = stack.pop(0)
        if hi - lo > 1:
            yield lo, hi
            mid = (lo + hi) // 2
            stack += [(lo, mid), (mid, hi)]


# Sources of results whose grasp was synthesized for the pose itself (shortcut 2 reuses only
# the trajectory's outcome), as opposed to results copied onto it by the coordinator.
SYNTHESIZED = frozenset({"evaluated", "shortcut:configuration"})


def normal_decisions(
    lattice: Lattice, p: Point, lookup: Lookup, mu_step_max: float | None
) -> tuple[list[Proposal], list[Inference]]:
    """Shortcut 1 for the normal through coarse point p (only ends whose grasp was
    synthesized here decide: evaluated ones, or ones that reused a matching grasp's outcome)."""
    s = lattice.scale(0)
    if lattice.birth(p) != 0:
        return [], []
    i = p.r_index // s
    proposals: list[Proposal] = []
    inferred: list[Inference] = []
    for lo, hi in normal_segments(lattice.n_r):
        if i not in (lo, hi):
            continue
        low, high = p.at_r(lo * s), p.at_r(hi * s)
        a, b = lookup(low), lookup(high)
        if a is None or b is None or a.source not in SYNTHESIZED or b.source not in SYNTHESIZED:
            continue
        mid = (lo + hi) // 2
        if differs(a, b, mu_step_max):
            proposals.append(Proposal(p.at_r(mid * s), 0, "normal"))
        else:
            for k in range(lo + 1, hi):
                source = low if k - lo <= hi - k else high
                inferred.append(Inference(p.at_r(k * s), source, "normal"))
    return proposals, inferred


def search_proposals(lattice: Lattice, maxima: list[Point], lookup: Lookup) -> list[Proposal]:
    """The unknown finest-level neighbours of each local maximum."""
    out = []
    for p in maxima:
        for _, q in lattice.neighbours(p, lattice.depth):
            if lookup(q) is None:
                out.append(Proposal(q, lattice.depth, "search"))
    return out
