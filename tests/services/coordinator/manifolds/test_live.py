"""Refreshes that write only what changed (manifolds/live.py) leave the store as a whole
rewrite does: manifold rows, each pose's manifold and robust score, on both databases; and
the running map notices a store it did not write."""

from __future__ import annotations

import math

from graspscape.services.coordinator.exploration.scheduler import ingest_results
from graspscape.services.coordinator.exploration.service import create_exploration
from graspscape.services.coordinator.manifolds import service
from graspscape.services.coordinator.state import current
from graspscape.services.coordinator.store.models import ExplorationRow, ManifoldRow, PoseRow
from graspscape.services.coordinator.store.queue import lease_tiles
from graspscape.shared.specs.exploration import ExplorationSpec
from sqlalchemy import select

from tests.factories import oracle_result


def sphere_grid(named_object, *, dtheta_deg: float, r_max: float,  # type: ignore[no-untyped-def]
                rolls: int | None = None) -> ExplorationSpec:
    """A grid exploration of the built-in sphere, no refinement, r from 0 by 1 cm."""
    grid = {"dtheta": math.radians(dtheta_deg), "r_min": 0.0, "r_max": r_max, "dr": 0.01}
    if rolls is not None:
        grid["attitudes"] = {"rolls": rolls}
    return ExplorationSpec(object_id=named_object("sphere"), gripper="robotiq_3f",
                           strategy={"name": "grid"}, refinement={"levels": 0}, grid=grid)


def stored(s, eid: int) -> tuple:  # type: ignore[no-untyped-def]
    labels = dict(s.execute(select(ManifoldRow.id, ManifoldRow.label)
                            .where(ManifoldRow.exploration_id == eid)).all())
    rows = s.execute(select(ManifoldRow.label, ManifoldRow.size, ManifoldRow.best_pose_key,
                            ManifoldRow.summary, ManifoldRow.volume_cm3, ManifoldRow.large,
                            ManifoldRow.robust_best_key, ManifoldRow.signature)
                     .where(ManifoldRow.exploration_id == eid)
                     .order_by(ManifoldRow.label)).all()
    poses = s.execute(select(PoseRow.pose_key, PoseRow.manifold_id, PoseRow.robust_s,
                             PoseRow.robust_q, PoseRow.robust_label)
                      .where(PoseRow.exploration_id == eid).order_by(PoseRow.pose_key)).all()
    return ([tuple(r) for r in rows],
            [(k, labels.get(m), rs, rq, rl) for k, m, rs, rq, rl in poses])


def test_refreshes_tile_by_tile_store_the_whole_rewrite(sessions, named_object) -> None:
    spec = sphere_grid(named_object, dtheta_deg=45, r_max=0.02, rolls=2)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=16, max_poses=10**6).id
        tiles = []
        while leased := lease_tiles(s, worker_id="w", n=50, lease_seconds=60):
            tiles += leased
        assert len(tiles) >= 8
        for n, t in enumerate(tiles):
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
            if n % 3 == 0:
                s.commit()
                continue  # some tiles arrive between refreshes
            if n % 4 == 0:
                service.compute_map(s, eid)  # computed, written by the next refresh
            service.refresh_manifolds(s, eid)
            s.commit()
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        incremental = stored(s, eid)
        current().maps.clear()  # a restarted process: read everything, write it whole
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert stored(s, eid) == incremental
        assert len(incremental[0]) >= 2 and all(p[4] is not None for p in incremental[1])


def test_a_table_written_by_another_process_is_written_whole(sessions, named_object) -> None:
    spec = sphere_grid(named_object, dtheta_deg=45, r_max=0.01)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=10, max_poses=10**6).id
        tiles = lease_tiles(s, worker_id="w", n=50, lease_seconds=60)
        for t in tiles[:-1]:
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
        service.refresh_manifolds(s, eid)
        s.commit()
        # Someone else emptied the table (a migration, another coordinator).
        s.execute(ManifoldRow.__table__.delete().where(ManifoldRow.exploration_id == eid))
        s.get(ExplorationRow, eid).manifolds_poses_done = None
        s.commit()
        t = tiles[-1]
        ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                       results=[oracle_result(p) for p in t.poses()])
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        after = stored(s, eid)
        current().maps.clear()
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert stored(s, eid) == after
        assert all(m is not None for k, m, *_ in after[1]
                   if s.scalar(select(PoseRow.viable).where(PoseRow.pose_key == k,
                                                            PoseRow.exploration_id == eid)))


