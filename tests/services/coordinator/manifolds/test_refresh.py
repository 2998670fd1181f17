"""Manifolds are refreshed as results arrive, in geometric steps, the refresh noted on the
exploration; a map picture draws the stored table, refreshing it first only when stale
(manifolds.service, maps.picture)."""

from __future__ import annotations

import itertools
import math

import pytest
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds import service
from graspscape.services.coordinator.store.models import ExplorationRow, TileRow
from graspscape.services.local.run import run_local
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import select

from tests.factories import oracle_result


@pytest.mark.slow
def test_manifolds_refresh_while_exploring_in_steps_that_grow(sessions, named_object,
                                                              monkeypatch) -> None:
    # Every refresh writes the map once (`write`, by its name in the service module): the
    # poses stored then tell the steps apart.
    refreshes: list[int] = []
    write = service.write

    def recording(session, exploration_id, *args, **kwargs):
        refreshes.append(session.get(ExplorationRow, exploration_id).poses_done)
        return write(session, exploration_id, *args, **kwargs)

    monkeypatch.setattr(service, "write", recording)
    spec = ExplorationSpec(
        object_id=named_object("sphere"),
        grid={"dtheta": math.radians(30), "r_min": 0.0, "r_max": 0.02, "dr": 0.01},
        refinement={"levels": 1, "local_search_rounds": 1},
    )
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=4, max_poses=10**6).id
    run_local(sessions, lambda poses, match=None: [oracle_result(p) for p in poses],
              workers=1, seed=0)

    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        # The last refresh is the final one, noted on the exploration.
        assert row.manifolds_final and row.manifolds_poses_done == row.poses_done
    final_done = refreshes[-1]
    during = refreshes[:-1]
    # Refreshed before the end (a reader sees manifolds while the exploration runs) ...
    assert during and min(during) < final_done
    # ... but not every few tiles: a quarter more poses between refreshes, besides the one
    # each later round makes, local search or certification (dozens of 4-pose tiles finish
    # here).
    growing = sorted(set(during))
    steps = sum(1 for a, b in itertools.pairwise(growing) if b < 1.25 * a)
    with sessions() as s:
        rounds = len(set(s.scalars(select(TileRow.round).where(
            TileRow.exploration_id == eid, TileRow.round > 0))))
    assert steps <= rounds


@pytest.mark.slow
def test_a_map_picture_draws_the_stored_table_and_refreshes_only_a_stale_one(
        sessions, named_object, monkeypatch, tmp_path) -> None:
    from graspscape.services.coordinator.maps.picture import write_map_files
    from graspscape.services.coordinator.store.models import ManifoldRow
    from sqlalchemy import select

    spec = ExplorationSpec(
        object_id=named_object("sphere"),
        grid={"dtheta": math.radians(45), "r_min": 0.0, "r_max": 0.02, "dr": 0.01},
        refinement={"levels": 1, "local_search_rounds": 0},
    )
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
    run_local(sessions, lambda poses, match=None: [oracle_result(p) for p in poses])
    computed = []
    update = service.update_state  # the running map brought up to date: a refresh's work
    monkeypatch.setattr(service, "update_state",
                        lambda *a, **k: computed.append(1) or update(*a, **k))
    with sessions() as s:
        row = s.get(ExplorationRow, eid)
        assert (row.manifolds_poses_done, row.manifolds_final) == (row.poses_done, True)
        summaries = s.scalars(select(ManifoldRow.summary)
                              .where(ManifoldRow.exploration_id == eid)).all()
        assert summaries and not any({"final", "poses_done"} & set(m) for m in summaries)
        for stale in (False, True):  # current, then as a database from before 0008 reads
            if stale:
                row.manifolds_poses_done, row.manifolds_final = None, False
                s.commit()
            computed.clear()
            write_map_files(s, eid, tmp_path / "map.png")
            # Drawn from the stored labels: grouped again only where the table is stale.
            assert len(computed) == int(stale)
            assert service.is_final(s, eid)
