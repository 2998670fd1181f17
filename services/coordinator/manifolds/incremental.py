"""Manifold grouping kept current batch by batch (pure): the same components as
`grouping.components` over everything seen, without recomputing the whole map.

The links are those of `grouping.components`: a viable pose p links a same-behaviour viable
neighbour q of one of its levels L (from its birth level down) unless the level-L+1 midpoint
of (p, q) is stored, and its attitude neighbours always. A link is added when the later of
its two ends arrives; one whose midpoint arrives later is cut then (refinement found the
border between them). Components are kept as explicit member sets:

- joins merge the smaller set into the larger (each point moves O(log n) times in all);
- a cut link (p, q) is checked, as soon as it is cut, by two breadth-first searches run in
  step from p and from q over the remaining links: they meet (still one component: usually
  within a few steps, through the new midpoint's own links) or one side runs out first, and
  that side (the smaller part) becomes a new component.

So a batch costs its own points' neighbourhoods plus the parts it splits off, not the map.
Specks are folded as `grouping.components` does (`_merge_specks`), from votes kept between
batches (manifolds/specks.py: weights between components, moved with the points that change
component, decisions redone only where they may change): `update_fold` costs the batch, not
the specks. `components()` hands the components over in the canonical order (a pass over
the map: for tests and callers that want them all); the sorted member lists are kept per
component and rebuilt only where a batch changed that component. Samples are stored
results: a point arriving again with the same result changes nothing, with a different one
the state is rebuilt from everything seen.
"""

from __future__ import annotations

import threading
from bisect import bisect_left, insort
from collections import deque
from collections.abc import Hashable, Iterable, Mapping
from typing import Protocol

from graspscape.services.coordinator.manifolds.behaviour import JOINT_TOLERANCE_RAD, StoredPose
from graspscape.services.coordinator.manifolds.grouping import SPECK_TOLERANCE_RAD
from graspscape.services.coordinator.manifolds.pairs import PairBehaviour, answers
from graspscape.services.coordinator.manifolds.specks import SpeckVotes
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point

Pair = tuple[Point, Point]
# p → q, its midpoint, whether q → p is made too (q stored before the batch), that one's
Link = tuple[Point, Point, "Point | None", bool, "Point | None"]


def _pair(p: Point, q: Point) -> Pair:
    return (p, q) if p < q else (q, p)


class Listener(Protocol):
    def on_new(self, cid: int, p: Point) -> None: ...
    def on_join(self, into: int, gone: int, moved: set[Point]) -> None: ...
    def on_detach(self, old: int, new: int, part: set[Point]) -> None: ...


