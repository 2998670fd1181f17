"""One keeper per exploration across coordinator processes (manifolds/keeper.py): two Keepers
on one database, standing in for two processes (they differ only in their id). The holder of
an exploration's lease refreshes its table; another process does not until the lease runs
out or the table is too far behind, and writes the final table whoever holds it; of two
taking a run out lease at once exactly one does; the table stays the whole rewrite's. On
SQLite and PostgreSQL."""

from __future__ import annotations

import threading
from datetime import timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient
from graspscape.services.coordinator import state
from graspscape.services.coordinator.app import create_app
from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds import keeper, service
from graspscape.services.coordinator.store.base import utcnow
from graspscape.services.coordinator.store.models import ExplorationRow
from sqlalchemy import select, update

from tests.factories import oracle_result
from tests.services.coordinator.manifolds.test_keeper import _leased, _marks
from tests.services.coordinator.manifolds.test_live import sphere_grid, stored


def _lease(s: Any, eid: int) -> tuple[str | None, Any]:
    s.rollback()  # a fresh read
    row = s.execute(select(ExplorationRow.manifolds_keeper,
                           ExplorationRow.manifolds_keeper_until)
                    .where(ExplorationRow.id == eid)).one()
    s.rollback()
    return row[0], row[1]


def _store(s: Any, tiles: list[Any], finisher: keeper.Keeper | None = None) -> None:
    for t in tiles:
        ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                       results=[oracle_result(p) for p in t.poses()], keeper=finisher)


def _the_whole_rewrite(s: Any, eid: int) -> None:
    kept = stored(s, eid)
    state.current().maps.clear()  # a restarted process: read everything, write it whole
    service.refresh_manifolds(s, eid, final=True)
    s.commit()
    assert stored(s, eid) == kept and len(kept[0]) >= 2


@pytest.mark.parametrize("finisher", ["holder", "other"])
def test_one_keeper_refreshes_another_takes_over_when_the_lease_runs_out(
        sessions, named_object, monkeypatch, finisher: str) -> None:
    monkeypatch.setattr(keeper, "REFRESH_MIN_POSES", 20)
    monkeypatch.setattr(keeper, "REFRESH_MAX_POSES", 40)
    first, second = keeper.Keeper(), keeper.Keeper()
    assert first.me != second.me
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    t0 = utcnow()
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
        tiles = _leased(s)
        quarter = len(tiles) // 4
        assert quarter * 8 >= 40  # each quarter makes a refresh due
        _store(s, tiles[:quarter])
        assert first.keep(s, eid, now=t0)
        holder, until = _lease(s, eid)
        assert holder == first.me and until >= t0 + timedelta(seconds=keeper.LEASE_S)

        _store(s, tiles[quarter:2 * quarter])
        before = _marks(s, eid)
        assert before[0] - before[1] >= keeper.due_after(before[1])  # due
        assert not second.keep(s, eid, now=t0 + timedelta(seconds=10))  # first keeps it
        assert second.catch_up(s, now=t0 + timedelta(seconds=10)) == 0
        assert _marks(s, eid) == before and second.upkeep.refreshes == 0
        assert first.keep(s, eid, now=t0 + timedelta(seconds=10))  # its own: renewed
        assert _lease(s, eid)[1] >= t0 + timedelta(seconds=10 + keeper.LEASE_S)

        _store(s, tiles[2 * quarter:3 * quarter])
        later = t0 + timedelta(seconds=10 + keeper.LEASE_S + 60)  # first's lease ran out
        state.current().maps.clear()  # the second process's map: the table read once (live._adopt)
        assert second.keep(s, eid, now=later)
        assert _lease(s, eid)[0] == second.me
        done, at, final = _marks(s, eid)
        assert at == done and not final
        _store(s, tiles[3 * quarter:-1])
        assert _marks(s, eid)[0] > done
        assert not first.keep(s, eid, now=later)  # second keeps it now
        assert _marks(s, eid)[1] == done

        # The finishing batch gets the final table whichever process stores it, and gives
        # the lease up.
        _store(s, tiles[-1:], finisher=second if finisher == "holder" else first)
        done, at, final = _marks(s, eid)
        assert final and at == done
        assert _lease(s, eid) == (None, None)
        assert not first.keep(s, eid) and not second.keep(s, eid)
        _the_whole_rewrite(s, eid)


def test_a_table_too_far_behind_is_taken_over(sessions, named_object, monkeypatch) -> None:
    monkeypatch.setattr(keeper, "REFRESH_MIN_POSES", 20)
    monkeypatch.setattr(keeper, "REFRESH_MAX_POSES", 40)
    monkeypatch.setattr(keeper, "MAX_LAG_POSES", 60)
    first, second = keeper.Keeper(), keeper.Keeper()
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    t0 = utcnow()
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
        tiles = _leased(s)
        _store(s, tiles[:6])
        assert first.keep(s, eid, now=t0)
        n = 6
        while (lag := _marks(s, eid)[0] - _marks(s, eid)[1]) <= 60:
            assert lag < 40 or not second.keep(s, eid, now=t0)  # first's lease holds
            _store(s, tiles[n:n + 1])
            n += 1
        assert n < len(tiles) - 1
        assert second.keep(s, eid, now=t0)  # more than MAX_LAG_POSES behind: taken over
        assert _lease(s, eid)[0] == second.me
        assert _marks(s, eid)[1] == _marks(s, eid)[0]
        assert second.release(s) == 1 and _lease(s, eid) == (None, None)
        assert first.release(s) == 0
        _store(s, tiles[n:], finisher=first)
        assert _marks(s, eid)[2]
        _the_whole_rewrite(s, eid)


def test_of_two_taking_a_run_out_lease_at_once_exactly_one_does(
        sessions, named_object) -> None:
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    racers = [keeper.Keeper(), keeper.Keeper()]
    t0 = utcnow()
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
    for round_ in range(12):
        with sessions() as s:  # a lease held by a process gone since
            s.execute(update(ExplorationRow).where(ExplorationRow.id == eid).values(
                manifolds_keeper="gone", manifolds_keeper_until=t0 - timedelta(seconds=1)))
            s.commit()
        start = threading.Barrier(len(racers))
        won: dict[str, bool] = {}

        def race(k: keeper.Keeper, start: threading.Barrier, won: dict[str, bool]) -> None:
            with sessions() as mine:
                start.wait(timeout=30)
                won[k.me] = k._take(mine, eid, t0, force=False)

        threads = [threading.Thread(target=race, args=(k, start, won)) for k in racers]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=60)
        assert sorted(won.values()) == [False, True], round_
        with sessions() as s:
            assert _lease(s, eid)[0] == next(me for me, w in won.items() if w)


def test_a_coordinator_gives_its_leases_back_when_it_stops(
        settings, sessions, named_object, monkeypatch) -> None:
    monkeypatch.setattr(keeper, "REFRESH_MIN_POSES", 20)
    spec = sphere_grid(named_object, dtheta_deg=30, r_max=0.02, rolls=2)
    app = create_app(settings)
    apps_keeper = state.of(app).keeper
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=8, max_poses=10**6).id
        _store(s, _leased(s)[:4], finisher=apps_keeper)
        assert _lease(s, eid)[0] == apps_keeper.me
    with TestClient(app):
        pass
    with sessions() as s:
        assert _lease(s, eid) == (None, None)
