"""What a manifold's summary says of its members, as sums that can be added to and taken
from (pure): counts, exact sums of μs and its square, the grasp types counted, and per digit
the exact sums of its contact centroids and their squared norms.

`Stats` is what the full recompute (summary.build_map) adds up member by member and what the
running map (manifolds/running.py) keeps per component, merging two when they join and
taking a part away when a cut splits one; both read the summary's numbers through the same
functions here, so both give the same table to the last bit (manifolds/exact.py).

The description names the most common grasp type's digits (ties: the larger count, then the
sorted digits, as the summary's `digits`) and where each touches the object: the mean of
the members' contact centroids ± their RMS distance from it (kept as sums; the largest
distance it showed before issue 21 cannot be kept up to date without revisiting members).
"""

from __future__ import annotations

import heapq
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.exact import ONE, exact, pstdev, sqrt_of, value
from graspscape.services.coordinator.manifolds.grouping import FineGrid, nearest_known
from graspscape.services.coordinator.mapspace.lattice import Point
from scipy.spatial import cKDTree


@dataclass
class DigitSums:
    n: int = 0
    xyz: list[int] = field(default_factory=lambda: [0, 0, 0])  # exact Σ of each coordinate
    sq: int = 0  # exact Σ of x² + y² + z² (scale 2^(2·SCALE))

    def add(self, point: tuple[float, float, float], sign: int) -> None:
        e = [exact(c) for c in point]
        self.n += sign
        for i in range(3):
            self.xyz[i] += sign * e[i]
        self.sq += sign * (e[0] * e[0] + e[1] * e[1] + e[2] * e[2])


@dataclass
class Stats:
    """The members' sums (see the module docstring)."""

    count: int = 0
    evaluated: int = 0
    mu1: int = 0  # exact Σ μs
    mu2: int = 0  # exact Σ μs²
    kinds: Counter[frozenset[str]] = field(default_factory=Counter)
    digits: dict[str, DigitSums] = field(default_factory=dict)

    def add(self, s: StoredPose, sign: int = 1) -> None:
        e = exact(s.mu_s)
        self.count += sign
        self.evaluated += sign * (s.source == "evaluated")
        self.mu1 += sign * e
        self.mu2 += sign * e * e
        self.kinds[s.digits] += sign
        if not self.kinds[s.digits]:
            del self.kinds[s.digits]
        for d, point in s.contacts.items():
            sums = self.digits.get(d)
            if sums is None:
                sums = self.digits[d] = DigitSums()
            sums.add(point, sign)
            if not sums.n:
                del self.digits[d]

    def merge(self, other: Stats, sign: int = 1) -> None:
        """Add (sign 1) or take away (-1) another component's sums."""
        self.count += sign * other.count
        self.evaluated += sign * other.evaluated
        self.mu1 += sign * other.mu1
        self.mu2 += sign * other.mu2
        for kind, n in other.kinds.items():
            self.kinds[kind] += sign * n
            if not self.kinds[kind]:
                del self.kinds[kind]
        for d, o in other.digits.items():
            mine = self.digits.setdefault(d, DigitSums())
            mine.n += sign * o.n
            mine.xyz = [a + sign * b for a, b in zip(mine.xyz, o.xyz, strict=True)]
            mine.sq += sign * o.sq
            if not mine.n:
                del self.digits[d]

    @staticmethod
    def of(members: Iterable[StoredPose]) -> Stats:
        out = Stats()
        for s in members:
            out.add(s)
        return out

    # --- the summary's numbers ---------------------------------------------------------------
    def mu_mean(self) -> float:
        return value(self.mu1) / self.count  # statistics.fmean: fsum / n

    def mu_std(self) -> float:
        return pstdev(self.count, self.mu1, self.mu2)

    def majority(self) -> list[str]:
        """The most common grasp type's digits, sorted (ties: the sorted digits)."""
        if not self.kinds:
            return []
        return sorted(max(self.kinds.items(), key=lambda kv: (kv[1], sorted(kv[0])))[0])

    def description(self) -> str:
        digits = self.majority()
        parts = []
        for d in digits:
            sums = self.digits.get(d)
            if sums is None:
                continue
            x, y, z = (value(c, sums.n) for c in sums.xyz)
            # RMS distance from the mean: Σ|p|²/n − |mean|², exactly.
            mean_sq = sum(Fraction(c, ONE) ** 2 for c in sums.xyz) / (sums.n * sums.n)
            spread = sqrt_of(Fraction(sums.sq, ONE * ONE) / sums.n - mean_sq)
            parts.append(f"{d} at ({100 * x:.1f}, {100 * y:.1f}, {100 * z:.1f}) cm "
                         f"± {100 * spread:.1f} cm")
        touched = ", ".join(digits) or "nothing"
        return f"{touched} touch the object — " + "; ".join(parts)


