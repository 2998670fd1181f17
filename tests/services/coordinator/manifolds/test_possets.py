"""Position counts changed in bulk (aggregate.PosSet.apply, DensePosSet.apply) end where the
same points added and taken away one by one end: the same counts and the same exact total."""

from __future__ import annotations

import random

import numpy as np
from graspscape.services.coordinator.manifolds.aggregate import DensePosSet, PosSet
from graspscape.services.coordinator.manifolds.exact import exact


def test_bulk_changes_give_the_one_by_one_counts_and_total() -> None:
    rng = random.Random(5)
    n_pos = 40
    w = [exact(rng.uniform(1e-9, 1e-6)) for _ in range(n_pos)]
    one, bulk, dense = PosSet(), PosSet(), DensePosSet(n_pos, w)
    held = [0] * n_pos
    for _ in range(30):
        delta = [0] * n_pos
        for _ in range(25):  # points come and go; a position may net to zero
            pos = rng.randrange(n_pos)
            if held[pos] and rng.random() < 0.5:
                held[pos] -= 1
                delta[pos] -= 1
                one.remove(pos, w)
            else:
                held[pos] += 1
                delta[pos] += 1
                one.add(pos, w)
        at = [p for p in range(n_pos) if delta[p]]
        bulk.apply(at, [delta[p] for p in at], w)
        dense.apply(np.array(at, dtype=np.int64), np.array([delta[p] for p in at]), w)
        assert bulk.count == one.count
        assert dense.count.tolist() == held
        assert bulk.total == one.total == dense.total == sum(w[p] for p in one.count)