def test_a_restart_loads_the_saved_map_and_reads_only_the_rows_since(
        sessions, named_object, monkeypatch, tmp_path) -> None:
    from graspscape.services.coordinator.manifolds import snapshot

    monkeypatch.setenv(snapshot.ENV, str(tmp_path))
    monkeypatch.setattr(snapshot, "MIN_ROWS", 1)  # this map is small: save it anyway
    spec = sphere_grid(named_object, dtheta_deg=45, r_max=0.02, rolls=2)
    loaded: list = []
    load = snapshot.load
    monkeypatch.setattr(snapshot, "load", lambda *a: loaded.append(
        (got := load(*a), got and got.running, got and got.rows)) or got)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=16, max_poses=10**6).id
        tiles = []
        while leased := lease_tiles(s, worker_id="w", n=50, lease_seconds=60):
            tiles += leased

        def ingest(t) -> None:  # type: ignore[no-untyped-def]
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])

        for n, t in enumerate(tiles[:-1]):
            ingest(t)
            if n >= len(tiles) // 2:
                service.refresh_manifolds(s, eid)
                # Saved at the first: the later refreshes leave the store ahead of it.
                monkeypatch.setattr(snapshot, "SAVE_GROWTH", 1e9)
            s.commit()
        saved = list(tmp_path.iterdir())
        assert len(saved) == 1
        current().maps.clear()  # a restart
        ingest(tiles[-1])
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        state, running, rows = loaded[-1]
        # Loaded, then fed only the last tile's rows (a rebuild would replace the map).
        assert state is not None and state.running is running
        assert rows < state.rows == s.get(ExplorationRow, eid).poses_done
        after = stored(s, eid)
        # The same store as a map rebuilt from every row writes into an empty table.
        current().maps.clear()
        saved[0].unlink()
        s.execute(PoseRow.__table__.update().where(PoseRow.exploration_id == eid)
                  .values(manifold_id=None, robust_s=None, robust_q=None, robust_label=None))
        s.execute(ManifoldRow.__table__.delete().where(ManifoldRow.exploration_id == eid))
        s.get(ExplorationRow, eid).manifolds_poses_done = None
        s.commit()
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert loaded[-1][0] is None
        assert stored(s, eid) == after


def test_a_snapshot_of_another_exploration_or_format_is_not_used(tmp_path) -> None:
    from graspscape.services.coordinator.manifolds import snapshot

    (tmp_path / "x").mkdir()
    assert snapshot.directory("sqlite:////data/c.db") == snapshot.Path("/data/c.db.manifold-maps")
    path = snapshot._path(tmp_path, ("u", 1, "t"))
    path.write_bytes(b"not a pickle")
    assert snapshot.load(tmp_path, ("u", 1, "t")) is None
    import pickle

    path.write_bytes(pickle.dumps({"format": snapshot.code_version(),
                                   "key": repr(("u", 2, "t"))}))
    assert snapshot.load(tmp_path, ("u", 1, "t")) is None  # another key
    path.write_bytes(pickle.dumps({"format": "other code", "key": repr(("u", 1, "t"))}))
    assert snapshot.load(tmp_path, ("u", 1, "t")) is None  # another version of the code


def test_deleting_an_exploration_removes_its_saved_map(
        sessions, named_object, monkeypatch, tmp_path) -> None:
    from graspscape.services.coordinator.exploration.service import delete_exploration
    from graspscape.services.coordinator.manifolds import snapshot

    monkeypatch.setenv(snapshot.ENV, str(tmp_path))
    monkeypatch.setattr(snapshot, "MIN_ROWS", 1)
    spec = sphere_grid(named_object, dtheta_deg=90, r_max=0.01, rolls=1)
    with sessions() as s:
        eid = create_exploration(s, spec=spec, tile_target_poses=64, max_poses=10**6).id
        for t in lease_tiles(s, worker_id="w", n=50, lease_seconds=60):
            ingest_results(s, tile_id=t.tile_id, lease_epoch=t.lease_epoch, worker_id="w",
                           results=[oracle_result(p) for p in t.poses()])
        service.refresh_manifolds(s, eid, final=True)
        s.commit()
        assert len(list(tmp_path.iterdir())) == 1
        delete_exploration(s, exploration_id=eid)
        assert list(tmp_path.iterdir()) == []
