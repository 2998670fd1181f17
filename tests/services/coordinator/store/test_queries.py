"""store/queries.py: /best's index walk gives exactly the order a full sort gives."""

from __future__ import annotations

import math
import random

from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.store.models import ManifoldRow, PoseRow
from graspscape.services.coordinator.store.queries import (
    MU_S,
    Ranking,
    approach_vector,
    best_pose_ids,
    best_pose_rows,
)
from graspscape.services.coordinator.store.queue import lease_tiles
from sqlalchemy import select
from sqlalchemy.orm import Session

from tests.factories import fake_results, make_exploration

LABELS = ("robust", "uncertain", "fragile", "futile")
RANKINGS = {
    "mu_s": MU_S,
    "torque_margin_ratio": Ranking("torque_margin_ratio"),
    "friction_margin": Ranking("friction_margin", lower_is_better=True),
    "robust": Ranking("robust_q", group="robust_label", group_order=LABELS),
}


def _explore(session: Session) -> int:
    """A stored exploration whose ranking columns have NULLs, ties and every label."""
    eid = make_exploration(session, dtheta=0.6, target=50)
    while tiles := lease_tiles(session, worker_id="w", n=8, lease_seconds=60):
        for tile in tiles:
            # keeper=None: no manifold table kept; the rows below are made by hand
            ingest_results(session, tile_id=tile.tile_id, lease_epoch=tile.lease_epoch,
                           worker_id="w", results=fake_results(tile.poses(), seed=tile.tile_id),
                           keeper=None)
    manifolds = [ManifoldRow(exploration_id=eid, label=i, size=0) for i in range(2)]
    session.add_all(manifolds)
    session.flush()
    rng = random.Random(7)
    for row in session.scalars(select(PoseRow).where(PoseRow.exploration_id == eid)):
        row.viable = rng.random() < 0.6
        row.mu_s = rng.choice([0.25, 0.5, rng.random()])  # ties on μs, broken by the key
        row.torque_margin_ratio = rng.choice([None, 0.1, 0.4, rng.random()])
        row.friction_margin = rng.choice([None, 0.3, rng.random()])
        row.robust_label = rng.choice([None, *LABELS])
        row.robust_q = rng.choice([None, 0.2, rng.random()])
        row.manifold_id = rng.choice([None, *(m.id for m in manifolds)])
    session.commit()
    return eid


def _sorted(rows: list[PoseRow], ranking: Ranking) -> list[int]:
    """The order by a full sort in Python: what the index walk must give."""
    def key(row: PoseRow) -> tuple:
        group = 0
        if ranking.group is not None:
            label = getattr(row, ranking.group)
            group = ranking.group_order.index(label) if label is not None else 99
        value = getattr(row, ranking.value) if ranking.value else 0.0
        missing = value is None
        sign = 1.0 if ranking.lower_is_better else -1.0
        return (group, missing, 0.0 if missing else sign * value, -row.mu_s, row.pose_key)

    return [r.id for r in sorted(rows, key=key)]


def test_best_ids_equal_a_full_sort(session: Session) -> None:
    """Every ranking, with each filter, at limits 1, 5 and all: the same ids as sorting."""
    eid = _explore(session)
    viable = list(session.scalars(select(PoseRow).where(PoseRow.exploration_id == eid,
                                                        PoseRow.viable)))
    assert len(viable) > 40
    mid = session.scalars(select(ManifoldRow.id).where(ManifoldRow.exploration_id == eid)).first()
    axis, half = (0.0, 1.0, 0.0), math.radians(60)

    def in_cone(r: PoseRow) -> bool:
        v = approach_vector(r.theta, r.phi)
        return sum(a * b for a, b in zip(axis, v, strict=True)) >= math.cos(half) - 1e-12

    cases = [
        ({}, viable),
        ({"manifold_id": mid}, [r for r in viable if r.manifold_id == mid]),
        ({"max_effort_nm": 1.5}, [r for r in viable if r.effort_max_nm <= 1.5]),
        ({"cone_axis": axis, "cone_half_angle": half}, [r for r in viable if in_cone(r)]),
    ]
    for name, ranking in RANKINGS.items():
        for options, rows in cases:
            assert len(rows) > 0
            expected = _sorted(rows, ranking)
            for limit in (1, 5, len(viable) + 1):
                got = best_pose_ids(session, eid, ranking=ranking, limit=limit, **options)
                assert got == expected[:limit], (name, options, limit)
        best = best_pose_rows(session, eid, ranking=ranking, limit=3)
        assert [r.id for r in best] == _sorted(viable, ranking)[:3]
        assert all(isinstance(r, PoseRow) and r.viable for r in best)
