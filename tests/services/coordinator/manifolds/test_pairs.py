"""The batch's pairs answered at once (manifolds/pairs.py) are `same_behaviour`'s answers, and
the running map fed through them is the full recompute's, on a random lattice map of several
thousand poses with three joints per digit (the sum's order matters), poses without joint
angles (the contacts decide) and poses of another joint layout."""

from __future__ import annotations

import dataclasses
import math
import random

import pytest
from graspscape.services.coordinator.manifolds.behaviour import (
    JOINT_TOLERANCE_RAD,
    StoredPose,
    joint_difference,
    same_behaviour,
)
from graspscape.services.coordinator.manifolds.grouping import SPECK_TOLERANCE_RAD, components
from graspscape.services.coordinator.manifolds.incremental import IncrementalGrouping
from graspscape.services.coordinator.manifolds.pairs import NOT_SAME, PairBehaviour, answers
from graspscape.services.coordinator.manifolds.running import RunningMap
from graspscape.services.coordinator.manifolds.specks import Neighbours
from graspscape.services.coordinator.manifolds.summary import build_map
from graspscape.services.coordinator.mapspace.lattice import Lattice, Point
from graspscape.shared.specs.exploration import AttitudeSpec, PoseGridSpec

from tests.services.coordinator.manifolds.test_incremental import field
from tests.services.coordinator.manifolds.test_running import radius, with_contacts


def lattice_map(seed: int, degrees: float) -> tuple[Lattice, dict[Point, StoredPose]]:
    """`test_incremental.field` on 2 r levels × 2 rolls to depth 1 (15°: about 4,500 finest
    points, 20°: 2,500) with three joints per digit, angles that drift across a region, and
    every fifth viable pose without angles or with one joint less."""
    lattice = Lattice(PoseGridSpec(dtheta=math.radians(degrees), r_min=0.0, r_max=0.01,
                                   dr=0.01, attitudes=AttitudeSpec(rolls=2)), 1)
    rng = random.Random(seed)
    samples = with_contacts(field(lattice, rng), rng)
    out = {}
    for p, s in samples.items():
        if s.viable:
            base = next(iter(s.joints.values()))
            joints = {f"{d}_{i}": base + rng.gauss(0, 0.05) + 0.07 * i
                      for d in sorted(s.digits) for i in (1, 2, 3)}
            roll = rng.random()
            if roll < 0.1:
                joints = {}
            elif roll < 0.2:
                joints.pop(next(iter(joints)))
            s = dataclasses.replace(s, joints=joints)
        out[p] = s
    return lattice, out


def neighbour_pairs(lattice: Lattice, samples: dict[Point, StoredPose]) -> list[tuple[Point,
                                                                                     Point]]:
    at = Neighbours(lattice)
    return [(p, q) for p in sorted(samples)
            for level in range(lattice.birth(p), lattice.depth + 1)
            for q in at.at(p, level) if q in samples]


def test_differences_are_joint_difference_to_the_last_bit() -> None:
    lattice, samples = lattice_map(1, 20)
    assert len(samples) > 2000
    pairs = neighbour_pairs(lattice, samples)
    table = PairBehaviour()
    points = sorted(samples)
    for k in range(0, len(points), 700):  # in batches, as the running map adds them
        table.add({p: samples[p] for p in points[k : k + 700]})
    diffs = table.differences(pairs)
    got = diffs.tolist()
    decided = 0
    for (p, q), d in zip(pairs, got, strict=True):
        a, b = samples[p], samples[q]
        if d == NOT_SAME:
            assert not (a.viable and b.viable and a.digits == b.digits)
        elif d == d:
            decided += 1
            assert d == joint_difference(a, b, set(a.joints) & set(b.joints))
    assert decided > len(pairs) // 4  # most viable pairs are answered by the arrays
    # the answers either way round, with both tolerances, on a sample of the pairs
    for tolerance in (JOINT_TOLERANCE_RAD, SPECK_TOLERANCE_RAD):
        ok = answers(pairs, diffs, samples, tolerance)
        for k in random.Random(0).sample(range(len(pairs)), 1000):
            a, b = samples[pairs[k][0]], samples[pairs[k][1]]
            assert bool(ok[k] & 1) == same_behaviour(a, b, tolerance)
            assert bool(ok[k] & 2) == same_behaviour(b, a, tolerance)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [2, 3])
def test_the_running_map_through_the_pairs_is_the_full_recompute(seed: int) -> None:
    """Several thousand poses in shuffled batches: components after every batch, and the
    whole table (volumes, statistics, cores, maxima, robust scores) at the end."""
    lattice, samples = lattice_map(seed, 15)
    assert len(samples) > 4000
    rng = random.Random(seed)
    order = sorted(samples)
    rng.shuffle(order)
    grouping = IncrementalGrouping(lattice)
    running = RunningMap(lattice, radius)
    seen: dict[Point, StoredPose] = {}
    for k in range(0, len(order), 500):
        batch = {p: samples[p] for p in order[k : k + 500]}
        grouping.add(batch.items())
        running.add(batch)
        seen.update(batch)
        assert grouping.components() == components(lattice, seen), f"after {k}"
    full, _, _ = build_map(lattice, seen, radius)
    assert running.table.manifolds == full.manifolds


def test_each_joint_layout_sums_in_joint_difference_order() -> None:
    """Many joint layouts (2–4 digits of three joints, any names): the plan is the one
    same_behaviour's sets give. A set made from a dict and one made from a tuple of the same
    names can iterate differently (seen with one layout in a few dozen), and then the sum
    can differ in the last bit."""
    rng = random.Random(0)
    table = PairBehaviour()
    pairs = []
    poses: dict[Point, StoredPose] = {}
    for k in range(1500):
        digits = sorted(rng.sample("ABCDEFGHJK", rng.randint(2, 4)))
        names = [f"{d}_{i}" for d in digits for i in (1, 2, 3)]
        rng.shuffle(names)
        for a in (0, 1):
            poses[Point(k, 0, 0, a)] = StoredPose(
                key=f"{k}.{a}", theta=0.0, phi=0.0, r=0.0, roll=0.0, pitch=0.0, yaw=0.0,
                viable=True, outcome="held", mu_s=0.5, digits=frozenset(digits),
                joints={n: rng.random() for n in names})
        pairs.append((Point(k, 0, 0, 0), Point(k, 0, 0, 1)))
    table.add(poses)
    for (p, q), d in zip(pairs, table.differences(pairs).tolist(), strict=True):
        a, b = poses[p], poses[q]
        assert d == joint_difference(a, b, set(a.joints) & set(b.joints))

