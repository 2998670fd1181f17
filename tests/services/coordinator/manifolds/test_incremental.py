"""Incremental grouping equals the full recompute (`grouping.components`) after every batch,
on real lattices with random behaviour fields, refinement midpoints and shuffled arrivals."""

from __future__ import annotations

import math
import random

import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.grouping import components, speck_neighbours
from graspscape.services.coordinator.manifolds.incremental import (
    GroupingCache,
    IncrementalGrouping,
)
from graspscape.services.coordinator.manifolds.specks import Neighbours
from graspscape.shared.specs.exploration import AttitudeSpec, PoseGridSpec

GRIDS = {
    "30deg-2r-1roll": PoseGridSpec(dtheta=math.radians(30), r_min=0.0, r_max=0.02, dr=0.01),
    "45deg-1r-2rolls": PoseGridSpec(dtheta=math.radians(45), r_min=0.01, r_max=0.01,
                                    attitudes=AttitudeSpec(rolls=2)),
    "40deg-tilt": PoseGridSpec(dtheta=math.radians(40), r_min=0.0, r_max=0.01, dr=0.01,
                               attitudes=AttitudeSpec(rolls=2, tilts=(0.3,))),
    "25deg-4rolls-x4": PoseGridSpec(dtheta=math.radians(25), r_min=0.0, r_max=0.01, dr=0.01,
                                    attitudes=AttitudeSpec(rolls=4), azimuth_multiple=4),
    "60deg-2r-2rolls": PoseGridSpec(dtheta=math.radians(60), r_min=0.0, r_max=0.01, dr=0.01,
                                    attitudes=AttitudeSpec(rolls=2)),
}
KINDS = (frozenset({"A", "B"}), frozenset({"A", "B", "C"}), frozenset({"A", "B", "palm"}))


def finest_points(lattice: Lattice) -> list[Point]:
    n_i = (lattice.n_r << lattice.depth) + 1
    return [Point(K, J, i, a) for K, J in lattice.cells(lattice.depth)
            for i in range(n_i) for a in range(len(lattice.attitudes))]


def field(lattice: Lattice, rng: random.Random) -> dict[Point, StoredPose]:
    """A result at every finest point: behaviour regions cut by random planes through the
    direction sphere, joint angles that drift across a region (so that some neighbours in
    one region differ by more than the tolerance), and random failures."""
    planes = [tuple(rng.gauss(0, 1) for _ in range(3)) for _ in range(2)]
    fail = rng.uniform(0.05, 0.3)
    out = {}
    for p in finest_points(lattice):
        x = lattice.pose(p)
        d = lattice.direction(p)
        side = [sum(a * b for a, b in zip(n, d, strict=True)) > 0 for n in planes]
        kind = KINDS[(side[0] + 2 * side[1] + p.attitude) % len(KINDS)]
        viable = rng.random() > fail
        drift = 0.6 * d[2] + 0.02 * p.r_index + rng.gauss(0, 0.08)
        joints = {f"{g}_1": drift + 0.1 * i for i, g in enumerate(sorted(kind))}
        out[p] = StoredPose(
            key=f"{p.ring}.{p.azimuth}.{p.r_index}.{p.attitude}", theta=x.theta, phi=x.phi,
            r=x.r, roll=x.roll, pitch=x.pitch, yaw=x.yaw, viable=viable,
            outcome="held" if viable else "dropped", mu_s=rng.random() if viable else 0.0,
            digits=kind if viable else frozenset(), joints=joints if viable else {},
        )
    return out


def sampled(lattice: Lattice, rng: random.Random, share: float) -> dict[Point, StoredPose]:
    """The coarse pass, and a share of the finer points (the midpoints refinement adds)."""
    full = field(lattice, rng)
    return {p: s for p, s in full.items()
            if lattice.birth(p) == 0 or rng.random() < share}


def check_arrivals(lattice: Lattice, samples: dict[Point, StoredPose], seed: int) -> int:
    rng = random.Random(seed)
    order = sorted(samples)
    rng.shuffle(order)
    state = IncrementalGrouping(lattice)
    seen: dict[Point, StoredPose] = {}
    batches = 0
    i = 0
    while i < len(order):
        # Tiles of 1–25 poses on small maps; on larger ones proportionally more, so that a
        # run compares a few dozen times (each comparison regroups everything seen).
        n = rng.choice((1, 3, 8, 25)) * max(1, len(order) // 300)
        batch = order[i : i + n]
        i += n
        state.add((p, samples[p]) for p in batch)
        seen.update((p, samples[p]) for p in batch)
        assert state.components() == components(lattice, seen), f"after {i} of {len(order)}"
        batches += 1
    return batches


def neighbours_are_symmetric(lattice: Lattice) -> None:
    """q is p's level-L neighbour iff p is q's: the incremental state finds the links into
    a new point in its own neighbour lists."""
    back: dict[tuple[Point, int], set[Point]] = {}
    for p in finest_points(lattice):
        for level in range(lattice.birth(p), lattice.depth + 1):
            for _, q in lattice.neighbours(p, level):
                if (q, level) not in back:
                    back[(q, level)] = {x for _, x in lattice.neighbours(q, level)}
                assert p in back[(q, level)], (p, q, level)


def test_neighbours_are_symmetric() -> None:
    neighbours_are_symmetric(Lattice(GRIDS["45deg-1r-2rolls"], 1))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(GRIDS))
