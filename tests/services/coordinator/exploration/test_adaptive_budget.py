"""`refinement.max_poses` caps the adaptive strategy's local search as well as its border
refinement (strategies/adaptive.py): on the cube an uncapped search over every manifold spent
40-70 % of the dense grid (docs/design/exploration.md, "Robust map benchmark")."""

from __future__ import annotations

import pytest
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.objects.service import create_named
from graspscape.services.coordinator.store.models import PosePlanRow
from graspscape.services.local.run import run_local
from graspscape.shared.specs.exploration import ExplorationSpec, PoseGridSpec
from sqlalchemy import func, select

from tests.factories import oracle_result

GRID = PoseGridSpec(dtheta=0.6, r_min=0.0, r_max=0.02, dr=0.01)


def _plans(sessions, object_id: int, max_poses: int) -> dict[str, int]:
    """Planned poses by reason of one exploration (no certification: only refinement and
    search plan here)."""
    spec = ExplorationSpec(object_id=object_id, grid=GRID, certification={"share": 0.0},
                           refinement={"levels": 1, "local_search_rounds": 2,
                                       "max_poses": max_poses})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
    run_local(sessions, lambda poses, match=None: [oracle_result(p) for p in poses],
              workers=1, seed=0)
    with sessions() as s:
        return dict(s.execute(select(PosePlanRow.reason, func.count())
                              .where(PosePlanRow.exploration_id == eid)
                              .group_by(PosePlanRow.reason)).all())


@pytest.mark.slow  # two explorations: ~20 s on the loaded 2-core VM
def test_max_poses_caps_local_search_too(sqlite_sessions) -> None:
    sessions = sqlite_sessions
    with sessions() as s:
        object_id = create_named(s, name="sphere", properties={}, shared_dir=None)[0].id
    free = _plans(sessions, object_id, 10**6)
    refine, search = free.get("refine", 0), free.get("search", 0)
    assert refine > 0 and search > 4, free
    # Room for the refinement (planned first, in round 0) and half the search.
    capped = _plans(sessions, object_id, refine + search // 2)
    assert capped.get("refine", 0) == refine
    assert 0 < capped.get("search", 0) <= search // 2
    assert sum(capped.values()) <= refine + search // 2
