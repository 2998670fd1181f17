"""The manifold map kept up to date batch by batch (pure): the table `summary.build_map`
computes from every pose, at the cost of the batch and its surroundings, not of the map.

What a batch changes, and what is redone for it:

- grouping: `IncrementalGrouping` links the batch in (joins, cuts), telling this map of each
  component made, joined or split (`on_new`, `on_join`, `on_detach`);
- volumes: every finest-lattice point belongs to its nearest stored pose of its attitude
  (`aggregate.Owners`: only points within RHO of a new pose, or farther than RHO from their
  owner, are searched). Each component keeps its points' positions counted (`PosSet`, a
  position once however many attitudes reach it) with their exact volume, changed in bulk
  by the points that pass between classes (not viable, or a component: `_move`); a point
  taken over within its class, as most are while a sweep covers the lattice, changes none;
- robust scores (manifolds/robust.py) of the batch's poses and their N_δ neighbours;
- per pose, whether it is in its manifold's robust core and whether it is a local maximum,
  for the poses whose manifold (or whose neighbours') changed;
- per component, sums (aggregate.Stats) and heaps of the best, the lowest μs, the robust
  best and the local maxima, whose stale entries are dropped when they come to the top.

A join adds the smaller component's sums into the larger; a split computes the part that
left (the smaller) and takes it away. Manifolds are the components with their specks folded
in (`IncrementalGrouping.fold`); a manifold's summary is rebuilt only when one of its
components changed. Sums are exact (manifolds/exact.py), so the table is the full
recompute's to the last bit, whatever the arrival order (test_running.py).
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from graspscape.services.coordinator.manifolds.aggregate import (
    Comp,
    DensePosSet,
    Owners,
    Stats,
    top,
)
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.exact import value
from graspscape.services.coordinator.manifolds.grouping import (
    FineGrid,
    fine_grid,
    label_name,
)
from graspscape.services.coordinator.manifolds.incremental import IncrementalGrouping
from graspscape.services.coordinator.manifolds.robust import (
    LARGE_SHARE,
    Neighbourhoods,
    RobustScore,
    large_manifolds,
    robust_scores,
)
from graspscape.services.coordinator.manifolds.specks import Kept
from graspscape.services.coordinator.manifolds.summary import (
    ManifoldSummary,
    label_order,
    robust_order,
    summary_of,
)
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point

RHO_STEPS = 1.5  # search radius of a new pose's volume, in coarse angular steps


@dataclass
class Table:
    """The manifolds in label order, and what each manifold's poses are (by its main
    component: the one its specks are folded into)."""

    manifolds: list[ManifoldSummary]
    mains: list[int]  # main component of each manifold, in label order
    viable_volume_m3: float
    non_viable_volume_m3: float


class RunningMap:
    """The map of every sample `add`ed so far (see the module docstring)."""

    def __init__(self, lattice: Lattice, radius: Callable[[np.ndarray], np.ndarray],
                 maxima_per_manifold: int = 3, grid: FineGrid | None = None) -> None:
        self.lattice = lattice
        self.top = maxima_per_manifold
        self.grid = grid or fine_grid(lattice, radius)
        self.g = IncrementalGrouping(lattice)
        self.g.listener = self
        self.samples = self.g.samples
        self.hood = Neighbourhoods(lattice)
        self._hoods: Kept | None = None  # self.hood's lists, kept while a batch is added
        self.scores: dict[Point, RobustScore] = {}
        self.comps: dict[int, Comp] = {}
        n_pos, n_a = len(self.grid.weights), self.grid.n_a
        self.w = self.grid.weights_exact
        self.owners = Owners(self.grid, RHO_STEPS * lattice.dtheta(0))
        self.viable_pos = DensePosSet(n_pos, self.w)
        self.non_viable_pos = DensePosSet(n_pos, self.w, n_a)
        self._core: set[Point] = set()
        self._max: set[Point] = set()
        self._touched: set[int] = set()
        self._moved: set[Point] = set()
        self.rescored: set[Point] = set()  # poses whose robust score the last batch changed
        self._fold = self.g.fold  # speck → its main component, kept by the grouping
        # main component → (its components, volume m³, summary) as last written
        self._cache: dict[int, tuple[tuple[int, ...], float, ManifoldSummary]] = {}
        self.table = Table([], [], 0.0, 0.0)

    # --- grouping's news ---------------------------------------------------------------------
    def on_new(self, cid: int, p: Point) -> None:
        comp = self.comps[cid] = Comp()
        self._count_in(comp, p)
        self._touched.add(cid)
        self._moved.add(p)

    def on_join(self, into: int, gone: int, moved: set[Point]) -> None:
        a, b = self.comps[into], self.comps.pop(gone)
        a.stats.merge(b.stats)
        a.own.merge(b.own, self.w, 1)
        a.core.merge(b.core, self.w, 1)
        a.core_count += b.core_count
        for mine, theirs in ((a.best, b.best), (a.low, b.low), (a.robust, b.robust),
                             (a.maxima, b.maxima)):
            for entry in theirs:
                heapq.heappush(mine, entry)  # type: ignore[arg-type]
        self._touched.update((into, gone))
        self._moved |= moved

    def on_detach(self, old: int, new: int, part: set[Point]) -> None:
        comp = self.comps[new] = Comp()
        for p in part:
            self._count_in(comp, p)
        pos, n = self.owners.positions(part)
        comp.own.apply(pos, n, self.w)
        a = self.comps[old]
        a.stats.merge(comp.stats, -1)
        a.own.merge(comp.own, self.w, -1)
        a.core.merge(comp.core, self.w, -1)
        a.core_count -= comp.core_count
        self._touched.update((old, new))
        self._moved |= part

    def _count_in(self, comp: Comp, p: Point) -> None:
        """Add p's share to a component it has just joined (sums, flags; not the points it
        owns: a new pose owns none yet, a detached part's are counted at once)."""
        s = self.samples[p]
        comp.stats.add(s)
        if p in self._core:
            comp.core.add(self.grid.position(p), self.w)
            comp.core_count += 1
        heapq.heappush(comp.best, (-s.mu_s, s.key, p))
        heapq.heappush(comp.low, (s.mu_s, s.key, p))
        sc = self.scores.get(p)
        if sc is not None:
            heapq.heappush(comp.robust, (robust_order(s, sc), p))
        if p in self._max:
            heapq.heappush(comp.maxima, (-s.mu_s, p))

    # --- a batch ---------------------------------------------------------------------------
    def add(self, batch: Mapping[Point, StoredPose]) -> set[Point]:
        """Take a batch of stored samples; returns the poses whose manifold may have changed
        (the batch's, those moved between components, those of re-folded specks)."""
        new = {p: s for p, s in batch.items() if p not in self.samples}
        for p, s in batch.items():
            if p in self.samples and self.samples[p] != s:
                raise ValueError(f"the stored result of {p} changed: start a new map")
        self._moved = set()
        self.rescored = set()
        self._hoods = Kept(self.hood, {})  # N_δ lists, asked by the scores and the flags
        if new:
            self.g.add(new.items())  # components: on_new, on_join, on_detach
            self._own(new)
            self._score(new)
        refolded = self.g.update_fold()  # the specks decided again (manifolds/specks.py)
        dirty = set(self._moved)
        for c in refolded:
            if c in self.comps:
                dirty.update(self.g.members(c))
                self._touched.add(c)
        self._flags(dirty)
        self._table()
        self._hoods = None  # not kept with the map (nor in its snapshots)
        return dirty

    def final(self, p: Point) -> int | None:
        """The main component of p's manifold (None: not viable)."""
        cid = self.g.comp_of(p)
        return None if cid is None else self._fold.get(cid, cid)

    def _own(self, new: Mapping[Point, StoredPose]) -> None:
        """Give the new samples the finest points they are now nearest to."""
        moves = self.owners.take(new)
        if len(moves[0]):
            self._move(*moves)

    def _move(self, f: np.ndarray, old: np.ndarray, new: np.ndarray) -> None:
        """Finest points f pass from their old owners (-1: none) to new ones: the counts of
        the classes they leave and join (-1: not viable, else the owner's component) change
        where the two differ. Most moves stay in one class (a sweep's new poses take points
        from the same manifold's earlier ones): nothing changes for them."""
        owners = np.unique(np.concatenate([old[old >= 0], new]))
        point = self.owners.point
        cls = np.array([self._class(point[k]) for k in owners.tolist()],
                       dtype=np.int64)
        c_old = np.where(old >= 0, cls[np.searchsorted(owners, np.maximum(old, 0))], -1)
        c_new = cls[np.searchsorted(owners, new)]
        changed = c_old != c_new
        if not changed.any():
            return
        c_old, c_new = c_old[changed], c_new[changed]
        pos = f[changed] // self.grid.n_a
        n_pos, w = len(self.w), self.w
        # The map's viable positions: +1 where a point became viable, -1 where it stopped.
        d = (c_new >= 0).astype(np.int64) - (c_old >= 0)
        if d.any():
            at, delta = _summed(pos[d != 0], d[d != 0])
            self.viable_pos.apply(at, delta, w)
            self.non_viable_pos.apply(at, -delta, w)
        # Each component's: -1 where it lost a point, +1 where it gained one.
        cids = np.concatenate([c_old, c_new])
        viable = cids >= 0
        keys = cids[viable] * n_pos + np.concatenate([pos, pos])[viable]
        signs = np.repeat(np.array([-1, 1], dtype=np.int64), len(pos))[viable]
        at, delta = _summed(keys, signs)
        comp_of, bounds = at // n_pos, np.flatnonzero(np.diff(at // n_pos)) + 1
        for lo, hi in zip([0, *bounds.tolist()], [*bounds.tolist(), len(at)], strict=True):
            cid = int(comp_of[lo])
            self.comps[cid].own.apply((at[lo:hi] % n_pos).tolist(), delta[lo:hi].tolist(), w)
            self._touched.add(cid)

    def _class(self, p: Point) -> int:
        """-1: p is not viable; else its component."""
        cid = self.g.comp_of(p) if self.samples[p].viable else None
        return -1 if cid is None else cid

    def _score(self, new: Mapping[Point, StoredPose]) -> None:
        hood = self._hoods
        affected = set(new)
        for p in new:
            affected.update(q for q in hood(p) if q in self.samples)
        for p, sc in robust_scores(self.lattice, self.samples, sorted(affected),
                                   hood=hood).items():  # type: ignore[arg-type]
            if self.scores.get(p) == sc:
                continue
            self.scores[p] = sc
            self.rescored.add(p)
            cid = self.g.comp_of(p)
            if cid is not None:
                heapq.heappush(self.comps[cid].robust, (robust_order(self.samples[p], sc), p))
                self._touched.add(cid)

    def _flags(self, dirty: set[Point]) -> None:
        """Core and local-maximum flags of the dirty poses and their neighbours."""
        samples, grid, w = self.samples, self.grid, self.w
        hood = self._hoods
        # grouping.speck_neighbours, cached per direction cell; those the batch's speck votes
        # listed already are taken from them
        nbrs = Kept(self.g.neighbours, self.g.batch_neighbours)
        core_check: set[Point] = set()
        max_check: set[Point] = set()
        for p in dirty:
            core_check.add(p)
            core_check.update(hood(p))
            max_check.add(p)
            max_check.update(nbrs(p))
        for p in core_check:
            main = self.final(p)
            if main is None:
                continue
            is_core = all(q in samples and self.final(q) == main for q in hood(p))
            if is_core != (p in self._core):
                comp = self.comps[self.g.comp_of(p)]  # type: ignore[index]
                if is_core:
                    self._core.add(p)
                    comp.core.add(grid.position(p), w)
                    comp.core_count += 1
                else:
                    self._core.discard(p)
                    comp.core.remove(grid.position(p), w)
                    comp.core_count -= 1
                self._touched.add(self.g.comp_of(p))  # type: ignore[arg-type]
        for p in max_check:
            main = self.final(p)
            if main is None:
                continue
            mu = samples[p].mu_s
            is_max = not any(q in samples and samples[q].mu_s > mu and self.final(q) == main
                             for q in nbrs(p))
            if is_max != (p in self._max):
                cid = self.g.comp_of(p)
                if is_max:
                    self._max.add(p)
                    heapq.heappush(self.comps[cid].maxima, (-mu, p))  # type: ignore[index]
                else:
                    self._max.discard(p)
                self._touched.add(cid)  # type: ignore[arg-type]

    # --- the table -------------------------------------------------------------------------
    def _summary(self, parts: list[int]) -> tuple[float, Callable[[int, bool], ManifoldSummary]]:
        """(volume m³, summary by (label, large)) of the manifold of these components."""
        stats = Stats()
        main = self.comps[parts[0]]
        # The main component's volumes as kept; a folded speck adds the positions the main
        # one does not reach (a pass over the specks only: the main one may be most of the map).
        own_total, core_total = main.own.total, main.core.total
        own_extra: set[int] = set()
        core_extra: set[int] = set()
        core_count = 0
        best: list[Any] = []
        low: list[Any] = []
        robust: list[Any] = []
        maxima: list[Any] = []
        scores, samples, w = self.scores, self.samples, self.w
        for cid in parts:
            comp = self.comps[cid]
            stats.merge(comp.stats)
            if comp is not main:
                for pos in comp.own.count:
                    if pos not in main.own.count and pos not in own_extra:
                        own_extra.add(pos)
                        own_total += w[pos]
                for pos in comp.core.count:
                    if pos not in main.core.count and pos not in core_extra:
                        core_extra.add(pos)
                        core_total += w[pos]
            core_count += comp.core_count

            def here(p: Point, c: int = cid) -> bool:
                return self.g.comp_of(p) == c

            best += top(comp.best, lambda e: here(e[2]))
            low += top(comp.low, lambda e: here(e[2]))
            robust += top(comp.robust, lambda e: here(e[1]) and e[1] in scores
                                and robust_order(samples[e[1]], scores[e[1]]) == e[0])
            maxima += top(comp.maxima, lambda e: here(e[1]) and e[1] in self._max,
                                self.top)
        top_p = min(robust)[1]
        volume = value(own_total)

        def make(label: int, large: bool) -> ManifoldSummary:
            return summary_of(label, stats, volume, samples[min(best)[2]], min(low)[0],
                              [samples[p] for _, p in sorted(maxima)[: self.top]], core_count,
                              value(core_total), (samples[top_p], scores[top_p]), large)

        return volume, make

    def _table(self) -> None:
        mains: dict[int, list[int]] = {c: [c] for c in self.comps if c not in self._fold}
        for speck, into in sorted(self._fold.items()):
            mains[into].append(speck)
        ids = list(mains)
        vols: list[float] = []
        firsts: list[str] = []
        makers: list[Any] = []
        for main in ids:
            parts = mains[main]
            cached = self._cache.get(main)
            if cached is not None and cached[0] == tuple(parts) \
                    and not self._touched.intersection(parts):
                vols.append(cached[1])
                makers.append(cached[2])
            else:
                volume, make = self._summary(parts)
                vols.append(volume)
                makers.append(make)
            firsts.append(self.samples[min(self.g.first(c) for c in parts)].key)
        viable = value(self.viable_pos.total)
        order = label_order(vols, firsts)
        large = set(large_manifolds([vols[i] for i in order], viable, LARGE_SHARE))
        out = []
        cache: dict[int, tuple[tuple[int, ...], float, ManifoldSummary]] = {}
        for label, i in enumerate(order):
            make, is_large = makers[i], label in large
            if not isinstance(make, ManifoldSummary):
                summary = make(label, is_large)
            elif (make.label, make.large) == (label, is_large):
                summary = make
            else:
                # Labels follow volume order, so one manifold growing relabels those it
                # passes: a copy without validation (model_copy costs ~4x as much).
                summary = ManifoldSummary.model_construct(
                    make.model_fields_set, **{**make.__dict__, "label": label,
                                              "name": label_name(label), "large": is_large})
            cache[ids[i]] = (tuple(mains[ids[i]]), vols[i], summary)
            out.append(summary)
        self._cache = cache
        self._touched = set()
        self.table = Table(out, [ids[i] for i in order], viable,
                           value(self.non_viable_pos.total))


def _summed(keys: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct keys (sorted) and the sum of the values of each, those summing to 0
    left out."""
    at, inv = np.unique(keys, return_inverse=True)
    total = np.zeros(len(at), dtype=np.int64)
    np.add.at(total, inv, values)
    keep = total != 0
    return at[keep], total[keep]
