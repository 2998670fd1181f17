"""The running map (manifolds/running.py) gives the full recompute's table (summary.build_map)
to the last bit after every batch of shuffled arrivals: volumes, statistics, descriptions,
robust cores and bests, local maxima, labels and the dust."""

from __future__ import annotations

import dataclasses
import random

import numpy as np
import pytest
from graspscape.services.coordinator.exploration.lattice import Lattice, Point
from graspscape.services.coordinator.manifolds.behaviour import StoredPose
from graspscape.services.coordinator.manifolds.live import fine_labels_of, labels_of
from graspscape.services.coordinator.manifolds.running import RunningMap
from graspscape.services.coordinator.manifolds.summary import build_map

from tests.services.coordinator.manifolds.test_incremental import GRIDS, sampled


def radius(directions: np.ndarray) -> np.ndarray:
    # An elongated object: the surface radius differs by direction, so volumes do.
    return 0.03 + 0.02 * np.abs(directions[:, 2])


def with_contacts(samples: dict[Point, StoredPose], rng: random.Random) -> dict[Point, StoredPose]:
    out = {}
    for p, s in samples.items():
        contacts = {d: (rng.uniform(-0.05, 0.05), rng.uniform(-0.05, 0.05), rng.uniform(0, 0.1))
                    for d in sorted(s.digits)}
        source = "evaluated" if rng.random() < 0.7 else "shortcut:normal"
        out[p] = dataclasses.replace(s, contacts=contacts, source=source)
    return out


def check(lattice: Lattice, samples: dict[Point, StoredPose], seed: int, batches: int) -> None:
    rng = random.Random(seed)
    order = sorted(samples)
    rng.shuffle(order)
    running = RunningMap(lattice, radius)
    seen: dict[Point, StoredPose] = {}
    cuts = [*sorted(rng.sample(range(1, len(order)), batches - 1)), len(order)]
    start = 0
    for end in cuts:
        batch = {p: samples[p] for p in order[start:end]}
        start = end
        running.add(batch)
        seen.update(batch)
        full, fine, label_of = build_map(lattice, seen, radius)
        got = running.table
        assert got.manifolds == full.manifolds, f"after {end} of {len(order)}"
        assert round(got.viable_volume_m3 * 1e6, 3) == full.viable_volume_cm3
        assert round(got.non_viable_volume_m3 * 1e6, 3) == full.non_viable_volume_cm3
        assert labels_of(running) == label_of
        assert fine_labels_of(running).labels.tolist() == fine.labels.tolist()
        assert dict(running.scores) == {
            p: sc for p, sc in zip(sorted(seen), [full.robust[seen[p].key]
                                                    for p in sorted(seen)], strict=True)}


@pytest.mark.parametrize(("name", "depth", "seed", "batches"), [
    ("60deg-2r-2rolls", 1, 0, 6), ("45deg-1r-2rolls", 1, 2, 6),
    pytest.param("40deg-tilt", 1, 3, 6, marks=pytest.mark.slow),
    pytest.param("30deg-2r-1roll", 2, 1, 25, marks=pytest.mark.slow),
    pytest.param("25deg-4rolls-x4", 1, 4, 15, marks=pytest.mark.slow),
])
def test_shuffled_arrivals_give_the_full_table(name: str, depth: int, seed: int,
                                               batches: int) -> None:
    lattice = Lattice(GRIDS[name], depth)
    rng = random.Random(seed)
    samples = with_contacts(sampled(lattice, rng, share=0.5), rng)
    check(lattice, samples, seed, batches=batches)
