"""Manifolds are refreshed as results arrive, in geometric steps (manifolds.service)."""

from __future__ import annotations

import itertools
import math

import pytest
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds import service
from graspscape.services.coordinator.store.models import ExplorationRow
from graspscape.services.local.run import run_local
from graspscape.shared.specs.exploration import ExplorationSpec

from tests.factories import oracle_result


@pytest.mark.slow
def test_manifolds_refresh_while_exploring_in_steps_that_grow(sessions, named_object,
                                                              monkeypatch) -> None:
    refreshes: list[tuple[int, bool]] = []
    refresh = service.refresh_manifolds

    def recording(session, exploration_id, *args, **kwargs):
        done = session.get(ExplorationRow, exploration_id).poses_done
        refreshes.append((done, kwargs.get("final", False)))
        return refresh(session, exploration_id, *args, **kwargs)

    monkeypatch.setattr(service, "refresh_manifolds", recording)
    spec = ExplorationSpec(
        object_id=named_object("sphere"),
        grid={"dtheta": math.radians(30), "r_min": 0.0, "r_max": 0.02, "dr": 0.01},
        refinement={"levels": 1, "local_search_rounds": 1},
    )
    with sessions() as s:
        create_exploration(s, spec=spec, tile_target_poses=4, max_poses=10**6)
    run_local(sessions, lambda poses, match=None: [oracle_result(p) for p in poses],
              workers=1, seed=0)

    assert refreshes[-1][1], "the last refresh is the final one"
    final_done = refreshes[-1][0]
    during = [done for done, final in refreshes[:-1]]
    # Refreshed before the end (a reader sees manifolds while the exploration runs) ...
    assert during and min(during) < final_done
    # ... but not every few tiles: a quarter more poses between refreshes, besides the one
    # each local-search round makes (dozens of 4-pose tiles finish here).
    growing = sorted(set(during))
    steps = sum(1 for a, b in itertools.pairwise(growing) if b < 1.25 * a)
    assert steps <= spec.refinement.local_search_rounds