class PosSet:
    """Positions with how many points reach each, and the exact m³ of the distinct ones."""

    __slots__ = ("count", "total")

    def __init__(self) -> None:
        self.count: dict[int, int] = {}
        self.total = 0

    def add(self, pos: int, w: list[int], n: int = 1) -> None:
        c = self.count.get(pos, 0)
        if not c:
            self.total += w[pos]
        self.count[pos] = c + n

    def remove(self, pos: int, w: list[int], n: int = 1) -> None:
        c = self.count[pos] - n
        if c:
            self.count[pos] = c
        else:
            del self.count[pos]
            self.total -= w[pos]

    def merge(self, other: PosSet, w: list[int], sign: int) -> None:
        for pos, n in other.count.items():
            (self.add if sign > 0 else self.remove)(pos, w, n)

    def apply(self, pos: list[int], delta: list[int], w: list[int]) -> None:
        """Add delta[k] points at pos[k] (negative: take them away), distinct positions.
        The total follows only the positions whose count crosses zero: it is the exact sum
        over the positions reached, whatever the order the points came and went in."""
        count, total = self.count, self.total
        for p, d in zip(pos, delta, strict=True):
            c = count.get(p, 0) + d
            if c:
                if c == d:
                    total += w[p]
                count[p] = c
            else:
                del count[p]
                total -= w[p]
        self.total = total


class DensePosSet:
    """A PosSet over every position of the lattice (counts in one array): the map's viable
    and non-viable volumes, which a batch changes in bulk."""

    __slots__ = ("count", "total")

    def __init__(self, n_pos: int, w: list[int], n: int = 0) -> None:
        self.count = np.full(n_pos, n, dtype=np.int64)
        self.total = sum(w) if n else 0

    def apply(self, pos: np.ndarray, delta: np.ndarray, w: list[int]) -> None:
        """As PosSet.apply, positions and deltas as arrays."""
        before = self.count[pos]
        after = before + delta
        self.count[pos] = after
        gained = pos[(before == 0) & (after > 0)].tolist()
        lost = pos[(before > 0) & (after == 0)].tolist()
        self.total += sum(w[p] for p in gained) - sum(w[p] for p in lost)


@dataclass
class Comp:
    """One component's sums and heaps (stale heap entries are skipped when read)."""

    stats: Stats = field(default_factory=Stats)
    own: PosSet = field(default_factory=PosSet)  # positions of the points its poses own
    core: PosSet = field(default_factory=PosSet)  # positions of its robust-core poses
    core_count: int = 0
    best: list[tuple[float, str, Point]] = field(default_factory=list)  # (-μs, key, p)
    low: list[tuple[float, str, Point]] = field(default_factory=list)  # (μs, key, p)
    robust: list[tuple[Any, Point]] = field(default_factory=list)  # (robust_order, p)
    maxima: list[tuple[float, Point]] = field(default_factory=list)  # (-μs, p)


def top(heap: list[Any], ok: Callable[[Any], bool], k: int = 1) -> list[Any]:
    """The k best valid entries of one of a component's heaps, one per pose (stale and
    repeated entries are dropped on the way)."""
    out: list[Any] = []
    seen: set[Point] = set()
    while heap and len(out) < k:
        entry = heapq.heappop(heap)
        p = entry[-1]
        if p not in seen and ok(entry):
            seen.add(p)
            out.append(entry)
    for entry in out:
        heapq.heappush(heap, entry)
    return out


