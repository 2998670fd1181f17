"""The speck votes of `grouping._merge_specks`, kept between refreshes (pure).

`_merge_specks` folds each speck (a component of fewer than max(MIN_POSES, MIN_SHARE of the
viable poses) members) into the large neighbouring component it nearly matches most often:
for every member p and every lattice neighbour q of p (`speck_neighbours`, with repeats) in
another component that is large, one vote when `near(p, q)`. Recounting that on every refresh
visits every speck's members, and on fragmented maps that is most of the map.

Here the votes are kept as a weighted graph between components: `W[c][d]` is the number of
directed near links p → q with p in c and q in d ≠ c (every viable pair, large or not: which
components are large changes with the map). A new pose adds its links; a pose that changes
component (a join, a split: `IncrementalGrouping` says which) moves its links' weight from
its old component to its new one. Only the specks whose row changed, or one of whose targets
became large or small or got a new smallest point (the tie-break), are decided again; the
decision is `_merge_specks`'s: the most votes, ties to the smaller first point.

The lattice neighbours of a point depend on its direction cell and level only, apart from its
r index (the normal neighbours) and attitude (carried over): the ring and cross parts are
cached per (ring, azimuth, level), which makes a point's neighbours a few list operations.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Iterable, Mapping

from graspscape.services.coordinator.manifolds.behaviour import StoredPose, same_behaviour
from graspscape.services.coordinator.manifolds.grouping import (
    MIN_POSES,
    MIN_SHARE,
    SPECK_TOLERANCE_RAD,
)
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point


class Neighbours:
    """`grouping.speck_neighbours` (the same points with the same repeats), cached per cell."""

    def __init__(self, lattice: Lattice) -> None:
        self.lattice = lattice
        self._cells: dict[tuple[int, int, int], list[tuple[int, int]]] = {}
        self._top = lattice.n_r << lattice.depth

    def _cell(self, K: int, J: int, level: int) -> list[tuple[int, int]]:
        key = (K, J, level)
        got = self._cells.get(key)
        if got is None:
            lat, p = self.lattice, Point(K, J, 0, 0)
            got = [(q.ring, q.azimuth) for q in lat.ring_neighbours(p, level)
                   + lat.cross_neighbours(p, level)]
            self._cells[key] = got
        return got

    def __call__(self, p: Point) -> list[Point]:
        lat = self.lattice
        if lat.depth == 0:
            return self.at(p, 0)
        return [q for level in range(lat.birth(p), lat.depth + 1) for q in self.at(p, level)]

    def at(self, p: Point, level: int) -> list[Point]:
        """The points of `lattice.neighbours(p, level)`, in its order: normal, ring, cross."""
        top, new = self._top, tuple.__new__  # new: a Point without NamedTuple's __new__
        K, J, i, a = p
        s = 1 << (self.lattice.depth - level)  # lattice.scale(level)
        out = [new(Point, (K, J, r, a)) for r in (i - s, i + s) if 0 <= r <= top]
        out += [new(Point, (k, j, i, a)) for k, j in self._cell(K, J, level)]
        return out


class Kept:
    """A point's neighbour list (`fn(p)`, a pure function of the point) kept once asked: a
    batch asks for the same points' lists in the grouping, the votes, the scores and the
    flags. Lists are shared: callers must not change them."""

    __slots__ = ("fn", "lists")

    def __init__(self, fn: Callable[[Point], list[Point]],
                 lists: dict[Point, list[Point]]) -> None:
        self.fn, self.lists = fn, lists

    def __call__(self, p: Point) -> list[Point]:
        got = self.lists.get(p)
        if got is None:
            got = self.lists[p] = self.fn(p)
        return got


class SpeckVotes:
    """The fold of every speck into its large component (`fold`), kept current."""

    def __init__(self, lattice: Lattice, samples: Mapping[Point, StoredPose],
                 comp_of: Mapping[Point, int], members: Mapping[int, set[Point]],
                 first: Callable[[int], Point]) -> None:
        self.samples = samples
        self.neighbours = Neighbours(lattice)
        self._comp_of, self._members, self._first = comp_of, members, first
        self._rec: dict[Point, int] = {}  # per viable point: the component W counts it in
        self._out: dict[Point, dict[Point, int]] = {}  # near links p → q, with multiplicity
        self._in: dict[Point, dict[Point, int]] = {}  # the same, by q
        self.W: dict[int, Counter[int]] = {}
        self._W_in: dict[int, Counter[int]] = {}
        self._rows: set[int] = set()  # components whose row changed since the last decision
        self._comps: set[int] = set()  # components made, grown, shrunk or gone since
        self._known: dict[int, tuple[int, Point]] = {}  # component → (size, first) decided on
        self._by_size: dict[int, set[int]] = {}
        self._small = MIN_POSES
        self.fold: dict[int, int] = {}  # speck → the component it is folded into
        self.hoods: dict[Point, list[Point]] = {}  # the last batch's neighbour lists

    # --- feeding ---------------------------------------------------------------------------
    def changed(self, cids: Iterable[int]) -> None:
        """Components made, joined (both) or split (both) by the grouping."""
        self._comps.update(cids)

    def sync(self, new: Iterable[Point], moved: Iterable[Point],
             near: Mapping[Point, Mapping[Point, int]] | None = None) -> None:
        """Bring W up to date: the points that changed component first, then the new
        viable points' links (to every viable point counted so far, the batch's earlier
        ones included). `near`: new point → neighbour → whether they are near (bit 1: from
        the new point, bit 2: back), as the grouping has worked it out for the batch
        (`pairs.answers`); pairs not there are asked of `same_behaviour`."""
        rec, comp_of = self._rec, self._comp_of
        for x in moved:
            old = rec.get(x)
            if old is not None and old != comp_of[x]:
                self._rehome(x, old, comp_of[x])
        known = near or {}
        none: dict[Point, int] = {}
        samples = self.samples

        def asked(p: Point, q: Point) -> int:  # a pair the grouping did not answer
            a, b = samples[p], samples[q]
            return (same_behaviour(a, b, SPECK_TOLERANCE_RAD)
                    + 2 * same_behaviour(b, a, SPECK_TOLERANCE_RAD))

        # A point's neighbours are a pure function of it; within one batch the same points
        # are asked for again and again (x's neighbours q, then q's to count the links back),
        # so they are kept for the batch.
        hoods = self.hoods = {}  # kept until the next batch: the running map's flags ask too

        def neighbours(q: Point) -> list[Point]:
            got = hoods.get(q)
            if got is None:
                got = hoods[q] = self.neighbours(q)
            return got

        for x in new:
            cx = rec[x] = comp_of[x]
            mine = neighbours(x)
            out_x = self._out.setdefault(x, {})
            in_x = self._in.setdefault(x, {})
            near_x = known.get(x, none)
            for q, m in Counter(mine).items():
                cq = rec.get(q)
                if cq is None:
                    continue
                ok = near_x.get(q)
                if ok is None:
                    ok = asked(x, q)
                if ok & 1:
                    out_x[q] = m
                    self._in[q][x] = m
                    if cq != cx:
                        self._add(cx, cq, m)
                back = neighbours(q).count(x)  # q → x: as often as q's list names x
                if back and ok & 2:
                    self._out[q][x] = back
                    in_x[q] = back
                    if cq != cx:
                        self._add(cq, cx, back)

    def _add(self, c: int, d: int, m: int) -> None:
        row = self.W.setdefault(c, Counter())
        n = row[d] + m
        col = self._W_in.setdefault(d, Counter())
        if n:
            row[d] = col[c] = n
        else:
            del row[d], col[c]
            if not row:
                del self.W[c]
            if not col:
                del self._W_in[d]
        self._rows.add(c)

    def _rehome(self, x: Point, old: int, new: int) -> None:
        rec = self._rec
        for q, m in self._out[x].items():
            cq = rec[q]
            if cq != old:
                self._add(old, cq, -m)
            if cq != new:
                self._add(new, cq, m)
        for p, m in self._in[x].items():
            cp = rec[p]
            if cp != old:
                self._add(cp, old, -m)
            if cp != new:
                self._add(cp, new, m)
        rec[x] = new

    # --- deciding --------------------------------------------------------------------------
    def update(self) -> set[int]:
        """Decide again what may have changed; returns the specks whose fold changed (made,
        moved or undone) and the components gone that were specks."""
        members, first = self._members, self._first
        small = max(MIN_POSES, math.ceil(MIN_SHARE * len(self._rec)))
        redo = set(self._rows)
        moved: list[int] = []  # components whose size or first point changed
        for c in self._comps:
            known = self._known.pop(c, None)
            if known is not None:
                self._by_size[known[0]].discard(c)
            if c in members:
                now = (len(members[c]), first(c))
                self._known[c] = now
                self._by_size.setdefault(now[0], set()).add(c)
                if known is None or known[1] != now[1] \
                        or (known[0] >= self._small) != (now[0] >= small):
                    moved.append(c)
                redo.add(c)
            else:
                redo.add(c)
        if small != self._small:  # the threshold moved: sizes in between change side
            lo, hi = sorted((self._small, small))
            for size in range(lo, hi):
                moved += self._by_size.get(size, ())
        self._small = small
        for c in moved:
            redo.add(c)
            redo.update(self._W_in.get(c, ()))
        self._rows, self._comps = set(), set()
        changed: set[int] = set()
        for c in redo:
            was = self.fold.get(c)
            into = None
            if c in members and len(members[c]) < small:
                votes = [(-n, first(d), d) for d, n in self.W.get(c, {}).items()
                         if len(members[d]) >= small]
                if votes:
                    into = min(votes)[2]
            if into is None:
                self.fold.pop(c, None)
            else:
                self.fold[c] = into
            if into != was:
                changed.add(c)
        return changed