class IncrementalGrouping:
    """Components of the samples fed so far (`add`), equal to `grouping.components`."""

    def __init__(self, lattice: Lattice) -> None:
        self.lattice = lattice
        self.samples: dict[Point, StoredPose] = {}
        # Live links: directed links per unordered pair (a pair may be linked from both ends,
        # each with its own midpoint), and the adjacency of pairs with at least one.
        self._count: dict[Pair, int] = {}
        self._adj: dict[Point, set[Point]] = {}
        # midpoint → the pairs of the live links it cuts when it arrives
        self._cutters: dict[Point, list[Pair]] = {}
        self._comp_of: dict[Point, int] = {}
        self._members: dict[int, set[Point]] = {}
        self._sorted: dict[int, list[Point]] = {}  # sorted(members), per component
        self._next_id = 0
        # Told of every component change (manifolds/running.py keeps sums per component).
        self.listener: Listener | None = None
        self._votes = SpeckVotes(lattice, self.samples, self._comp_of, self._members,
                                 self.first)
        self.neighbours = self._votes.neighbours  # `grouping.speck_neighbours`, cached
        self._moved: list[Point] = []  # points that changed component in this batch
        self._attitude_cache: dict[int, tuple[int, ...]] = {}  # `_attitudes`
        self._pairs = PairBehaviour()  # the poses' behaviour as arrays, for a batch's pairs

    def __len__(self) -> int:
        return len(self.samples)

    # --- feeding ---------------------------------------------------------------------------
    def add(self, batch: Iterable[tuple[Point, StoredPose]]) -> None:
        """Take a batch of stored samples (any order, any mix of levels)."""
        new: dict[Point, StoredPose] = {}
        for p, s in batch:
            old = self.samples.get(p, new.get(p))
            if old is None:
                new[p] = s
            elif old != s:  # a stored result changed: not incremental any more
                self._rebuild({**self.samples, **new, p: s})
                return
        if not new:
            return
        self.samples.update(new)
        self._pairs.add(new)
        for p, s in new.items():
            if s.viable:
                self._new_component(p)
        links = self._links_of(new)
        # Whether each pair behaves alike, for the whole batch at once (manifolds/pairs.py):
        # bit 1 p → q, bit 2 q → p; the speck votes ask the same pairs with their tolerance.
        pairs = [(p, q) for p, q, _, _, _ in links]
        diffs = self._pairs.differences(pairs)
        same = answers(pairs, diffs, self.samples, JOINT_TOLERANCE_RAD)
        link = self._link
        for (p, q, mid, back, mid_back), ok in zip(links, same, strict=True):
            link(p, q, mid, ok & 1)
            if back:
                link(q, p, mid_back, ok & 2)
        # Then the links the new points cut (all of them made before this batch), one at a
        # time: a connected component less one link is at most two parts, so the search
        # from the link's ends finds the whole part that left. (Cutting them all first and
        # searching after could leave the rest in pieces: cuts P–Q and Q–X detach Q, and
        # P and X, no longer linked, stayed one component.)
        for m in new:
            for pair in self._cutters.pop(m, ()):
                if self._unlink(pair) and self._comp_of[pair[0]] == self._comp_of[pair[1]]:
                    self._split(*pair)
        moved, self._moved = self._moved, []
        by_point: dict[Point, dict[Point, int]] = {}
        for (p, q), ok in zip(pairs, answers(pairs, diffs, self.samples, SPECK_TOLERANCE_RAD),
                              strict=True):
            got = by_point.get(p)
            if got is None:
                got = by_point[p] = {}
            got[q] = ok
        self._votes.sync(sorted(p for p, s in new.items() if s.viable), moved, by_point)

    def _links_of(self, new: Mapping[Point, StoredPose]) -> list[Link]:
        """The links a batch's new points may make, in the order they are made: p → q of
        every new point, and q → p from the points stored before this batch (`back`). The
        neighbour relation is symmetric level by level (q is p's level-L neighbour iff p is
        q's: the tests check it), so p's own neighbour lists find both."""
        lat, samples, make = self.lattice, self.samples, tuple.__new__
        at = self.neighbours.at  # lat.neighbours(p, level)'s points, cached per direction cell
        out: list[Link] = []
        for p in sorted(new):
            if not new[p].viable:
                continue
            for level in range(lat.birth(p), lat.depth + 1):
                finest = level >= lat.depth  # lat.midpoint is None there: not asked
                for q in at(p, level):
                    b = samples.get(q)
                    if b is None or not b.viable:
                        continue
                    back = q not in new
                    out.append((p, q, None if finest else lat.midpoint(p, q, level), back,
                                None if finest or not back else lat.midpoint(q, p, level)))
            K, J, i, _ = p
            for a in self._attitudes(p):  # never cut: one link is enough
                q = make(Point, (K, J, i, a))
                if q in samples:
                    out.append((p, q, None, False, None))
        return out

    def _rebuild(self, samples: Mapping[Point, StoredPose]) -> None:
        fresh = IncrementalGrouping(self.lattice)
        fresh.add(samples.items())
        self.__dict__.update(fresh.__dict__)

    def _attitudes(self, p: Point) -> tuple[int, ...]:
        """The attitudes of `lattice.attitude_neighbours(p)`, in its order (they depend on
        p's attitude only: kept per attitude)."""
        got = self._attitude_cache.get(p.attitude)
        if got is None:
            got = tuple(q.attitude for q in self.lattice.attitude_neighbours(p))
            self._attitude_cache[p.attitude] = got
        return got

    def _link(self, p: Point, q: Point, mid: Point | None, same: int) -> None:
        """Link p → q as `grouping.components` does: both viable, the same behaviour (`same`:
        `same_behaviour(p's, q's)`, as `pairs.answers` gave it), and the midpoint between
        them (if any) not stored."""
        samples = self.samples
        if mid is not None and mid in samples:
            return
        a, b = samples[p], samples[q]
        if not (a.viable and b.viable and same):
            return
        pair = (p, q) if p < q else (q, p)  # _pair(p, q)
        n = self._count.get(pair, 0)
        self._count[pair] = n + 1
        if mid is not None:
            self._cutters.setdefault(mid, []).append(pair)
        if n == 0:
            self._adj.setdefault(p, set()).add(q)
            self._adj.setdefault(q, set()).add(p)
            self._join(p, q)

    def _unlink(self, pair: Pair) -> bool:
        """Drop one directed link of the pair; True when the pair has none left."""
        n = self._count[pair] - 1
        if n:
            self._count[pair] = n
            return False
        del self._count[pair]
        p, q = pair
        self._adj[p].discard(q)
        self._adj[q].discard(p)
        return True

    # --- components ------------------------------------------------------------------------
    def _new_component(self, p: Point) -> None:
        cid = self._next_id
        self._next_id += 1
        self._comp_of[p] = cid
        self._members[cid] = {p}
        self._sorted[cid] = [p]
        self._votes.changed((cid,))
        if self.listener is not None:
            self.listener.on_new(cid, p)

    def _join(self, p: Point, q: Point) -> None:
        a, b = self._comp_of[p], self._comp_of[q]
        if a == b:
            return
        if len(self._members[a]) < len(self._members[b]):
            a, b = b, a
        moved = self._members.pop(b)
        into = self._sorted[a]
        for x in self._sorted.pop(b):  # the smaller into the larger: log n steps each
            self._comp_of[x] = a
            insort(into, x)
        self._members[a] |= moved
        self._moved += moved
        self._votes.changed((a, b))
        if self.listener is not None:
            self.listener.on_join(a, b, moved)

    def _split(self, p: Point, q: Point) -> None:
        """p and q lost their direct link: search from both in step; if one search runs out
        before they meet, its points are a component of their own."""
        seen = ({p}, {q})
        queues = (deque([p]), deque([q]))
        while True:
            for side in (0, 1):
                queue, mine, other = queues[side], seen[side], seen[1 - side]
                if not queue:
                    self._detach(mine)
                    return
                x = queue.popleft()
                for y in self._adj.get(x, ()):
                    if y in other:
                        return  # they meet: still one component
                    if y not in mine:
                        mine.add(y)
                        queue.append(y)

    def _detach(self, part: set[Point]) -> None:
        old = self._comp_of[next(iter(part))]
        self._members[old] -= part
        rest = self._sorted[old]
        for x in part:  # the part that ran out first: the smaller one
            del rest[bisect_left(rest, x)]
        cid = self._next_id
        self._next_id += 1
        self._members[cid] = part
        self._sorted[cid] = sorted(part)
        for x in part:
            self._comp_of[x] = cid
        self._moved += part
        self._votes.changed((old, cid))
        if self.listener is not None:
            self.listener.on_detach(old, cid, part)

    # --- reading ---------------------------------------------------------------------------
    def raw_components(self) -> list[list[Point]]:
        """The linked components before speck folding, each sorted, by their first point."""
        return sorted(self._sorted.values(), key=lambda c: c[0])

    @property
    def fold(self) -> dict[int, int]:
        """speck → the component it is folded into, as of the last `update_fold` (shared:
        callers must not change it)."""
        return self._votes.fold

    def update_fold(self) -> set[int]:
        """Decide the specks again where the batches since the last call may have changed
        them; returns the specks whose fold changed (and specks gone)."""
        return self._votes.update()

    def components(self) -> list[list[Point]]:
        """What `grouping.components(lattice, samples)` gives for every sample fed so far
        (`_merge_specks`'s output: components not merged are the cached lists, shared:
        callers must not change them)."""
        self.update_fold()
        raw = self.raw_components()
        fold = self.fold
        if not fold:
            return raw
        parts: dict[int, list[list[Point]]] = {}
        for c in raw:
            cid = self._comp_of[c[0]]
            parts.setdefault(fold.get(cid, cid), []).append(c)
        return sorted((ps[0] if len(ps) == 1 else sorted(x for c in ps for x in c)
                       for ps in parts.values()), key=lambda g: g[0])

    @property
    def batch_neighbours(self) -> dict[Point, list[Point]]:
        """`neighbours` of the points the last batch asked about (shared: a neighbour list is
        a pure function of the point, so it stays true after the batch)."""
        return self._votes.hoods

    def comp_of(self, p: Point) -> int | None:
        return self._comp_of.get(p)

    def first(self, cid: int) -> Point:
        """The component's smallest point."""
        return self._sorted[cid][0]

    def members(self, cid: int) -> list[Point]:
        """The component's points, sorted (shared: callers must not change it)."""
        return self._sorted[cid]

    def cids(self) -> Iterable[int]:
        return self._sorted.keys()


class GroupingCache:
    """Per-process states by a caller's key (the coordinator: database, exploration id and
    creation time), the least recently used dropped beyond `size`. `components` feeds a
    state the samples it has not seen and answers its components; a state whose samples are
    not all among those given (another database, a rebuilt store) starts again from them, so
    a restart or a cold cache only costs one full grouping. Thread-safe."""

    def __init__(self, size: int = 8) -> None:
        self.size = size
        self._states: dict[Hashable, IncrementalGrouping] = {}
        self._lock = threading.Lock()

    def components(
        self, key: Hashable, lattice: Lattice, samples: Mapping[Point, StoredPose]
    ) -> list[list[Point]]:
        with self._lock:
            state = self._states.pop(key, None)
            if (state is None or state.lattice != lattice
                    or not state.samples.keys() <= samples.keys()):
                state = IncrementalGrouping(lattice)
            seen = state.samples
            state.add((p, s) for p, s in samples.items() if p not in seen)
            self._states[key] = state  # most recent last
            while len(self._states) > self.size:
                del self._states[next(iter(self._states))]
            return state.components()