class Owners:
    """Every finest point's nearest stored pose of its attitude (`grouping.nearest_known`),
    kept as samples arrive: a new pose can take only points within `rho` of it, or points
    whose nearest pose is farther than `rho` (`far`, empty once the coarse pass covers the
    lattice), so only those are searched.

    Points and samples are numbered f = position × n_a + attitude (a sample by its own
    point; the grid's cells are in (K, J) order, so f orders samples as Points do). What a
    sample owns is read from the owner array when asked (`positions`), not kept per sample:
    a sweep's new poses take over most unswept points batch after batch."""

    def __init__(self, grid: FineGrid, rho: float) -> None:
        assert grid.cells == sorted(grid.cells)
        n = len(grid.weights) * grid.n_a
        self.grid, self.rho = grid, rho
        self.tree = cKDTree(grid.embedding)
        self.owner = np.full(n, -1, dtype=np.int64)  # f of its nearest sample; -1: none
        self.d2 = np.full(n, np.inf)  # the rounded squared distance to it (`sq_dist`)
        self.point: dict[int, Point] = {}  # f → the sample there
        self.far = [np.arange(len(grid.weights)) for _ in range(grid.n_a)]  # per attitude
        self._sorted: tuple[np.ndarray, np.ndarray] | None = None  # owner sorted, cached

    def key(self, p: Point) -> int:
        return self.grid.position(p) * self.grid.n_a + p.attitude

    def take(self, new: Iterable[Point]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Give the new samples the points they are now nearest to: (f, old owner, new
        owner) of the points that changed hands."""
        grid, n_a = self.grid, self.grid.n_a
        by_att: dict[int, list[Point]] = {}
        for p in new:
            by_att.setdefault(p.attitude, []).append(p)
        moves = [(np.zeros(0, dtype=np.int64),) * 3]
        # A tile is cells × r levels × attitudes, so a batch's poses of every attitude are
        # usually at the same positions: the search (which sees positions only, and indexes
        # the sorted known poses, which are then in the same order) is made once per distinct
        # positions and candidates, not once per attitude. The same arrays either way.
        searched: dict[tuple[bytes, bytes], tuple[np.ndarray, np.ndarray]] = {}
        nearby: dict[bytes, np.ndarray] = {}
        for a, known in by_att.items():
            known.sort()
            own_pos = np.array([grid.position(p) for p in known])
            keys = own_pos * n_a + a
            self.point.update(zip(keys.tolist(), known, strict=True))
            at = own_pos.tobytes()
            near = nearby.get(at)
            if near is None:
                near = nearby[at] = np.concatenate([
                    np.asarray(x, dtype=np.int64) for x in self.tree.query_ball_point(
                        grid.embedding[own_pos], self.rho * (1 + 1e-9))])
            # and every far one: while a sweep covers the lattice, the batch is nearer to
            # most of them than their owner (a first pass to sort them out costs more).
            # The sorted union by a mask over the positions: while the sweep runs `far` is
            # most of the lattice, and np.unique's hash/sort of it was ~12 ms per attitude.
            mask = np.zeros(len(grid.weights), dtype=bool)
            mask[near] = True
            mask[self.far[a]] = True
            cand = np.flatnonzero(mask)
            found = searched.get((at, cand.tobytes()))
            if found is None:
                found = searched[(at, cand.tobytes())] = nearest_known(grid, known, cand)
            idx, d2 = found
            f = cand * n_a + a
            cur, old, q = self.d2[f], self.owner[f], keys[idx]
            # Nearer, or as near and the smaller point (nearest_known's ties).
            take = (d2 < cur) | ((d2 == cur) & ((old < 0) | (q < old)))
            f, old, q = f[take], old[take], q[take]
            self.owner[f] = q
            self.d2[f] = d2[take]
            moves.append((f, old, q))
            far = self.far[a]
            self.far[a] = far[self.d2[far * n_a + a] > self.rho ** 2]
        self._sorted = None
        f, old, q = (np.concatenate(x) for x in zip(*moves, strict=True))
        return f, old, q

    def positions(self, part: Iterable[Point]) -> tuple[list[int], list[int]]:
        """The positions of the points these samples own, with how many of them each."""
        if self._sorted is None:  # once per batch that asks (one that splits a component)
            order = np.argsort(self.owner, kind="stable")
            self._sorted = (order, self.owner[order])
        order, owners = self._sorted
        keys = np.array([self.key(p) for p in part], dtype=np.int64)
        lo = np.searchsorted(owners, keys, "left")
        hi = np.searchsorted(owners, keys, "right")
        if not (hi > lo).any():
            return [], []
        f = np.concatenate([order[a:b] for a, b in zip(lo.tolist(), hi.tolist(), strict=True)])
        pos, n = np.unique(f // self.grid.n_a, return_counts=True)
        return pos.tolist(), n.tolist()