def test_neighbours_are_symmetric_two_levels(name: str) -> None:
    neighbours_are_symmetric(Lattice(GRIDS[name], 2))


@pytest.mark.parametrize(("name", "depth", "seed"), [
    ("60deg-2r-2rolls", 1, 0), ("45deg-1r-2rolls", 1, 2),
])
def test_shuffled_arrivals_give_the_full_recompute(name: str, depth: int, seed: int) -> None:
    lattice = Lattice(GRIDS[name], depth)
    samples = sampled(lattice, random.Random(seed), share=0.5)
    check_arrivals(lattice, samples, seed)


def test_a_midpoint_splits_and_a_speck_folds() -> None:
    """Two level-0 neighbours of one behaviour are one component until their level-1
    midpoint arrives non-viable; the same once the whole field is in."""
    lattice = Lattice(GRIDS["45deg-1r-2rolls"], 1)
    full = field(lattice, random.Random(5))
    coarse = {p: s for p, s in full.items() if lattice.birth(p) == 0}
    state = IncrementalGrouping(lattice)
    state.add(coarse.items())
    assert state.components() == components(lattice, coarse)
    before = len(state.raw_components())
    state.add((p, s) for p, s in full.items() if p not in coarse)
    assert state.components() == components(lattice, full)
    assert len(state.raw_components()) != before


def test_a_changed_result_rebuilds() -> None:
    lattice = Lattice(GRIDS["60deg-2r-2rolls"], 1)
    full = field(lattice, random.Random(7))
    state = IncrementalGrouping(lattice)
    state.add(full.items())
    state.add(full.items())  # the same again: nothing changes
    assert state.components() == components(lattice, full)
    p = next(p for p, s in sorted(full.items()) if s.viable)
    flipped = {**full, p: StoredPose(**{**full[p].__dict__, "viable": False,
                                        "digits": frozenset(), "joints": {}})}
    state.add([(p, flipped[p])])
    assert state.components() == components(lattice, flipped)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(GRIDS))
@pytest.mark.parametrize("depth", [1, 2])
@pytest.mark.parametrize("seed", range(4))
def test_shuffled_arrivals_randomized(name: str, depth: int, seed: int) -> None:
    lattice = Lattice(GRIDS[name], depth)
    rng = random.Random(1000 * seed + depth)
    samples = sampled(lattice, rng, share=rng.uniform(0.2, 0.9))
    check_arrivals(lattice, samples, seed)


def test_the_cache_feeds_what_is_new_and_starts_again_on_another_store() -> None:
    lattice = Lattice(GRIDS["60deg-2r-2rolls"], 1)
    full = field(lattice, random.Random(11))
    coarse = {p: s for p, s in full.items() if lattice.birth(p) == 0}
    cache = GroupingCache(size=1)
    assert cache.components("x", lattice, coarse) == components(lattice, coarse)
    assert cache.components("x", lattice, full) == components(lattice, full)
    # Fewer samples under the same key (a store rebuilt): grouped again from them alone.
    part = {p: s for p, s in full.items() if p.attitude == 0}
    assert cache.components("x", lattice, part) == components(lattice, part)
    assert cache.components("y", lattice, coarse) == components(lattice, coarse)
    assert list(cache._states) == ["y"]


@pytest.mark.parametrize("name", ["60deg-2r-2rolls", "45deg-1r-2rolls"])
def test_cached_neighbours_are_the_speck_neighbours(name: str) -> None:
    """The vote state's neighbour lists (cached per direction cell) are `speck_neighbours`'s,
    repeats and order included, at every point of a two-level lattice."""
    lattice = Lattice(GRIDS[name], 2)
    cached = Neighbours(lattice)
    for p in finest_points(lattice):
        assert cached(p) == speck_neighbours(lattice, p), p


@pytest.mark.parametrize(("name", "seed"), [("60deg-2r-2rolls", 21), ("45deg-1r-2rolls", 22)])
def test_refinement_after_the_coarse_pass_cuts_and_refolds(name: str, seed: int) -> None:
    """The coarse pass first, then two levels of midpoints in shuffled tiles: every cut and
    split (and the specks' votes moving with the points) leaves the full recompute's
    components, and the refinement does split some components."""
    lattice = Lattice(GRIDS[name], 2)
    rng = random.Random(seed)
    samples = sampled(lattice, rng, share=0.8)
    state = IncrementalGrouping(lattice)
    splits = Splits()
    state.listener = splits
    seen: dict[Point, StoredPose] = {}
    for level in (0, 1, 2):
        order = sorted(p for p in samples if lattice.birth(p) == level)
        rng.shuffle(order)
        step = max(7, len(order) // 6)
        for i in range(0, len(order), step):
            batch = [(p, samples[p]) for p in order[i : i + step]]
            state.add(batch)
            seen.update(batch)
            assert state.components() == components(lattice, seen)
    assert splits.n > 0


class Splits:
    """Counts the splits the grouping reports (its listener)."""

    n = 0

    def on_new(self, cid: int, p: Point) -> None:
        pass

    def on_join(self, into: int, gone: int, moved: set[Point]) -> None:
        pass

    def on_detach(self, old: int, new: int, part: set[Point]) -> None:
        self.n += 1
