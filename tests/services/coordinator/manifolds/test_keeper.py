"""The manifold table's keeper (manifolds/keeper.py): run after each committed batch for every
strategy, within its stated lag, final once the exploration is; the table it leaves is the
whole rewrite's; the read routes never write. On SQLite and PostgreSQL."""

from __future__ import annotations

import random
from typing import Any

from fastapi.testclient import TestClient
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import (
    cancel_exploration,
    create_exploration,
)
from graspscape.services.coordinator.manifolds import keeper, service
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import ExplorationRow, ManifoldRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import event, func, select

from tests.factories import oracle_result
from tests.services.coordinator.manifolds.test_live import sphere_grid, stored


def _leased(s: Any) -> list[Any]:
    tiles = []
    while leased := lease_tiles(s, worker_id="w", n=50, lease_seconds=60):
        tiles += leased
    return tiles


def _marks(s: Any, eid: int) -> tuple[int, int | None, bool]:
    row = s.execute(select(ExplorationRow.poses_done, ExplorationRow.manifolds_poses_done,
                           ExplorationRow.manifolds_final)
                    .where(ExplorationRow.id == eid)).one()
    return row[0], row[1], bool(row[2])


def test_the_keeper_keeps_the_table_within_its_lag_and_final(
        sessions, named_object, monkeypatch) -> None:
    # Small bounds, so that this small map is refreshed between batches too.
    monkeypatch.setattr(keeper, "REFRESH_MIN_POSES", 20)
    monkeypatch.setattr(keeper, "REFRESH_MAX_POSES", 40)
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    refreshes = keeper.current_keeper().upkeep.refreshes
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
        tiles = _leased(s)
        random.Random(7).shuffle(tiles)  # any arrival order
        assert len(tiles) >= 10
        for t in tiles[:-1]:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
            done, at, final = _marks(s, eid)
            assert not final and done - (at or 0) < keeper.due_after(at or 0) <= 40
        assert _marks(s, eid)[1], "refreshed while running"
        last = tiles[-1]
        ingest_results(s, tile_id=last.tile_id, lease_epoch=last.lease_epoch, worker_id="w",
                       results=[oracle_result(p) for p in last.poses()])
        done, at, final = _marks(s, eid)
        assert final and at == done  # the finishing batch waited for the final table
        kept = stored(s, eid)
        current().maps.clear()  # a restarted process: read everything, write it whole
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert stored(s, eid) == kept and len(kept[0]) >= 2
    assert keeper.current_keeper().upkeep.refreshes > refreshes + 2


def test_off_lattice_poses_are_kept_apart_and_the_table_current(sessions, named_object) -> None:
    spec = ExplorationSpec(object_id=named_object("sphere"), gripper="robotiq_3f",
                           strategy={"name": "random", "poses": 60, "seed": 3},
                           refinement={"levels": 0},
                           grid={"dtheta": 0.6, "r_min": 0.0, "r_max": 0.02, "dr": 0.01})
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=20, max_poses=10**6).id
        for t in _leased(s):
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
        done, at, final = _marks(s, eid)
        assert done == 60 and at == 60 and final
        assert s.scalar(select(func.count()).select_from(ManifoldRow)
                        .where(ManifoldRow.exploration_id == eid)) == 0


def test_a_cancel_leaves_the_final_table_of_what_was_stored(sessions, named_object) -> None:
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
        tiles = _leased(s)
        for t in tiles[: len(tiles) // 2]:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
        assert not _marks(s, eid)[2]
        cancel_exploration(s, exploration_id=eid)
        done, at, final = _marks(s, eid)
        assert final and at == done > 0


def test_the_read_routes_never_write(client: TestClient, object_id: int, sessions) -> None:
    grid = {"dtheta": 0.6, "r_min": 0.0, "r_max": 0.02, "dr": 0.01, "attitudes": {"rolls": 2}}
    eid = client.post("/explorations", json={
        "object_id": object_id, "gripper": "robotiq_3f", "grid": grid,
        "strategy": {"name": "grid"}, "refinement": {"levels": 0}}).json()["id"]
    with sessions() as s:
        tiles = _leased(s)
        for t in tiles[: len(tiles) // 2]:  # behind the table: below REFRESH_MIN_POSES
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
        before = _marks(s, eid)
    assert before[0] > 0 and before[1] is None
    writes: list[str] = []

    def note(conn: Any, cursor: Any, statement: str, *args: Any) -> None:
        if statement.lstrip().split(None, 1)[0].upper() in ("INSERT", "UPDATE", "DELETE"):
            writes.append(statement)

    engine = client.app.state.engine
    event.listen(engine, "before_cursor_execute", note)
    try:
        for path in ("best?limit=3", "manifolds", "manifolds/A", "export/poses.csv",
                     "export/manifolds.json", "map.png", "poses?limit=5", ""):
            response = client.get(f"/explorations/{eid}/{path}".rstrip("/"))
            assert response.status_code in (200, 404), (path, response.text)
    finally:
        event.remove(engine, "before_cursor_execute", note)
    assert writes == []
    with sessions() as s:
        assert _marks(s, eid) == before
    progress = client.get(f"/explorations/{eid}").json()["progress"]
    assert progress["manifolds_lag_poses"] == before[0] and progress["manifolds_poses_done"] == 0


def test_the_sweep_catches_up_a_table_left_behind(sessions, named_object) -> None:
    # Stored without the keeper's turn (as after a crash between a batch's commit and its
    # refresh): the lease sweep's catch_up brings the finished exploration's table final.
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
        for t in _leased(s):
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()], keeper=None)
        done, at, final = _marks(s, eid)
        assert done > 0 and at is None and not final
        assert keeper.current_keeper().catch_up(s) >= 1
        done, at, final = _marks(s, eid)
        assert final and at == done
        assert keeper.current_keeper().catch_up(s) == 0  # nothing behind any more


def test_a_prefed_map_refreshes_to_the_whole_rewrite(sessions, named_object) -> None:
    # The keeper feeds the running map without the row lock (prefeed), then refreshes under
    # it: rows stored between the two are read by the refresh, the table is the whole
    # rewrite's.
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
        tiles = _leased(s)
        third = len(tiles) // 3
        for n, t in enumerate(tiles):
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()], keeper=None)
            if n == third:
                service.prefeed(s, eid)  # fed, nothing written
                assert _marks(s, eid)[1] is None
                state = service._state(s, eid)[1]
                running, fed = state.running, state.rows
                assert fed == _marks(s, eid)[0]
            if n == 2 * third:
                service.refresh_manifolds(s, eid)
                s.commit()
                assert _marks(s, eid)[1] == _marks(s, eid)[0]
                # the refresh read only the rows since the prefeed: the same map, not rebuilt
                assert state.running is running and state.rows == _marks(s, eid)[0]
                service.prefeed(s, eid)  # nothing new: nothing fed
                assert state.rows == _marks(s, eid)[0]
        service.prefeed(s, eid)
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        kept = stored(s, eid)
        current().maps.clear()
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert stored(s, eid) == kept and len(kept[0]) >= 2
